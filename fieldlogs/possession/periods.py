"""On-rail periods of a road-rail run and the GPS analysis of each [S001 §3.1, §4.2].

**On rail** = PTO on (``cab.pto``, carried forward; off before the first event). A run
without any PTO value counts as on rail throughout (fail-safe). Each on-rail period is
analysed on its own (the GPS decision state starts afresh, as the vehicle may come back on
another track); the fixes of the ``lead_s`` before PTO on (the approach on the road) feed the
trust filter and the km estimate but are no evidence for the up/down decision.

**Up/down decision** = the pipeline's GPS analysis (:mod:`fieldlogs.pipeline.gps`): a
sequential likelihood-ratio test on the mean offset of *trusted* D-GPS fixes (5/15/30 s RMS
filter), decided as soon as the evidence suffices, otherwise *undecided* — never guessed
[S001 §4.2]. Beside it, the test's statistics over the first ``decision_target_s`` on rail
(:func:`fieldlogs.pipeline.gps.analysis.track_odds`) say where the evidence leans. Fixes the analysis
does not use (fix 1, high HDOP) are map-matched too (:func:`with_degraded_fixes`): they serve
the km filter as coarse measurements, never the decision.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from dbtools.gis.matching import TrackIndex, track_index_for
from dbtools.network import Network
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.cycles import build_cycles
from fieldlogs.pipeline.gps.analysis import TrackOdds, analyse_gps, track_odds
from fieldlogs.pipeline.gps.trust import trust_filter
from fieldlogs.pipeline.types import GpsAnalysis
from fieldlogs.possession.config import PossessionConfig
from fieldlogs.possession.tacho import Tacho


@dataclass
class RailPeriod:
    """One on-rail period and the GPS analysis of its fixes (from ``t_on − lead_s``)."""

    t_on: float
    t_off: float
    gps: GpsAnalysis
    tacho: Tacho | None = None
    """The run's usable tacho (:func:`fieldlogs.possession.tacho.tacho_track`), None without
    one; only its on-rail part is used."""
    odds: list[TrackOdds] = field(default_factory=list)
    """The up/down test's statistics over the first ``decision_target_s`` on rail
    (:func:`fieldlogs.pipeline.gps.analysis.track_odds`, likeliest first): where the evidence leans."""


def rail_periods(cab: pd.DataFrame | None, t_end: float, t_start: float = 0.0) -> list[tuple[float, float]]:
    """(t_on, t_off) of every PTO-on period; the whole run when there is no PTO value."""
    if not _has_pto(cab):
        return [(t_start, t_end)] if t_end > t_start else []
    assert cab is not None
    c = cab[cab["t"].notna()].sort_values("t", kind="stable")
    t = c["t"].to_numpy(dtype=float)
    pto = c["pto"].astype("Float64").ffill().fillna(0).to_numpy(dtype=float) > 0.5
    out: list[tuple[float, float]] = []
    on_since: float | None = None
    for tt, p in zip(t, pto, strict=True):
        if p and on_since is None:
            on_since = float(tt)
        elif not p and on_since is not None:
            if tt > on_since:
                out.append((on_since, float(tt)))
            on_since = None
    if on_since is not None and t_end > on_since:
        out.append((on_since, t_end))
    return out


def _has_pto(cab: pd.DataFrame | None) -> bool:
    return cab is not None and bool(len(cab)) and "pto" in cab.columns and not cab["pto"].isna().all()


def with_degraded_fixes(ga: GpsAnalysis, index: TrackIndex, gps_cfg: GpsConfig) -> GpsAnalysis:
    """Map-match the fixes the GPS analysis does not use (fix 1, high HDOP) so that they can
    serve as coarse km measurements; adds a ``degraded`` column. The up/down decision is untouched."""
    f = ga.fixes.copy()
    t = f["t"].to_numpy(dtype=float)
    lat, lon = f["lat"].to_numpy(dtype=float), f["lon"].to_numpy(dtype=float)
    usable = f["usable"].to_numpy(dtype=bool)
    inc = np.ones(t.size, dtype=bool)
    inc[1:] = t[1:] > t[:-1]
    deg = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(t) & (f["fix"].to_numpy() >= 1) & ~usable & inc
    f["degraded"] = deg
    if deg.any():
        both = usable | deg
        x, y = index.to_xy(np.where(both, lat, np.nan), np.where(both, lon, np.nan))
        _, rms = trust_filter(t, x, y, both, gps_cfg)
        for w, r in rms.items():
            col = f"rms_{w}"
            if col in f.columns:
                f.loc[deg, col] = r[deg]
        rows = np.flatnonzero(deg)
        m = index.match_xy(x[rows], y[rows], max_offset_m=gps_cfg.max_offset_m)
        m = m[m["best"].to_numpy()]
        at = rows[m["fix"].to_numpy()]
        f.loc[at, "km_m"] = m["km_m"].to_numpy()
        f.loc[at, "offset_m"] = m["offset_m"].to_numpy()
        f.loc[at, "line_code"] = m["line_code"].astype(str).to_numpy()
        f.loc[at, "track"] = m["track"].astype(str).to_numpy()
    return GpsAnalysis(f, ga.decisions, ga.crossovers)


def _by_time(frame: pd.DataFrame | None) -> pd.DataFrame | None:
    if frame is None:
        return None
    return frame[frame["t"].notna()].sort_values("t", kind="stable").reset_index(drop=True)


def analyse_periods(
    gps: pd.DataFrame | None,
    cab: pd.DataFrame | None,
    network: Network,
    gps_cfg: GpsConfig,
    cfg: PossessionConfig,
    tacho: Tacho | None = None,
) -> list[RailPeriod]:
    """Every on-rail period of a run with the GPS analysis of its fixes (module docstring)."""
    gps, cab = _by_time(gps), _by_time(cab)
    present = [s for s in (gps, cab) if s is not None and len(s)]
    t_end = max((float(s["t"].iloc[-1]) for s in present), default=0.0)
    t_start = min((float(s["t"].iloc[0]) for s in present), default=0.0)
    spans = rail_periods(cab, t_end, t_start)
    cycles = build_cycles(tacho=None, imu=None, cab=cab, wheel_diameter_m=1.0, teeth=1, t_end=t_end)
    if not _has_pto(cab):
        cycles.pto[:] = 1
    index = track_index_for(network)
    periods = []
    for t_on, t_off in spans:
        if gps is not None and len(gps):
            tt = gps["t"].to_numpy(dtype=float)
            sl = gps[(tt >= t_on - cfg.lead_s) & (tt <= t_off)].reset_index(drop=True)
        else:
            sl = None
        ga = analyse_gps(sl, network, gps_cfg, cycles, index=index)
        odds = track_odds(ga.fixes, index, gps_cfg, t_on, t_on + cfg.decision_target_s)
        periods.append(RailPeriod(t_on, t_off, with_degraded_fixes(ga, index, gps_cfg), tacho, odds))
    return periods


def period_line(fixes: pd.DataFrame, t_on: float, max_offset: float) -> str | None:
    """The period's line: the line most of its matched fixes (on rail, else all) lie on."""
    ok = fixes["km_m"].notna() & (fixes["offset_m"].abs() <= max_offset) & fixes["line_code"].notna()
    on = ok & (fixes["t"] >= t_on)
    sel = fixes.loc[on if on.any() else ok, "line_code"]
    if sel.empty:
        return None
    return str(Counter(sel.astype(str)).most_common(1)[0][0])
