"""Array helpers of the odometry stages: trailing filters, hold/edge masks, gap bridging,
filter tail sums, the least-squares acceleration functional and a sliding slope.

All are pure: they return new arrays and never write into their arguments.
"""

from __future__ import annotations

from typing import TypeVar

import numpy as np
import numpy.typing as npt

from fieldlogs.pipeline.cycles import moving_average, trailing_sum
from fieldlogs.pipeline.types import FloatArray

BoolArray = npt.NDArray[np.bool_]
IntArray = npt.NDArray[np.intp]
A = TypeVar("A", bound=npt.NDArray[np.generic])


def readonly(x: A) -> A:
    """A read-only view of ``x`` (``x`` itself stays writable): what a frozen stage result
    holds, so that nothing downstream can change it."""
    v = x.view()
    v.flags.writeable = False
    return v


def bridge(x: FloatArray, fill: float = 0.0) -> FloatArray:
    """Linear interpolation over missing cycles (edges held; ``fill`` when all missing)."""
    ok = np.isfinite(x)
    if ok.all():
        return x.astype(float, copy=True)
    if not ok.any():
        return np.full(x.size, fill)
    idx = np.arange(x.size)
    return np.interp(idx, idx[ok], x[ok])


def tail_sums(weights: FloatArray) -> FloatArray:
    """Tail sums S_l = Σ_{m≥l} w_m of weights on lags 0..M−1 (S_M = 0 appended)."""
    return np.concatenate([np.cumsum(weights[::-1])[::-1], [0.0]])


def lsq_accel_weights(m: int, dt: float) -> tuple[FloatArray, FloatArray]:
    """Weights (c, g), oldest sample first, of the least-squares acceleration over m cycles.

    ``c·d`` is the second-order coefficient of a quadratic fitted to m pulse distances:
    it uses every sample, so its quantisation error is ≈ 10× smaller than that of a
    difference of two speeds. ``g·a`` applies the *same* functional to cycle-mean
    accelerations (d_j − d_{j−1} = v_j·dt, v_j − v_{j−1} = ½(a_{j−1} + a_j)·dt), so
    ``g·a_x − c·d`` is exactly the g-weighted mean of G·sinθ for any speed profile.
    """
    tau = (np.arange(m) - (m - 1) / 2) * dt
    x = np.stack([np.ones(m), tau, 0.5 * tau**2], axis=1)
    c = np.linalg.pinv(x)[2]
    c1 = np.cumsum(c[::-1])[::-1]  # Σ_{j≥k} c_j
    c2 = np.cumsum(c1[::-1])[::-1]  # Σ_{k'≥k} c1_k'
    g = np.zeros(m)
    g[:-1] += 0.5 * c2[1:]
    g[1:] += 0.5 * c2[1:]
    return c, g * dt * dt


def ma(x: FloatArray, window: int) -> FloatArray:
    """Trailing moving average (``cycles.moving_average``, one cumsum when x has no NaN)."""
    if window <= 1 or not np.isfinite(x).all():
        return moving_average(x, window)
    cs = np.empty(x.size + 1)
    cs[0] = 0.0
    np.cumsum(x, out=cs[1:])
    out = np.empty(x.size)
    w = min(window, x.size)
    out[:w] = cs[1 : w + 1] / np.arange(1, w + 1)
    out[w:] = (cs[w + 1 :] - cs[1 : x.size - w + 1]) / w
    return out


def held(ok: BoolArray, cycles: int) -> BoolArray:
    """True where ``ok`` has held for the last ``cycles`` cycles (this one included)."""
    cond = ok.copy()
    for lag in range(1, cycles):
        cond[lag:] &= ok[:-lag]
        cond[:lag] = False
    return cond


def rising(mask: BoolArray) -> IntArray:
    """Indices where ``mask`` turns True."""
    return np.flatnonzero(mask[1:] & ~mask[:-1]) + 1


def recent(mask: BoolArray, window: int) -> BoolArray:
    """True where ``mask`` was True at this cycle or one of the ``window − 1`` before."""
    out: BoolArray = trailing_sum(mask, window) > 0
    return out


def sliding_slope(t: FloatArray, y: FloatArray, w: BoolArray, window: int) -> tuple[FloatArray, FloatArray]:
    """Least-squares slope dy/dt over the samples with ``w`` in the trailing window of
    ``window`` cycles ending at each cycle, and their count (running sums, O(n))."""
    x = t - t[t.size // 2] if t.size else t
    wf = w.astype(float)
    yz = np.where(w, y, 0.0)

    s0, s1, s2 = (trailing_sum(a, window) for a in (wf, wf * x, wf * x * x))
    sy, sxy = trailing_sum(yz, window), trailing_sum(yz * x, window)
    den = s0 * s2 - s1 * s1
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = np.where(den > 1e-12 * np.maximum(s0, 1.0) ** 2, (s0 * sxy - s1 * sy) / den, 0.0)
    return slope, s0


def finite_or_none(x: float) -> float | None:
    return x if np.isfinite(x) else None
