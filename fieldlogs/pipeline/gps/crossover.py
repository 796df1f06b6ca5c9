"""Crossover (渡り線) detection [S001 §7.1(b); SPEC §5.4].

**Crossover** [S001 §7.1(b)]. With a decided base track d, at each trusted fix: RMS of the
offsets from d over the last ``crossover_window_s`` ≥ ``crossover_rms_m``; their mean
moved toward the other track of the line — relative to a ``crossover_ref_s`` reference
window ending ``crossover_lag_s`` before — by ≥ ``crossover_min_shift`` × the track
spacing and by ≥ ``crossover_z`` × the model's 1-σ drift of the slow error over that lag;
and past the midpoint between the tracks; and not explained by the slow error turning in a
curve: that error is nearly constant in the plane, so through a curve its along-track part
becomes lateral (3.6 m along the track before a 46° curve is 2.6 m across it inside). A
plane bias b (prior N(0, σ²) per axis) is fitted to the offsets r = b·N of the reference
window and the lag (N the track's left normal at each fix) and the RMS window's mean must
differ from b̂·N̄ by ≥ half the spacing and ≥ ``crossover_z`` × the prediction's 1-σ. On
straight track b̂·N̄ is the earlier mean; in a curve a crossover made while such an error
turns the other way can be missed — the redecision then finds the new track, never a
wrong one → ``Event(t, "crossover", km, {line_code, from, to, rms_m, shift_m})``. The
decision evidence restarts after it.
"""

from __future__ import annotations

import numpy as np

from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.gps.evidence import Evidence
from fieldlogs.pipeline.types import BoolArray, FloatArray, IntArray


def crossing(ev: Evidence, i: IntArray, reset_lo: int, d: int, o: int, cfg: GpsConfig) -> tuple[BoolArray, ...]:
    """Crossover condition from base column d toward column o at rows i (vectorised)."""
    lo = np.maximum(np.searchsorted(ev.t, ev.t[i] - cfg.crossover_window_s, side="right"), reset_lo)
    t_ref_end = ev.t[i] - cfg.crossover_window_s - cfg.crossover_lag_s
    le = np.minimum(np.maximum(np.searchsorted(ev.t, t_ref_end, side="right"), reset_lo), lo)
    lr = np.minimum(np.maximum(np.searchsorted(ev.t, t_ref_end - cfg.crossover_ref_s, side="right"), reset_lo), le)
    hi = i + 1
    n5 = ev.cn[hi, d] - ev.cn[lo, d]
    nref = ev.cn[le, d] - ev.cn[lr, d]
    both = np.isfinite(ev.r[:, d]) & np.isfinite(ev.r[:, o])
    cc = np.concatenate([[0.0], np.cumsum(np.where(both, ev.r[:, d] - ev.r[:, o], 0.0))])
    cb = np.concatenate([[0], np.cumsum(both)])
    with np.errstate(invalid="ignore", divide="ignore"):
        rms5 = np.sqrt((ev.cq[hi, d] - ev.cq[lo, d]) / n5)
        m5 = (ev.cs[hi, d] - ev.cs[lo, d]) / n5
        mref = (ev.cs[le, d] - ev.cs[lr, d]) / nref
        spacing = (cc[hi] - cc[lr]) / (cb[hi] - cb[lr])
    side = np.sign(spacing)
    shift = (m5 - mref) * side
    # what the slow error alone moves between the two window centres (model, 1-σ)
    lag = 0.5 * cfg.crossover_window_s + cfg.crossover_lag_s + 0.5 * cfg.crossover_ref_s
    drift = cfg.noise_sigma_m * np.sqrt(2.0 * (1.0 - np.exp(-lag / cfg.noise_tau_s))) if cfg.noise_tau_s > 0 else 0.0
    # the slow error is (nearly) constant in the plane, not across the track: through a curve
    # it turns from along-track into lateral. Fit that bias b (2-D, prior N(0, σ²)) to the
    # offsets r = b·N of the reference window and the lag (N: the track's left normal) and ask
    # how far the RMS window's mean lies from what b alone predicts there.
    unexplained, sd_pred = rotating_bias_residual(ev, d, lr, lo, hi, n5, m5, drift, cfg)
    cross = (
        (n5 >= 3)
        & (nref >= 3)
        & (rms5 >= cfg.crossover_rms_m)
        & (shift >= np.maximum(cfg.crossover_min_shift * np.abs(spacing), cfg.crossover_z * drift))
        & (unexplained * side >= np.maximum(0.5 * np.abs(spacing), cfg.crossover_z * sd_pred))
        & (m5 * side >= 0.5 * np.abs(spacing))
        & np.isfinite(spacing)
    )
    return cross, rms5, shift


def rotating_bias_residual(
    ev: Evidence,
    d: int,
    lr: IntArray,
    lo: IntArray,
    hi: IntArray,
    n5: FloatArray,
    m5: FloatArray,
    drift: float,
    cfg: GpsConfig,
) -> tuple[FloatArray, FloatArray]:
    """(m5 − b̂·N̄5, 1-σ of that prediction incl. the drift) per row (vectorised 2×2 solves);
    n5, m5: count and mean offset of the RMS window [lo, hi).

    b̂ is the MAP estimate of a constant plane bias from the offsets of rows [lr, lo) on
    column d (per-fix σ² = white² + drift², prior σ = ``noise_sigma_m`` per axis); N̄5 is the
    mean left normal over the RMS window [lo, hi). On straight track only b's lateral part is
    observable and b̂·N̄5 is the reference mean; through a curve the along-track part is seen too.
    """
    s_w2 = cfg.noise_white_m**2 + drift**2
    p = 1.0 / max(cfg.noise_sigma_m**2, 1e-12)
    a11 = (ev.s_ee[lo, d] - ev.s_ee[lr, d]) / s_w2 + p
    a12 = (ev.s_en[lo, d] - ev.s_en[lr, d]) / s_w2
    a22 = (ev.s_nn2[lo, d] - ev.s_nn2[lr, d]) / s_w2 + p
    r1 = (ev.s_re[lo, d] - ev.s_re[lr, d]) / s_w2
    r2 = (ev.s_rn[lo, d] - ev.s_rn[lr, d]) / s_w2
    det = a11 * a22 - a12 * a12
    i11, i12, i22 = a22 / det, -a12 / det, a11 / det  # posterior covariance of b
    be, bn = i11 * r1 + i12 * r2, i12 * r1 + i22 * r2
    with np.errstate(invalid="ignore", divide="ignore"):
        ue = (ev.s_ne[hi, d] - ev.s_ne[lo, d]) / n5
        un = (ev.s_nn[hi, d] - ev.s_nn[lo, d]) / n5
    pred = be * ue + bn * un
    var = ue * ue * i11 + 2.0 * ue * un * i12 + un * un * i22
    return m5 - pred, np.sqrt(np.maximum(var, 0.0) + drift * drift)


def partner(ev: Evidence, col: int, keys: list[tuple[str, str]]) -> int | None:
    """The other track of the same line with the most evidence (crossover target)."""
    line = keys[int(ev.tracks[col])][0]
    best, best_n = None, 0.0
    for j, tid in enumerate(ev.tracks):
        if j != col and keys[int(tid)][0] == line and ev.cn[-1, j] > best_n:
            best, best_n = j, float(ev.cn[-1, j])
    return best
