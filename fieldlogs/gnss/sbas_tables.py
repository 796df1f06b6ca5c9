"""Look-up tables of RTCA DO-229 (Appendix A): the standard, read by the SBAS decoder and its user
algorithms (``fieldlogs.gnss.sbas``) and by the simulated SBAS stream (``fieldlogs.simulate.gnss``).

* UDREI → UDRE [m] and σ²_UDRE [m²] (Table A-6); 14 "not monitored", 15 "do not use";
* GIVEI → GIVE [m] and σ²_GIVE [m²] (Table A-17); 15 "not monitored";
* fast-correction degradation factor indicator a_i → a [m/s²] and the user time-out interval
  of fast corrections [s] for en-route through non-precision approach (Table A-8, the column a
  train's use corresponds to);
* message time-outs for en-route through non-precision approach (Table A-25);
* the PRN mask's slot numbers (Table A-3: 1–37 GPS, 38–61 GLONASS slots, 120–158 SBAS; the
  rest spare in DO-229, of which the QZSS interface specification for its L1 SBAS-type signals
  (IS-QZSS L1-SAIF / L1S) assigns 193–202 to the QZSS satellites of PRN 193–202 (J01–J10) and
  183–192 to their L1S signals as SBAS ranging sources, not used here);
* the ionospheric grid points of bands 0–8 (Table A-14): 40° of longitude each, columns every
  5°; a column at an odd multiple of 5° holds the 23 latitudes −55…55 every 5°; the others add
  ±65, ±75, and 85° N where the longitude is a multiple of 90° (180° W, 90° W, 0°, 90° E) or
  85° S at 140° W, 50° W, 40° E, 130° E — 201 IGPs per band, 200 in band 8;
* bands 9 (north) and 10 (south), row by row from the equator's side, each row eastward from
  180° W: 60° every 5° of longitude (IGPs 1–72), 65°, 70°, 75° every 10° (73–108, 109–144,
  145–180), 85° every 30° (181–192) from 180° W in band 9 and from 170° W in band 10 (the
  65°/75° IGPs coincide with bands 0–8's and are the same points).
"""

from __future__ import annotations

from typing import Final

import numpy as np

from fieldlogs.gnss.constants import IntArray

NAN: Final = float("nan")
UDREI_NOT_MONITORED: Final = 14
UDREI_DO_NOT_USE: Final = 15
GIVEI_NOT_MONITORED: Final = 15

#: Table A-6: UDRE [m] (99.9 % bound) and σ²_UDRE [m²] per UDREI 0–13.
UDRE_M: Final = np.array([0.75, 1.0, 1.25, 1.75, 2.25, 3.0, 3.75, 4.5, 5.25, 6.0, 7.5, 15.0, 50.0, 150.0, NAN, NAN])
SIGMA2_UDRE_M2: Final = np.array(
    [0.0520, 0.0924, 0.1444, 0.2830, 0.4678, 0.8315, 1.2992, 1.8709, 2.5465, 3.3260, 5.1968, 20.7870, 230.9661,
     2078.695, NAN, NAN]
)  # fmt: skip
#: Table A-17: GIVE [m] and σ²_GIVE [m²] per GIVEI 0–14.
GIVE_M: Final = np.array([0.3, 0.6, 0.9, 1.2, 1.5, 1.8, 2.1, 2.4, 2.7, 3.0, 3.6, 4.5, 6.0, 15.0, 45.0, NAN])
SIGMA2_GIVE_M2: Final = np.array(
    [0.0084, 0.0333, 0.0749, 0.1331, 0.2079, 0.2994, 0.4075, 0.5322, 0.6735, 0.8315, 1.1974, 1.8709, 3.3260,
     20.7870, 187.0826, NAN]
)  # fmt: skip
#: Table A-8: fast-correction degradation factor a [m/s²] per indicator a_i 0–15 …
FC_DEGRADATION_MPS2: Final = np.array(
    [0.0, 0.00005, 0.00009, 0.00012, 0.00015, 0.00020, 0.00030, 0.00045, 0.00060, 0.00090, 0.00150, 0.00210,
     0.00270, 0.00330, 0.00460, 0.00580]
)  # fmt: skip
#: … and the user time-out of fast corrections [s], en-route through non-precision approach.
FC_TIMEOUT_S: Final = np.array([180, 180, 153, 135, 135, 117, 99, 81, 63, 45, 45, 27, 27, 27, 18, 18], dtype=float)

#: Table A-25, en-route through non-precision approach [s].
TIMEOUT_S: Final = {
    "mask": 600.0,  # MT 1
    "udrei": 18.0,  # MT 2–6, 24
    "degradation": 360.0,  # MT 7, MT 10
    "long_term": 360.0,  # MT 24, 25
    "igp_mask": 1200.0,  # MT 18
    "iono": 600.0,  # MT 26
}
#: DO-229 §A.4.5.1: σ_flt without MT 10 is σ_UDRE·δUDRE + 8 m.
NO_MT10_DEGRADATION_M: Final = 8.0
#: IGP vertical delay code 511 (63.875 m): "do not use" (§A.4.4.10).
IGP_DO_NOT_USE: Final = 511
#: The grid is used where |φ_pp| ≤ this (``grid`` docstring) [deg].
GRID_MAX_LAT_DEG: Final = 75.0
#: Above this |φ_pp| [deg] the cells are 5° of latitude by 10° of longitude (``grid``).
GRID_WIDE_CELL_LAT_DEG: Final = 60.0


def mask_slot_sat(slot_prn: IntArray) -> list[str]:
    """Satellite ids of PRN-mask bit numbers (1–210): G01–G37, R01–R24 (slots 38–61), S20–S58
    for 120–158 (RINEX's SBAS numbering PRN − 100), J01–J10 for 193–202 (QZSS PRN − 192);
    others '' (not used)."""
    out = []
    for p in np.asarray(slot_prn, dtype=np.int64).tolist():
        if 1 <= p <= 37:
            out.append(f"G{p:02d}")
        elif 38 <= p <= 61:
            out.append(f"R{p - 37:02d}")
        elif 120 <= p <= 158:
            out.append(f"S{p - 100:02d}")
        elif 193 <= p <= 202:
            out.append(f"J{p - 192:02d}")
        else:
            out.append("")
    return out


_LAT_ODD = list(range(-55, 60, 5))
_LAT_EVEN = [-75, -65, *range(-55, 60, 5), 65, 75]


def _column_lats(lon: int) -> list[int]:
    """Latitudes of the IGP column at ``lon`` (module docstring)."""
    if lon % 10 != 0:
        return _LAT_ODD
    if lon % 90 == 0:
        return [*_LAT_EVEN, 85]
    if (lon + 140) % 90 == 0:
        return [-85, *_LAT_EVEN]
    return _LAT_EVEN


def _polar_band(band: int) -> tuple[IntArray, IntArray]:
    """Band 9 or 10 (module docstring)."""
    sign = 1 if band == 9 else -1
    rows = [(60, range(-180, 180, 5)), (65, range(-180, 180, 10)), (70, range(-180, 180, 10)),
            (75, range(-180, 180, 10)), (85, range(-180 if band == 9 else -170, 180, 30))]  # fmt: skip
    lats = [sign * la for la, lons in rows for _ in lons]
    lons = [lo for _, row in rows for lo in row]
    return np.array(lats, dtype=np.int64), np.array(lons, dtype=np.int64)


def band_igps(band: int) -> tuple[IntArray, IntArray]:
    """(latitude, longitude) [deg] of IGP numbers 1… of band 0–10, in mask-bit order (Table A-14):
    bands 0–8 column by column eastward from 180° W + 40°·band, each south to north; bands 9–10
    row by row (module docstring)."""
    if band in (9, 10):
        return _polar_band(band)
    if not 0 <= band <= 8:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    lats: list[int] = []
    lons: list[int] = []
    for k in range(8):
        lon = -180 + 40 * band + 5 * k
        col = _column_lats(lon)
        lats += col
        lons += [lon] * len(col)
    return np.array(lats, dtype=np.int64), np.array(lons, dtype=np.int64)


def igp_key(lat_deg: IntArray, lon_deg: IntArray) -> IntArray:
    """An integer id of an IGP: (lat + 90)·1000 + (lon mod 360)."""
    lat = np.asarray(lat_deg, dtype=np.int64)
    lon = np.mod(np.asarray(lon_deg, dtype=np.int64), 360)
    return np.asarray((lat + 90) * 1000 + lon, dtype=np.int64)
