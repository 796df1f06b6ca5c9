"""Slip/slide detection and inertial correction of the pulse odometry [S000 §3.1, SPEC §5.1].

Everything runs on the 100 ms cycle arrays of :class:`Cycles`. Detection, jerks, smoothing
and the start-point search are vectorised over the whole run; only the (rare) episodes are
visited in a Python loop, each integrated with ``np.cumsum`` over at most 10 s of cycles.

Travel frame
    Pulses are unsigned, the IMU is body-fixed. With ``cab`` = +1 the travel direction is
    body +x, with −1 it is −x: the travel frame is the body frame turned 180° about z, so
    ``ax, ay, wx, wy`` change sign and ``az, wz`` do not. All formulas below are in the
    travel frame (x along travel, y left, z up; SPEC §4.1), pitch θ is nose-up in the travel
    direction (the gradient climbed), roll ψ is positive with the left side up.

Streams and alignment
    Pulse speed ``v`` is the per-cycle backward difference; A_p = dv/dt. The pulse stream is
    delayed ``pulse_delay_cycles`` (300 ms) to line up with the IMU, so index k of the
    *aligned* arrays holds pulse and IMU data of the same physical instant. A_p and a_x are
    smoothed with the trailing 3 s moving average ``MA3``. Before differentiating, the pulse
    speed is averaged over ``SPEED_AVG_S`` (1 s) and a_x gets the identical 1 s average, so
    both go through the same filter K = MA3∘MA1 (a 3.9 s trapezoid) and, while adhering,
    ``K·a_x − K·A_p = K·(G·sinθ)`` whatever the jerk (to half a cycle, see "Pulse delay").
    Why the extra 1 s: at 10 Hz one pulse (≈ 3 cm) is 0.3 m/s of speed and 3 m/s² of A_p;
    ``MA3`` alone leaves ±0.11 m/s² (0.4 km/h/s, a third of Ta, false alarms on 25 ‰ lines)
    and steps Jp by 0.36 km/h/s per 0.1 s, above its 0.15 limit, so the start-point
    condition would almost never hold. After
    ``MA1`` the residue is ±0.025 m/s² and Jp steps by 0.036 km/h/s. Cost: ≈ 0.3 s more
    detection latency (0.7–0.8 s from onset for a 3.5–4.5 m/s wheel-speed step, 0.3 s of
    it the pulse delay); the look-back absorbs it.

Pulse delay (``_align``)
    The 300 ms is the SPEC's installation; a delay off by δ leaves δ·(jerk of K·a_x) in
    K·a_x − K·A_p (0.3 s × 0.3 m/s³ ≈ 0.09 m/s² in every jerk-limited transition, θ0 errors
    up to 9 mrad). With ``pulse_delay_search_cycles`` > 0 the run itself decides, within
    that many cycles of the SPEC value: the grade-compensated residual u (below) and the
    jerk of K·a_x, both high-passed by a second difference over DELAY_HP_S (removing the
    accelerometer bias, the gyro drift and most grade changes; values beyond
    DELAY_CLIP_MPS2 — slips — left out), are regressed on each other; the coefficient is
    the time by which A_p lags a_x. Half a cycle of it is built in (A_p of cycle k spans
    (t_k − 1.05, t_k − 0.05], a pulse speed being the mean over its cycle, a_x's 1 s mean
    (t_k − 1, t_k]); the rest, rounded to cycles, moves the delay (one refinement) when it
    exceeds DELAY_SIGMAS standard errors (K-correlated samples counted once per filter
    length). Without jerk in the run the SPEC value stays. The simulator's IMU has no lag:
    every run gives 0.24–0.29 s at the SPEC value and ends at d = 0; the tests' harness
    (four transitions in 120 s) gives back its 0, 300 and 600 ms, while a one-cycle
    difference needs more jerk than that to be significant. (The built-in half cycle
    remains: K·a_x − K·A_p = K·G·sinθ + 0.05 s·jerk, ≤ 0.02 m/s².)

Gyro pitch-rate bias (``_gyro_pitch``)
    θ_g = ∫θ̇ dt over the whole run (eq. 12, body frame so that a change of cab does not
    break it; roll per cycle as at a start point, eq. 11 carried with ω_x) and
    u = K·(a_x − A_p)/G − K·θ_g. While adhering u = b_a/G − const − b·t + noise (b_a the
    accelerometer bias, b the pitch-rate bias): the least-squares slope of u over the
    adhering cycles of the trailing ``bias_window_s`` is −b (``_sliding_slope``, running
    sums, O(n); no estimate, and no residual, before BIAS_MIN_S of data). An ADIS16480-class
    gyro has a bias of 0.05 °/s ≈ 0.9 mrad/s (1σ): uncorrected, θ drifts 9 mrad in a 10 s
    correction, the
    acceleration error grows to 0.09 m/s² and the distance error to G·b·(t_c·T²/2 + T³/6)
    ≈ 3 m in 8 s (t_c the 1.9 s carry to i0) — it was the main cause of corrections off by
    2–5 % (bench/slip_study.py: 80 % → 96 % within ±2 %). b is removed from θ̇ in the carry
    to i0 and in the integration.

Detection (eq. 1)
    ``|a_x − A_p| > Ta`` on the smoothed aligned values, pulse speed ≥ ``min_speed_kmh``.
    ``a_x − A_p < −Ta``: the wheel accelerates faster than the body → *slip* (traction);
    ``> +Ta``: the wheel decelerates faster → *slide* (braking). The gravity term G·sinθ is
    at most Ta (35 ‰), so the sign decides. Only rising edges of the mask open an episode.

Second criterion: grade-compensated residual (``residual_threshold_kmh_s``, 0 = off)
    Ta must exceed the largest G·sinθ, so a slip whose K-filtered excess acceleration stays
    below 0.34 m/s² goes unseen: shallow (10–20 %) slips at 2–8 m/s, 0.4–4 m of distance
    each. But the change of θ is known from the gyro: with u as above (adhering: constant
    − b·t), the residual over the horizon H = ``residual_horizon_s``

        r(k) = G·[u(k) − u(k − H) + b̂·H]      (travel frame: slip < 0 < slide)

    is K·(a_x − A_p) minus its value H ago minus the gyro's change of G·sinθ in between:
    grades, vertical curves, cant and the accelerometer bias drop out and r stays near zero
    while adhering. Its noise is the pulse quantisation of two K windows (±0.04 m/s²), the
    gyro error over H after the bias estimate (≈ 0.3 mrad/s in sharp canted curves, from
    the roll error × ω_z) and the IMU noise: over 300 simulated runs |r| ≤ 0.076 m/s² on
    adhering cycles (99.9 % ≤ 0.05), against the threshold 0.45 km/h/s = 0.125 m/s² (Ta/2.7).
    H = 4 s ≥ the filter length M = 3.9 s: the two K windows do not overlap, so a slip
    onset shows in full. A detection needs an adhering reference: u(k − H) not in a Ta
    detection and not within a filter length after a cycle either criterion flags (two
    passes); a residual onset whose reference falls in the previous episode (k − H − M ≤
    its end) is ignored; and there is no residual before the bias estimate exists. The
    residual needs the right pulse delay (above): with the SPEC's 300 ms on lag-free data
    it reaches 0.15 m/s² (37 false detections in 100 simulated runs).

Correction start point
    From the detection cycle minus ``lookback_s`` search backwards (at most
    ``SEARCH_SPAN_S``, never before the previous episode's end) for the last cycle at which
    |Ji| ≤ 0.1, |Jp| ≤ 0.15 and |Ji − Jp| < 0.05 km/h/s per 0.1 s held for ``hold_cycles``
    consecutive cycles (Ji, Jp: per-cycle differences of smoothed a_x, A_p). Vectorised as
    "last index ≤ k where the rolling condition holds" (``np.maximum.accumulate``). If none
    is found the look-back point itself is used (``detail['start_found'] = False``).
    A residual detection comes earlier (0.4–1.3 s after the onset, median 0.8 s, on the
    simulated runs), so its look-back point is instead QUIET_MARGIN_S before the last cycle
    at which |r| was within QUIET_SHARE of the threshold (where the residual leaves its
    noise band), but never earlier than the SPEC
    look-back: as often before the onset as with the SPEC look-back (8 against 4 of 958
    simulated episodes start after it), ≈ 0.5 s shorter corrections, 12 % fewer fail-safes.
    A slip shorter than the filter shows in r as two opposite lobes that cancel while both
    are in the window; when only the end lobe crosses the threshold, the look-back counts
    from the first cycle of the opposite lobe within H + M before (beyond half the
    threshold) and the kind is reversed (``criterion`` "residual-end", ``_lobe``).

Attitude at the start point (i0)
    Pitch (eq. 3): θ̄ = arcsin((a_x0 − A_p0)/G) with A_p0 the least-squares acceleration of a
    quadratic fitted to the M = 3.9 s of pulse distances ending at i0 and a_x0 the *same*
    linear functional applied to the a_x cycle means (``_lsq_accel_weights``), so
    a_x0 − A_p0 is a weighted mean of G·sinθ for any speed profile, with ≈ 0.003 m/s² of
    pulse-quantisation error instead of ±0.025 (a two-speed difference). Roll (eq. 11):
    ψ̄ = arctan(K·(a_y − v·ω_z) / K·a_z) (in a canted left curve a_y = v²/R + G·sinψ, ψ < 0).
    Both are means over a window centred ≈ 1.9 s before i0; they are carried to i0 with the
    gyros, ``x(i0) = x̄ + Σ_l ẋ(i0−l)·dt·S_{l+1}`` with ``S_l`` the tail sums of the window
    weights (exact for any rate history), so a vertical curve or a transition just before
    the start point does not bias θ0, ψ0. |θ̄| is limited to arcsin(Ta/G) (35 ‰): more
    means the start point was not adhering (``detail['theta_clipped']``). The start speed
    v0 is the 1 s mean pulse speed carried to i0 the same way with A_x; the pulse distance
    at i0 anchors the distance.

Attitude propagation (eqs. 4, 6, 12 in our frame)
    Kinematics of SPEC §4.1 (heading Ψ, nose-up pitch θ, roll ψ):
    ``wx = ψ̇ + Ψ̇·sinθ``, ``wy = −θ̇·cosψ + Ψ̇·cosθ·sinψ``, ``wz = θ̇·sinψ + Ψ̇·cosθ·cosψ``.
    Eliminating Ψ̇ (wz·sinψ − wy·cosψ):

        θ̇ = −wy·cosψ + wz·sinψ                                (eq. 12, our frame)

    i.e. the papers' ω_y'' = ω_y + ω_z·sinψ with ω_y = −wy and cosψ ≈ 1 (eq. 5 and the first
    two terms of eq. 12); θ(t) = θ0 + ∫θ̇ dt (eq. 4). The papers' third term −k·ω_x·sinψ
    (k = ±1 by curve hand) has no counterpart in rigid-body kinematics: with k = sign(ω_z)
    it integrates to k·(cosψ − cosψ0), an empirical correction for their installation, and
    it is left out (it would bias exact data by up to 1 − cos ψ ≈ 0.005 rad at 100 mm cant).
    The gyro bias b̂ at i0 is subtracted from θ̇ (see above).
    Roll: ψ(t) = ψ0 + ∫ωx dt (eq. 6); a second pass adds the exact −Ψ̇·sinθ term with
    Ψ̇·cosθ = wy·sinψ + wz·cosψ (on 25 ‰ in an R 400 m curve at 20 m/s eq. 6 alone drifts
    0.05 rad/s·0.025·10 s ≈ 0.013 rad in ψ).

Correction (eq. 2)
    A_x = a_x − G·sinθ (θ at mid-cycle), integrated from i0 (trapezoid of the cycle means,
    which is exact for the cycle-mean speed under a linear acceleration) to the speed, then
    to the distance. Negative speeds are clipped (the distance never decreases).

Re-adhesion
    After detection, the first cycle at which the 1 s mean inertial speed and the 1 s mean
    pulse speed ``vp1`` have agreed within ``readhesion_tol_kmh`` + β·(t − t0) for
    ``readhesion_hold_s``. The SPEC compares the per-cycle pulse speed (±0.3 m/s of
    quantisation) within β·t and also requires |a_x − A_p| ≤ Ta. Both fail for shallow
    slips: |a_x − A_p| never exceeds Ta, and β·t with the former β = 0.8 km/h/s lets a
    0.4 m/s speed excess "re-adhere" 2 s after the start while still slipping. The 1 s means
    are quiet to ±0.03 m/s, so the tolerance can follow the inertial error instead: 0.1 m/s
    (quantisation, and wheel wear up to 0.5 % of v0) + 0.15 km/h/s·t (with the gyro bias
    removed the inertial speed of the simulated corrections is off by ≤ 0.17 m/s at their
    end in 95 %, ≤ 0.26 m/s in 99 %). Holding 1 s stands in for the acceleration condition
    (a crossing of the two speeds does not hold), without the 3.9 s filter's lag:
    corrections end 1.2 s after the slip on average instead of 2.3 s, and none of 653
    simulated re-adhesions comes before the slip's end (before: 7 of 90 more than 0.3 s
    before it).
    From there the distance continues on the pulses with a constant offset (continuous,
    never decreasing). A correction still running ``max_correction_s`` after i0 ends there
    as a *fail-safe* episode (``failsafe=True``): the distance continues on the pulses and
    the solver makes the position uncertain.
    Only rising edges of the detection masks open an episode, and a new start point needs
    the look-back's room after the previous end (see ``find_episodes``): otherwise, if the
    two speeds still agree since the re-adhesion, the detection is the filters' echo of the
    slip's end and is ignored (``detail['echo_t']``); if not, the re-adhesion was premature
    and is re-opened; a detection just after a fail-safe is ignored. A correction lasts
    ≈ look-back 1–2 s + slip + 1.2 s, so slips longer than ≈ 7.5 s end as fail-safe.

Fail-safe watch (``failsafe_watch_s``, ``_watch``)
    After a fail-safe the wheel may still be slipping while the distance runs on its
    pulses. The integration goes on (radar where it covers) for up to ``failsafe_watch_s``
    and is compared with the pulses as in the re-adhesion test; until they agree the
    allowance grows by |v − v_pulse| + the speed's own error bound (Δa·t from the start
    point, eq. 13's model; radar 1 % of v) per second, and detections (and residual
    references) inside the watch belong to the same disturbance: they are ignored
    (``redetect_t``). Why: a 34 % slide going on 6 s past its fail-safe left 31 m of error
    against 8 m of margin (once in 300 simulated runs); a new correction started from the
    still-sliding pulses doubled the error. ``detail``: ``watch_end_t``,
    ``watch_allowance_m``, ``watch_readhered``, ``watch_speed_source``.

Re-adhesion speed update (``readhesion_speed_update``)
    Once re-adhered the wheel measures the ground speed again, so the difference δ of the
    1 s mean inertial and pulse speeds at ie is the inertial speed error accumulated since
    i0 (known to ±0.03 m/s: one pulse per second), and the correction, retroactive anyway,
    is closed on it: δ·(t − t0)/T is subtracted from the inertial speed (a ramp from 0 at i0,
    where the speed came from adhering pulses, to δ at ie, T = t_ie − t0), which changes the
    episode distance by −½·δ·T (exactly −δ·Σ_k (t_k − t0)·dt_k / T over the cycles of the
    correction). What it removes: the inertial errors grow with time, the episode distance
    with speed, so at 1–3 m/s a correction of 8–9 s (40 m) is off by 2–2.7 % although its
    speed ends only 0.2–0.3 m/s off (bench/slip_study.py, worst of 653 simulated episodes:
    θ0 error 0.4 m, v0 0.25 m, the gyro's angle random walk over 8 s 0.5 m, the residual
    gyro bias 0.1–0.2 m, the accelerometer noise 0.1 m). A linear ramp is the conditional
    mean of the distance error given δ when the error is a constant acceleration error
    (θ0, accelerometer bias change: ½·δ·T); a residual gyro bias gives ⅓·δ·T, an angle
    random walk ⅜·δ·T, a v0 error δ·T: the ramp sits in the middle, and the least-squares
    coefficient of the 653 episode errors on δ·T is 0.50. Bounded: by the re-adhesion
    condition |δ| ≤ ``readhesion_tol_kmh`` + β·T, so a re-adhesion declared on a still
    slightly slipping wheel moves the distance by at most (0.1 + 0.042·T)·T/2 m (2.6 m at
    10 s, against eq. 13's 22.8 m, which stays the allowance). Scale: v0 and the pulse speed
    at ie both carry the wheel's diameter error (wear, ≤ 0.5 %), so the update closes the
    correction in the pulses' scale, that of the rest of the odometry (the solver's
    correction percentage removes it); the inertial increments alone are in true scale.
    Effect on the 300 simulated runs (653 episodes): against the true distance max |error|
    2.72 → 1.20 %, p95 1.09 → 0.61 % (mean +0.26 %: the wear); against the pulse-scale
    distance p95 1.04 → 0.32 %, rms 0.37 → 0.11 m. Fail-safe and truncated episodes
    (no re-adhesion) and radar-bridged ones keep their speeds. ``detail``:
    ``end_speed_error_mps`` (δ) and ``speed_update_m`` (the distance change).

Output time base
    Episodes are found on the aligned arrays and written back shifted by the pulse delay,
    so ``d``, ``v`` and the episode indices refer to the cycle grid of ``cycles.t`` (the
    correction is retroactive from the start point, as the onboard unit recomputes it once
    it detects the slip at ``t_detect``, which is the clock time of the detection cycle).

Allowance (eq. 13)
    ``allowance[k]`` = Σ over finished episodes of ½·Δa·T² (T = their correction time)
    plus, inside a running episode, ½·Δa·(t − t_start)². It is continuous, never decreases,
    and equals the full eq. 13 budget from each episode's end on (22.8 m for T = 10 s).

NaN policy: missing IMU cycles are bridged by linear interpolation for the integration; the
moving averages use what exists; no detection where a smoothed value is missing.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import Cycles, delay, moving_average, trailing_sum
from fieldlogs.pipeline.types import FloatArray, Odometry, SlipEpisode, pulse_only_odometry, slip_budget_m
from schemas.units import G, kmh_s_to_mps2, mps2_to_kmh_s

#: Averaging of the pulse speed (and of a_x, identically) before the 3 s moving average [s].
SPEED_AVG_S = 1.0
#: How far before the look-back point the start-point search may go [s].
SEARCH_SPAN_S = 3.0
CYCLE_S = 0.1
#: Pulse-delay search: high-pass span (second difference over this) [s], residuals beyond
#: this left out (slips) [m/s²], and how many standard errors the lag estimate must have.
DELAY_HP_S = 5.0
DELAY_CLIP_MPS2 = 0.1
DELAY_SIGMAS = 3.0
#: Residual detections: the look-back point is QUIET_MARGIN_S before the residual last
#: stayed within QUIET_SHARE of its threshold.
QUIET_SHARE = 0.25
QUIET_MARGIN_S = 1.0
#: The end lobe of a shallow slip is at most this many times its onset lobe (the same speed
#: change; the residual's echo of the onset adds to the end lobe) [–].
LOBE_RATIO = 4.0
#: Least adhering data in the bias window before the gyro bias is estimated [s].
BIAS_MIN_S = 10.0
#: Error budget of a radar-bridged episode: this share of its distance plus a constant [%, m].
RADAR_ERROR_PCT = 1.0
RADAR_ERROR_M = 0.5


def correct_odometry(cycles: Cycles, cfg: OdometryConfig, radar_mps: FloatArray | None = None) -> Odometry:
    """Pulse odometry with slip/slide episodes replaced by the inertial solution (SPEC §5.1).

    ``radar_mps``: an independent ground speed on the cycle grid (2-frequency CW radar
    [S004]; NaN where there is none). Detection is unchanged, but over an episode the
    radar covers completely its speed replaces the inertial one: it does not drift, so the
    episode's error budget is the radar's (1 % of the distance + 0.5 m) when smaller than
    eq. 13's.
    """
    n = cycles.n
    d_pulse = np.nan_to_num(np.asarray(cycles.d_pulse, dtype=float), nan=0.0)
    v_pulse = np.nan_to_num(np.asarray(cycles.v_pulse, dtype=float), nan=0.0)
    if not cycles.has_imu or not cycles.has_tacho or n < 3:
        return pulse_only_odometry(d_pulse, v_pulse)
    s = _Streams(cycles, cfg, d_pulse, v_pulse)
    episodes = s.find_episodes()
    return s.assemble(episodes, radar_mps)


@dataclass
class _Integration:
    i_lim: int
    v_in: FloatArray
    theta: FloatArray
    theta0: float
    psi0: float
    v0: float
    clipped: bool


class _Streams:
    """The aligned, smoothed streams of one run and the per-episode integration."""

    def __init__(self, cycles: Cycles, cfg: OdometryConfig, d_pulse: FloatArray, v_pulse: FloatArray) -> None:
        self.cfg = cfg
        self.n = n = cycles.n
        self.t = np.asarray(cycles.t, dtype=float)
        dt = np.asarray(cycles.dt, dtype=float)
        self.cyc = float(np.median(dt)) if n > 1 else CYCLE_S
        self.dt = np.where(np.isfinite(dt) & (dt > 0), dt, self.cyc)
        self.uniform = bool(np.all(np.abs(self.dt - self.cyc) < 1e-6))
        self.W = max(round(cfg.avg_window_s / self.cyc), 1)
        self.P = max(round(SPEED_AVG_S / self.cyc), 1)
        self.readhesion_hold = max(round(cfg.readhesion_hold_s / self.cyc), 1)  # re-adhesion hold [cycles]
        self.readhesion_tol0 = cfg.readhesion_tol_kmh / 3.6  # re-adhesion tolerance, constant part [m/s]
        self.d_pulse, self.v_pulse = d_pulse, v_pulse
        self._cache: dict[int, _Integration] = {}
        self._agree: dict[int, npt.NDArray[np.bool_]] = {}
        # filter K = MA_W ∘ MA_P as weights on lags 0..M−1, and its tail sums S_l = Σ_{m≥l} w_m
        self.kernel = np.convolve(np.full(self.P, 1.0 / self.P), np.full(self.W, 1.0 / self.W))
        self.M = self.kernel.size
        self.tail = _tail(self.kernel)
        self.tail_p = _tail(np.full(self.P, 1.0 / self.P))
        self.lsq_c, self.lsq_g = _lsq_accel_weights(self.M, self.cyc)
        self.tail_g = _tail(self.lsq_g[::-1])

        # travel frame (cab −1: body turned 180° about z); IMU gaps are bridged per window
        cab = np.asarray(cycles.cab)
        self.sign = None if (cab >= 0).all() else np.where(cab < 0, -1.0, 1.0)
        self.sgn = np.ones(n) if self.sign is None else self.sign
        self.imu = {c: np.asarray(cycles.imu[c], dtype=float) for c in ("ax", "ay", "az", "wx", "wy", "wz")}
        ax_raw = self.imu["ax"] if self.sign is None else self.imu["ax"] * self.sign
        self.axs = self._k(ax_raw)

        # pulse stream delayed onto the IMU (aligned index k ↔ output index k − D); the first
        # pulse speed is 0 by construction and the delay repeats it: everything before
        # ``warm`` is excluded from detection and from the start-point windows
        self.D = D = self._align(max(int(cfg.pulse_delay_cycles), 0))
        self.vp = delay(v_pulse, D)
        self.dp = delay(d_pulse, D)
        self.vp1 = _ma(self.vp, self.P)
        ap = np.diff(self.vp1, prepend=self.vp1[0])
        ap /= self.dt
        self.aps = _ma(ap, self.W)
        self.diff = self.axs - self.aps
        self.ta = cfg.ta_mps2
        self.warm = warm = min(D + self.P + self.M, n)  # first cycle whose windows hold only valid data

        # detection mask (eq. 1) and its rising edges
        moving = self.vp1 >= cfg.min_speed_kmh / 3.6
        with np.errstate(invalid="ignore"):
            mask = (np.abs(self.diff) > self.ta) & moving
        mask[:warm] = False
        self.mask = mask
        ta_onsets = _rising(mask)

        # second criterion: the grade-compensated residual (see the module docstring)
        self._gyro_pitch()
        self.res = np.full(n, np.nan)
        self.res_mask = np.zeros(n, dtype=bool)
        hz = round(cfg.residual_horizon_s / self.cyc)
        self.H = hz
        if cfg.residual_threshold_kmh_s > 0 and 0 < hz < n:
            ref, now = slice(0, n - hz), slice(hz, n)
            u, t = self.u, self.t
            self.res[now] = G * self.sgn[now] * (u[now] - u[ref] + self.bias[ref] * (t[now] - t[ref]))
            with np.errstate(invalid="ignore"):
                over = (np.abs(self.res) > kmh_s_to_mps2(cfg.residual_threshold_kmh_s)) & self.u_valid & moving
            # the reference must be adhering: no Ta detection there, and not within a filter
            # length after a cycle either criterion flags (its K window would hold the
            # disturbance); two passes settle which residual detections count
            quiet = self.u_ok & self.bias_ok
            for _ in range(2):
                ref_ok = np.zeros(n, dtype=bool)
                ref_ok[now] = quiet[ref]
                quiet = self.u_ok & self.bias_ok & ~_recent(mask | (over & ref_ok), self.M)
            self.res[~(ref_ok & self.u_valid)] = np.nan
            self.res_mask = over & ref_ok
        res_onsets = _rising(self.res_mask)
        self.onsets = np.union1d(ta_onsets, res_onsets)
        self.is_ta_onset = np.isin(self.onsets, ta_onsets)

        # start-point condition: jerks per 0.1 s, held for hold_cycles → last index where it held
        per: float | FloatArray = 0.1 / self.cyc if self.uniform else 0.1 / self.dt
        ji = np.diff(self.axs, prepend=np.nan) * per
        jp = np.diff(self.aps, prepend=np.nan) * per
        with np.errstate(invalid="ignore"):
            ok = np.abs(ji) <= kmh_s_to_mps2(cfg.jerk_imu_max_kmh_s) + 1e-12
            ok &= np.abs(jp) <= kmh_s_to_mps2(cfg.jerk_pulse_max_kmh_s) + 1e-12
            ji -= jp
            ok &= np.abs(ji) < kmh_s_to_mps2(cfg.jerk_diff_max_kmh_s)
        ok[:warm] = False
        h = max(int(cfg.hold_cycles), 1)
        run = ok.copy()
        for lag in range(1, h):
            run[lag:] &= ok[:-lag]
            run[:lag] = False
        self.last_hold = np.maximum.accumulate(np.where(run, np.arange(n), -1))

    def _k(self, x: FloatArray) -> FloatArray:
        """The filter K = MA_W ∘ MA_P."""
        return _ma(_ma(x, self.P), self.W)

    def _theta_gyro(self, vp: FloatArray) -> FloatArray:
        """Body-frame pitch integrated from the gyros (eq. 12) over the whole run, K-filtered
        (an arbitrary constant and the gyro bias·t included); ``vp`` the aligned pulse speed
        for the roll's centripetal term."""
        n = self.n
        ay, az = _bridge(self.imu["ay"]), _bridge(self.imu["az"], G)
        wx, wy, wz = _bridge(self.imu["wx"]), _bridge(self.imu["wy"]), _bridge(self.imu["wz"])
        # roll per cycle: eq. 11's window mean carried to the cycle with ω_x (as at i0)
        psi = np.arctan2(self._k(ay - self.sgn * vp * wz), self._k(az))
        psi += np.convolve(wx * self.dt, self.tail[1:])[:n]
        theta_dot = -wy * np.cos(psi) + wz * np.sin(psi)
        return self._k(np.cumsum(theta_dot * self.dt))

    def _align(self, d0: int) -> int:
        """Pulse delay: the SPEC value ``d0``, or the one within ±pulse_delay_search_cycles
        that the run's data show (regression of the residual on the jerk, see the docstring)."""
        span = max(int(self.cfg.pulse_delay_search_cycles), 0)
        hp = round(DELAY_HP_S / self.cyc)
        n = self.n
        first = min(d0 + span, n) + self.P + self.M + 2 * hp
        self.theta_k = self._theta_gyro(delay(self.v_pulse, d0))
        if span == 0 or n <= first + 10 * hp:
            return d0
        vp1 = _ma(self.v_pulse, self.P)
        aps = _ma(np.diff(vp1, prepend=vp1[0]) / self.dt, self.W)
        body = self.sgn * self.axs / G - self.theta_k

        def h2(x: FloatArray) -> FloatArray:  # second difference over DELAY_HP_S
            return (x[2 * hp :] - 2.0 * x[hp:-hp] + x[: -2 * hp])[first - 2 * hp :]

        jerk = h2(np.gradient(self.sgn * self.axs) / self.cyc)
        moving = vp1[first:] > 1.0
        d = d0
        for _ in range(2):
            e = G * h2(body - self.sgn * delay(aps, d) / G)
            with np.errstate(invalid="ignore"):
                m = moving & np.isfinite(e) & np.isfinite(jerk) & (np.abs(e) <= DELAY_CLIP_MPS2)
            jj = float(np.dot(jerk[m], jerk[m]))
            if m.sum() < 10 * hp or jj <= 0.0:
                break
            lead = float(np.dot(e[m], jerk[m])) / jj  # A_p behind a_x by this much [s]
            rest = e[m] - lead * jerk[m]
            sigma = float(np.sqrt(np.dot(rest, rest) / m.sum() / jj * self.M))  # K-correlated samples
            lead -= 0.5 * self.cyc  # A_p of cycle k is centred half a cycle before a_x's
            if abs(lead) < DELAY_SIGMAS * sigma:
                break
            nd = int(np.clip(d - round(lead / self.cyc), max(d0 - span, 0), d0 + span))
            if nd == d:
                break
            d = nd
        if d != d0:
            self.theta_k = self._theta_gyro(delay(self.v_pulse, d))
        return d

    def _gyro_pitch(self) -> None:
        """``u`` = K·(a_x − A_p)/G − K·θ_gyro in the body frame, and the gyro bias.

        While adhering u = accelerometer bias/G − the gyro pitch's constant − b·t + noise
        (b the pitch-rate bias of eq. 12): its trailing least-squares slope is −b. Body frame
        (``sgn`` turns it back) so that a change of cab does not break the gyro integral;
        K windows across a change of cab mix the frames and are left out."""
        n = self.n
        with np.errstate(invalid="ignore"):
            self.u = self.sgn * self.diff / G - self.theta_k
        valid = np.isfinite(self.u)
        valid[: self.warm] = False
        if self.sign is not None:
            for c in np.flatnonzero(np.diff(self.sgn) != 0) + 1:
                valid[c : c + self.M + self.P] = False
        self.u_valid = valid
        self.u_ok = valid & ~self.mask
        self.bias = np.zeros(n)
        self.bias_ok = np.ones(n, dtype=bool)  # without an estimate the residual drifts by G·b·H
        lb = round(self.cfg.bias_window_s / self.cyc)
        if lb > 0:
            slope, count = _sliding_slope(self.t, self.u, self.u_ok, lb)
            self.bias_ok = count >= min(BIAS_MIN_S / self.cyc, lb)
            self.bias = np.where(self.bias_ok, -slope, 0.0)

    def imu_window(self, name: str, sl: slice, fill: float = 0.0) -> FloatArray:
        """Travel-frame IMU column over a window, gaps bridged linearly (edges held)."""
        x = self.imu[name][sl]
        if self.sign is not None and name in ("ax", "ay", "wx", "wy"):
            x = x * self.sign[sl]
        return _bridge(x, fill)

    # ------------------------------------------------------------------ episodes
    def find_episodes(self) -> list[tuple[SlipEpisode, FloatArray]]:
        """Episodes in time order, each with its inertial speed on the aligned cycles i0..ie.

        A start point needs ``lookback`` cycles of room after the previous episode's end ie
        (and after a fail-safe also a full filter window, so that θ0 and v0 are computed
        from data of after the disturbance). A detection without that room is
        * after a re-adhesion, with the speeds agreeing ever since: the filters' echo of the
          slip's end — ignored, listed in ``echo_t``;
        * after a re-adhesion otherwise: proof that the re-adhesion was premature — the
          previous correction is re-opened and continues from its own start point;
        * after a fail-safe: still the same disturbance — ignored, the distance stays on
          the pulses (the position is uncertain anyway); listed in ``redetect_t``.
        A residual onset whose reference u(k − H) lies within the previous episode (or a
        filter length after it) is ignored: the residual then compares with slipping pulses.
        """
        cfg = self.cfg
        episodes: list[tuple[SlipEpisode, FloatArray]] = []
        lookback = round(cfg.lookback_s / self.cyc)
        span = round(SEARCH_SPAN_S / self.cyc)
        floor = self.warm
        pos = 0
        while True:
            j = int(np.searchsorted(self.onsets, pos))
            if j >= self.onsets.size:
                break
            det = int(self.onsets[j])
            ta = bool(self.is_ta_onset[j])
            prev = episodes[-1][0] if episodes else None
            if not ta and prev is not None and det - self.H - self.M <= prev.detail["i_settled_aligned"]:
                pos = det + 1  # the residual's reference lies in the previous episode
                continue
            if prev is not None and det - lookback < floor:
                pd = prev.detail
                if prev.readhered and self._agrees(pd["i_start_aligned"], pd["i_end_aligned"], det):
                    pd["echo_t"].append(float(self.t[det]))
                    pos = det + 1  # the filters' echo of the slip's end: the speeds still agree
                    continue
                pd["redetect_t"].append(float(self.t[det]))
                if prev.failsafe:
                    pos = det + 1
                    continue
                episodes.pop()
                ep, v_in = self._episode(
                    pd["i_detect_aligned"],
                    pd["i_start_aligned"],
                    pd["start_found"],
                    det,
                    pd["redetect_t"],
                    pd["criterion"],
                )
            else:
                if ta:
                    crit, back = "ta", det - lookback
                else:
                    crit, ref = self._lobe(det)
                    back = self._quiet_before(ref, ref - lookback)
                i0, found = self._start_point(det, back, span, floor)
                ep, v_in = self._episode(det, i0, found, det, [], crit)
            episodes.append((ep, v_in))
            ie = ep.detail["i_end_aligned"]
            floor = ie + 1
            ep.detail["i_settled_aligned"] = ie
            if ep.failsafe:  # still the same disturbance while the pulses disagree
                w = self._watch(ep.detail["i_start_aligned"], ie) if cfg.failsafe_watch_s > 0 else None
                ep.detail["i_settled_aligned"] = max(ie, w.end if w is not None else 0)
                floor = max(ie + self.M, ep.detail["i_settled_aligned"] + 1)
            pos = ie + 1
        return episodes

    def _lobe(self, det: int) -> tuple[str, int]:
        """A slip shorter than the filter shows in the residual as two lobes of opposite
        sign (onset, then end) that cancel while both are in the window; a sub-threshold
        onset lobe followed by a detected end lobe would put the look-back inside the slip.
        If the residual had the opposite sign (beyond half the threshold) within the
        horizon + filter before ``det``, rising from its noise band there, and the detected
        lobe's peak over the next filter length is at most LOBE_RATIO times that lobe's, the
        look-back counts from the first cycle of that lobe and the kind is reversed (the
        kind and start point are settled a filter length after ``det``: the correction is
        retroactive anyway)."""
        lo = max(det - self.H - self.M, 0)
        thr = kmh_s_to_mps2(self.cfg.residual_threshold_kmh_s)
        with np.errstate(invalid="ignore"):
            opp = np.flatnonzero(np.sign(self.res[det]) * self.res[lo:det] < -0.5 * thr)
        if opp.size == 0:
            return "residual", det
        back = opp[::-1]
        brk = np.flatnonzero(np.diff(back) != -1)
        lobe = back[: brk[0] + 1] if brk.size else back  # the latest opposite lobe, backwards
        first = int(lobe[-1])
        with np.errstate(invalid="ignore"):  # a lobe rises from the noise band, a drift does not
            rose = bool((np.abs(self.res[lo : lo + first]) <= QUIET_SHARE * thr).any())
        # one slip's lobes carry the same speed change: an end lobe far larger than the
        # opposite lobe is a new, deep disturbance (a 34 % slide 5 s after a noise lobe of
        # half the threshold was once taken for a slip's end: its correction started 8 s
        # early and ran out of time mid-slide)
        sgn = np.sign(self.res[det])
        with np.errstate(invalid="ignore"):
            peak_opp = float(np.nanmax(-sgn * self.res[lo + lobe]))
            peak_end = float(np.nanmax(sgn * self.res[det : det + self.M]))
        if peak_end > LOBE_RATIO * peak_opp:
            return "residual", det
        return ("residual-end", lo + first) if rose else ("residual", det)

    def _agrees(self, i0: int, ie: int, det: int) -> bool:
        """Pulse and inertial speeds of the correction from i0 still agree from its
        re-adhesion ie up to cycle det (False when det is past the integrated span)."""
        agree = self._agree.get(i0)
        if agree is None or det - i0 >= agree.size:
            return False
        return bool(agree[ie - i0 : det - i0 + 1].all())

    def _quiet_before(self, ref: int, back: int) -> int:
        """Look-back point of a residual detection: QUIET_MARGIN_S before the last cycle
        before ``ref`` at which |residual| was within QUIET_SHARE of the threshold (the
        onset is where the residual leaves its noise band), but not before ``back``."""
        thr = QUIET_SHARE * kmh_s_to_mps2(self.cfg.residual_threshold_kmh_s)
        lo = max(back, 0)
        with np.errstate(invalid="ignore"):
            q = np.flatnonzero(np.abs(self.res[lo:ref]) <= thr)
        if q.size == 0:
            return back
        return max(lo + int(q[-1]) - round(QUIET_MARGIN_S / self.cyc), back)

    def _start_point(self, det: int, k: int, span: int, floor: int) -> tuple[int, bool]:
        lo = max(floor, k - span)
        if k < lo:
            return max(min(det - 1, floor), 0), False
        j = int(self.last_hold[k])
        if j >= lo:
            return j, True
        return k, False

    def _window(self, i0: int) -> slice:
        """Cycles of the filter window ending at i0."""
        return slice(max(i0 - self.M + 1, 0), i0 + 1)

    def _kmean(self, x: FloatArray) -> float:
        """Filter-weighted mean of a window slice (oldest first), NaNs skipped."""
        seg = x[::-1]
        w = self.kernel[: seg.size]
        ok = np.isfinite(seg)
        sw = float(w[ok].sum())
        return float(np.dot(w[ok], seg[ok]) / sw) if sw > 0 else float("nan")

    def _carry(self, rate: FloatArray, h: FloatArray, tail: FloatArray) -> float:
        """Σ_l rate(i0−l)·dt·S_{l+1} over a window slice (oldest first) ending at i0: moves a
        filter-window mean to the window's last cycle."""
        m = min(rate.size, tail.size - 1)
        seg = (rate * h)[::-1][:m]
        return float(np.dot(seg, tail[1 : m + 1]))

    def _integrate(self, i0: int) -> _Integration:
        """Attitude at start point i0 and the inertial solution for up to max_correction_s
        (cached: a re-opened episode keeps its start point)."""
        if i0 in self._cache:
            return self._cache[i0]
        cfg = self.cfg
        n, t, dt = self.n, self.t, self.dt
        t_lim = t[i0] + cfg.max_correction_s
        i_lim = min(int(np.searchsorted(t, t_lim - 1e-9)), n - 1)
        i_far = min(int(np.searchsorted(t, t_lim + max(cfg.failsafe_watch_s, 0.0) - 1e-9)), n - 1)
        w = self._window(i0)  # filter window ending at i0
        span = slice(w.start, i_far + 1)  # window + integration (+ fail-safe watch), IMU bridged once
        ax, ay, az = self.imu_window("ax", span), self.imu_window("ay", span), self.imu_window("az", span, G)
        wx, wy, wz = self.imu_window("wx", span), self.imu_window("wy", span), self.imu_window("wz", span)
        nw = i0 - w.start + 1
        pre, post = slice(0, nw), slice(nw - 1, None)

        # attitude and speed at the start point (eqs. 3, 11), carried from window mean to i0
        hw = dt[w]
        psi_bar = float(np.arctan2(self._kmean(ay[pre] - self.vp[w] * wz[pre]), self._kmean(az[pre])))
        psi0 = psi_bar + self._carry(wx[pre], hw, self.tail)
        if nw == self.M:  # least-squares A_p0 (see _lsq_accel_weights)
            diff0 = float(np.dot(self.lsq_g, ax[pre]) - np.dot(self.lsq_c, self.dp[w]))
            tail_th = self.tail_g
        else:
            diff0 = float(self.diff[i0]) if np.isfinite(self.diff[i0]) else 0.0
            tail_th = self.tail
        # |G·sinθ| ≤ Ta by design (35 ‰); more means the start point was not adhering
        theta_max = float(np.arcsin(min(self.ta / G, 1.0)))
        theta_bar = float(np.arcsin(np.clip(diff0 / G, -1.0, 1.0)))
        clipped = abs(theta_bar) > theta_max
        theta_bar = float(np.clip(theta_bar, -theta_max, theta_max))
        bias = float(self.bias[i0] * self.sgn[i0])  # gyro pitch-rate bias, travel frame
        theta0 = theta_bar + self._carry(-wy[pre] * np.cos(psi0) + wz[pre] * np.sin(psi0) - bias, hw, tail_th)
        v0 = float(self.vp1[i0]) + self._carry(ax[pre] - G * np.sin(theta0), hw, self.tail_p)

        # integrate over max_correction_s and the fail-safe watch (eqs. 4, 6, 12, 2)
        sl = slice(i0, i_far + 1)
        h = dt[sl].copy()
        h[0] = 0.0
        ax, wx, wy, wz = ax[post], wx[post], wy[post], wz[post]
        psi = psi0 + np.cumsum(wx * h)
        theta_dot = -wy * np.cos(psi) + wz * np.sin(psi) - bias
        theta = theta0 + np.cumsum(theta_dot * h)
        yaw_c = wy * np.sin(psi) + wz * np.cos(psi)  # Ψ̇·cosθ
        psi = psi0 + np.cumsum((wx - yaw_c * np.tan(theta)) * h)
        theta_dot = -wy * np.cos(psi) + wz * np.sin(psi) - bias
        theta = theta0 + np.cumsum(theta_dot * h)
        theta_mid = theta - 0.5 * theta_dot * h
        acc = ax - G * np.sin(theta_mid)
        dv = np.concatenate([[0.0], 0.5 * (acc[1:] + acc[:-1]) * h[1:]])
        v_in = np.maximum(v0 + np.cumsum(dv), 0.0)
        res = _Integration(i_lim, v_in, theta, theta0, psi0, v0, clipped)
        self._cache[i0] = res
        return res

    def _episode(
        self, det: int, i0: int, found: bool, after: int, redetect_t: list[float], criterion: str
    ) -> tuple[SlipEpisode, FloatArray]:
        """Episode detected at ``det`` corrected from start point i0; re-adhesion is looked
        for after cycle ``after`` (later than ``det`` when a premature one was re-opened)."""
        cfg = self.cfg
        n, t = self.n, self.t
        ig = self._integrate(i0)
        i_lim = ig.i_lim
        v_in, theta = ig.v_in[: i_lim - i0 + 1], ig.theta[: i_lim - i0 + 1]
        sl = slice(i0, i_lim + 1)

        # re-adhesion after detection (1 s mean speeds agree within ε + β·t for readhesion_hold_s),
        # else fail-safe at the time limit, else end of data
        tt = t[sl] - t[i0]
        lead = self.vp[max(i0 - self.P + 1, 0) : i0]  # the 1 s mean starts on adhering pulses
        v1 = _ma(np.concatenate([lead, v_in]), self.P)[lead.size :]
        with np.errstate(invalid="ignore"):
            agree = np.abs(v1 - self.vp1[sl]) <= self.readhesion_tol0 + cfg.beta_mps2 * tt
        self._agree[i0] = agree
        cond = _held(agree, self.readhesion_hold)
        cond[: max(after - i0 + 1, 0)] = False
        hit = np.flatnonzero(cond)
        readhered = hit.size > 0
        failsafe = False
        if readhered:
            ie = i0 + int(hit[0])
        elif t[i_lim] - t[i0] >= cfg.max_correction_s - 1e-9:
            ie, failsafe = i_lim, True
        else:
            ie = n - 1
        m_end = ie - i0 + 1
        v_in, theta = v_in[:m_end], theta[:m_end]
        duration = float(t[ie] - t[i0])
        # re-adhesion speed update: the 1 s means' difference at ie is the inertial speed
        # error, removed as a ramp from 0 at i0 (module docstring)
        end_err = float(v1[m_end - 1] - self.vp1[ie]) if readhered else float("nan")
        update_m = 0.0
        if readhered and cfg.readhesion_speed_update and duration > 0 and np.isfinite(end_err):
            ramp = end_err * tt[:m_end] / duration
            update_m = -float(np.dot(ramp[1:], self.dt[i0 + 1 : ie + 1]))
            v_in = np.maximum(v_in - ramp, 0.0)
        sense = float(self.diff[det] if criterion == "ta" else self.res[det])
        kind = "slip" if (sense < 0) != (criterion == "residual-end") else "slide"
        detail: dict[str, Any] = {
            "theta0_rad": ig.theta0,
            "psi0_rad": ig.psi0,
            "theta_end_rad": float(theta[-1]),
            "v0_mps": ig.v0,
            "diff_at_detect_kmh_s": mps2_to_kmh_s(float(self.diff[det])),
            "ax_at_detect_kmh_s": mps2_to_kmh_s(float(self.axs[det])),
            "ap_at_detect_kmh_s": mps2_to_kmh_s(float(self.aps[det])),
            "v_pulse_at_detect_mps": float(self.vp1[det]),
            "criterion": criterion,
            "residual_at_detect_kmh_s": _finite(mps2_to_kmh_s(float(self.res[det]))),
            "gyro_bias_rad_s": float(self.bias[i0] * self.sgn[i0]),
            "start_found": found,
            "theta_clipped": ig.clipped,
            "end_speed_error_mps": _finite(end_err),
            "speed_update_m": update_m,
            "lookback_s": float(t[det] - t[i0]),
            "delay_cycles": self.D,
            "i_detect_aligned": det,
            "i_start_aligned": i0,
            "i_end_aligned": ie,
            "truncated": not readhered and not failsafe,
            "redetect_t": redetect_t,
            "echo_t": [],
        }
        ep = SlipEpisode(
            kind=kind,
            t_detect=float(t[det]),
            t_start=0.0,
            t_end=0.0,
            i_start=i0 - self.D,
            i_end=ie - self.D,
            d_pulse_m=0.0,
            d_corrected_m=0.0,
            max_error_m=slip_budget_m(duration, cfg.delta_a_mps2),
            readhered=readhered,
            failsafe=failsafe,
            detail=detail,
        )
        return ep, v_in

    # ------------------------------------------------------------------ output
    def assemble(self, found: list[tuple[SlipEpisode, FloatArray]], radar: FloatArray | None = None) -> Odometry:
        n, t = self.n, self.t
        d_pulse, v_pulse = self.d_pulse, self.v_pulse
        v = v_pulse.copy()
        slipping = np.zeros(n, dtype=bool)
        off_step = np.zeros(n + 1)
        allow_step = np.zeros(n + 1)
        seg_d: list[tuple[int, FloatArray]] = []
        growth: list[tuple[int, int, float]] = []
        offset = 0.0
        da = self.cfg.delta_a_mps2
        for ep, v_in in found:
            s, e = ep.i_start, ep.i_end
            if ep.detail["truncated"] and e < n - 1:  # data ended mid-correction: hold the speed
                v_in = np.concatenate([v_in, np.full(n - 1 - e, v_in[-1])])
                e = n - 1
                ep.i_end = e
            use_radar = radar is not None and bool(np.isfinite(radar[s : e + 1]).all())
            if use_radar:
                assert radar is not None
                v_in = radar[s : e + 1].astype(float)
            ep.detail["speed_source"] = "radar" if use_radar else "inertial"
            d_s = d_pulse[s] + offset
            inc = np.concatenate([[0.0], v_in[1:] * self.dt[s + 1 : e + 1]])
            d_seg = d_s + np.cumsum(inc)
            seg_d.append((s, d_seg))
            v[s + 1 : e + 1] = v_in[1:]
            slipping[s + 1 : e + 1] = True
            new_offset = float(d_seg[-1] - d_pulse[e])
            off_step[e + 1] += new_offset - offset
            offset = new_offset
            budget = slip_budget_m(float(t[e] - t[s]), da)
            if use_radar:
                budget = min(budget, RADAR_ERROR_PCT / 100.0 * float(d_seg[-1] - d_seg[0]) + RADAR_ERROR_M)
            allow_step[e + 1] += budget
            growth.append((s, e, budget))
            ep.t_start, ep.t_end = float(t[s]), float(t[e])
            ep.max_error_m = budget
            ep.d_pulse_m = float(d_pulse[e] - d_pulse[s])
            ep.d_corrected_m = float(d_seg[-1] - d_seg[0])
        d = d_pulse + np.cumsum(off_step)[:n]
        allowance = np.cumsum(allow_step)[:n]
        for (s, d_seg), (_, e, budget) in zip(seg_d, growth, strict=True):
            d[s : e + 1] = d_seg
            grow = 0.5 * da * (t[s + 1 : e + 1] - t[s]) ** 2
            allowance[s + 1 : e + 1] += np.minimum(grow, budget)
        if self.cfg.failsafe_watch_s > 0:
            for ep, _ in found:
                if ep.failsafe:
                    self._add_watch(ep, allowance, radar)
        return Odometry(d, v, slipping, allowance, [ep for ep, _ in found])

    def _watch(self, i0: int, ie: int, radar: FloatArray | None = None) -> _Watch | None:
        """Fail-safe watch (``OdometryConfig.failsafe_watch_s``) of the correction from i0
        that failed safe at ie: from ie on, compare the 1 s mean inertial speed of its
        integration (the radar's where it covers the watch) with the 1 s mean pulse speed
        as the re-adhesion test does. Until they have agreed for ``readhesion_hold_s`` the
        pulses may still be slipping: the error rate is bounded by |v − v_pulse| + the
        speed's own error (Δa·t from the start point; radar 1 % of v)."""
        cfg, t = self.cfg, self.t
        ig = self._integrate(i0)
        lead = self.vp[max(i0 - self.P + 1, 0) : i0]
        v1 = _ma(np.concatenate([lead, ig.v_in]), self.P)[lead.size + ie - i0 :]
        k = np.arange(ie, ie + v1.size)  # aligned cycles; output cycle = k − D
        out = k - self.D
        if v1.size < 2 or out[0] - self.P + 1 < 0:
            return None
        tt = t[k] - t[i0]
        use_radar = radar is not None and bool(np.isfinite(radar[out[0] - self.P + 1 : out[-1] + 1]).all())
        if use_radar:
            assert radar is not None
            v1 = _ma(radar[out[0] - self.P + 1 : out[-1] + 1].astype(float), self.P)[self.P - 1 :]
            own = RADAR_ERROR_PCT / 100.0 * v1
            tol = self.readhesion_tol0 + own
        else:
            own = cfg.delta_a_mps2 * tt
            tol = self.readhesion_tol0 + cfg.beta_mps2 * tt
        dv = np.abs(v1 - self.vp1[k])
        held = _held(dv <= tol, self.readhesion_hold)
        held[0] = False
        hit = np.flatnonzero(held)
        j = int(hit[0]) if hit.size else v1.size - 1
        grow = np.cumsum((dv + own)[1 : j + 1] * self.dt[out[1 : j + 1]])
        return _Watch(ie + j, out[1 : j + 1], grow, bool(hit.size), "radar" if use_radar else "inertial")

    def _add_watch(self, ep: SlipEpisode, allowance: FloatArray, radar: FloatArray | None) -> None:
        """The fail-safe watch's growth added to the allowance; ``watch_*`` in the detail."""
        w = self._watch(int(ep.detail["i_start_aligned"]), int(ep.detail["i_end_aligned"]), radar)
        if w is None:
            return
        if w.grow.size:
            allowance[w.cycles] += w.grow
            allowance[w.cycles[-1] + 1 :] += w.grow[-1]
        ep.detail.update(
            watch_end_t=float(self.t[w.end - self.D]),
            watch_allowance_m=float(w.grow[-1]) if w.grow.size else 0.0,
            watch_readhered=w.readhered,
            watch_speed_source=w.source,
        )


@dataclass
class _Watch:
    end: int
    """Aligned cycle at which the watch ends (re-adhesion, or its time limit)."""
    cycles: npt.NDArray[np.intp]
    """Output cycles after the fail-safe up to the end."""
    grow: FloatArray
    """Cumulative allowance growth on those cycles [m]."""
    readhered: bool
    source: str


def _bridge(x: npt.NDArray[np.float64], fill: float = 0.0) -> FloatArray:
    """Linear interpolation over missing cycles (edges held; ``fill`` when all missing)."""
    ok = np.isfinite(x)
    if ok.all():
        return x.astype(float, copy=True)
    if not ok.any():
        return np.full(x.size, fill)
    idx = np.arange(x.size)
    return np.interp(idx, idx[ok], x[ok])


def _tail(weights: FloatArray) -> FloatArray:
    """Tail sums S_l = Σ_{m≥l} w_m of weights on lags 0..M−1 (S_M = 0 appended)."""
    return np.concatenate([np.cumsum(weights[::-1])[::-1], [0.0]])


def _lsq_accel_weights(m: int, dt: float) -> tuple[FloatArray, FloatArray]:
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


def _ma(x: FloatArray, window: int) -> FloatArray:
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


def _held(ok: npt.NDArray[np.bool_], cycles: int) -> npt.NDArray[np.bool_]:
    """True where ``ok`` has held for the last ``cycles`` cycles (this one included)."""
    cond = ok.copy()
    for lag in range(1, cycles):
        cond[lag:] &= ok[:-lag]
        cond[:lag] = False
    return cond


def _rising(mask: npt.NDArray[np.bool_]) -> npt.NDArray[np.intp]:
    """Indices where ``mask`` turns True."""
    return np.flatnonzero(mask[1:] & ~mask[:-1]) + 1


def _sliding_slope(
    t: FloatArray, y: FloatArray, w: npt.NDArray[np.bool_], window: int
) -> tuple[FloatArray, FloatArray]:
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


def _recent(mask: npt.NDArray[np.bool_], window: int) -> npt.NDArray[np.bool_]:
    """True where ``mask`` was True at this cycle or one of the ``window − 1`` before."""
    return trailing_sum(mask, window) > 0


def _finite(x: float) -> float | None:
    return x if np.isfinite(x) else None
