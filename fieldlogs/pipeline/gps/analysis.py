"""The GPS analysis of one run [S001 §4.2; SPEC §5.4].

**Usable fixes.** fix ≥ ``min_fix`` (D-GPS), HDOP ≤ ``max_hdop`` (missing HDOP is no
reason to drop a fix), finite lat/lon, a time stamp later than the previous fix's. Every
usable fix is map-matched (:mod:`dbtools.gis.matching`) to *all* tracks within
``max_offset_m``: km on the nearest segment of each track and the signed offset (positive
left of increasing km).

If ``cycles`` are given, fixes while the PTO says off-rail (road-rail vehicles on the road)
are matched and reported but are no evidence for decisions or crossovers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from dbtools.gis.matching import TrackIndex, track_index_for
from dbtools.network import Network
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.gps.decision import decide, decided_columns
from fieldlogs.pipeline.gps.evidence import Evidence, windows
from fieldlogs.pipeline.gps.trust import trust_filter
from fieldlogs.pipeline.types import FloatArray, GpsAnalysis

#: Fixed columns of ``GpsAnalysis.fixes``; one ``rms_<w>`` column per trust window follows
#: ``offset_m`` and the decided-track columns come last.
FIX_COLUMNS = ("t", "lat", "lon", "fix", "usable", "trusted", "line_code", "track", "km_m", "offset_m")
DECIDED_COLUMNS = ("decided_line_code", "decided_track", "decided_km_m", "decided_offset_m")


def analyse_gps(
    gps: pd.DataFrame | None,
    network: Network,
    cfg: GpsConfig,
    cycles: Cycles | None = None,
    *,
    index: TrackIndex | None = None,
) -> GpsAnalysis:
    """Trust, map-matching, up/down decisions and crossovers of one run's GPS stream.

    ``fixes`` has one row per GPS row (sorted by t): ``t, lat, lon, fix, usable, trusted,
    line_code, track, km_m, offset_m`` (nearest track), ``rms_<w>`` per trust window and
    ``decided_line_code, decided_track, decided_km_m, decided_offset_m`` (the decision in
    force and the fix's km/offset on that track). A missing stream gives an empty analysis.
    """
    if gps is None or not len(gps):
        return GpsAnalysis(_empty_fixes(cfg))
    if index is None:
        index = track_index_for(network)
    df = gps.sort_values("t", kind="stable").reset_index(drop=True)
    n = len(df)
    t = _col(df, "t")
    lat, lon = _col(df, "lat"), _col(df, "lon")
    fixq = np.nan_to_num(_col(df, "fix"), nan=0.0)
    hdop = _col(df, "hdop")
    usable = np.isfinite(t) & np.isfinite(lat) & np.isfinite(lon) & (fixq >= cfg.min_fix) & ~(hdop > cfg.max_hdop)
    usable[1:] &= t[1:] > t[:-1]
    x, y = index.to_xy(np.where(usable, lat, np.nan), np.where(usable, lon, np.nan))
    x = np.where(usable, x, np.nan)
    y = np.where(usable, y, np.nan)

    trusted, rms = trust_filter(t, x, y, usable, cfg)
    matches = index.match_xy(x, y, max_offset_m=cfg.max_offset_m)
    best = matches[matches["best"].to_numpy()]
    bf = best["fix"].to_numpy()
    line_code = np.full(n, None, dtype=object)
    track = np.full(n, None, dtype=object)
    km = np.full(n, np.nan)
    off = np.full(n, np.nan)
    line_code[bf] = best["line_code"].astype(str).to_numpy()
    track[bf] = best["track"].astype(str).to_numpy()
    km[bf] = best["km_m"].to_numpy()
    off[bf] = best["offset_m"].to_numpy()

    on_rail = np.ones(n, dtype=bool)
    if cycles is not None and cycles.n:
        i = np.clip(np.searchsorted(cycles.t, t, side="right") - 1, 0, cycles.n - 1)
        on_rail = cycles.pto[i] == 1
    evidence = trusted & on_rail & np.isin(np.arange(n), bf)
    ev = Evidence.build(t, evidence, matches, index)
    decisions, crossovers, periods = decide(ev, index, cfg)

    out = pd.DataFrame(
        {
            "t": t,
            "lat": lat,
            "lon": lon,
            "fix": fixq.astype(np.int64),
            "usable": usable,
            "trusted": trusted,
            "line_code": pd.array(line_code, dtype="string"),
            "track": pd.array(track, dtype="string"),
            "km_m": km,
            "offset_m": off,
        }
    )
    for w, r in rms.items():
        out[f"rms_{w}"] = r
    decided_columns(out, periods, matches, index)
    return GpsAnalysis(out, decisions, crossovers)


@dataclass(frozen=True)
class TrackOdds:
    """Evidence for one candidate track over a window (see :func:`track_odds`)."""

    line_code: str
    track: str
    n_fixes: int
    mean_offset_m: float
    sigma_m: float
    llr: float
    """min over the other candidates b of (m_b² − m_j²)/(2 SE_j²): > 0 = this track is the
    likeliest; ≥ ln(1/``decide_error``) would decide it."""


def track_odds(
    fixes: pd.DataFrame, network: Network | TrackIndex, cfg: GpsConfig, t_from: float, t_to: float
) -> list[TrackOdds]:
    """The up/down test's statistics over the trusted fixes in (t_from, t_to] of ``fixes``
    (an :func:`analyse_gps` table), per candidate track, likeliest first — where the
    evidence leans when it does not (yet) decide. Empty without trusted matched fixes."""
    if not len(fixes):
        return []
    t = _col(fixes, "t")
    sel = (t > t_from) & (t <= t_to) & fixes["trusted"].fillna(False).to_numpy(dtype=bool)
    if not sel.any():
        return []
    index = network if isinstance(network, TrackIndex) else track_index_for(network)
    ts = t[sel]
    x, y = index.to_xy(_col(fixes, "lat")[sel], _col(fixes, "lon")[sel])
    matches = index.match_xy(x, y, max_offset_m=cfg.max_offset_m)
    if not len(matches):
        return []
    ev = Evidence.build(ts, np.isin(np.arange(ts.size), matches["fix"].to_numpy()), matches, index)
    if ev.size == 0:
        return []
    w = windows(ev, np.array([ev.size - 1]), 0, cfg, float(t_to - t_from))
    out = [
        TrackOdds(
            index.keys[int(tid)][0],
            index.keys[int(tid)][1],
            int(w.n[0, j]),
            float(w.mean[0, j]),
            float(np.sqrt(w.se2[0, j])),
            float(w.llr[0, j]),
        )
        for j, tid in enumerate(ev.tracks)
        if w.n[0, j] > 0
    ]
    return sorted(out, key=lambda o: -o.llr)


def _col(df: pd.DataFrame, name: str) -> FloatArray:
    if name not in df.columns:
        return np.full(len(df), np.nan)
    return pd.to_numeric(df[name], errors="coerce").to_numpy(dtype=float, na_value=np.nan)


def _empty_fixes(cfg: GpsConfig) -> pd.DataFrame:
    cols: dict[str, pd.Series] = {c: pd.Series([], dtype=float) for c in FIX_COLUMNS}
    cols["fix"] = pd.Series([], dtype=np.int64)
    cols["usable"] = pd.Series([], dtype=bool)
    cols["trusted"] = pd.Series([], dtype=bool)
    for c in ("line_code", "track"):
        cols[c] = pd.Series([], dtype="string")
    for w in cfg.windows_s:
        cols[f"rms_{w}"] = pd.Series([], dtype=float)
    for c in DECIDED_COLUMNS:
        cols[c] = pd.Series([], dtype="string" if c in ("decided_line_code", "decided_track") else float)
    return pd.DataFrame(cols)
