"""GIS height rules (SPEC §3; needed by track-constrained GNSS [S002], SPEC §5.6).

The rail height ``height_m`` of the 20 m grid is optional, but where a line/track has it, it
is the vertical part of the 3-D track the GNSS solver constrains the antennas to, so it must
be complete and smooth. Per line/track, points sorted by km, over *regular* steps only (km
difference equal to the grid spacing; a kilometrage break is no step of the track):

* grade g_j = (h_{j+1} − h_j) / Δkm_j [‰] — the steepest adhesion main lines are ~35 ‰
  (SPEC §5.1: Ta is its gravity component), a few mountain lines reach 60–80 ‰;
* vertical curvature κ_j = (g_j − g_{j−1}) / ((Δkm_{j−1} + Δkm_j)/2) [1/m] between two
  consecutive regular steps, i.e. 1/R of the vertical curve — railways use R ≥ 2,000–4,000 m
  (conventional lines; more on high-speed lines); a single point 0.5 m off gives R ≈ 400 m.

Rules:

* ``gis.height_partial`` (error) — ``height_m`` is given on some but not all points of a
  line/track (the GNSS aid refuses such a track); reported once per line/track with the first
  empty row. Fix: fill ``height_m`` on every point of the line/track, or empty it everywhere.
* ``gis.height_grade`` (warning / error) — |g| above ``height_grade_warning_permille`` (an
  unusual gradient: check the survey) / ``height_grade_error_permille`` (no railway). Fix:
  check the survey's heights of that stretch and correct the wrong ones.
* ``gis.height_curvature`` (warning / error) — |κ| above 1/``height_radius_warning_m`` /
  1/``height_radius_error_m`` (a spike or a step in the heights). Fix: correct the height of
  the point (a spike or a step), or smooth the survey.
* ``gis.height_datum`` (warning) — heights present but the DB meta declares them orthometric
  (``height_datum``; ``geoid_model``): the GNSS aid needs ellipsoidal heights and no geoid model
  is shipped. A DB whose meta does not state the datum is taken as ellipsoidal, which is what the
  ``gis.height_m`` column declares; no finding. Fix: convert the heights to ellipsoidal
  heights and set ``height_datum`` to ``ellipsoidal``.

Consecutive offending steps of one line/track are reported as one finding per stretch (the
first point, the stretch's extreme value and its length in points).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis import index as grid_blocks
from dbtools.gis.index import GridIndex
from dbtools.network import sorted_by
from dbtools.rules.common import Locator, capped, fmt_km, py
from dbtools.rules.config import ValidationConfig
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.tables import GIS

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: The order the rules read the points in: by line, track and km (the GIS key).
_ORDER = ("line_code", "track", "km_m")


def check_heights(
    gis: pd.DataFrame,
    meta: Mapping[str, str],
    config: ValidationConfig,
    loc: Locator,
    grid: GridIndex | None = None,
) -> list[Finding]:
    """All height rules (module docstring). ``grid``: the frame's grid index, if built — when
    every row is one of its points, in its order (a DB's frame), its track ids are the rows'
    (line, track) keys: no sort, no factorizing, no copy of the frame."""
    if "height_m" not in gis.columns or not gis["height_m"].notna().any():
        return []
    if grid is not None and grid.gis is gis and grid.whole_frame:
        g, key, pos = gis, grid.tid, None  # row j is point j
    else:
        g = gis.reset_index(drop=True).assign(_pos=np.arange(len(gis)))
        if not sorted_by(g, _ORDER):  # a Network's frame is (canonical): no sort, no copy
            g = g.sort_values(list(_ORDER), kind="stable")
        key, pos = _track_key(g), g["_pos"].to_numpy(dtype=np.int64)
    out = _datum(meta, loc)
    out += _partial(g, key, pos, config, loc)
    steps = _steps(g, key, pos, config)
    for rule, values, warn, err, what in (
        ("gis.height_grade", steps["grade"], config.height_grade_warning_permille, config.height_grade_error_permille,
         "grade"),
        ("gis.height_curvature", steps["curv_radius"], config.height_radius_warning_m, config.height_radius_error_m,
         "vertical curve radius"),
    ):  # fmt: skip
        out += _limits(rule, what, steps, values, warn, err, config, loc)
    return out


def _datum(meta: Mapping[str, str], loc: Locator) -> list[Finding]:
    datum = str(meta.get("height_datum") or "ellipsoidal")
    if datum == "ellipsoidal":
        return []
    geoid = str(meta.get("geoid_model") or "")
    return [
        Finding(
            "gis.height_datum",
            Severity.WARNING,
            GIS.name,
            f"heights are {datum}{f' ({geoid})' if geoid else ''}: track-constrained GNSS needs ellipsoidal "
            "heights and refuses this DB",
            value=datum,
            limit="ellipsoidal",
            column="height_m",
            file=loc.file(GIS.name),
        )
    ]


def _track_key(g: pd.DataFrame) -> I64:
    """One integer per (line_code, track) pair of each row, equal for equal pairs; a row
    missing either gets a key of its own (negative), equal to no other row's."""
    lc, _ = pd.factorize(g["line_code"])
    tc, tu = pd.factorize(g["track"])
    key = lc.astype(np.int64) * (len(tu) + 1) + tc
    missing = (lc < 0) | (tc < 0)
    key[missing] = -1 - np.flatnonzero(missing)
    return np.asarray(key, dtype=np.int64)


def _partial(g: pd.DataFrame, key: I64, pos: I64 | None, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """``gis.height_partial`` per line/track in key order (the rows of a pair are
    consecutive in ``g``, sorted by line, track and km; pairs with a missing key are left
    out, as ``groupby`` leaves them)."""
    has = g["height_m"].notna().to_numpy(dtype=bool)
    n = len(g)
    starts = np.flatnonzero(np.concatenate([[True], key[1:] != key[:-1]])) if n else np.zeros(0, dtype=np.int64)
    ends = np.append(starts[1:], n)
    n_has = np.add.reduceat(has.astype(np.int64), starts) if n else np.zeros(0, dtype=np.int64)
    partial = np.flatnonzero((key[starts] >= 0) & (n_has > 0) & (n_has < ends - starts))
    km_m = g["km_m"].to_numpy(dtype=float)
    out: list[Finding] = []
    for r in partial[: config.max_findings_per_rule]:
        a, b = int(starts[r]), int(ends[r])
        row = a + int(np.flatnonzero(~has[a:b])[0])
        line, track = g["line_code"].iat[row], g["track"].iat[row]
        km = float(km_m[row])
        out.append(
            Finding(
                "gis.height_partial",
                Severity.ERROR,
                GIS.name,
                f"height_m is given on {int(n_has[r])} of {b - a} points of {line}/{track}; the first empty one is "
                f"km {fmt_km(km)}",
                keys={"line_code": py(line), "track": py(track), "km_m": km},
                value=int(n_has[r]),
                limit=b - a,
                column="height_m",
                **loc.at(GIS.name, _row(pos, row)),
            )
        )
    return out


def _steps(g: pd.DataFrame, key: I64, pos: I64 | None, config: ValidationConfig) -> dict[str, Any]:
    """Per step j (point j → j+1 of one line/track): grade [‰] and, at point j+1, the radius of
    the vertical curve between steps j and j+1 [m] (NaN where not both regular). ``BLOCK``
    steps at a time: the two results and block-sized temporaries."""
    km = g["km_m"].to_numpy(dtype=float)
    h = g["height_m"].to_numpy(dtype=float, na_value=np.nan)
    n = max(km.size - 1, 0)
    grade, radius, regular = np.empty(n), np.full(n, np.nan), np.empty(n, dtype=bool)
    with np.errstate(invalid="ignore", divide="ignore"):
        for a in range(0, n, grid_blocks.BLOCK):  # grade Δh / Δkm on regular steps, NaN elsewhere
            b = min(a + grid_blocks.BLOCK, n)
            dkm = km[a + 1 : b + 1] - km[a:b]
            off = np.abs(dkm - config.gis_spacing_m)
            reg = regular[a:b]
            np.logical_and(key[a + 1 : b + 1] == key[a:b], off <= config.km_epsilon_m, out=reg)
            part = grade[a:b]
            np.subtract(h[a + 1 : b + 1], h[a:b], out=part)
            part /= dkm
            part[~reg] = np.nan
        for a in range(1, n, grid_blocks.BLOCK):  # |1 / κ|, κ = Δgrade / mean Δkm of two regular steps
            b = min(a + grid_blocks.BLOCK, n)
            curv = radius[a:b]
            np.subtract(grade[a:b], grade[a - 1 : b - 1], out=curv)
            half = (km[a + 1 : b + 1] - km[a:b]) + (km[a:b] - km[a - 1 : b - 1])
            half *= 0.5
            curv /= half
            curv[~(regular[a:b] & regular[a - 1 : b - 1])] = np.nan
            np.divide(1.0, curv, out=curv)
            np.abs(curv, out=curv)
        np.abs(grade, out=grade)
        grade *= 1000.0
    return {
        "grade": grade,
        "curv_radius": radius,
        "pos": pos,
        "km": km,
        "key": key,
        "line": g["line_code"].array,
        "track": g["track"].array,
    }


def _row(pos: I64 | None, i: int) -> int:
    """The frame's row of the ``i``-th point in key order (``pos`` None: the same)."""
    return i if pos is None else int(pos[i])


def _stretches(bad: npt.NDArray[np.bool_], key: npt.NDArray[Any]) -> list[tuple[int, int]]:
    """(first, last) step index of each run of consecutive offending steps of one line/track."""
    idx = np.flatnonzero(bad)
    if not idx.size:
        return []
    new = np.concatenate([[True], (np.diff(idx) > 1) | (key[idx[1:]] != key[idx[:-1]])])
    starts = np.flatnonzero(new)
    ends = np.concatenate([starts[1:], [idx.size]]) - 1
    return [(int(idx[a]), int(idx[b])) for a, b in zip(starts, ends, strict=True)]


def _limits(
    rule: str,
    what: str,
    st: dict[str, Any],
    values: F64,
    warn: float,
    err: float,
    config: ValidationConfig,
    loc: Locator,
) -> list[Finding]:
    radius = what.startswith("vertical")
    with np.errstate(invalid="ignore"):
        bad = (values < warn) if radius else (values > warn)
    runs = _stretches(np.nan_to_num(bad, nan=False).astype(bool), st["key"])
    unit = "m" if radius else "‰"

    def build(r: int) -> Finding:
        a, b = runs[r]
        seg = values[a : b + 1]
        worst = float(np.nanmin(seg) if radius else np.nanmax(seg))
        severe = worst < err if radius else worst > err
        p = a if radius else a + 1  # the curvature lives at a point, the grade between two
        limit = err if severe else warn
        return Finding(
            rule,
            Severity.ERROR if severe else Severity.WARNING,
            GIS.name,
            f"{what} {worst:.1f} {unit} at km {fmt_km(st['km'][p])} of {st['line'][p]}/{st['track'][p]} "
            f"({b - a + 1} point(s)); {'at least' if radius else 'at most'} {limit:g} {unit} expected",
            keys={"line_code": py(st["line"][p]), "track": py(st["track"][p]), "km_m": py(st["km"][p])},
            value=round(worst, 3),
            limit=limit,
            column="height_m",
            **loc.at(GIS.name, _row(st["pos"], p)),
        )

    return capped(rule, Severity.WARNING, GIS.name, np.arange(len(runs)), build, config.max_findings_per_rule,
                  loc.file(GIS.name))  # fmt: skip
