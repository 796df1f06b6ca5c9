"""GPS time, UTC with leap seconds, and a recorder clock put on GNSS time.

``gnss_time_s`` is continuous GPS time in seconds since 1980-01-06T00:00:00 (see
``schemas.gnss``). UTC → GPS: ``gps = (utc − 1980-01-06) + ΔLS(utc)`` with ΔLS = GPS − UTC
from the leap-second table (IERS Bulletin C; 18 s since 2017-01-01).

Recorder clock drift: a logger whose own clock ``τ`` runs at ``1 + d`` times GNSS time
(d > 0: the recorder runs fast) logs some rows with both ``τ`` and a GNSS time ``g`` (a PPS
stamp, a fix time). The clock model ``g = a + s·τ`` with ``s = 1 / (1 + d)`` is fitted by
least squares over those pairs, then every recorder time is mapped through it. The
residual (RMS and max |g − ĝ|) is reported in the run's provenance; a fit with fewer than
2 pairs, or a rate error |d| above ``MAX_DRIFT``, is refused.
"""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime, timedelta

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

GPS_EPOCH = datetime(1980, 1, 6, tzinfo=UTC)
UNIX_TO_GPS_S = (GPS_EPOCH - datetime(1970, 1, 1, tzinfo=UTC)).total_seconds()  # 315964800
#: Dates (UTC) from which GPS − UTC took the value beside them [s].
LEAP_SECONDS: tuple[tuple[str, int], ...] = (
    ("1981-07-01", 1),
    ("1982-07-01", 2),
    ("1983-07-01", 3),
    ("1985-07-01", 4),
    ("1988-01-01", 5),
    ("1990-01-01", 6),
    ("1991-01-01", 7),
    ("1992-07-01", 8),
    ("1993-07-01", 9),
    ("1994-07-01", 10),
    ("1996-01-01", 11),
    ("1997-07-01", 12),
    ("1999-01-01", 13),
    ("2006-01-01", 14),
    ("2009-01-01", 15),
    ("2012-07-01", 16),
    ("2015-07-01", 17),
    ("2017-01-01", 18),
)
_LEAP_UTC_S = np.array(
    [(datetime.fromisoformat(d).replace(tzinfo=UTC) - GPS_EPOCH).total_seconds() for d, _ in LEAP_SECONDS]
)
_LEAP_N = np.array([n for _, n in LEAP_SECONDS], dtype=np.float64)
#: BeiDou time = GPS time − 14 s.
BDT_OFFSET_S = 14.0
#: Largest plausible recorder clock rate error (issue 16: research loggers drift by up to ~1 %).
MAX_DRIFT = 0.05


def leap_seconds_utc(utc_s_since_gps_epoch: npt.ArrayLike) -> FloatArray:
    """GPS − UTC [s] at UTC times given as seconds since 1980-01-06 on the UTC scale."""
    u = np.asarray(utc_s_since_gps_epoch, dtype=np.float64)
    idx = np.searchsorted(_LEAP_UTC_S, u, side="right")
    return np.where(idx > 0, _LEAP_N[np.maximum(idx - 1, 0)], 0.0)


#: UTC days (seconds since 1980-01-06 of their midnight) that end with an inserted leap
#: second 23:59:60: the day before each date of ``LEAP_SECONDS`` (IERS Bulletin C).
_LEAP_DAY_START_S = _LEAP_UTC_S - 86400.0


def ends_with_leap_second(day_start_s: npt.ArrayLike) -> npt.NDArray[np.bool_]:
    """Whether the UTC day starting at ``day_start_s`` (seconds since 1980-01-06, UTC scale,
    a multiple of 86400) ends with a leap second 23:59:60 (IERS Bulletin C table)."""
    out: npt.NDArray[np.bool_] = np.isin(np.asarray(day_start_s, dtype=np.float64), _LEAP_DAY_START_S)
    return out


def utc_to_gps(utc_s_since_gps_epoch: npt.ArrayLike) -> FloatArray:
    """UTC seconds since 1980-01-06 (UTC scale) → continuous GPS seconds."""
    u = np.asarray(utc_s_since_gps_epoch, dtype=np.float64)
    return u + leap_seconds_utc(u)


def gps_to_utc(gps_s: npt.ArrayLike) -> FloatArray:
    """Continuous GPS seconds → UTC seconds since 1980-01-06 (UTC scale)."""
    g = np.asarray(gps_s, dtype=np.float64)
    first = g - leap_seconds_utc(g)
    return g - leap_seconds_utc(first)


def unix_to_gps(unix_s: npt.ArrayLike) -> FloatArray:
    """Unix time (UTC, no leap seconds counted) → continuous GPS seconds."""
    return utc_to_gps(np.asarray(unix_s, dtype=np.float64) - UNIX_TO_GPS_S)


def gps_to_iso(gps_s: float) -> str:
    """ISO 8601 UTC (with +00:00) of a GPS time, to the microsecond."""
    u = float(gps_to_utc(gps_s))
    return (GPS_EPOCH + timedelta(seconds=u)).isoformat(timespec="microseconds")


def iso_to_gps(text: str) -> float:
    """ISO 8601 with an offset (a naive time is refused by the callers) → GPS seconds."""
    dt = datetime.fromisoformat(text)
    if dt.tzinfo is None:
        raise ValueError(f"'{text}' has no UTC offset")
    return float(utc_to_gps((dt - GPS_EPOCH).total_seconds()))


def calendar_to_utc_s(
    year: npt.ArrayLike,
    month: npt.ArrayLike,
    day: npt.ArrayLike,
    seconds_of_day: npt.ArrayLike,
) -> FloatArray:
    """Calendar date + seconds of day → seconds since 1980-01-06 on the same scale (vectorised)."""
    y = np.asarray(year, dtype=np.int64)
    m = np.asarray(month, dtype=np.int64)
    d = np.asarray(day, dtype=np.int64)
    days = ((y - 1970).astype("datetime64[Y]").astype("datetime64[M]") + (m - 1).astype("timedelta64[M]")).astype(
        "datetime64[D]"
    ) + (d - 1).astype("timedelta64[D]")
    since = (days - np.datetime64("1980-01-06", "D")).astype(np.int64).astype(np.float64) * 86400.0
    out: FloatArray = since + np.asarray(seconds_of_day, dtype=np.float64)
    return out


@dataclass(frozen=True)
class ClockFit:
    """``g = offset_s + slope·τ``, ``drift = 1 / slope − 1`` (recorder rate error); residuals."""

    offset_s: float
    slope: float
    drift: float
    pairs: int
    residual_rms_s: float
    residual_max_s: float

    def apply(self, tau: npt.ArrayLike) -> FloatArray:
        out: FloatArray = self.offset_s + self.slope * np.asarray(tau, dtype=np.float64)
        return out

    def to_dict(self) -> dict[str, float | int]:
        return {
            "offset_s": self.offset_s,
            "slope": self.slope,
            "drift": self.drift,
            "drift_ppm": self.drift * 1e6,
            "pairs": self.pairs,
            "residual_rms_s": self.residual_rms_s,
            "residual_max_s": self.residual_max_s,
        }


def fit_clock(tau: npt.ArrayLike, gnss: npt.ArrayLike) -> ClockFit:
    """Least-squares clock model from (recorder time, GNSS time) pairs (NaN pairs ignored).

    Centred on the means so that the normal equations stay well conditioned for GPS times
    of 1.4·10⁹ s. Raises ValueError with fewer than 2 distinct pairs or |drift| > MAX_DRIFT.
    """
    t = np.asarray(tau, dtype=np.float64)
    g = np.asarray(gnss, dtype=np.float64)
    ok = np.isfinite(t) & np.isfinite(g)
    t, g = t[ok], g[ok]
    if len(t) < 2 or np.ptp(t) <= 0:
        raise ValueError(f"{len(t)} usable time pair(s); at least 2 at different times are needed")
    tm, gm = t.mean(), g.mean()
    slope = float(np.dot(t - tm, g - gm) / np.dot(t - tm, t - tm))
    drift = 1.0 / slope - 1.0 if slope > 0 else float("inf")
    if abs(drift) > MAX_DRIFT:
        raise ValueError(f"clock rate {slope:.6f} is off GNSS time by more than {MAX_DRIFT:.0%}: wrong time unit?")
    offset = float(gm - slope * tm)
    res = g - (offset + slope * t)
    return ClockFit(offset, slope, drift, len(t), float(np.sqrt(np.mean(res**2))), float(np.max(np.abs(res))))
