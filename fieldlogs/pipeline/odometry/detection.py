"""Stage 2: detections on the aligned streams (:class:`Detections`).

Detection (eq. 1)
    ``|a_x − A_p| > Ta`` on the K-smoothed aligned values, 1 s mean pulse speed ≥
    ``min_speed_kmh``. ``a_x − A_p < −Ta``: the wheel accelerates faster than the body →
    *slip* (traction); ``> +Ta``: the wheel decelerates faster → *slide* (braking). The
    gravity term G·sinθ is at most Ta (35 ‰), so the sign decides. Only rising edges of the
    mask open an episode.

Gyro pitch-rate bias (``bias_window_s``)
    Not in the papers: while adhering u = b_a/G − const − b·t + noise (stage 1), so the
    least-squares slope of u over the cycles of the trailing ``bias_window_s`` that eq. 1
    does not flag is −b (running sums, O(n); no estimate, and no residual, before
    BIAS_MIN_S of such data). An ADIS16480-class gyro has a bias of 0.05 °/s ≈ 0.9 mrad/s
    (1σ): uncorrected, θ drifts 9 mrad in a 10 s correction, the acceleration error grows
    to 0.09 m/s² and the distance error to G·b·(t_c·T²/2 + T³/6) ≈ 3 m in 8 s (t_c the
    1.9 s carry to i0). b is removed from θ̇ in the carry to i0 and in the integration
    (measurement: bench/NOTES.md, "Odometry").

Second criterion: grade-compensated residual (``residual_threshold_kmh_s``, 0 = off)
    Not in the papers. Ta must exceed the largest G·sinθ, so a slip whose K-filtered excess
    acceleration stays below 0.34 m/s² goes unseen: shallow (10–20 %) slips at 2–8 m/s,
    0.4–4 m of distance each. But the change of θ is known from the gyro: with u as above
    (adhering: constant − b·t), the residual over the horizon H = ``residual_horizon_s``

        r(k) = G·[u(k) − u(k − H) + b̂·H]      (travel frame: slip < 0 < slide)

    is K·(a_x − A_p) minus its value H ago minus the gyro's change of G·sinθ in between:
    grades, vertical curves, cant and the accelerometer bias drop out and r stays near zero
    while adhering. Its noise is the pulse quantisation of two K windows (±0.04 m/s²), the
    gyro error over H after the bias estimate (≈ 0.3 mrad/s in sharp canted curves, from
    the roll error × ω_z) and the IMU noise, well below the threshold 0.45 km/h/s =
    0.125 m/s² (Ta/2.7; the measured noise is in bench/NOTES.md, "Odometry").
    H = 4 s ≥ the filter length M = 3.9 s: the two K windows do not overlap, so a slip
    onset shows in full. A detection needs an adhering reference: u(k − H) not in a Ta
    detection and not within a filter length after a cycle either criterion flags (two
    passes); and there is no residual before the bias estimate exists (stage 3 also ignores
    a residual onset whose reference falls in the previous episode). The residual needs the
    right pulse delay (stage 1).

Ground-speed criterion (``ground_detect_z``, 0 = off; only with a ground speed)
    Not in S000, which has no independent speed. With the radar [S004] (stage 1b):

        e(k) = v̄_p(k) − v̄_g(k),   |e| > tol0 + WEAR_SHARE·v̄_g + z·σ̄_g      (> 0: slip)

    with v̄ the 1 s means (pulses: ``vp1``; ground: only where its whole window has
    values), tol0 = ``readhesion_tol_kmh`` (the pulses' quantisation), σ̄_g the 1σ of the
    ground 1 s mean and z = ``ground_detect_z``. It sits beside eq. 1 and the residual (the
    onsets of all three open episodes) and sees what they cannot: a slip whose excess
    acceleration stays below every threshold, a slip at low speed (no ``min_speed_kmh``
    gate: the radar measures from standstill, and a wheel spinning at rest or locked while
    sliding shows as |e| ≈ v), within ≈ 1 s of its onset instead of the 3.9 s filter.
    Its flagged cycles are left out of the gyro-bias estimate and count as disturbed for
    the residual's reference.

Start-point condition
    |Ji| ≤ ``jerk_imu_max_kmh_s``, |Jp| ≤ ``jerk_pulse_max_kmh_s`` and |Ji − Jp| <
    ``jerk_diff_max_kmh_s`` per 0.1 s (Ji, Jp: per-cycle differences of K·a_x, K·A_p) held
    for ``hold_cycles`` consecutive cycles; ``last_hold[k]`` is the last cycle ≤ k at which
    it held (``np.maximum.accumulate``), so the start-point search of stage 3 is a lookup.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.ground import GroundSpeed, tolerance
from fieldlogs.pipeline.odometry.signals import (
    BoolArray,
    IntArray,
    held,
    readonly,
    recent,
    rising,
    sliding_slope,
)
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.types import FloatArray
from schemas.units import G, kmh_s_to_mps2

#: Least adhering data in the bias window before the gyro bias is estimated [s].
BIAS_MIN_S = 10.0


@dataclass(frozen=True, eq=False)
class Detections:
    """What eq. 1 and the residual flag, the gyro bias and the start-point condition, on
    the aligned cycles; arrays are read-only."""

    ta_mask: BoolArray
    """|K·a_x − K·A_p| > Ta while moving (eq. 1)."""
    bias: FloatArray
    """Gyro pitch-rate bias b̂, body frame [rad/s] (0 where not estimated)."""
    bias_ok: BoolArray
    """The bias estimate exists (enough adhering data in its window)."""
    horizon: int
    """Residual horizon H [cycles]."""
    residual: FloatArray
    """r(k), travel frame [m/s²]; NaN where off or without an adhering reference."""
    residual_mask: BoolArray
    """|r| above its threshold with an adhering reference."""
    onsets: IntArray
    """Rising edges of either mask, in time order."""
    is_ta_onset: BoolArray
    """Per onset: it is a rising edge of ``ta_mask``."""
    last_hold: IntArray
    """Last cycle ≤ k at which the start-point condition held (−1: none yet)."""
    ground_e: FloatArray | None = None
    """e = 1 s mean pulse − ground speed [m/s] (None without the ground-speed criterion)."""
    ground_thr: FloatArray | None = None
    """Its threshold [m/s]."""
    ground_mask: BoolArray | None = None
    """|e| above its threshold."""
    is_ground_onset: BoolArray | None = None
    """Per onset: it is a rising edge of ``ground_mask`` (this criterion then names it)."""


def detect(s: AlignedStreams, cfg: OdometryConfig, ground: GroundSpeed | None = None) -> Detections:
    """Stage 2: eq. 1, the gyro bias, the residual criterion, the ground-speed criterion
    (with ``ground``) and the start-point condition."""
    moving = s.vp1 >= cfg.min_speed_kmh / 3.6
    with np.errstate(invalid="ignore"):
        mask = (np.abs(s.diff) > cfg.ta_mps2) & moving
    mask[: s.warm] = False
    ge, gthr, gmask = _ground_criterion(s, cfg, ground)
    flagged = mask if gmask is None else mask | gmask
    u_ok = s.u_valid & ~flagged
    bias, bias_ok = _gyro_bias(s, cfg, u_ok)
    horizon = round(cfg.residual_horizon_s / s.cyc)
    res, res_mask = _residual(s, cfg, horizon, flagged, moving, u_ok & bias_ok, bias)
    ta_onsets = rising(mask)
    onsets = np.union1d(ta_onsets, rising(res_mask))
    g_onset = None
    if gmask is not None:
        g_onsets = rising(gmask)
        onsets = np.union1d(onsets, g_onsets)
        g_onset = readonly(np.isin(onsets, g_onsets))
    return Detections(
        ta_mask=readonly(mask),
        bias=readonly(bias),
        bias_ok=readonly(bias_ok),
        horizon=horizon,
        residual=readonly(res),
        residual_mask=readonly(res_mask),
        onsets=readonly(onsets),
        is_ta_onset=readonly(np.isin(onsets, ta_onsets)),
        last_hold=readonly(_last_hold(s, cfg)),
        ground_e=None if ge is None else readonly(ge),
        ground_thr=None if gthr is None else readonly(gthr),
        ground_mask=None if gmask is None else readonly(gmask),
        is_ground_onset=g_onset,
    )


def _ground_criterion(
    s: AlignedStreams, cfg: OdometryConfig, g: GroundSpeed | None
) -> tuple[FloatArray | None, FloatArray | None, BoolArray | None]:
    """e = v̄_p − v̄_g, its threshold and mask (all None without a ground speed or with
    ``ground_detect_z`` 0)."""
    if g is None or cfg.ground_detect_z <= 0:
        return None, None, None
    e = s.vp1 - g.v1
    thr = tolerance(cfg, g.v1, g.sigma1, cfg.ground_detect_z)
    with np.errstate(invalid="ignore"):
        over = np.abs(e) > thr
    over[: s.warm] = False
    return e, thr, over


def _gyro_bias(s: AlignedStreams, cfg: OdometryConfig, u_ok: BoolArray) -> tuple[FloatArray, BoolArray]:
    """−(trailing least-squares slope of u over adhering cycles) and where it exists.
    Without an estimate the residual would drift by G·b·H: it is then not used."""
    n = s.n
    bias = np.zeros(n)
    bias_ok = np.ones(n, dtype=bool)
    lb = round(cfg.bias_window_s / s.cyc)
    if lb > 0:
        slope, count = sliding_slope(s.t, s.u, u_ok, lb)
        bias_ok = count >= min(BIAS_MIN_S / s.cyc, lb)
        bias = np.where(bias_ok, -slope, 0.0)
    return bias, bias_ok


def _residual(
    s: AlignedStreams,
    cfg: OdometryConfig,
    hz: int,
    mask: BoolArray,
    moving: BoolArray,
    quiet0: BoolArray,
    bias: FloatArray,
) -> tuple[FloatArray, BoolArray]:
    """The residual r and its detection mask. ``quiet0``: adhering cycles with a bias
    estimate, before excluding the filter lengths after flagged cycles."""
    n = s.n
    res = np.full(n, np.nan)
    if not (cfg.residual_threshold_kmh_s > 0 and 0 < hz < n):
        return res, np.zeros(n, dtype=bool)
    ref, now = slice(0, n - hz), slice(hz, n)
    u, t, sgn = s.u, s.t, s.sgn
    res[now] = G * sgn[now] * (u[now] - u[ref] + bias[ref] * (t[now] - t[ref]))
    with np.errstate(invalid="ignore"):
        over = (np.abs(res) > kmh_s_to_mps2(cfg.residual_threshold_kmh_s)) & s.u_valid & moving
    # the reference must be adhering: no Ta detection there, and not within a filter
    # length after a cycle either criterion flags (its K window would hold the
    # disturbance); two passes settle which residual detections count
    quiet = quiet0
    ref_ok = np.zeros(n, dtype=bool)
    for _ in range(2):
        ref_ok = np.zeros(n, dtype=bool)
        ref_ok[now] = quiet[ref]
        quiet = quiet0 & ~recent(mask | (over & ref_ok), s.filters.M)
    res[~(ref_ok & s.u_valid)] = np.nan
    return res, over & ref_ok


def _last_hold(s: AlignedStreams, cfg: OdometryConfig) -> IntArray:
    """Start-point condition (jerks per 0.1 s held for ``hold_cycles``) → the last cycle ≤ k
    at which it held."""
    per: float | FloatArray = 0.1 / s.cyc if s.uniform else 0.1 / s.dt
    ji = np.diff(s.axs, prepend=np.nan) * per
    jp = np.diff(s.aps, prepend=np.nan) * per
    with np.errstate(invalid="ignore"):
        ok = np.abs(ji) <= kmh_s_to_mps2(cfg.jerk_imu_max_kmh_s) + 1e-12
        ok &= np.abs(jp) <= kmh_s_to_mps2(cfg.jerk_pulse_max_kmh_s) + 1e-12
        ji -= jp
        ok &= np.abs(ji) < kmh_s_to_mps2(cfg.jerk_diff_max_kmh_s)
    ok[: s.warm] = False
    run = held(ok, max(int(cfg.hold_cycles), 1))
    out: IntArray = np.maximum.accumulate(np.where(run, np.arange(s.n), -1))
    return out
