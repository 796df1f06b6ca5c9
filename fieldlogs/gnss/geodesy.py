"""WGS-84 geodesy on arrays: ECEF ↔ geodetic, local ENU frame, azimuth and elevation.

* geodetic → ECEF: N = a/√(1 − e² sin²φ); x = (N + h) cos φ cos λ, y = (N + h) cos φ sin λ,
  z = (N(1 − e²) + h) sin φ (NIMA TR8350.2);
* ECEF → geodetic: Bowring's iteration on φ from p = √(x² + y²) (four passes reach 1e-12 rad
  at any height a railway has);
* ENU rows at (φ, λ): e = (−sin λ, cos λ, 0), n = (−sin φ cos λ, −sin φ sin λ, cos φ),
  u = (cos φ cos λ, cos φ sin λ, sin φ);
* elevation = asin(u·ρ̂), azimuth = atan2(e·ρ̂, n·ρ̂) clockwise from north in [0, 2π).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from fieldlogs.gnss.constants import WGS84_A_M, WGS84_E2, FloatArray


def geodetic_to_ecef(lat_rad: npt.ArrayLike, lon_rad: npt.ArrayLike, h_m: npt.ArrayLike) -> FloatArray:
    """ECEF [m] (…, 3) of geodetic latitude/longitude [rad] and ellipsoidal height [m]."""
    lat, lon, h = (np.asarray(v, dtype=float) for v in (lat_rad, lon_rad, h_m))
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    return np.stack(
        [
            (n + h) * np.cos(lat) * np.cos(lon),
            (n + h) * np.cos(lat) * np.sin(lon),
            (n * (1.0 - WGS84_E2) + h) * np.sin(lat),
        ],
        axis=-1,
    )


def ecef_to_geodetic(xyz: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(lat [rad], lon [rad], h [m]) of ECEF points (…, 3)."""
    xyz = np.asarray(xyz, dtype=float)
    x, y, z = xyz[..., 0], xyz[..., 1], xyz[..., 2]
    p = np.hypot(x, y)
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, p * (1.0 - WGS84_E2))
    for _ in range(4):
        n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
        h = p / np.maximum(np.cos(lat), 1e-12) - n
        lat = np.arctan2(z, p * (1.0 - WGS84_E2 * n / (n + h)))
    n = WGS84_A_M / np.sqrt(1.0 - WGS84_E2 * np.sin(lat) ** 2)
    h = p / np.maximum(np.cos(lat), 1e-12) - n
    return lat, lon, h


def enu_basis(lat_rad: FloatArray, lon_rad: FloatArray) -> FloatArray:
    """Rows (east, north, up) of the local frame: array (…, 3, 3)."""
    lat = np.asarray(lat_rad, dtype=float)
    lon = np.asarray(lon_rad, dtype=float)
    sl, cl, sp, cp = np.sin(lon), np.cos(lon), np.sin(lat), np.cos(lat)
    zero = np.zeros_like(lat)
    east = np.stack([-sl, cl, zero], axis=-1)
    north = np.stack([-sp * cl, -sp * sl, cp], axis=-1)
    up = np.stack([cp * cl, cp * sl, sp], axis=-1)
    return np.stack([east, north, up], axis=-2)


def azimuth_elevation(rx_ecef: FloatArray, sat_ecef: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Azimuth (clockwise from north, [0, 2π)) and elevation [rad] of satellites seen from receivers.

    ``rx_ecef`` broadcasts against ``sat_ecef`` (both (…, 3)).
    """
    rx = np.asarray(rx_ecef, dtype=float)
    sat = np.asarray(sat_ecef, dtype=float)
    lat, lon, _ = ecef_to_geodetic(rx)
    basis = enu_basis(lat, lon)
    d = sat - rx
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    e = np.sum(basis[..., 0, :] * d, axis=-1)
    n = np.sum(basis[..., 1, :] * d, axis=-1)
    u = np.sum(basis[..., 2, :] * d, axis=-1)
    az = np.mod(np.arctan2(e, n), 2.0 * np.pi)
    return az, np.arcsin(np.clip(u, -1.0, 1.0))
