"""Stage 1: the aligned, smoothed streams of one run (:class:`AlignedStreams`).

Travel frame
    Pulses are unsigned, the IMU is body-fixed. With the sense of motion
    (:attr:`fieldlogs.pipeline.cycles.Cycles.motion`: the driving cab's direction, or a
    two-phase tachometer's — a train rolling back) = +1 the travel direction is body +x, with
    −1 it is −x: the travel frame is the body frame turned 180° about z, so
    ``ax, ay, wx, wy`` change sign and ``az, wz`` do not. x along travel, y left, z up
    (SPEC §4.1); pitch θ is nose-up in the travel direction (the gradient climbed), roll ψ
    is positive with the left side up.

Streams and alignment
    Pulse speed ``v`` is the per-cycle backward difference; A_p = dv/dt. The pulse stream is
    delayed D cycles (``pulse_delay_cycles``, SPEC 300 ms) to line up with the IMU, so index
    k of the *aligned* arrays holds pulse and IMU data of the same physical instant. A_p and
    a_x are smoothed with the trailing 3 s moving average ``MA3`` of the SPEC. Before
    differentiating, the pulse speed is averaged over ``SPEED_AVG_S`` (1 s) and a_x gets
    the identical 1 s average, so both go through the same filter K = MA3∘MA1 (a 3.9 s
    trapezoid) and, while adhering, ``K·a_x − K·A_p = K·(G·sinθ)`` whatever the jerk (to
    half a cycle, see "Pulse delay"). Departure from the SPEC (MA3 alone): at 10 Hz one
    pulse (≈ 3 cm) is 0.3 m/s of speed and 3 m/s² of A_p; MA3 alone leaves ±0.11 m/s²
    (a third of Ta) and steps Jp by 0.36 km/h/s per 0.1 s, above its 0.15 limit, so the
    start-point condition would almost never hold; after MA1 the residue is ±0.025 m/s²
    and Jp steps by 0.036 km/h/s, for ≈ 0.3 s more detection latency, which the look-back
    absorbs.

Pulse delay (``pulse_delay_search_cycles``)
    Departure from the SPEC's fixed 300 ms: a delay off by δ leaves δ·(jerk of K·a_x) in
    K·a_x − K·A_p (0.3 s × 0.3 m/s³ ≈ 0.09 m/s² in every jerk-limited transition, θ0 errors
    up to 9 mrad), and the residual criterion (stage 2) needs the true delay. With
    ``pulse_delay_search_cycles`` > 0 the run itself decides, within that many cycles of the
    SPEC value: the grade-compensated u (below) and the jerk of K·a_x, both high-passed by a
    second difference over DELAY_HP_S (removing the accelerometer bias, the gyro drift and
    most grade changes; values beyond DELAY_CLIP_MPS2 — slips — left out), are regressed on
    each other; the coefficient is the time by which A_p lags a_x. Half a cycle of it is
    built in (A_p of cycle k spans (t_k − 1.05, t_k − 0.05], a pulse speed being the mean
    over its cycle, a_x's 1 s mean (t_k − 1, t_k]); the rest, rounded to cycles, moves the
    delay (one refinement) when it exceeds DELAY_SIGMAS standard errors (K-correlated
    samples counted once per filter length). Without jerk in the run the SPEC value stays.
    The built-in half cycle remains: K·a_x − K·A_p = K·G·sinθ + 0.05 s·jerk (≤ 0.02 m/s²).
    Measurements: bench/NOTES.md, "Odometry".

Gyro pitch (eq. 12 over the whole run)
    θ_g = ∫θ̇ dt with θ̇ = −wy·cosψ + wz·sinψ (eq. 12 in this frame, see
    :mod:`~fieldlogs.pipeline.odometry.integration`), in the body frame so that a change of
    cab does not break it; roll per cycle as at a start point (eq. 11's window mean carried
    with ω_x). u = K·(a_x − A_p)/G − K·θ_g; while adhering u = b_a/G − const − b·t + noise
    (b_a the accelerometer bias, b the pitch-rate bias), which stage 2 uses for the gyro
    bias and the residual. K windows across a change of cab mix the frames and are left out
    (``u_valid``).

The first pulse speed is 0 by construction and the delay repeats it: everything before
``warm`` is excluded from detection and from the start-point windows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import IMU_COLUMNS, Cycles, delay
from fieldlogs.pipeline.odometry.signals import (
    BoolArray,
    bridge,
    lsq_accel_weights,
    ma,
    readonly,
    tail_sums,
)
from fieldlogs.pipeline.types import FloatArray
from schemas.units import G

#: Averaging of the pulse speed (and of a_x, identically) before the 3 s moving average [s].
SPEED_AVG_S = 1.0
#: Cycle length assumed for a run of one cycle [s].
CYCLE_S = 0.1
#: Pulse-delay search: high-pass span (second difference over this) [s], residuals beyond
#: this left out (slips) [m/s²], and how many standard errors the lag estimate must have.
DELAY_HP_S = 5.0
DELAY_CLIP_MPS2 = 0.1
DELAY_SIGMAS = 3.0
#: IMU columns whose sign flips between the body and the travel frame.
TRAVEL_SIGNED = ("ax", "ay", "wx", "wy")


@dataclass(frozen=True, eq=False)
class Imu:
    """The six IMU columns of a span of cycles (accelerations [m/s²], rates [rad/s]), in
    the order of ``cycles.IMU_COLUMNS``."""

    ax: FloatArray
    ay: FloatArray
    az: FloatArray
    wx: FloatArray
    wy: FloatArray
    wz: FloatArray


@dataclass(frozen=True, eq=False)
class Filters:
    """The filter K = MA_W ∘ MA_P and the window weights derived from it (one cycle length)."""

    cyc: float
    """Cycle length (median) [s]."""
    P: int
    """1 s mean [cycles]."""
    W: int
    """``avg_window_s`` moving average [cycles]."""
    kernel: FloatArray
    """K as weights on lags 0..M−1."""
    tail: FloatArray
    """Tail sums S_l = Σ_{m≥l} w_m of ``kernel`` (S_M = 0 appended)."""
    tail_p: FloatArray
    """Tail sums of the 1 s mean."""
    lsq_c: FloatArray
    """Least-squares acceleration weights on pulse distances over M cycles (oldest first)."""
    lsq_g: FloatArray
    """The same functional on cycle-mean accelerations."""
    tail_g: FloatArray
    """Tail sums of ``lsq_g`` (newest first)."""

    @property
    def M(self) -> int:
        """Filter length of K [cycles]."""
        return int(self.kernel.size)

    def k(self, x: FloatArray) -> FloatArray:
        """The filter K = MA_W ∘ MA_P."""
        return ma(ma(x, self.P), self.W)


def make_filters(cfg: OdometryConfig, cyc: float) -> Filters:
    """K and its window weights for cycle length ``cyc``."""
    p = max(round(SPEED_AVG_S / cyc), 1)
    w = max(round(cfg.avg_window_s / cyc), 1)
    kernel = np.convolve(np.full(p, 1.0 / p), np.full(w, 1.0 / w))
    lsq_c, lsq_g = lsq_accel_weights(kernel.size, cyc)
    return Filters(
        cyc=cyc,
        P=p,
        W=w,
        kernel=readonly(kernel),
        tail=readonly(tail_sums(kernel)),
        tail_p=readonly(tail_sums(np.full(p, 1.0 / p))),
        lsq_c=readonly(lsq_c),
        lsq_g=readonly(lsq_g),
        tail_g=readonly(tail_sums(lsq_g[::-1])),
    )


@dataclass(frozen=True, eq=False)
class AlignedStreams:
    """One run's streams in the travel frame, the pulses delayed onto the IMU (index k ↔
    output cycle k − ``delay``), smoothed with K; arrays are read-only."""

    t: FloatArray
    """Cycle times [s] (the output grid; the aligned arrays share it)."""
    dt: FloatArray
    """Cycle lengths, gaps replaced by the median [s]."""
    uniform: bool
    """All cycles have the median length."""
    filters: Filters
    sgn: FloatArray
    """+1 / −1: travel frame = body frame × sgn for ax, ay, wx, wy."""
    reversed_cab: bool
    """Some cycles run with cab −1."""
    imu: Imu
    """IMU cycle means in the body frame (NaN where missing)."""
    d_pulse: FloatArray
    """Pulse distance on the output grid, NaN → 0 [m]."""
    v_pulse: FloatArray
    """Pulse speed on the output grid, NaN → 0 [m/s]."""
    delay: int
    """Pulse delay D [cycles]."""
    vp: FloatArray
    """Aligned pulse speed [m/s]."""
    dp: FloatArray
    """Aligned pulse distance [m]."""
    vp1: FloatArray
    """Aligned 1 s mean pulse speed [m/s]."""
    aps: FloatArray
    """K·A_p [m/s²]."""
    axs: FloatArray
    """K·a_x, travel frame [m/s²]."""
    diff: FloatArray
    """K·a_x − K·A_p (eq. 1's quantity) [m/s²]."""
    u: FloatArray
    """K·(a_x − A_p)/G − K·θ_gyro, body frame [rad]."""
    u_valid: BoolArray
    """``u`` finite, after ``warm`` and not across a change of cab."""
    warm: int
    """First cycle whose windows hold only valid data."""

    @property
    def n(self) -> int:
        return int(self.t.size)

    @property
    def cyc(self) -> float:
        return self.filters.cyc

    def imu_window(self, name: str, sl: slice, fill: float = 0.0) -> FloatArray:
        """Travel-frame IMU column over a window, gaps bridged linearly (edges held)."""
        x: FloatArray = getattr(self.imu, name)[sl]
        if self.reversed_cab and name in TRAVEL_SIGNED:
            x = x * self.sgn[sl]
        return bridge(x, fill)


def align_streams(cycles: Cycles, cfg: OdometryConfig) -> AlignedStreams:
    """Stage 1: travel frame, pulse delay (searched), K-filtered a_x and A_p, gyro pitch u."""
    n = cycles.n
    t = np.asarray(cycles.t, dtype=float)
    d_pulse = np.nan_to_num(np.asarray(cycles.d_pulse, dtype=float), nan=0.0)
    v_pulse = np.nan_to_num(np.asarray(cycles.v_pulse, dtype=float), nan=0.0)
    dt_raw = np.asarray(cycles.dt, dtype=float)
    cyc = float(np.median(dt_raw)) if n > 1 else CYCLE_S
    dt = np.where(np.isfinite(dt_raw) & (dt_raw > 0), dt_raw, cyc)
    f = make_filters(cfg, cyc)

    cab = np.asarray(cycles.motion)
    reversed_cab = not bool((cab >= 0).all())
    sgn = np.where(cab < 0, -1.0, 1.0) if reversed_cab else np.ones(n)
    imu = Imu(*(readonly(np.asarray(cycles.imu[c], dtype=float)) for c in IMU_COLUMNS))
    axs = f.k(imu.ax * sgn if reversed_cab else imu.ax)

    d, theta_k = _pulse_delay(cfg, f, dt, sgn, imu, axs, v_pulse)
    vp = delay(v_pulse, d)
    vp1 = ma(vp, f.P)
    ap = np.diff(vp1, prepend=vp1[0])
    ap /= dt
    aps = ma(ap, f.W)
    diff = axs - aps
    warm = min(d + f.P + f.M, n)
    u, u_valid = _gyro_u(f, sgn, reversed_cab, diff, theta_k, warm)
    return AlignedStreams(
        t=readonly(t),
        dt=readonly(dt),
        uniform=bool(np.all(np.abs(dt - cyc) < 1e-6)),
        filters=f,
        sgn=readonly(sgn),
        reversed_cab=reversed_cab,
        imu=imu,
        d_pulse=readonly(d_pulse),
        v_pulse=readonly(v_pulse),
        delay=d,
        vp=readonly(vp),
        dp=readonly(delay(d_pulse, d)),
        vp1=readonly(vp1),
        aps=readonly(aps),
        axs=readonly(axs),
        diff=readonly(diff),
        u=readonly(u),
        u_valid=readonly(u_valid),
        warm=warm,
    )


def _theta_gyro(f: Filters, dt: FloatArray, sgn: FloatArray, imu: Imu, vp: FloatArray) -> FloatArray:
    """Body-frame pitch integrated from the gyros (eq. 12) over the whole run, K-filtered
    (an arbitrary constant and the gyro bias·t included); ``vp`` the aligned pulse speed
    for the roll's centripetal term."""
    n = dt.size
    ay, az = bridge(imu.ay), bridge(imu.az, G)
    wx, wy, wz = bridge(imu.wx), bridge(imu.wy), bridge(imu.wz)
    # roll per cycle: eq. 11's window mean carried to the cycle with ω_x (as at i0)
    psi = np.arctan2(f.k(ay - sgn * vp * wz), f.k(az))
    psi += np.convolve(wx * dt, f.tail[1:])[:n]
    theta_dot = -wy * np.cos(psi) + wz * np.sin(psi)
    return f.k(np.cumsum(theta_dot * dt))


def _pulse_delay(
    cfg: OdometryConfig,
    f: Filters,
    dt: FloatArray,
    sgn: FloatArray,
    imu: Imu,
    axs: FloatArray,
    v_pulse: FloatArray,
) -> tuple[int, FloatArray]:
    """Pulse delay and the gyro pitch θ_gyro for it: the SPEC value, or the one within
    ±pulse_delay_search_cycles that the run's data show (regression of u on the jerk).

    The SPEC value is kept when the run is too short for the search or its cycle is longer
    than the high-pass window ``DELAY_HP_S`` (no second difference to take: whatever the
    input, this never fails)."""
    d0 = max(int(cfg.pulse_delay_cycles), 0)
    span = max(int(cfg.pulse_delay_search_cycles), 0)
    hp = round(DELAY_HP_S / f.cyc) if np.isfinite(f.cyc) and f.cyc > 0 else 0
    n = dt.size
    first = min(d0 + span, n) + f.P + f.M + 2 * hp
    theta_k = _theta_gyro(f, dt, sgn, imu, delay(v_pulse, d0))
    if span == 0 or hp < 1 or n <= first + 10 * hp:
        return d0, theta_k
    vp1 = ma(v_pulse, f.P)
    aps = ma(np.diff(vp1, prepend=vp1[0]) / dt, f.W)
    body = sgn * axs / G - theta_k

    def h2(x: FloatArray) -> FloatArray:  # second difference over DELAY_HP_S
        return (x[2 * hp :] - 2.0 * x[hp:-hp] + x[: -2 * hp])[first - 2 * hp :]

    jerk = h2(np.gradient(sgn * axs) / f.cyc)
    moving = vp1[first:] > 1.0
    d = d0
    for _ in range(2):
        e = G * h2(body - sgn * delay(aps, d) / G)
        shift = _lag_cycles(e, jerk, moving, hp, f)
        nd = d if shift is None else int(np.clip(d - shift, max(d0 - span, 0), d0 + span))
        if nd == d:
            break
        d = nd
    if d != d0:
        theta_k = _theta_gyro(f, dt, sgn, imu, delay(v_pulse, d))
    return d, theta_k


def _lag_cycles(e: FloatArray, jerk: FloatArray, moving: BoolArray, hp: int, f: Filters) -> int | None:
    """Whole cycles by which A_p lags a_x beyond the built-in half cycle, from the
    regression of the high-passed u on the jerk; None when not significant (or no data)."""
    with np.errstate(invalid="ignore"):
        m = moving & np.isfinite(e) & np.isfinite(jerk) & (np.abs(e) <= DELAY_CLIP_MPS2)
    jj = float(np.dot(jerk[m], jerk[m]))
    if m.sum() < 10 * hp or jj <= 0.0:
        return None
    lead = float(np.dot(e[m], jerk[m])) / jj  # A_p behind a_x by this much [s]
    rest = e[m] - lead * jerk[m]
    sigma = float(np.sqrt(np.dot(rest, rest) / m.sum() / jj * f.M))  # K-correlated samples
    lead -= 0.5 * f.cyc  # A_p of cycle k is centred half a cycle before a_x's
    if abs(lead) < DELAY_SIGMAS * sigma:
        return None
    return round(lead / f.cyc)


def _gyro_u(
    f: Filters, sgn: FloatArray, reversed_cab: bool, diff: FloatArray, theta_k: FloatArray, warm: int
) -> tuple[FloatArray, BoolArray]:
    """``u`` = K·(a_x − A_p)/G − K·θ_gyro in the body frame (``sgn`` turns it back) and
    where it is valid (finite, after ``warm``, no K window across a change of cab)."""
    with np.errstate(invalid="ignore"):
        u = sgn * diff / G - theta_k
    valid = np.isfinite(u)
    valid[:warm] = False
    if reversed_cab:
        for c in np.flatnonzero(np.diff(sgn) != 0) + 1:
            valid[c : c + f.M + f.P] = False
    return u, valid
