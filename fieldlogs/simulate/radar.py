"""Raw IF samples of a 2-frequency CW radar looking down at the track bed [S004].

The vehicle's true motion (``running.Motion``) carries the antenna, mounted ``height_m``
above the track bed surface with its beam ``depression_deg`` below the horizontal, toward
the ``looks_toward`` end. The ground is a field of point scatterers (ballast: heights
uniform in ± ``ballast_roughness_m``; slab: ±2 mm and ``slab_reflectivity`` times weaker)
plus strong ones (sleeper edges, fasteners: ``strong_per_m``, jittered, ``strong_gain``
times stronger), each with a complex Gaussian amplitude a_j. The radar alternates f1 = f0
and f2 = f0 + Δf every T_pri; the mixer output of frequency f_k at time t is

    z_k(t) = Σ_j a_j · g(ε_j, φ_j) · sin δ_j / R_j² · exp(−j·4π·f_k·R_j(t)/c)

with R_j(t) the exact antenna–scatterer distance, δ_j the depression of the line of sight,
ε_j = δ_j − depression, φ_j its azimuth, and a Gaussian two-way amplitude pattern in the
direction sines g = exp(−ln2·((sin ε/sin β_e)² + (sin φ/sin β_a)²)) (one-way −3 dB at the
half-widths β). The sin δ is a
Lambertian backscatter (steeper incidence reflects more), the 1/R² the two-way spreading
of the field. f1 is sampled at t_n = n·2·T_pri, f2 at t_n + T_pri, so an approaching
reflector turns the phase forward (positive Doppler in I + jQ).

The receiver adds white complex Gaussian noise (``snr_db`` below the mean power of a ballast
bed at the nominal geometry, computed by integrating the same sum over the footprint), a
static leakage (``dc_leak``) and an ADC: samples scaled so that ballast clutter is 0.05 of
full scale, clipped at ±1 and quantised to ``adc_bits``. ``vibration_mm`` moves the antenna
up and down sinusoidally.

Nothing here is shared with ``fieldlogs.radar``: the processing only sees the samples and
the run.json ``radar`` block. The echo sum runs in a compiled kernel (numba; per sample a
loop over the scatterers in the footprint, found by ``searchsorted`` on their sorted track
positions) because it is O(samples × scatterers in view).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
from numba import njit

from fieldlogs.simulate.running import DT, Motion
from fieldlogs.simulate.scenario import RadarIfCfg, Scenario
from fieldlogs.simulate.sensors import in_spans
from fieldlogs.simulate.track import TrackGeometry
from schemas.radar import RadarParams
from schemas.units import SPEED_OF_LIGHT_MPS

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: Beam half-widths beyond which scatterers are skipped (two-way amplitude < e^(−ln2·6.25) ≈ 1.3 %).
VIEW_BEAMWIDTHS = 2.5
#: Ballast clutter RMS as a share of the ADC full scale.
CLUTTER_FS = 0.05
#: Slab surface: scatterer heights uniform in ± this [m].
SLAB_ROUGHNESS_M = 0.002
#: Samples per kernel call (bounds the temporary arrays of a long run).
CHUNK = 1 << 20


def radar_params(cfg: RadarIfCfg) -> RadarParams:
    """The run.json ``radar`` block the simulated radar declares."""
    return RadarParams(
        f0_hz=cfg.f0_hz,
        delta_f_hz=cfg.delta_f_hz,
        t_pri_s=cfg.t_pri_s,
        t_epi_s=cfg.t_epi_s,
        height_m=cfg.height_m,
        depression_deg=cfg.depression_deg,
        beam_elev_deg=cfg.beam_elev_deg,
        beam_az_deg=cfg.beam_az_deg,
        looks_toward=cfg.looks_toward,
    )


@dataclass(frozen=True)
class Ground:
    """Point scatterers sorted by track position σ [m]: lateral y [m], height z [m], amplitude."""

    sigma: FloatArray
    y: FloatArray
    z: FloatArray
    amp: npt.NDArray[np.complex128]


@dataclass(frozen=True)
class View:
    """What the antenna can see: ground distances ahead [m], the lateral half-width [m] and
    the depression and azimuth bounds [rad] at ± ``VIEW_BEAMWIDTHS`` half-widths."""

    x_near: float
    x_far: float
    y_max: float
    dep_lo: float
    dep_hi: float
    az_max: float


def view(cfg: RadarIfCfg, margin_m: float = 0.0) -> View:
    """Footprint bounds at ± ``VIEW_BEAMWIDTHS`` half-widths (the antenna ``margin_m`` higher or lower)."""
    lo = math.radians(max(cfg.depression_deg - VIEW_BEAMWIDTHS * cfg.beam_elev_deg, 2.0))
    hi = math.radians(min(cfg.depression_deg + VIEW_BEAMWIDTHS * cfg.beam_elev_deg, 89.0))
    az = math.radians(VIEW_BEAMWIDTHS * cfg.beam_az_deg)
    h_hi = cfg.height_m + margin_m + cfg.ballast_roughness_m
    h_lo = max(cfg.height_m - margin_m - cfg.ballast_roughness_m, 0.01)
    x_far = h_hi / math.tan(lo)
    return View(h_lo / math.tan(hi), x_far, x_far * math.tan(az), lo, hi, az)


def track_position(motion: Motion, t: FloatArray) -> FloatArray:
    """σ(t) [m] between the 100 Hz steps: σ_k + u_k·τ + (u_{k+1} − u_k)·τ²/(2·DT), the
    quadratic whose derivative interpolates u linearly (σ is the trapezoid integral of u)."""
    k = np.clip((t / DT).astype(np.int64), 0, max(motion.n - 2, 0))
    tau = np.clip(t - motion.t[k], 0.0, DT)
    u0 = motion.u[k]
    u1 = motion.u[np.minimum(k + 1, motion.n - 1)]
    return np.asarray(motion.sigma[k] + u0 * tau + (u1 - u0) * tau * tau / (2.0 * DT))


def _bed_is_slab(cfg: RadarIfCfg, geom: TrackGeometry, sigma: FloatArray) -> npt.NDArray[np.bool_]:
    if cfg.track_bed == "slab":
        return np.ones(len(sigma), dtype=bool)
    return in_spans(np.asarray(geom.km_at(sigma), dtype=float), cfg.slab_km_m)


def ground(
    cfg: RadarIfCfg, geom: TrackGeometry, span: tuple[float, float], band_m: float, rng: np.random.Generator
) -> Ground:
    """Diffuse and strong scatterers over σ ∈ span, |y| ≤ band_m."""
    lo, hi = span
    n = int(rng.poisson(cfg.scatterers_per_m2 * (hi - lo) * 2 * band_m))
    s = rng.uniform(lo, hi, n)
    slab = _bed_is_slab(cfg, geom, s)
    rough = np.where(slab, SLAB_ROUGHNESS_M, cfg.ballast_roughness_m)
    z = rng.uniform(-1.0, 1.0, n) * rough
    gain = np.where(slab, cfg.slab_reflectivity, 1.0)
    pitch = 1.0 / cfg.strong_per_m if cfg.strong_per_m > 0 else np.inf
    m = int((hi - lo) / pitch) if np.isfinite(pitch) else 0
    s_strong = lo + (np.arange(m) + 0.5) * pitch + rng.uniform(-0.05, 0.05, m)
    s_all = np.concatenate([s, s_strong])
    y = rng.uniform(-band_m, band_m, len(s_all))
    z_all = np.concatenate([z, np.zeros(m)])
    g_all = np.concatenate([gain, np.full(m, cfg.strong_gain)])
    amp = g_all * (rng.standard_normal(len(s_all)) + 1j * rng.standard_normal(len(s_all))) / np.sqrt(2.0)
    order = np.argsort(s_all, kind="stable")
    return Ground(s_all[order], y[order], z_all[order], amp[order])


@njit(cache=True, nogil=True)
def _echo_kernel(
    pos: FloatArray,
    height: FloatArray,
    lo: IntArray,
    hi: IntArray,
    s: FloatArray,
    y: FloatArray,
    z: FloatArray,
    a_re: FloatArray,
    a_im: FloatArray,
    look: float,
    k_wave: float,
    cos0: float,
    sin0: float,
    c_el: float,
    c_az: float,
    tan2: FloatArray,
    out_re: FloatArray,
    out_im: FloatArray,
) -> None:  # pragma: no cover - compiled
    """z(t_i) = Σ_j a_j·g·sin δ/R²·exp(−j·k_wave·R) over the scatterers lo[i]:hi[i];
    ``tan2`` = tan² of the view's (lowest, highest) depression and widest azimuth: cheap
    rejections before the angles are computed."""
    for i in range(pos.shape[0]):
        sr = 0.0
        si = 0.0
        p = pos[i]
        hh = height[i]
        for j in range(lo[i], hi[i]):
            x = look * (s[j] - p)
            if x <= 0.0:
                continue
            dz = hh - z[j]
            yy = y[j]
            if yy * yy > tan2[2] * x * x:
                continue
            rho2 = x * x + yy * yy
            dz2 = dz * dz
            if dz2 < tan2[0] * rho2 or dz2 > tan2[1] * rho2:
                continue
            r2 = rho2 + dz2
            r = math.sqrt(r2)
            rho = math.sqrt(rho2)
            sin_eps = (dz * cos0 - rho * sin0) / r
            lg = -(c_el * sin_eps * sin_eps + c_az * yy * yy / rho2)
            amp = math.exp(lg) * (dz / r) / r2
            ph = k_wave * r
            c = math.cos(ph)
            sn = math.sin(ph)
            sr += amp * (a_re[j] * c + a_im[j] * sn)
            si += amp * (a_im[j] * c - a_re[j] * sn)
        out_re[i] = sr
        out_im[i] = si


def echo(
    g: Ground,
    pos: FloatArray,
    height: FloatArray,
    look: int,
    f_hz: float,
    cfg: RadarIfCfg,
    v: View,
) -> npt.NDArray[np.complex128]:
    """The noiseless mixer output of one frequency at antenna positions ``pos`` (σ, m)."""
    a, b = sorted((look * v.x_near, look * v.x_far))
    lo = np.searchsorted(g.sigma, pos + a).astype(np.int64)
    hi = np.searchsorted(g.sigma, pos + b).astype(np.int64)
    out_re, out_im = np.empty(len(pos)), np.empty(len(pos))
    ln2 = math.log(2.0)
    _echo_kernel(
        np.ascontiguousarray(pos),
        np.ascontiguousarray(height),
        lo,
        hi,
        g.sigma,
        g.y,
        g.z,
        np.ascontiguousarray(g.amp.real),
        np.ascontiguousarray(g.amp.imag),
        float(look),
        4.0 * math.pi * f_hz / SPEED_OF_LIGHT_MPS,
        math.cos(math.radians(cfg.depression_deg)),
        math.sin(math.radians(cfg.depression_deg)),
        ln2 / math.sin(math.radians(cfg.beam_elev_deg)) ** 2,
        ln2 / math.sin(math.radians(cfg.beam_az_deg)) ** 2,
        np.array([math.tan(v.dep_lo) ** 2, math.tan(v.dep_hi) ** 2, math.tan(v.az_max) ** 2]),
        out_re,
        out_im,
    )
    return out_re + 1j * out_im


def warm() -> None:
    """Compile the echo kernel (or load it from the disk cache) for the argument types
    :func:`echo` passes, on one sample: done ahead by ``make`` (the install step)."""
    f = np.zeros(1)
    i = np.zeros(1, dtype=np.int64)
    _echo_kernel(f, f, i, i, f, f, f, f, f, 1.0, 1.0, 1.0, 0.0, 1.0, 1.0, np.zeros(3), np.empty(1), np.empty(1))


def pattern(cfg: RadarIfCfg, sin_eps: FloatArray, sin_phi: FloatArray) -> FloatArray:
    """Two-way amplitude g = exp(−ln2·((sin ε / sin β_e)² + (sin φ / sin β_a)²))."""
    ln2 = math.log(2.0)
    se, sa = math.sin(math.radians(cfg.beam_elev_deg)), math.sin(math.radians(cfg.beam_az_deg))
    return np.asarray(np.exp(-ln2 * ((sin_eps / se) ** 2 + (sin_phi / sa) ** 2)))


def reference_power(cfg: RadarIfCfg, n: int = 400) -> float:
    """Mean |z|² of a ballast bed at the nominal geometry: the scatterer density times
    ∫∫ (g·sin δ/R²)² dx dy over the footprint (unit mean |a|²), by the midpoint rule."""
    v = view(cfg)
    dx, dy = (v.x_far - v.x_near) / n, 2 * v.y_max / n
    x = v.x_near + (np.arange(n) + 0.5) * dx
    y = -v.y_max + (np.arange(n) + 0.5) * dy
    xx, yy = np.meshgrid(x, y)
    h = cfg.height_m
    rho = np.hypot(xx, yy)
    r2 = rho * rho + h * h
    g = pattern(
        cfg,
        (h * math.cos(math.radians(cfg.depression_deg)) - rho * math.sin(math.radians(cfg.depression_deg)))
        / np.sqrt(r2),
        yy / rho,
    )
    a = g * (h / np.sqrt(r2)) / r2
    return float(cfg.scatterers_per_m2 * np.sum(a * a) * dx * dy)


def _receiver(
    z: npt.NDArray[np.complex128], scale: float, cfg: RadarIfCfg, rng: np.random.Generator
) -> npt.NDArray[np.complex128]:
    """Gain, leakage, noise, ADC clipping and quantisation."""
    noise_rms = CLUTTER_FS * 10.0 ** (-cfg.snr_db / 20.0)
    leak = cfg.dc_leak * CLUTTER_FS * np.exp(1j * rng.uniform(0.0, 2 * np.pi))
    out = z * scale + leak
    out += (rng.standard_normal(len(z)) + 1j * rng.standard_normal(len(z))) * (noise_rms / np.sqrt(2.0))
    re, im = np.clip(out.real, -1.0, 1.0), np.clip(out.imag, -1.0, 1.0)
    if cfg.adc_bits:
        q = float(2 ** (cfg.adc_bits - 1))
        re, im = np.round(re * q) / q, np.round(im * q) / q
    return np.asarray(re + 1j * im, dtype=np.complex128)


def radar_if_stream(
    motion: Motion, geom: TrackGeometry, scenario: Scenario, rng: np.random.Generator
) -> tuple[pd.DataFrame, dict[str, Any]]:
    """The ``radar_if`` frame (t, i1, q1, i2, q2; float32 samples) and the run.json ``radar`` block."""
    cfg = scenario.radar_if
    params = radar_params(cfg)
    n = int(np.floor(motion.duration_s * params.sample_rate_hz)) + 1
    t = np.arange(n, dtype=np.float64) / params.sample_rate_hz
    look = motion.facing * params.look_sign
    amp_v = cfg.vibration_mm / 1000.0
    v = view(cfg, amp_v)
    lo_sigma = float(motion.sigma.min()) - v.x_far - 1.0
    hi_sigma = float(motion.sigma.max()) + v.x_far + 1.0
    g = ground(cfg, geom, (lo_sigma, hi_sigma), v.y_max, rng)
    phase_v = rng.uniform(0.0, 2 * np.pi)
    scale = CLUTTER_FS / math.sqrt(reference_power(cfg))
    cols: dict[str, Any] = {"t": t}
    for k, (f_hz, dt) in enumerate(((cfg.f0_hz, 0.0), (cfg.f0_hz + cfg.delta_f_hz, cfg.t_pri_s))):
        z = np.empty(n, dtype=np.complex128)
        for c0 in range(0, n, CHUNK):
            tk = t[c0 : c0 + CHUNK] + dt
            height = cfg.height_m + amp_v * np.sin(2 * np.pi * cfg.vibration_hz * tk + phase_v)
            z[c0 : c0 + CHUNK] = echo(g, track_position(motion, tk), height, look, f_hz, cfg, v)
        out = _receiver(z, scale, cfg, rng)
        cols[f"i{k + 1}"] = out.real.astype(np.float32)
        cols[f"q{k + 1}"] = out.imag.astype(np.float32)
    return pd.DataFrame(cols), params.to_json()
