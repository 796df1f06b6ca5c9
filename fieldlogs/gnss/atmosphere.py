"""Ionosphere and troposphere delay models for single-frequency pseudoranges.

**Klobuchar** (IS-GPS-200N §20.3.3.5.2.5, Figure 20-4; QZSS broadcasts the same model with its
own α/β, IS-QZSS-PNT), in semicircles (π = 3.1415926535898) with E the elevation:
ψ = 0.0137/(E + 0.11) − 0.022; φ_i = φ_u + ψ cos A clamped to ±0.416; λ_i = λ_u + ψ sin A/cos φ_i;
φ_m = φ_i + 0.064 cos(λ_i − 1.617); t = 4.32e4·λ_i + t_GPS (mod 86 400 s);
F = 1 + 16(0.53 − E)³; AMP = Σα_n φ_mⁿ (≥ 0); PER = Σβ_n φ_mⁿ (≥ 72 000 s);
x = 2π(t − 50 400)/PER; T = F·(5e-9 + AMP(1 − x²/2 + x⁴/24)) for |x| < 1.57, else F·5e-9 [s]
on L1, scaled by (f_L1/f)² on another frequency. It removes about half of the delay (rms).

**Galileo effective ionisation** (OS SIS ICD §5.1.6): the broadcast a_i0..a_i2 give the
effective ionisation level Az = a_i0 + a_i1·μ + a_i2·μ² [sfu] at the modified dip latitude μ
(tan μ = I/√cos φ, I the dip of a centred dipole with its north pole at 80.65° N, 72.68° W,
IGRF-13 2020: tan I = 2 tan φ_gm). NeQuick-G proper integrates a 3-D electron density model
driven by Az; this core does **not** implement it. It uses Az in a thin-shell (350 km) Klobuchar
shape instead: vertical delay on L1 = 5 ns + A·cos(2π(t_LT − 14 h)/PER) by day (zero
otherwise, |x| < π/2), A = 0.06 ns/sfu·Az·|cos φ_m| (φ_m Klobuchar's geomagnetic latitude of
the pierce point, clipped to ±0.5 semicircle), PER = 26 h, mapped by the
Klobuchar obliquity F. At Az = 100 sfu that is ~ 11 ns (3.3 m) midday at mid latitudes — the
order of the real mid-latitude delay; its error is expected to be no better than
Klobuchar's (≈ 50 % rms of the delay; unvalidated against NeQuick-G). When the GPS α/β are
available the Galileo satellites use Klobuchar (as RTKLIB does); this model is the fallback.

**Troposphere**: Saastamoinen (1972) zenith delays with the standard atmosphere
(P = 1013.25 (1 − 2.2557e-5 h)^5.2568 hPa, T = 15 − 6.5e-3 h + 273.16 K, relative humidity
50 % → e = 6.108·RH·exp((17.15 T − 4684)/(T − 38.45)) hPa):
zhd = 0.0022768 P/(1 − 0.00266 cos 2φ − 0.00028 h_km), zwd = 0.002277 (1255/T + 0.05) e,
mapped by Black & Eisner's m(E) = 1.001/√(0.002001 + sin²E) (RTCA DO-229 A.4.2.4). Residual
after the model: a few cm at zenith (≈ 0.12 m·m(E) as DO-229's σ_tropo).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
import numpy.typing as npt

from fieldlogs.gnss.constants import C_MPS, F_L1_HZ, GPS_PI, FloatArray

_POLE_LAT = np.radians(80.65)
_POLE_LON = np.radians(-72.68)


def klobuchar_s(
    lat_rad: npt.ArrayLike,
    lon_rad: npt.ArrayLike,
    az_rad: npt.ArrayLike,
    el_rad: npt.ArrayLike,
    t_gps_s: npt.ArrayLike,
    alpha: Sequence[float],
    beta: Sequence[float],
) -> FloatArray:
    """Klobuchar L1 ionospheric delay [s] (module docstring); inputs broadcast together."""
    e = np.asarray(el_rad, dtype=float) / GPS_PI
    a = np.asarray(az_rad, dtype=float)
    psi = 0.0137 / (e + 0.11) - 0.022
    phi_i = np.clip(np.asarray(lat_rad, dtype=float) / GPS_PI + psi * np.cos(a), -0.416, 0.416)
    lam_i = np.asarray(lon_rad, dtype=float) / GPS_PI + psi * np.sin(a) / np.cos(phi_i * GPS_PI)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * GPS_PI)
    t = np.mod(4.32e4 * lam_i + np.asarray(t_gps_s, dtype=float), 86_400.0)
    f = 1.0 + 16.0 * (0.53 - e) ** 3
    amp = np.maximum(sum(alpha[n] * phi_m**n for n in range(4)), 0.0)
    per = np.maximum(sum(beta[n] * phi_m**n for n in range(4)), 72_000.0)
    x = 2.0 * np.pi * (t - 50_400.0) / per
    day = np.abs(x) < 1.57
    return np.asarray(np.where(day, f * (5e-9 + amp * (1.0 - x**2 / 2.0 + x**4 / 24.0)), f * 5e-9), dtype=float)


def modip_rad(lat_rad: npt.ArrayLike, lon_rad: npt.ArrayLike) -> FloatArray:
    """Modified dip latitude μ from a centred dipole (module docstring)."""
    lat = np.asarray(lat_rad, dtype=float)
    lon = np.asarray(lon_rad, dtype=float)
    sin_gm = np.sin(lat) * np.sin(_POLE_LAT) + np.cos(lat) * np.cos(_POLE_LAT) * np.cos(lon - _POLE_LON)
    gm = np.arcsin(np.clip(sin_gm, -1.0, 1.0))
    dip = np.arctan(2.0 * np.tan(gm))
    return np.asarray(np.arctan(dip / np.sqrt(np.maximum(np.cos(lat), 1e-6))), dtype=float)


def galileo_effective_s(
    lat_rad: npt.ArrayLike,
    lon_rad: npt.ArrayLike,
    az_rad: npt.ArrayLike,
    el_rad: npt.ArrayLike,
    t_gps_s: npt.ArrayLike,
    ai: Sequence[float],
) -> FloatArray:
    """L1/E1 ionospheric delay [s] of the simplified effective-ionisation model (module docstring)."""
    mu_deg = np.degrees(modip_rad(lat_rad, lon_rad))
    ai0, ai1, ai2 = (float(v) for v in ai[:3])
    az_sfu = 63.7 if ai0 == ai1 == ai2 == 0.0 else None
    level = np.full(np.shape(mu_deg), az_sfu) if az_sfu is not None else ai0 + ai1 * mu_deg + ai2 * mu_deg**2
    level = np.clip(level, 0.0, 400.0)
    e = np.asarray(el_rad, dtype=float) / GPS_PI
    a = np.asarray(az_rad, dtype=float)
    psi = 0.0137 / (e + 0.11) - 0.022
    phi_i = np.clip(np.asarray(lat_rad, dtype=float) / GPS_PI + psi * np.cos(a), -0.416, 0.416)
    lam_i = np.asarray(lon_rad, dtype=float) / GPS_PI + psi * np.sin(a) / np.cos(phi_i * GPS_PI)
    phi_m = phi_i + 0.064 * np.cos((lam_i - 1.617) * GPS_PI)
    t = np.mod(4.32e4 * lam_i + np.asarray(t_gps_s, dtype=float), 86_400.0)
    f = 1.0 + 16.0 * (0.53 - e) ** 3
    amp = 0.06e-9 * level * np.abs(np.cos(np.clip(phi_m, -0.5, 0.5) * GPS_PI))
    x = 2.0 * np.pi * (t - 50_400.0) / (26.0 * 3600.0)
    return np.asarray(f * (5e-9 + np.where(np.abs(x) < np.pi / 2.0, amp * np.cos(x), 0.0)), dtype=float)


def iono_delay_m(
    system: npt.ArrayLike,
    freq_hz: npt.ArrayLike,
    lat_rad: npt.ArrayLike,
    lon_rad: npt.ArrayLike,
    az_rad: npt.ArrayLike,
    el_rad: npt.ArrayLike,
    t_gps_s: npt.ArrayLike,
    params: Mapping[str, Sequence[float]] | None,
) -> FloatArray:
    """Model ionospheric group delay [m] on each signal's frequency; 0 where no parameters.

    ``params`` keys: ``gps_alpha``, ``gps_beta`` (Klobuchar, GPS and, absent ``qzss_*``, QZSS
    and Galileo), ``qzss_alpha``, ``qzss_beta``, ``gal_ai`` (a_i0, a_i1, a_i2).
    """
    shape = np.broadcast(np.asarray(el_rad), np.asarray(system)).shape
    out = np.zeros(shape)
    if not params:
        return out
    sysl = np.broadcast_to(np.asarray(system), shape)
    args = (lat_rad, lon_rad, az_rad, el_rad, t_gps_s)
    g_a, g_b = params.get("gps_alpha"), params.get("gps_beta")
    if g_a is not None and g_b is not None:
        out = np.where(sysl != "J", np.broadcast_to(klobuchar_s(*args, g_a, g_b), shape), out)
    elif params.get("gal_ai") is not None:
        out = np.where(sysl == "E", np.broadcast_to(galileo_effective_s(*args, params["gal_ai"]), shape), out)
    q_a, q_b = params.get("qzss_alpha", g_a), params.get("qzss_beta", g_b)
    if q_a is not None and q_b is not None:
        out = np.where(sysl == "J", np.broadcast_to(klobuchar_s(*args, q_a, q_b), shape), out)
    return np.asarray(C_MPS * out * (F_L1_HZ / np.asarray(freq_hz, dtype=float)) ** 2, dtype=float)


def saastamoinen_zenith_m(
    lat_rad: npt.ArrayLike, h_m: npt.ArrayLike, humidity: float = 0.5
) -> tuple[FloatArray, FloatArray]:
    """Saastamoinen zenith hydrostatic and wet delays [m] in the standard atmosphere."""
    h = np.clip(np.asarray(h_m, dtype=float), -100.0, 1e4)
    pres = 1013.25 * (1.0 - 2.2557e-5 * h) ** 5.2568
    temp = 15.0 - 6.5e-3 * h + 273.16
    e = 6.108 * humidity * np.exp((17.15 * temp - 4684.0) / (temp - 38.45))
    zhd = 0.0022768 * pres / (1.0 - 0.00266 * np.cos(2.0 * np.asarray(lat_rad, dtype=float)) - 0.00028 * h / 1e3)
    zwd = 0.002277 * (1255.0 / temp + 0.05) * e
    return zhd, zwd


def tropo_mapping(el_rad: npt.ArrayLike) -> FloatArray:
    """Black & Eisner mapping 1.001/√(0.002001 + sin²E) (RTCA DO-229 A.4.2.4)."""
    s = np.sin(np.asarray(el_rad, dtype=float))
    return np.asarray(1.001 / np.sqrt(0.002001 + s * s), dtype=float)


def tropo_delay_m(lat_rad: npt.ArrayLike, h_m: npt.ArrayLike, el_rad: npt.ArrayLike) -> FloatArray:
    """Slant tropospheric delay [m]: (zhd + zwd)·m(E)."""
    zhd, zwd = saastamoinen_zenith_m(lat_rad, h_m)
    return np.asarray((zhd + zwd) * tropo_mapping(el_rad), dtype=float)
