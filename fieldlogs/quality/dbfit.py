"""Does a run belong to the DB it is replayed with? (issue 32 item 11)

A run replayed with the DB of another network (a Swiss DB for a Japanese run) used to exit 0
with "route —, first determined never" and no word: every telegram unknown, every GPS fix
far away. Before positioning, the run's own evidence is held against the DB:

* GPS: of the run's fixes (fix ≥ 1, finite lat/lon), none lies within the DB's GIS
  bounding box ± ``CheckLimits.area_margin_m`` (the margin ``logs check --db`` uses), and
  there are at least :data:`MIN_FIXES` of them;
* balises: of the I1 telegrams with a line code, none names a line of the DB.

Either, with no evidence that fits, is a ``run.db_mismatch`` error (exit 1): the run is not on
this network. Evidence that fits on one side (some fixes in the area, or one known line)
keeps the run: a short excursion or a few foreign telegrams are ``logs check``'s warnings.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.quality.checks import CheckLimits, DbRefs, area_box
from fieldlogs.runs.handle import Run
from schemas.enums import BaliseKind, Severity
from schemas.errors import FindingsError
from schemas.findings import Finding

#: Fewest GPS fixes that can show a run lies off the DB's network.
MIN_FIXES = 10


def _gps_fit(gps: pd.DataFrame | None, refs: DbRefs, margin_m: float) -> tuple[int, int]:
    """(fixes, fixes inside the DB's area ± margin)."""
    box = area_box(refs, margin_m)
    if gps is None or box is None or gps.empty or not {"lat", "lon", "fix"} <= set(gps.columns):
        return 0, 0
    lat = gps["lat"].to_numpy(dtype=float, na_value=np.nan)
    lon = gps["lon"].to_numpy(dtype=float, na_value=np.nan)
    fix = gps["fix"].to_numpy(dtype=float, na_value=0.0)
    ok = (fix >= 1) & np.isfinite(lat) & np.isfinite(lon)
    inside = ok & (lat >= box[0]) & (lat <= box[1]) & (lon >= box[2]) & (lon <= box[3])
    return int(ok.sum()), int(inside.sum())


def _balise_fit(balise: pd.DataFrame | None, refs: DbRefs) -> tuple[int, int]:
    """(I1 telegrams with a line code, of which naming a line of the DB)."""
    if balise is None or balise.empty or "line_code" not in balise.columns:
        return 0, 0
    i1 = balise[(balise["kind"] == BaliseKind.I1.value).to_numpy(dtype=bool, na_value=False)]
    codes = i1["line_code"].dropna().astype(str)
    return len(codes), int(codes.isin(list(refs.line_codes)).sum())


def db_fit_findings(run: Run, network: Network, limits: CheckLimits | None = None) -> list[Finding]:
    """``run.db_mismatch`` findings (module docstring); empty when the run fits or cannot tell."""
    limits = limits or CheckLimits()
    refs = network.cached(("db_refs",), lambda: DbRefs.from_network(network))
    n_fix, fix_in = _gps_fit(run.stream("gps") if run.has("gps") else None, refs, limits.area_margin_m)
    n_i1, i1_known = _balise_fit(run.stream("balise") if run.has("balise") else None, refs)
    if fix_in or i1_known:
        return []
    out: list[Finding] = []
    if n_fix >= MIN_FIXES:
        out.append(
            Finding(
                "run.db_mismatch",
                Severity.ERROR,
                "gps",
                f"none of the run's {n_fix} GPS fixes lies within the DB's area ± {limits.area_margin_m:g} m "
                f"({refs.origin}): the run is not on this DB's network",
                file=str(run.stream_file("gps") or run.folder),
                column="lat",
                limit=area_box(refs, limits.area_margin_m),
            )
        )
    if n_i1:
        out.append(
            Finding(
                "run.db_mismatch",
                Severity.ERROR,
                "balise",
                f"none of the run's {n_i1} I1 telegrams names a line of the DB ({refs.origin}): "
                "the run is not on this DB's network",
                file=str(run.stream_file("balise") or run.folder),
                column="line_code",
            )
        )
    return out


def require_db_fit(run: Run, network: Network) -> None:
    """FindingsError (exit 1) when the run's evidence shows it is not on the DB's network."""
    problems = db_fit_findings(run, network)
    if problems:
        raise FindingsError(f"the run does not fit the DB: {problems[0].message}", problems, path=run.folder)
