"""Pseudorange multipath from a reflecting surface beside the track (the ``network.multipath``
knob on raw GNSS; :mod:`fieldlogs.simulate.netsim` says where and how strong) [S002].

A vertical reflecting surface parallel to the track — a platform canopy or station building
at the neighbouring track, a noise barrier, a double-deck train standing there — on one side
(+1 left, −1 right, facing increasing s), at the perpendicular distance d from the antenna and
up to ``REFLECTOR_TOP_M`` above the rail; the antenna is h above the rail.

* **Geometry** (specular reflection: the reflected ray comes from the antenna's mirror image
  2d behind the surface): for a satellite at elevation E and azimuth A, the excess path of the
  reflected ray over the direct one is

      Δ = 2 d cos E cos α,   cos α = n̂·û_h = side · sin(A − ψ)

  (n̂ the horizontal unit normal from the surface toward the antenna, û_h the satellite's
  horizontal direction, ψ the azimuth of increasing s). A reflection exists only for a
  satellite on the antenna's side of the surface (cos α > 0) whose specular point, d tan E /
  cos α above the antenna, lies on the surface (≤ top − h): Δ > 0 always, largest for low
  satellites straight across from the surface, none above E = atan((top − h) cos α / d).
  A surface nearer than ``MIN_DISTANCE_M`` (inside the loading gauge) is none.
* **Signal**: the direct signal plus the reflection of relative amplitude a and phase
  θ = 2πΔ/λ + φ(t), the composite phasor 1 + a·e^{iθ}. φ(t) is a random walk whose increments
  have variance 2·dt/T, so that E[cos(φ(t + τ) − φ(t))] = exp(−|τ|/T): the reflecting
  surface is not one mirror (masts, gaps, the cars of a standing train) and the phase
  decorrelates as the car moves, over T = ``ErrorSpec.mp_tau_s`` (seconds).
* **Code**: a non-coherent early-minus-late delay-lock loop with a narrow correlator follows
  (van Nee 1992; Braasch, in Parkinson & Spilker vol. I ch. 14)

      e = Δ_c · a (a + cos θ) / (1 + a² + 2a cos θ)

  — a·Δ_c/(1 + a) in phase (θ = 0: the late reflection pulls the tracked peak late, a positive
  range error), −a·Δ_c/(1 − a) out of phase; its mean over θ is 0 for a < 1, so the error is a
  bias of either sign held over seconds, not white noise. Δ_c = min(Δ, ``HALF_SPACING_M``):
  the formula holds within half the correlator spacing (0.1 chip of the 293.05 m C/A chip),
  beyond it the error envelope is flat.
* **Carrier**: the composite phase, arg(1 + a e^{iθ})·λ/2π = atan2(a sin θ, 1 + a cos θ)·λ/2π
  (at most asin(a)·λ/2π, 2.5 cm for a = 0.5).
* **C/N0**: 20·log10|1 + a e^{iθ}| dB added (a fade when out of phase).
* **Amplitude**: a = min(|bias_m| / d, ``MAX_AMPLITUDE``), the knob's bias over the distance:
  an in-phase reflection of every satellite at small a would move a fix by a·d ≈ bias_m, the
  pull the knob gives the D-GPS fixes. A single bounce turns the right-hand circular
  polarisation left-handed, which the antenna rejects by ≥ 6 dB: a ≤ 0.5.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from fieldlogs.gnss.constants import C_MPS, F_L1_HZ, FloatArray

#: Top of the reflecting surface above the rail [m] (a platform canopy, a station's wall).
REFLECTOR_TOP_M = 8.0
#: A surface nearer the antenna than this [m] would foul the train: no reflector.
MIN_DISTANCE_M = 1.7
#: Half the spacing of a 0.1-chip narrow correlator on the C/A code [m].
HALF_SPACING_M = 0.05 * C_MPS / 1.023e6
#: Largest relative amplitude of a single-bounce (cross-polarised) reflection.
MAX_AMPLITUDE = 0.5
LAMBDA_L1_M = C_MPS / F_L1_HZ


@dataclass(frozen=True)
class Reflectors:
    """Per epoch: the side of the reflecting surface (+1 left, −1 right of increasing s, 0 none),
    its perpendicular distance from the antenna d [m] and the reflection's amplitude a."""

    side: FloatArray
    dist_m: FloatArray
    amp: FloatArray


#: The reflectors at the antenna's arc lengths s (what the simulator's caller provides).
ReflectorsAt = Callable[[FloatArray], Reflectors]


def amplitude(bias_m: FloatArray, dist_m: FloatArray) -> FloatArray:
    """a = min(|bias_m| / d, MAX_AMPLITUDE) (module docstring), 0 where d < MIN_DISTANCE_M."""
    d = np.asarray(dist_m, dtype=float)
    a = np.abs(np.asarray(bias_m, dtype=float)) / np.maximum(d, MIN_DISTANCE_M)
    return np.asarray(np.where(d >= MIN_DISTANCE_M, np.minimum(a, MAX_AMPLITUDE), 0.0), dtype=float)


def excess_path(
    side: FloatArray, dist_m: FloatArray, el: FloatArray, rel_az: FloatArray, antenna_up_m: float
) -> FloatArray:
    """Δ = 2 d cos E cos α [m] where the satellite is reflected to the antenna, else 0 (module
    docstring); ``rel_az`` = A − ψ [rad], arrays broadcast together."""
    cos_a = side * np.sin(rel_az)
    d = np.asarray(dist_m, dtype=float)
    above = REFLECTOR_TOP_M - antenna_up_m
    on_surface = d * np.tan(el) <= above * np.maximum(cos_a, 0.0)
    hit = (side != 0) & (d >= MIN_DISTANCE_M) & (cos_a > 0) & (el > 0) & on_surface
    return np.asarray(np.where(hit, 2.0 * d * np.cos(el) * cos_a, 0.0), dtype=float)


def code_error(delta_m: FloatArray, a: FloatArray, theta: FloatArray) -> FloatArray:
    """e = Δ_c · a (a + cos θ) / (1 + a² + 2a cos θ) [m], Δ_c = min(Δ, HALF_SPACING_M)."""
    dc = np.minimum(delta_m, HALF_SPACING_M)
    c = np.cos(theta)
    return np.asarray(dc * a * (a + c) / (1.0 + a * a + 2.0 * a * c), dtype=float)


def carrier_error(a: FloatArray, theta: FloatArray) -> FloatArray:
    """atan2(a sin θ, 1 + a cos θ)·λ/2π [m] (module docstring)."""
    return np.asarray(np.arctan2(a * np.sin(theta), 1.0 + a * np.cos(theta)) * LAMBDA_L1_M / (2 * np.pi), dtype=float)


def cn0_change(a: FloatArray, theta: FloatArray) -> FloatArray:
    """20·log10|1 + a e^{iθ}| [dB]."""
    return np.asarray(10.0 * np.log10(1.0 + a * a + 2.0 * a * np.cos(theta)), dtype=float)


def phase_walk(rng: np.random.Generator, n_t: int, n_s: int, dt: float, tau_s: float) -> FloatArray:
    """φ (n_t, n_s): a uniform start plus a random walk with increments N(0, 2 dt/T)."""
    steps = rng.normal(0.0, np.sqrt(2.0 * dt / tau_s), (n_t, n_s))
    steps[0] = rng.uniform(0.0, 2 * np.pi, n_s)
    return np.asarray(np.cumsum(steps, axis=0), dtype=float)


@dataclass(frozen=True)
class ReflectionErrors:
    """Per epoch and satellite: the code and carrier errors [m], the C/N0 change [dB] and Δ [m]."""

    code_m: FloatArray
    carrier_m: FloatArray
    cn0_db: FloatArray
    delta_m: FloatArray


def reflection_errors(
    refl: Reflectors, el: FloatArray, rel_az: FloatArray, antenna_up_m: float, phi: FloatArray
) -> ReflectionErrors:
    """The errors of every satellite (el, rel_az: (n_t, n_s)) at the epochs' reflectors, with
    the random phase φ (:func:`phase_walk`)."""
    delta = excess_path(refl.side[:, None], refl.dist_m[:, None], el, rel_az, antenna_up_m)
    a = np.where(delta > 0, refl.amp[:, None], 0.0)
    theta = 2 * np.pi * delta / LAMBDA_L1_M + phi
    return ReflectionErrors(code_error(delta, a, theta), carrier_error(a, theta), cn0_change(a, theta), delta)
