"""GPS trust filter [S001 §4.2.2; SPEC §5.4].

**Trust filter** [S001 §4.2.2: RMS of the second-to-second change over 5, 15, 30 s]. For
a moving train the per-second displacement p_k − p_{k−1} is ~20–30 m, so it is its
*change* that reveals a bad receiver state::

    a_k = (p_k − p_{k−1})/Δt_k − (p_{k−1} − p_{k−2})/Δt_{k−1}      [m, at 1 Hz; 2-D]
    RMS_w(k) = sqrt( mean_W |a_j|² − |mean_W a_j|² ),   W = {j : t_k − w < t_j ≤ t_k}

i.e. the scatter of the 2-D second difference of positions about its window mean (the
window mean is the smooth expectation: constant acceleration or braking cancels). A
time-correlated D-GPS error (Gauss-Markov, σ 1.5 m, τ ≥ 60 s) contributes ≤ 0.26·σ per
axis, white noise σ_w contributes √6·σ_w per axis: ≈ 1.0 m RMS in 2-D for σ_w = 0.25 m. A multipath
jump of J metres puts two values ±J into every window containing it: RMS ≳ J·sqrt(2/n) —
for J = 5 m, 3.3 / 2.1 / 1.65 m in the 5 / 15 / 30 s windows. A fix is **trusted** only
if, in every window ending at it, RMS_w ≤ ``rms_threshold_m[w]`` (defaults 2.5 / 1.8 /
1.5 m), its own |a_k| ≤ ``max_change_m`` (3 m: the first fix of a jump, seen only once by a
causal window), no fix of the last ``jump_hold_s`` (30 s) had a larger |a_k| (multipath
bursts ramp on and off smoothly, so the fixes after the first jump of a 5–8 m burst stay
below every window's threshold) and at least ``min_history_s`` of uninterrupted usable
fixes precede it. A
gap (no usable fix for more than ``max_gap_s``: outage, fix 1, high HDOP) resets all
windows. So a burst and the 30 s after it are untrusted; an isolated fix never is.
"""

from __future__ import annotations

import numpy as np

from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.types import BoolArray, FloatArray


def trust_filter(
    t: FloatArray, x: FloatArray, y: FloatArray, usable: BoolArray, cfg: GpsConfig
) -> tuple[BoolArray, dict[int, FloatArray]]:
    """(trusted, {window: RMS}) per fix — the statistic of the module docstring.

    Runs of usable fixes are cut where a fix is unusable or the time step exceeds
    ``max_gap_s``; second differences and windows never reach across a cut.
    """
    n = t.size
    rms = {int(w): np.full(n, np.nan) for w in cfg.windows_s}
    trusted = np.zeros(n, dtype=bool)
    u = np.flatnonzero(usable)
    if u.size == 0:
        return trusted, rms
    tu, xu, yu = t[u], x[u], y[u]
    new = np.ones(u.size, dtype=bool)
    new[1:] = (np.diff(tu) > cfg.max_gap_s) | (np.diff(u) > 1)
    starts = np.flatnonzero(new)
    first = starts[np.cumsum(new) - 1]
    pos = np.arange(u.size)
    valid = pos - first >= 2
    ax = np.zeros(u.size)
    ay = np.zeros(u.size)
    if u.size > 2:
        dt = np.diff(tu)
        vx, vy = np.diff(xu) / dt, np.diff(yu) / dt
        ax[2:] = vx[1:] - vx[:-1]
        ay[2:] = vy[1:] - vy[:-1]
    ax[~valid] = 0.0
    ay[~valid] = 0.0
    cn = np.concatenate([[0], np.cumsum(valid)])
    cx = np.concatenate([[0.0], np.cumsum(ax)])
    cy = np.concatenate([[0.0], np.cumsum(ay)])
    cq = np.concatenate([[0.0], np.cumsum(ax * ax + ay * ay)])
    jump = valid & (np.hypot(ax, ay) > cfg.max_change_m)
    last_jump = np.maximum.accumulate(np.where(jump, tu, -np.inf))
    ok = (tu - tu[first] >= cfg.min_history_s - 1e-9) & valid & ~jump
    # a burst may ramp on smoothly after its first jump, below every window's threshold
    ok &= ~(tu - last_jump < cfg.jump_hold_s)
    for w, thr in zip(cfg.windows_s, cfg.rms_threshold_m, strict=True):
        lo = np.maximum(np.searchsorted(tu, tu - w, side="right"), first + 2)
        hi = pos + 1
        cnt = np.where(hi > lo, cn[hi] - cn[np.minimum(lo, hi)], 0)
        lo_c = np.minimum(lo, hi)
        with np.errstate(invalid="ignore", divide="ignore"):
            mx = (cx[hi] - cx[lo_c]) / cnt
            my = (cy[hi] - cy[lo_c]) / cnt
            var = (cq[hi] - cq[lo_c]) / cnt - mx * mx - my * my
        r = np.where(cnt >= 2, np.sqrt(np.maximum(var, 0.0)), np.nan)
        rms[int(w)][u] = r
        ok &= r <= thr
    trusted[u] = ok
    return trusted, rms
