"""The inertial solution from a start point i0 (stage 3's integration, eqs. 2–6, 11, 12).

Attitude at the start point (eqs. 3, 11)
    Pitch (eq. 3): θ̄ = arcsin((a_x0 − A_p0)/G) with A_p0 the least-squares acceleration of a
    quadratic fitted to the M = 3.9 s of pulse distances ending at i0 and a_x0 the *same*
    linear functional applied to the a_x cycle means (``signals.lsq_accel_weights``), so
    a_x0 − A_p0 is a weighted mean of G·sinθ for any speed profile, with ≈ 0.003 m/s² of
    pulse-quantisation error instead of ±0.025 (a two-speed difference) — a departure from
    the paper's difference of the smoothed values at i0, for that error. Roll (eq. 11):
    ψ̄ = arctan(K·(a_y − v·ω_z) / K·a_z) (in a canted left curve a_y = v²/R + G·sinψ, ψ < 0).
    Both are means over a window centred ≈ 1.9 s before i0; they are carried to i0 with the
    gyros, ``x(i0) = x̄ + Σ_l ẋ(i0−l)·dt·S_{l+1}`` with ``S_l`` the tail sums of the window
    weights (exact for any rate history), so a vertical curve or a transition just before
    the start point does not bias θ0, ψ0. |θ̄| is limited to arcsin(Ta/G) (35 ‰): more
    means the start point was not adhering (``clipped``). The start speed v0 is the 1 s
    mean pulse speed carried to i0 the same way with A_x; the pulse distance at i0 anchors
    the distance.

Attitude propagation (eqs. 4, 6, 12 in our frame)
    Kinematics of SPEC §4.1 (heading Ψ, nose-up pitch θ, roll ψ):
    ``wx = ψ̇ + Ψ̇·sinθ``, ``wy = −θ̇·cosψ + Ψ̇·cosθ·sinψ``, ``wz = θ̇·sinψ + Ψ̇·cosθ·cosψ``.
    Eliminating Ψ̇ (wz·sinψ − wy·cosψ):

        θ̇ = −wy·cosψ + wz·sinψ                                (eq. 12, our frame)

    i.e. the papers' ω_y'' = ω_y + ω_z·sinψ with ω_y = −wy and cosψ ≈ 1 (eq. 5 and the first
    two terms of eq. 12); θ(t) = θ0 + ∫θ̇ dt (eq. 4). Departure: the papers' third term
    −k·ω_x·sinψ (k = ±1 by curve hand) has no counterpart in rigid-body kinematics — with
    k = sign(ω_z) it integrates to k·(cosψ − cosψ0), an empirical correction for their
    installation — so it is left out (it would bias exact data by up to 1 − cos ψ ≈
    0.005 rad at 100 mm cant). The gyro bias b̂ at i0 (stage 2) is subtracted from θ̇.
    Roll: ψ(t) = ψ0 + ∫ωx dt (eq. 6); a second pass adds the exact −Ψ̇·sinθ term with
    Ψ̇·cosθ = wy·sinψ + wz·cosψ (on 25 ‰ in an R 400 m curve at 20 m/s eq. 6 alone drifts
    0.05 rad/s·0.025·10 s ≈ 0.013 rad in ψ).

Correction (eq. 2)
    A_x = a_x − G·sinθ (θ at mid-cycle), integrated from i0 (trapezoid of the cycle means,
    which is exact for the cycle-mean speed under a linear acceleration) to the speed.
    Negative speeds are clipped (the distance never decreases). The solution runs for
    ``max_correction_s`` plus the fail-safe watch (``failsafe_watch_s``).

NaN policy: missing IMU cycles are bridged by linear interpolation over the window and the
integration span (``AlignedStreams.imu_window``); the window means skip NaNs.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import IMU_COLUMNS
from fieldlogs.pipeline.odometry.detection import Detections
from fieldlogs.pipeline.odometry.signals import readonly
from fieldlogs.pipeline.odometry.streams import AlignedStreams, Imu
from fieldlogs.pipeline.types import FloatArray
from schemas.units import G


@dataclass(frozen=True, eq=False)
class StartAttitude:
    """Attitude and speed at a start point i0 (eqs. 3, 11, carried to i0)."""

    theta0: float
    """Pitch θ0, travel frame (the gradient climbed) [rad]."""
    psi0: float
    """Roll ψ0 (left side up) [rad]."""
    v0: float
    """Speed [m/s]."""
    clipped: bool
    """|θ̄| exceeded arcsin(Ta/G) and was limited."""
    bias: float
    """Gyro pitch-rate bias b̂ at i0, travel frame [rad/s]."""


@dataclass(frozen=True, eq=False)
class Integration:
    """The inertial solution from start point ``i0`` on the aligned cycles i0..i_far."""

    i0: int
    i_lim: int
    """Aligned cycle at which ``max_correction_s`` is reached (or the last one)."""
    start: StartAttitude
    v_in: FloatArray
    """Inertial speed on cycles i0..i_far (v_in[0] = v0) [m/s]."""
    theta: FloatArray
    """Pitch on the same cycles [rad]."""


def integrate(s: AlignedStreams, d: Detections, cfg: OdometryConfig, i0: int, extend_s: float = 0.0) -> Integration:
    """Attitude at start point i0 and the inertial solution for ``max_correction_s`` and
    the fail-safe watch (eqs. 3, 11, then 4, 6, 12, 2); ``extend_s``: for longer than the
    watch beyond ``max_correction_s`` (a correction a ground speed carries)."""
    n, t = s.n, s.t
    t_lim = t[i0] + cfg.max_correction_s
    i_lim = min(int(np.searchsorted(t, t_lim - 1e-9)), n - 1)
    i_far = min(int(np.searchsorted(t, t_lim + max(cfg.failsafe_watch_s, extend_s, 0.0) - 1e-9)), n - 1)
    w = _window(s, i0)
    span = slice(w.start, i_far + 1)  # window + integration (+ fail-safe watch), IMU bridged once
    imu = Imu(*(s.imu_window(c, span, G if c == "az" else 0.0) for c in IMU_COLUMNS))  # travel frame, bridged
    nw = i0 - w.start + 1
    start = _start_attitude(s, d, cfg, i0, imu, nw)
    v_in, theta = _propagate(s, start, imu, slice(i0, i_far + 1), nw - 1)
    return Integration(i0, i_lim, start, readonly(v_in), readonly(theta))


def _window(s: AlignedStreams, i0: int) -> slice:
    """Cycles of the filter window ending at i0."""
    return slice(max(i0 - s.filters.M + 1, 0), i0 + 1)


def _kmean(kernel: FloatArray, x: FloatArray) -> float:
    """Filter-weighted mean of a window slice (oldest first), NaNs skipped."""
    seg = x[::-1]
    w = kernel[: seg.size]
    ok = np.isfinite(seg)
    sw = float(w[ok].sum())
    return float(np.dot(w[ok], seg[ok]) / sw) if sw > 0 else float("nan")


def _carry(rate: FloatArray, h: FloatArray, tail: FloatArray) -> float:
    """Σ_l rate(i0−l)·dt·S_{l+1} over a window slice (oldest first) ending at i0: moves a
    filter-window mean to the window's last cycle."""
    m = min(rate.size, tail.size - 1)
    seg = (rate * h)[::-1][:m]
    return float(np.dot(seg, tail[1 : m + 1]))


def _start_attitude(s: AlignedStreams, d: Detections, cfg: OdometryConfig, i0: int, imu: Imu, nw: int) -> StartAttitude:
    """θ0, ψ0, v0 at i0 from the window means (eqs. 3, 11) carried to i0 with the gyros."""
    f = s.filters
    w = _window(s, i0)
    pre = slice(0, nw)
    ax, wy, wz = imu.ax[pre], imu.wy[pre], imu.wz[pre]
    hw = s.dt[w]
    psi_bar = float(np.arctan2(_kmean(f.kernel, imu.ay[pre] - s.vp[w] * wz), _kmean(f.kernel, imu.az[pre])))
    psi0 = psi_bar + _carry(imu.wx[pre], hw, f.tail)
    if nw == f.M:  # least-squares A_p0 (see signals.lsq_accel_weights)
        diff0 = float(np.dot(f.lsq_g, ax) - np.dot(f.lsq_c, s.dp[w]))
        tail_th = f.tail_g
    else:
        diff0 = float(s.diff[i0]) if np.isfinite(s.diff[i0]) else 0.0
        tail_th = f.tail
    # |G·sinθ| ≤ Ta by design (35 ‰); more means the start point was not adhering
    theta_max = float(np.arcsin(min(cfg.ta_mps2 / G, 1.0)))
    theta_bar = float(np.arcsin(np.clip(diff0 / G, -1.0, 1.0)))
    clipped = abs(theta_bar) > theta_max
    theta_bar = float(np.clip(theta_bar, -theta_max, theta_max))
    bias = float(d.bias[i0] * s.sgn[i0])  # gyro pitch-rate bias, travel frame
    theta0 = theta_bar + _carry(-wy * np.cos(psi0) + wz * np.sin(psi0) - bias, hw, tail_th)
    v0 = float(s.vp1[i0]) + _carry(ax - G * np.sin(theta0), hw, f.tail_p)
    return StartAttitude(theta0, psi0, v0, clipped, bias)


def _propagate(s: AlignedStreams, a: StartAttitude, imu: Imu, sl: slice, first: int) -> tuple[FloatArray, FloatArray]:
    """Speed and pitch from i0 over the aligned cycles ``sl`` (eqs. 4, 6, 12, 2); the IMU
    arrays start ``first`` cycles before i0."""
    h = s.dt[sl].copy()
    h[0] = 0.0
    post = slice(first, None)
    ax, wx, wy, wz = imu.ax[post], imu.wx[post], imu.wy[post], imu.wz[post]
    psi = a.psi0 + np.cumsum(wx * h)
    theta_dot = -wy * np.cos(psi) + wz * np.sin(psi) - a.bias
    theta = a.theta0 + np.cumsum(theta_dot * h)
    yaw_c = wy * np.sin(psi) + wz * np.cos(psi)  # Ψ̇·cosθ
    psi = a.psi0 + np.cumsum((wx - yaw_c * np.tan(theta)) * h)
    theta_dot = -wy * np.cos(psi) + wz * np.sin(psi) - a.bias
    theta = a.theta0 + np.cumsum(theta_dot * h)
    theta_mid = theta - 0.5 * theta_dot * h
    acc = ax - G * np.sin(theta_mid)
    dv = np.concatenate([[0.0], 0.5 * (acc[1:] + acc[:-1]) * h[1:]])
    return np.maximum(a.v0 + np.cumsum(dv), 0.0), theta
