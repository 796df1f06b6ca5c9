"""Physical constants, per-system ICD constants, signals and the frame columns of the GNSS core.

Every system is evaluated with its own interface-control document's constants:

* GPS (IS-GPS-200N §20.3.3.4.3, Table 20-IV): μ = 3.986005e14 m³/s², Ω̇e = 7.2921151467e-5 rad/s,
  F = −2√μ/c² = −4.442807633e-10 s/√m (§20.3.3.3.3.1);
* Galileo (OS SIS ICD §5.1.1 and the clock correction's F): μ = 3.986004418e14 m³/s², Ω̇e = 7.2921151467e-5 rad/s,
  F = −4.442807309e-10 s/√m;
* QZSS (IS-QZSS-PNT: the GPS LNAV algorithm and constants): the GPS values.

The speed of light is c = 299 792 458 m/s for all. Times are continuous GPS seconds since
1980-01-06T00:00:00 (no leap seconds; GST and QZSST are steered to the same scale, their
offsets to GPS time — a few ns — are left to an inter-system bias in the solvers).

Frame columns (the ``gnss_obs`` / ``gnss_nav`` streams are declared in ``schemas/`` by the
recorder-formats work; this module only names the columns the core reads):

* observations, long format: t, gnss_time_s, receiver, sat, signal, pseudorange_m,
  carrier_cycles, doppler_hz, cn0_dbhz, lli;
* broadcast ephemerides, one row each, the RINEX 3 navigation fields under georinex's names
  plus ``toc_gps_s`` (continuous GPS seconds of the time of clock) and ``week`` (GPS week
  of Toe).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Final

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
StrArray = npt.NDArray[np.str_]

C_MPS: Final = 299_792_458.0
WEEK_S: Final = 604_800.0
HALF_WEEK_S: Final = 302_400.0
GPS_PI: Final = 3.1415926535898
"""π as IS-GPS-200 defines it for semicircle conversions (§20.3.3.5.2.5, Klobuchar)."""

# WGS-84 ellipsoid (NIMA TR8350.2); GTRF and the QZSS JGS agree with it at the cm level.
WGS84_A_M: Final = 6_378_137.0
WGS84_F: Final = 1.0 / 298.257223563
WGS84_E2: Final = WGS84_F * (2.0 - WGS84_F)

F_L1_HZ: Final = 1_575.42e6
F_L2_HZ: Final = 1_227.60e6
F_L5_HZ: Final = 1_176.45e6
F_E5B_HZ: Final = 1_207.14e6
F_E6_HZ: Final = 1_278.75e6


@dataclass(frozen=True)
class SystemConstants:
    """ICD constants of one system (see the module docstring for the sources)."""

    mu_m3ps2: float
    omega_e_radps: float
    f_rel_s_per_sqrtm: float
    fit_half_s: float
    """Default half fit interval: an ephemeris is used for |t − Toe| ≤ this."""


GPS: Final = SystemConstants(3.986005e14, 7.2921151467e-5, -4.442807633e-10, 7_200.0)
GALILEO: Final = SystemConstants(3.986004418e14, 7.2921151467e-5, -4.442807309e-10, 14_400.0)
QZSS: Final = SystemConstants(3.986005e14, 7.2921151467e-5, -4.442807633e-10, 3_600.0)

SYSTEMS: Final[dict[str, SystemConstants]] = {"G": GPS, "E": GALILEO, "J": QZSS}
"""Systems the core computes (GLONASS 'R', BeiDou 'C', SBAS 'S' rows are left out)."""

SYSTEM_ORDER: Final = ("G", "E", "J")

# Carrier frequency of a RINEX 3 observation code's band digit, per system.
BAND_FREQ_HZ: Final[dict[tuple[str, str], float]] = {
    ("G", "1"): F_L1_HZ,
    ("G", "2"): F_L2_HZ,
    ("G", "5"): F_L5_HZ,
    ("J", "1"): F_L1_HZ,
    ("J", "2"): F_L2_HZ,
    ("J", "5"): F_L5_HZ,
    ("E", "1"): F_L1_HZ,
    ("E", "5"): F_L5_HZ,
    ("E", "7"): F_E5B_HZ,
    ("E", "6"): F_E6_HZ,
}

# gnss_obs columns
OBS_T: Final = "t"
OBS_TIME: Final = "gnss_time_s"
OBS_RECEIVER: Final = "receiver"
OBS_SAT: Final = "sat"
OBS_SIGNAL: Final = "signal"
OBS_PR: Final = "pseudorange_m"
OBS_CARRIER: Final = "carrier_cycles"
OBS_DOPPLER: Final = "doppler_hz"
OBS_CN0: Final = "cn0_dbhz"
OBS_LLI: Final = "lli"
OBS_COLUMNS: Final = (
    OBS_T,
    OBS_TIME,
    OBS_RECEIVER,
    OBS_SAT,
    OBS_SIGNAL,
    OBS_PR,
    OBS_CARRIER,
    OBS_DOPPLER,
    OBS_CN0,
    OBS_LLI,
)

# gnss_nav columns (georinex's RINEX 3 names)
NAV_KEPLER: Final = (
    "SVclockBias",
    "SVclockDrift",
    "SVclockDriftRate",
    "IODE",
    "Crs",
    "DeltaN",
    "M0",
    "Cuc",
    "Eccentricity",
    "Cus",
    "sqrtA",
    "Toe",
    "Cic",
    "Omega0",
    "Cis",
    "Io",
    "Crc",
    "omega",
    "OmegaDot",
    "IDOT",
    "TGD",
    "health",
    "SVacc",
    "TransTime",
    "FitIntvl",
)
NAV_GALILEO: Final = ("BGDe5a", "BGDe5b", "DataSrc")
NAV_COLUMNS: Final = ("sat", "toc_gps_s", *NAV_KEPLER, *NAV_GALILEO, "week")

# Galileo DataSrc bits (RINEX 3.04 Table A8): bit 0 I/NAV E1-B, bit 1 F/NAV E5a-I, bit 2 I/NAV
# E5b-I, bit 8 clock for E5a,E1, bit 9 clock for E5b,E1.
GAL_INAV_BITS: Final = 0b101
GAL_FNAV_BITS: Final = 0b010


def system_of(sat: npt.ArrayLike) -> npt.NDArray[np.str_]:
    """The system letter of satellite ids such as 'G07' (vectorised)."""
    return np.char.upper(np.asarray(sat, dtype=str).astype("U1"))


def signal_frequency_hz(system: npt.ArrayLike, signal: npt.ArrayLike) -> FloatArray:
    """Carrier frequency of each (system letter, RINEX 3 code) pair; NaN if unknown."""
    sys_a = np.asarray(system, dtype=str)
    two = np.ascontiguousarray(np.asarray(signal, dtype=str).astype("U2"))
    band = two.view("U1").reshape(*two.shape, 2)[..., 1] if two.size else two
    out = np.full(sys_a.shape, np.nan)
    for (s, b), f in BAND_FREQ_HZ.items():
        out[(sys_a == s) & (band == b)] = f
    return out
