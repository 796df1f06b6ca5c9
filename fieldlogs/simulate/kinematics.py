"""True attitude, specific force and angular rates in the body frame (SPEC §4.1).

Body frame: x toward the vehicle's F end, y left, z up, right-handed; rates positive
counter-clockwise about each axis seen from its positive end. The body does not turn round
on a reversal: running toward the R end only changes the sign of the velocity along x.

Attitude (heading Ψ, nose-up pitch θ, roll ψ; applied heading, then pitch, then roll):
R_wb = Rz(Ψ)·Ry(−θ)·Rx(ψ), world x east, y north, z up. A body facing increasing km has
Ψ = Ψ_track, θ = θ_track, ψ = ψ_cant; facing decreasing km Ψ + π, −θ, −ψ (f = ±1 below).

Rates (exact): wx = ψ̇ + Ψ̇·sinθ, wy = −θ̇·cosψ + Ψ̇·cosθ·sinψ, wz = θ̇·sinψ + Ψ̇·cosθ·cosψ,
with Ψ̇ = dΨ/dkm·k̇, θ̇ = f·dθ/dkm·k̇, ψ̇ = f·dψ/dkm·k̇ (k̇ = dkm/dt = u/J).

Specific force: f_b = R_wbᵀ·(a_w + (0, 0, G)) with the exact acceleration of a point moving
along the 3-D track curve, a_w = u̇·T + u²·dT/dσ, T = (cosθ cosΨ, cosθ sinΨ, sinθ) (track
frame, increasing km), dT/dσ = θ'·(−sinθ cosΨ, −sinθ sinΨ, cosθ) + Ψ'·cosθ·(−sinΨ, cosΨ, 0):
tangential dv/dt, centripetal v²κ toward the curve centre and vertical v²·dθ/ds.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fieldlogs.simulate.running import Motion
from fieldlogs.simulate.track import Cant, TrackGeometry
from schemas.units import G

FloatArray = npt.NDArray[np.float64]


@dataclass
class BodyKinematics:
    """True IMU quantities at every simulation step, plus the attitude for checks."""

    ax: FloatArray
    ay: FloatArray
    az: FloatArray
    wx: FloatArray
    wy: FloatArray
    wz: FloatArray
    pitch: FloatArray
    """Nose-up pitch θ of the body [rad]."""
    roll: FloatArray
    """Roll ψ of the body [rad] (< 0: left side down)."""


def body_kinematics(geom: TrackGeometry, cant: Cant, motion: Motion) -> BodyKinematics:
    st = geom.state(motion.km)
    f = float(motion.facing)
    u, udot = motion.u, motion.udot
    cpsi, spsi = st.cos_psi, st.sin_psi
    th_t = st.theta
    cth, sth = np.cos(th_t), np.sin(th_t)
    roll_t, droll_dkm = cant.roll(st.kappa, st.dkappa_dkm)
    scale = geom.cant_scale(motion.km)  # no cant on a route's turnouts
    if scale is not None:
        roll_t, droll_dkm = roll_t * scale[0], droll_dkm * scale[0] + roll_t * scale[1]
    kdot = u / st.j  # dkm/dt
    # attitude of the body
    theta, roll = f * th_t, f * roll_t
    hb_dot = st.dpsi_dkm * kdot
    th_dot = f * st.dtheta_dkm * kdot
    rl_dot = f * droll_dkm * kdot
    cb, sb = np.cos(theta), np.sin(theta)
    cr, sr = np.cos(roll), np.sin(roll)
    wx = rl_dot + hb_dot * sb
    wy = -th_dot * cr + hb_dot * cb * sr
    wz = th_dot * sr + hb_dot * cb * cr
    # world acceleration along the track curve + gravity reaction
    dth_ds = st.dtheta_dkm / st.j
    dpsi_ds = st.dpsi_dkm / st.j
    u2 = u * u
    fx = udot * cth * cpsi + u2 * (-dth_ds * sth * cpsi - dpsi_ds * cth * spsi)
    fy = udot * cth * spsi + u2 * (-dth_ds * sth * spsi + dpsi_ds * cth * cpsi)
    fz = udot * sth + u2 * dth_ds * cth + G
    # into the body: Rx(−ψ)·Ry(θ)·Rz(−Ψ_b); facing decreasing km: cos/sin Ψ_b = −cos/sin Ψ
    cpb, spb = f * cpsi, f * spsi
    g1 = cpb * fx + spb * fy
    g2 = -spb * fx + cpb * fy
    h1 = cb * g1 + sb * fz
    h3 = -sb * g1 + cb * fz
    ax = h1
    ay = cr * g2 + sr * h3
    az = -sr * g2 + cr * h3
    off = ~motion.on_rail  # road-rail vehicle standing on the road: level, at rest
    if off.any():
        for arr in (ax, ay, wx, wy, wz):
            arr[off] = 0.0
        az[off] = G
    return BodyKinematics(ax, ay, az, wx, wy, wz, theta, roll)
