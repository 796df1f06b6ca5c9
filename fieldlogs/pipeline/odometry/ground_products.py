"""Stage 6 (with a ground speed, the radar [S004]): what it adds to the assembled odometry.

Not in S000. The episodes (stages 2–5) already use the ground speed; this stage adds:

Speed at low speed and at standstill (``ground_low_speed_kmh``)
    A cycle's pulse speed counts whole pulses: one pulse in a 0.1 s cycle is 0.3 m/s
    (90 teeth, 0.86 m), a quarter of the speed at 4 km/h. Where the vehicle is slower than
    ``ground_low_speed_kmh`` by both the 1 s mean pulse speed and the ground speed, and not
    in a correction, the speed ``v`` is the ground speed; in the radar's standstill frames
    that is 0 (the radar sees no Doppler; a wheel turning at rest is a slip, stage 2). The
    distance stays on the pulses: they count whole pulses, exact to one, without drift.

Wheel calibration (``WheelCalibration``, summary ``wheel_calibration``)
    Over the adhering stretches — a ground speed of at least CAL_MIN_SPEED_MPS, the
    direction check passed, and farther than CAL_GUARD_S from every episode (its start …
    the end of its fail-safe watch) — the ratio of ground to pulse distance

        r = Σ v_g·Δt / Σ Δd_p

    is the true wheel diameter over the nominal one (the pulse distance is
    N·π·D_nom / teeth, so D = r·D_nom). Its 95 % interval is ±1.96·σ_r with
    σ_r² = (Σ n_c·σ_g²·Δt² + (b·Σ Δt)² + n_s·q²/6·r²) / (Σ Δd_p)²: independent radar frames
    (n_c cycles share one), the ground speed's systematic error b = ``GROUND_BIAS_MPS``
    (1σ, the same in every frame), and each of the n_s stretches cut to one pulse q at
    either end. It does not contain an error of the radar's mounting (height, depression),
    which would scale every frame and which the calibration inherits.

Scale (``wheel_calibration`` setting, default off)
    With it, the pulse increments outside the corrections are multiplied by the running
    estimate r_k (the sums up to cycle k, so what the unit knows then) from the first cycle
    at which at least CAL_MIN_M of pulse distance is in it and its 95 % half-width is at
    most CAL_MAX_HALF; before, by 1. The corrections' own distances are already in the
    ground's scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.ground import GROUND_BIAS_MPS, GroundSpeed
from fieldlogs.pipeline.odometry.signals import BoolArray, ma, recent
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.types import FloatArray, GroundReport, Odometry, SlipEpisode, WheelCalibration

#: Calibration: least ground speed of a cycle used (the radar's systematic error b is
#: absolute: relatively smaller at speed) [m/s].
CAL_MIN_SPEED_MPS = 5.0
#: … and its distance from an episode (start point … end of the watch) [s].
CAL_GUARD_S = 3.0
#: The scale is applied once this much pulse distance is in the estimate [m] …
CAL_MIN_M = 500.0
#: … and its 95 % half-width is at most this [–].
CAL_MAX_HALF = 0.001
#: Two-sided 95 % [–].
Z95 = 1.96


def _disturbed(s: AlignedStreams, episodes: list[SlipEpisode], settled: list[int]) -> BoolArray:
    """Output cycles within CAL_GUARD_S of an episode (start … end of its watch)."""
    n = s.n
    inside = np.zeros(n + 1, dtype=np.int64)
    for ep, end in zip(episodes, settled, strict=True):
        inside[max(ep.i_start, 0)] += 1
        inside[min(max(end, ep.i_end), n - 1) + 1] -= 1
    busy = np.cumsum(inside)[:n] > 0
    guard = max(round(CAL_GUARD_S / s.cyc), 1)
    after = recent(busy, guard)
    before = recent(busy[::-1], guard)[::-1]
    out: BoolArray = after | before
    return out


@dataclass(frozen=True, eq=False)
class _Sums:
    """Running sums over the cycles the calibration uses."""

    ground_m: FloatArray
    pulse_m: FloatArray
    var: FloatArray
    """Σ n_c·σ²·Δt² [m²]."""
    time_s: FloatArray
    stretches: FloatArray


def _sums(s: AlignedStreams, g: GroundSpeed, use: BoolArray) -> _Sums:
    dd = np.diff(s.d_pulse, prepend=s.d_pulse[0] if s.n else 0.0)
    starts = use & ~np.concatenate([[False], use[:-1]])
    return _Sums(
        ground_m=np.cumsum(np.where(use, np.nan_to_num(g.out_v) * s.dt, 0.0)),
        pulse_m=np.cumsum(np.where(use, dd, 0.0)),
        var=np.cumsum(np.where(use, g.n_corr * np.nan_to_num(g.out_sigma) ** 2 * s.dt * s.dt, 0.0)),
        time_s=np.cumsum(np.where(use, s.dt, 0.0)),
        stretches=np.cumsum(starts).astype(float),
    )


def calibrate(
    s: AlignedStreams, g: GroundSpeed, cfg: OdometryConfig, odo: Odometry, settled: list[int]
) -> tuple[WheelCalibration | None, FloatArray]:
    """The wheel calibration of the run and the running scale per output cycle (1 where
    not applied)."""
    n = s.n
    with np.errstate(invalid="ignore"):
        use = (g.out_v >= CAL_MIN_SPEED_MPS) & ~g.against & ~_disturbed(s, odo.episodes, settled)
    use[:1] = False  # the first cycle has no pulse increment
    c = _sums(s, g, use)
    scale = np.ones(n)
    if n == 0 or c.pulse_m[-1] <= 0:
        return None, scale
    q = g.pulse_m
    with np.errstate(invalid="ignore", divide="ignore"):
        r = c.ground_m / c.pulse_m
        var = c.var + (GROUND_BIAS_MPS * c.time_s) ** 2 + c.stretches * q * q / 6.0 * r * r
        half = Z95 * np.sqrt(var) / c.pulse_m
    known = (c.pulse_m >= CAL_MIN_M) & (half <= CAL_MAX_HALF)
    first = int(np.argmax(known)) if known.any() else None
    applied = bool(cfg.wheel_calibration and first is not None)
    if applied:
        scale = np.where(np.maximum.accumulate(known), _carry(r, known), 1.0)
    cal = WheelCalibration(
        ratio=float(r[-1]),
        half_width=float(half[-1]),
        distance_m=float(c.pulse_m[-1]),
        stretches=int(c.stretches[-1]),
        applied=applied,
        applied_from_t=float(s.t[first]) if applied and first is not None else None,
    )
    return cal, scale


def _carry(r: FloatArray, known: BoolArray) -> FloatArray:
    """The last known r carried forward over cycles where the estimate is not known."""
    idx = np.maximum.accumulate(np.where(known, np.arange(r.size), 0))
    out: FloatArray = r[idx]
    return out


def ground_products(
    s: AlignedStreams, g: GroundSpeed, cfg: OdometryConfig, odo: Odometry, settled: list[int]
) -> Odometry:
    """Stage 6: the speed at low speed and standstill, the wheel calibration and (if set)
    the scale, and the report."""
    n = s.n
    slipping = odo.slipping
    with np.errstate(invalid="ignore"):
        slow = np.maximum(g.out_v, ma(s.v_pulse, s.filters.P)) < cfg.ground_low_speed_kmh / 3.6
    low = slow & ~slipping & np.isfinite(g.out_v)
    v = np.where(low, g.out_v, odo.v)
    cal, scale = calibrate(s, g, cfg, odo, settled)
    d = odo.d
    if cal is not None and cal.applied:
        dd = np.diff(d, prepend=d[0])
        d = d[0] + np.cumsum(np.where(slipping, dd, dd * scale))
        v = np.where(slipping, v, v * scale)
    with np.errstate(invalid="ignore"):
        moving = ma(s.v_pulse, s.filters.P) >= CAL_MIN_SPEED_MPS
    covered = float(np.isfinite(g.out_v[moving]).mean()) if moving.any() else 0.0
    report = GroundReport(
        source=g.source,
        covered_share=covered,
        against_cab_s=float(s.dt[g.against].sum()),
        low_speed_share=float(low.mean()) if n else 0.0,
        calibration=cal,
    )
    return Odometry(d, v, slipping, odo.allowance, odo.episodes, odo.diagnostics, ground=report)
