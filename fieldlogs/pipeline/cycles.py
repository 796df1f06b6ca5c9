"""Vectorised preprocessing: the run's streams on the onboard 100 ms cycle grid.

The cycle grid is the tachometer's time base (10 Hz). IMU samples (100 Hz) are averaged
over each cycle ``(t[k−1], t[k]]``; cab direction and PTO are carried forward from their
events. Nothing here is sequential, so it is all numpy.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.pipeline.block_means import means_by_blocks
from fieldlogs.pipeline.cycle_grid import FloatArray, Segments, cycle_index, cycle_means, means_into, segments
from schemas import units
from schemas.enums import CabDirection

__all__ = [
    "IMU_COLUMNS",
    "Cycles",
    "FloatArray",
    "Segments",
    "build_cycles",
    "cab_signs",
    "cycle_index",
    "cycle_means",
    "delay",
    "imu_cycle_means",
    "means_into",
    "moving_average",
    "segments",
    "standstill_mean",
    "step_values",
    "trailing_sum",
]

IMU_COLUMNS = ("ax", "ay", "az", "wx", "wy", "wz")


@dataclass
class Cycles:
    """Per-cycle arrays (length n) of one run."""

    t: FloatArray
    pulses: FloatArray
    """Cumulative pulse count (NaN where the tacho is absent)."""
    d_pulse: FloatArray
    """Travel distance by pulses since the first cycle [m] (unsigned, never decreasing)."""
    v_pulse: FloatArray
    """Speed by pulses, backward difference over one cycle [m/s] (unsigned)."""
    imu: dict[str, FloatArray]
    """Cycle means of ax, ay, az [m/s²] and wx, wy, wz [rad/s]; NaN where no sample."""
    cab: npt.NDArray[np.int8]
    """+1 running toward the F end (body +x), −1 reversed."""
    pto: npt.NDArray[np.int8]
    """1 on rail (road-rail vehicles), 0 off; 1 for trains."""
    has_tacho: bool
    has_imu: bool
    rotation: npt.NDArray[np.int8] | None = None
    """Sense of motion from a two-phase tachometer (the tacho ``direction``: +1 toward the F
    end, −1 toward the R end, 0 where not known); None without one."""

    @property
    def motion(self) -> npt.NDArray[np.int8]:
        """Sense of motion per cycle: +1 toward the F end, −1 toward the R end. The driving
        cab's direction, except where a two-phase tachometer tells otherwise — a train rolling
        back on a gradient moves against its cab [S003 §2]: the last sense it gave holds while
        it gives none (standstill), and the cab's before its first."""
        if self.rotation is None:
            return self.cab
        return tacho_motion(self.rotation, self.cab)

    @property
    def n(self) -> int:
        return int(self.t.size)

    @property
    def dt(self) -> FloatArray:
        return np.diff(self.t, prepend=self.t[0] - 0.1 if self.t.size else 0.0)


def tacho_motion(rotation: npt.NDArray[np.int8], cab: npt.NDArray[np.int8]) -> npt.NDArray[np.int8]:
    """Sense of motion from the tacho's ``direction`` (0: keep the last sense given; the cab's
    before the first): see :attr:`Cycles.motion`."""
    r = np.asarray(rotation, dtype=np.int8)
    known = r != 0
    last = np.maximum.accumulate(np.where(known, np.arange(r.size), -1)) if r.size else np.zeros(0, np.int64)
    return np.where(last >= 0, r[np.maximum(last, 0)], np.asarray(cab, dtype=np.int8)).astype(np.int8)


def step_values(t_cycles: FloatArray, t_events: FloatArray, values: npt.ArrayLike, default: float) -> FloatArray:
    """Value of the last event at or before each cycle (``default`` before the first)."""
    vals = np.asarray(values, dtype=float)
    idx = np.searchsorted(t_events, t_cycles, side="right") - 1
    return np.where(idx >= 0, vals[np.clip(idx, 0, None)] if vals.size else default, default)


def cab_signs(t: FloatArray, t_cab: FloatArray, directions: npt.ArrayLike) -> FloatArray:
    """The driving cab at each ``t``: +1 forward, −1 reverse, from the last cab event at or
    before it (``t_cab`` sorted; +1 before the first)."""
    reverse = np.asarray(directions).astype(str) == CabDirection.REVERSE.value
    return step_values(t, t_cab, np.where(reverse, -1.0, 1.0), 1.0)


def build_cycles(
    *,
    tacho: pd.DataFrame | None,
    imu: pd.DataFrame | None,
    cab: pd.DataFrame | None,
    wheel_diameter_m: float | None,
    teeth: int | None,
    t_end: float | None = None,
    cycle_s: float = 0.1,
    uses_pto: bool = True,
) -> Cycles:
    """Resample a run's streams onto its cycle grid (streams must be sorted by t).

    ``uses_pto`` False (a train): a ``pto`` column of the cab stream is ignored and the
    vehicle is on rail throughout — recorders write every column for every vehicle, and a
    train's PTO 0 must not switch it "off rail" [S001 §4.2.4: PTO is a road-rail signal]."""
    has_tacho = tacho is not None and len(tacho) > 1
    has_imu = imu is not None and len(imu) > 0
    if has_tacho:
        assert tacho is not None
        t = tacho["t"].to_numpy(dtype=float)
        pulses = tacho["pulses"].to_numpy(dtype=float, na_value=np.nan)
    else:
        end = t_end if t_end is not None else (float(imu["t"].iloc[-1]) if has_imu and imu is not None else 0.0)
        t = np.arange(0.0, end + 1e-9, cycle_s)
        pulses = np.full(t.size, np.nan)
    if has_tacho and (wheel_diameter_m is None or teeth is None):
        raise ValueError("a tacho stream needs wheel_diameter_m and teeth")
    if has_tacho:
        p0 = pulses[np.isfinite(pulses)][0] if np.isfinite(pulses).any() else 0.0
        assert wheel_diameter_m is not None and teeth is not None
        d = (pulses - p0) * units.metres_per_pulse(wheel_diameter_m, teeth)
        d = np.maximum.accumulate(np.nan_to_num(d, nan=0.0))
        dd = np.diff(d, prepend=d[0])
        dtt = np.diff(t, prepend=t[0] - cycle_s)
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.where(dtt > 0, dd / dtt, 0.0)
    else:
        d = np.zeros(t.size)
        v = np.zeros(t.size)
    imu_means = imu_cycle_means(t, imu) if has_imu and imu is not None else {}
    for c in IMU_COLUMNS:
        imu_means.setdefault(c, np.full(t.size, np.nan))
    if cab is not None and len(cab):
        te = cab["t"].to_numpy(dtype=float)
        cab_sign = cab_signs(t, te, cab["direction"].astype(str).to_numpy()).astype(np.int8)
        if uses_pto and "pto" in cab.columns and cab["pto"].notna().any():
            pto_vals = cab["pto"].astype("Float64").ffill().fillna(0).to_numpy(dtype=float)
            pto = step_values(t, te, pto_vals, 0.0).astype(np.int8)
        else:
            pto = np.ones(t.size, dtype=np.int8)
    else:
        cab_sign = np.ones(t.size, dtype=np.int8)
        pto = np.ones(t.size, dtype=np.int8)
    rotation = None
    if has_tacho and tacho is not None and "direction" in tacho.columns and tacho["direction"].notna().any():
        rotation = np.sign(tacho["direction"].to_numpy(dtype=float, na_value=0.0)).astype(np.int8)
    return Cycles(t, pulses, d, v, imu_means, cab_sign, pto, has_tacho, has_imu, rotation)


def imu_cycle_means(t_cycles: FloatArray, imu: pd.DataFrame) -> dict[str, FloatArray]:
    """Cycle means of the IMU's six columns, consumed block by block
    (:mod:`fieldlogs.pipeline.block_means`: bit-identical to :func:`cycle_means`, without
    the whole stream's per-sample index and masks); samples not in time order go through
    :func:`cycle_means` over the whole stream, whose result they define."""

    def block(start: int, stop: int) -> tuple[FloatArray, dict[str, FloatArray]]:
        part = imu.iloc[start:stop]
        cols = {c: part[c].to_numpy(dtype=float, na_value=np.nan) for c in IMU_COLUMNS}
        return part["t"].to_numpy(dtype=float, na_value=np.nan), cols

    means = means_by_blocks(t_cycles, len(imu), block, IMU_COLUMNS)
    if means is not None:
        return means
    t_imu = imu["t"].to_numpy(dtype=float)
    seg = segments(cycle_index(t_cycles, t_imu), t_cycles.size)  # once for the six columns
    return {
        c: cycle_means(t_cycles, t_imu, imu[c].to_numpy(dtype=float, na_value=np.nan), seg=seg) for c in IMU_COLUMNS
    }


def trailing_sum(x: npt.ArrayLike, window: int) -> npt.NDArray[Any]:
    """Sum over the trailing ``window`` samples ending at each sample (fewer at the start);
    one cumsum, so integer and boolean inputs give exact integer counts."""
    a = np.asarray(x)
    c = np.concatenate([np.zeros(1, dtype=np.cumsum(a[:0]).dtype), np.cumsum(a)])
    hi = np.arange(1, a.size + 1)
    out: npt.NDArray[Any] = c[hi] - c[np.maximum(hi - window, 0)]
    return out


def standstill_mean(
    t: FloatArray, v: FloatArray, x: FloatArray, settle_s: float, window_s: float, min_s: float
) -> tuple[FloatArray, npt.NDArray[np.bool_]]:
    """Causal mean of ``x`` over the latest standstill cycles, per cycle, and whether it
    exists yet (the mean is 0 where not).

    A cycle counts when the speed ``v`` has been exactly 0 (no pulse) for at least
    ``settle_s`` and ``x`` is finite: at standstill a yaw gyro should read 0, so its mean
    there is the gyro's bias (Earth rate included). The estimate at cycle i averages the
    last ``window_s`` worth of counted cycles up to i; it is 0 until ``min_s`` of them exist.
    """
    n = t.size
    if n == 0 or window_s <= 0.0:
        return np.zeros(n), np.zeros(n, dtype=bool)
    still = v == 0.0
    starts = still & ~np.concatenate([[False], still[:-1]])
    run_start = np.maximum.accumulate(np.where(starts, t, -np.inf))  # t is increasing
    counted = still & (t - run_start >= settle_s - 1e-9) & np.isfinite(x)
    dt = float(np.median(np.diff(t))) if n > 1 else 0.1
    m = max(round(window_s / dt), 1)
    pos = np.flatnonzero(counted)
    csum = np.concatenate([[0.0], np.cumsum(x[pos])])
    k = np.cumsum(counted)  # counted cycles up to and including i
    lo = np.maximum(k - m, 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (csum[k] - csum[lo]) / (k - lo)
    known = k * dt >= min_s - 1e-9
    return np.where(known, mean, 0.0), known


def moving_average(x: FloatArray, window: int) -> FloatArray:
    """Trailing moving average over ``window`` samples (what an onboard unit can compute
    in real time); NaNs are ignored, the first samples average what exists."""
    if window <= 1:
        return x.astype(float, copy=True)
    ok = np.isfinite(x)
    n = trailing_sum(ok, window)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(n > 0, trailing_sum(np.where(ok, x, 0.0), window) / n, np.nan)


def delay(x: FloatArray, cycles: int) -> FloatArray:
    """``x`` delayed by ``cycles`` (the first values repeat the first sample)."""
    if cycles <= 0:
        return x.copy()
    return np.concatenate([np.full(cycles, x[0] if x.size else np.nan), x[:-cycles]])[: x.size]
