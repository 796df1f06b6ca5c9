"""The up/down decision state machine [S001 §4.2; SPEC §5.4].

A track j is decided when n ≥ ``decide_min_fixes`` over ≥ ``decide_min_duration_s``, share_j ≥
``decide_min_share``, the track fits (|m_j| ≤ ``decide_fit_z``·SE_j and ≤
``decide_max_mean_m``: not between two tracks, not beside one) and LLR_jb ≥ ln(1/``decide_error``)
against every other candidate b (as in Wald's sequential test, the chance of ever deciding
the wrong track is then of the order of ``decide_error``). The test is re-evaluated at
every trusted fix ("as soon as the evidence suffices"), on the ``decide_window_s`` window and
on the last ``decide_recent_s`` (30 s) alone — older fixes that a slow error put between the
tracks must not hold back what the recent ones show; weak evidence leaves the run
*undecided* rather than wrong.
A :class:`TrackDecision` carries the km of the last fix on the decided track and
km_dir = sign of the km change over the evidence window (0 if below ``km_dir_min_m``).
After a decision nothing is emitted while the evidence agrees; another track is emitted
only when it passes the test with ``redecide_factor`` × the LLR threshold — or the normal
threshold after a detected crossover, when the next decision is always emitted (even for
the same track, which tells the GPS aid the crossover was not one).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from dbtools.gis.matching import TrackIndex
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.gps.crossover import crossing, partner
from fieldlogs.pipeline.gps.evidence import Evidence, Window, merge_windows, windows
from fieldlogs.pipeline.types import Event, TrackDecision
from schemas.enums import EventType

#: Evidence rows examined per vectorised step of the decision state machine.
CHUNK = 2048


def decide(
    ev: Evidence, index: TrackIndex, cfg: GpsConfig
) -> tuple[list[TrackDecision], list[Event], list[tuple[float, int]]]:
    """The decision state machine over the evidence rows (vectorised in chunks)."""
    decisions: list[TrackDecision] = []
    crossovers: list[Event] = []
    periods: list[tuple[float, int]] = []  # (t from, track id) of the decision in force
    if ev.size == 0 or ev.tracks.size == 0:
        return decisions, crossovers, periods
    thr = float(np.log(1.0 / cfg.decide_error))
    current: int | None = None  # column of the decided track
    pending = False  # a crossover was detected since the last decision
    reset_lo = 0
    pos = 0
    keys = index.keys
    while pos < ev.size:
        i = np.arange(pos, min(pos + CHUNK, ev.size))
        need = thr if (current is None or pending) else thr * cfg.redecide_factor
        w = windows(ev, i, reset_lo, cfg, cfg.decide_window_s)
        cand = w.ok & (w.llr >= need)
        if 0.0 < cfg.decide_recent_s < cfg.decide_window_s:
            # the recent fixes alone may decide when older ones were ambiguous
            wr = windows(ev, i, reset_lo, cfg, cfg.decide_recent_s)
            cand_r = wr.ok & (wr.llr >= need)
            use_r = cand_r & ~cand
            w = merge_windows(w, wr, use_r)
            cand = cand | cand_r
        if current is not None and not pending:
            cand[:, current] = False
        dec_rows = np.flatnonzero(cand.any(axis=1))
        first_dec = int(dec_rows[0]) if dec_rows.size else None
        first_cross = None
        other = None
        if current is not None and not pending:
            other = partner(ev, current, keys)
            if other is not None:
                cross, rms5, shift = crossing(ev, i, reset_lo, current, other, cfg)
                rows = np.flatnonzero(cross)
                first_cross = int(rows[0]) if rows.size else None
        if first_cross is not None and (first_dec is None or first_cross <= first_dec):
            assert current is not None and other is not None
            e = int(i[first_cross])
            d_id, o_id = int(ev.tracks[current]), int(ev.tracks[other])
            crossovers.append(
                Event(
                    float(ev.t[e]),
                    EventType.CROSSOVER,
                    _finite(float(ev.km[e, current])),
                    detail={
                        "line_code": keys[d_id][0],
                        "from": keys[d_id][1],
                        "to": keys[o_id][1],
                        "rms_m": round(float(rms5[first_cross]), 3),
                        "shift_m": round(float(shift[first_cross]), 3),
                    },
                )
            )
            pending = True
            reset_lo = e + 1
            pos = e + 1
            continue
        if first_dec is not None:
            e = int(i[first_dec])
            j = int(np.argmax(np.where(cand[first_dec], w.llr[first_dec], -np.inf)))
            decisions.append(_decision(ev, w, first_dec, j, keys, cfg.km_dir_min_m))
            periods.append((float(ev.t[e]), int(ev.tracks[j])))
            current = j
            pending = False
            pos = e + 1
            continue
        pos = int(i[-1]) + 1
    return decisions, crossovers, periods


def _finite(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _decision(
    ev: Evidence, w: Window, row: int, j: int, keys: list[tuple[str, str]], km_dir_min_m: float
) -> TrackDecision:
    e, lo = int(w.i[row]), int(w.lo[row])
    seen = np.flatnonzero(np.isfinite(ev.km[lo : e + 1, j])) + lo
    km_first, km_last = float(ev.km[seen[0], j]), float(ev.km[seen[-1], j])
    dkm = km_last - km_first
    tid = int(ev.tracks[j])
    return TrackDecision(
        t=float(ev.t[e]),
        line_code=keys[tid][0],
        track=keys[tid][1],
        km_m=km_last,
        km_dir=int(np.sign(dkm)) if abs(dkm) >= km_dir_min_m else 0,
        evidence={
            "n_fixes": int(w.n[row, j]),
            "mean_offset_m": round(float(w.mean[row, j]), 3),
            "sigma_m": round(float(np.sqrt(w.se2[row, j])), 3),
            "duration_s": round(float(ev.t[e] - ev.t[lo]), 1),
            "share": round(float(w.share[row, j]), 3),
            "llr": round(float(w.llr[row, j]), 2) if np.isfinite(w.llr[row, j]) else None,
        },
    )


def decided_columns(
    out: pd.DataFrame, periods: list[tuple[float, int]], matches: pd.DataFrame, index: TrackIndex
) -> None:
    n = len(out)
    tid = np.full(n, -1, dtype=np.int64)
    if periods:
        t_from = np.array([p[0] for p in periods])
        k = np.searchsorted(t_from, out["t"].to_numpy(dtype=float), side="right") - 1
        ids = np.array([p[1] for p in periods], dtype=np.int64)
        tid = np.where(k >= 0, ids[np.clip(k, 0, None)], -1)
    lc = np.full(n, None, dtype=object)
    tr = np.full(n, None, dtype=object)
    has = tid >= 0
    if has.any():
        lc[has] = [index.keys[i][0] for i in tid[has]]
        tr[has] = [index.keys[i][1] for i in tid[has]]
    km = np.full(n, np.nan)
    off = np.full(n, np.nan)
    if len(matches) and has.any():
        f = matches["fix"].to_numpy()
        sel = tid[f] == matches["track_id"].to_numpy()
        km[f[sel]] = matches["km_m"].to_numpy()[sel]
        off[f[sel]] = matches["offset_m"].to_numpy()[sel]
    out["decided_line_code"] = pd.array(lc, dtype="string")
    out["decided_track"] = pd.array(tr, dtype="string")
    out["decided_km_m"] = km
    out["decided_offset_m"] = off
