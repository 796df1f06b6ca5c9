"""Receiver clock coasting: predict each receiver's clock from its own recent solutions.

A receiver clock (TCXO) follows b(t) ≈ a + d·t over a minute to well under a metre, so a
predicted clock is one more observation for the epochs the satellites alone cannot carry —
one satellite then fixes s, two poorly placed ones gain the missing geometry. The prediction
is causal (only earlier epochs), per receiver, by weighted least squares over the solved
epochs of the last ``window_s``: minimise Σ_j (b_j − a − d(t_j − t_i))²/σ_j², whose window
sums come from prefix sums (no loop over epochs). Its variance is the fit's
[1 0](AᵀWA)⁻¹[1 0]ᵀ plus a random walk q²·(t_i − t_last + 1) for the clock's own wander and
the estimates' correlation, q = ``walk_m_per_sqrt_s``. Epochs more than ``max_gap_s`` after
the last solved one, or with fewer than ``min_epochs`` in the window, get no prediction.
A clock jump (a receiver's millisecond reset, steering) shows as a failing test of the
clock row: the epoch is then refused, never silently shifted.
"""

from __future__ import annotations

import numpy as np

from fieldlogs.gnss.constants import BoolArray, FloatArray, StrArray


def predict_clock(
    receiver: StrArray,
    t: FloatArray,
    clock_m: FloatArray,
    sigma_m: FloatArray,
    ok: BoolArray,
    *,
    window_s: float = 60.0,
    max_gap_s: float = 30.0,
    min_epochs: int = 5,
    walk_m_per_sqrt_s: float = 0.3,
) -> tuple[FloatArray, FloatArray]:
    """(predicted clock [m], its 1σ [m]; +inf where none) for every epoch (module docstring)."""
    pred = np.full(t.size, np.nan)
    sig = np.full(t.size, np.inf)
    for name in np.unique(receiver):
        idx = np.flatnonzero(receiver == name)
        idx = idx[np.argsort(t[idx], kind="stable")]
        p, s = _predict_one(
            t[idx], clock_m[idx], sigma_m[idx], ok[idx], window_s, max_gap_s, min_epochs, walk_m_per_sqrt_s
        )
        pred[idx], sig[idx] = p, s
    return pred, sig


def _predict_one(
    t: FloatArray,
    b: FloatArray,
    sb: FloatArray,
    ok: BoolArray,
    window_s: float,
    max_gap_s: float,
    min_epochs: int,
    q: float,
) -> tuple[FloatArray, FloatArray]:
    good = ok & np.isfinite(b) & np.isfinite(sb) & (sb > 0)
    w = np.where(good, 1.0 / np.where(good, sb, 1.0) ** 2, 0.0)
    tt = t - t[0]
    bb = np.where(good, b, 0.0)
    cols = np.stack([w, w * tt, w * tt * tt, w * bb, w * tt * bb, good.astype(float)], axis=1)
    csum = np.vstack([np.zeros((1, 6)), np.cumsum(cols, axis=0)])  # exclusive prefix sums
    lo = np.searchsorted(t, t - window_s, side="left")
    i = np.arange(t.size)
    s0, s1, s2, sb_, stb, n = (csum[i, c] - csum[lo, c] for c in range(6))
    # re-centre the sums on t_i: Σw(t_j − t_i)ⁿ from Σw t_jⁿ
    ti = tt
    m1 = s1 - s0 * ti
    m2 = s2 - 2.0 * s1 * ti + s0 * ti * ti
    mb = stb - sb_ * ti
    det = s0 * m2 - m1 * m1
    last = np.where(good, t, -np.inf)
    last_good = np.concatenate([[-np.inf], np.maximum.accumulate(last)[:-1]])
    gap = t - last_good
    valid = (n >= min_epochs) & (det > 1e-12 * np.maximum(s0 * m2, 1e-300)) & (gap <= max_gap_s)
    det_safe = np.where(valid, det, 1.0)
    a = (m2 * sb_ - m1 * mb) / det_safe
    var = m2 / det_safe
    pred = np.where(valid, a, np.nan)
    sig = np.where(valid, np.sqrt(np.abs(var) + q * q * (np.where(valid, gap, 0.0) + 1.0)), np.inf)
    return pred, sig
