"""Pseudorange error model: the 1σ that weights the solvers and scales their uncertainty.

σ² = σ_sis² + σ_iono² + σ_tropo² + σ_noise² + σ_mp², each term [m]:

* σ_sis — broadcast orbit and clock (signal-in-space range error): the broadcast accuracy
  (SVacc: GPS URA, Galileo SISA) clipped to [``sis_floor_m``, ``sis_cap_m``], ``sis_default_m``
  where it is missing;
* σ_iono — residual after the model: max(``iono_frac``·model delay,
  ``iono_floor_vert_m``·F(E)), F the thin-shell obliquity 1/√(1 − (R cos E/(R + 350 km))²)
  (Klobuchar removes ≈ 50 % rms: IS-GPS-200N §20.3.3.5.2.5; DO-229 Appendix J bounds it more
  conservatively);
* σ_tropo = ``tropo_vert_m``·m(E) with Black & Eisner's m (DO-229 A.4.2.4: 0.12 m);
* σ_noise — code tracking noise by C/N0: ``noise_45_m``·10^((45 − C/N0)/20) (a DLL's σ grows
  as 1/√(C/N0); 0.3 m at 45 dB-Hz for a 1-chip-spacing-narrow correlator);
* σ_mp — multipath by elevation: ``mp_zenith_m`` + ``mp_low_m``·exp(−E/``mp_scale_deg``)
  (the shape of DO-229's airborne model 0.13 + 0.53 exp(−E/10°), larger beside a railway).

Where a correction (SBAS/D-GPS) applies its ``sigma_m`` replaces σ_sis, and σ_iono/σ_tropo too
when it covers the atmosphere. Carrier smoothing over n samples scales σ_noise and σ_mp by
max(√(``smooth_corr_samples``/n), ``smooth_floor``): noise and fast multipath average down,
slow multipath (correlated over tens of seconds beside a structure) does not, hence the floor.
Where the SBAS ionospheric grid gives the delay its σ_UIRE (``iono_sigma_m``) replaces σ_iono.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.gnss.atmosphere import tropo_mapping
from fieldlogs.gnss.constants import BoolArray, FloatArray

_R_E = 6_371_000.0
_H_IONO = 350_000.0


@dataclass(frozen=True)
class ErrorModel:
    """Coefficients of the pseudorange σ (module docstring), metres unless named otherwise."""

    sis_floor_m: float = 0.5
    sis_cap_m: float = 10.0
    sis_default_m: float = 2.0
    iono_frac: float = 0.5
    iono_floor_vert_m: float = 0.6
    tropo_vert_m: float = 0.12
    noise_45_m: float = 0.3
    mp_zenith_m: float = 0.3
    mp_low_m: float = 2.0
    mp_scale_deg: float = 15.0
    smooth_corr_samples: float = 5.0
    smooth_floor: float = 0.35


def obliquity(el_rad: FloatArray) -> FloatArray:
    """Thin-shell ionospheric obliquity factor at 350 km."""
    c = _R_E * np.cos(np.asarray(el_rad, dtype=float)) / (_R_E + _H_IONO)
    return np.asarray(1.0 / np.sqrt(1.0 - c * c), dtype=float)


def pseudorange_sigma_m(
    model: ErrorModel,
    el_rad: FloatArray,
    cn0_dbhz: FloatArray,
    iono_m: FloatArray,
    sv_acc_m: FloatArray,
    corr_sigma_m: FloatArray | None = None,
    covers_atmosphere: BoolArray | None = None,
    smooth_n: FloatArray | None = None,
    iono_sigma_m: FloatArray | None = None,
) -> FloatArray:
    """1σ [m] of each corrected pseudorange (module docstring)."""
    el = np.asarray(el_rad, dtype=float)
    acc = np.asarray(sv_acc_m, dtype=float)
    sis = np.where(np.isfinite(acc) & (acc > 0), np.clip(acc, model.sis_floor_m, model.sis_cap_m), model.sis_default_m)
    iono = np.maximum(
        model.iono_frac * np.abs(np.asarray(iono_m, dtype=float)), model.iono_floor_vert_m * obliquity(el)
    )
    if iono_sigma_m is not None:
        grid = np.asarray(iono_sigma_m, dtype=float)
        iono = np.where(np.isfinite(grid), grid, iono)
    tropo = model.tropo_vert_m * tropo_mapping(el)
    cn0 = np.nan_to_num(np.asarray(cn0_dbhz, dtype=float), nan=35.0)
    noise = model.noise_45_m * 10.0 ** ((45.0 - cn0) / 20.0)
    mp = model.mp_zenith_m + model.mp_low_m * np.exp(-np.degrees(el) / model.mp_scale_deg)
    if smooth_n is not None:
        n = np.maximum(np.nan_to_num(np.asarray(smooth_n, dtype=float), nan=1.0), 1.0)
        f = np.minimum(np.maximum(np.sqrt(model.smooth_corr_samples / n), model.smooth_floor), 1.0)
        noise, mp = noise * f, mp * f
    if corr_sigma_m is not None:
        cs = np.asarray(corr_sigma_m, dtype=float)
        has = np.isfinite(cs)
        sis = np.where(has, cs, sis)
        if covers_atmosphere is not None:
            atm = has & np.asarray(covers_atmosphere, dtype=bool)
            iono = np.where(atm, 0.0, iono)
            tropo = np.where(atm, 0.0, tropo)
    return np.asarray(np.sqrt(sis**2 + iono**2 + tropo**2 + noise**2 + mp**2), dtype=float)
