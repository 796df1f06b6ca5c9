"""A run's ``gps`` stream as the fixes of a track match (:mod:`fieldlogs.trackmatch.match`).

A row is a position where lat and lon are given and ``fix`` ≠ 0 (a row whose fix is empty
counts as a position: a vendor trace without quality columns). Its horizontal 1-σ is the RMS
of ``sigma_lat_m`` and ``sigma_lon_m`` where the receiver logged them, else ``hdop`` × UERE
(``UERE_M``), never below ``MIN_SIGMA_M``; NaN (the match's default σ) where neither is known.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

F64 = npt.NDArray[np.float64]
#: User equivalent range error turning HDOP into a horizontal 1-σ [m].
UERE_M = 4.0
#: Smallest σ taken from a receiver's own figures [m].
MIN_SIGMA_M = 2.0


def _col(frame: pd.DataFrame, name: str) -> F64:
    if name not in frame.columns:
        return np.full(len(frame), np.nan)
    return frame[name].to_numpy(dtype=np.float64, na_value=np.nan)


def gps_fixes(gps: pd.DataFrame) -> tuple[F64, F64, F64, F64]:
    """(t, lat, lon, σ) of a ``gps`` stream; lat/lon NaN where the row is no position."""
    t, lat, lon = _col(gps, "t"), _col(gps, "lat"), _col(gps, "lon")
    fix = _col(gps, "fix")
    none = fix == 0
    lat, lon = np.where(none, np.nan, lat), np.where(none, np.nan, lon)
    s_lat, s_lon = _col(gps, "sigma_lat_m"), _col(gps, "sigma_lon_m")
    sigma = np.sqrt(0.5 * (s_lat**2 + s_lon**2))
    sigma = np.where(np.isfinite(sigma), sigma, _col(gps, "hdop") * UERE_M)
    sigma = np.where(np.isfinite(sigma), np.maximum(sigma, MIN_SIGMA_M), np.nan)
    return t, lat, lon, sigma
