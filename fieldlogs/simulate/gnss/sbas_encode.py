"""SBAS L1 message encoder (RTCA DO-229 Appendix A), written from the standard's tables apart
from the decoder so that each checks the other: plain Python integers, the CRC-24Q by bitwise
long division (the decoder's is table-driven over numpy bit arrays). The simulator's SBAS
stream (``fieldlogs.simulate.gnss.sbas_stream``) and the tests use it.

Field layouts, MSB first after the 8-bit preamble and 6-bit message type (212 data bits):

* MT 1 (Table A-3): 210 PRN-mask bits (bit n = PRN n), IODP 2, total 212;
* MT 2–5 (Table A-4): IODF 2, IODP 2, 13 × fast correction (12 bits, 0.125 m, signed),
  13 × UDREI (4 bits);
* MT 6 (Table A-5): IODF₂…IODF₅ (2 bits each), 51 × UDREI;
* MT 7 (Table A-7): system latency t_lat 4 (1 s), IODP 2, spare 2, 51 × a_i (4 bits);
* MT 10 (Table A-9): B_rrc 10 (0.002 m), C_ltc_lsb 10 (0.002 m), C_ltc_v1 10 (0.00005 m/s),
  I_ltc_v1 9 (1 s), C_ltc_v0 10 (0.002 m), I_ltc_v0 9 (1 s), C_geo_lsb 10 (0.0005 m),
  C_geo_v 10 (0.00005 m/s), I_geo 9 (1 s), C_er 6 (0.5 m), C_iono_step 10 (0.001 m),
  I_iono 9 (1 s), C_iono_ramp 10 (0.000005 m/s), RSS_UDRE 1, RSS_iono 1, C_covariance 7 (0.1),
  spare 81;
* MT 18 (Table A-15): number of bands 4, band number 4, IODI 2, 201 IGP-mask bits, spare 1;
* MT 24 (Table A-6 … A-12): 6 × fast correction, 6 × UDREI, IODP 2, block ID 2, IODF 2, spare 4,
  then one 106-bit long-term half;
* MT 25 (Tables A-10, A-11): two 106-bit halves. Velocity code 0: code 1, then twice {PRN-mask
  number 6, IODE 8, δx δy δz 9 each (0.125 m), δaf0 10 (2⁻³¹ s)}, IODP 2, spare 1. Velocity
  code 1: code 1, PRN-mask number 6, IODE 8, δx δy δz 11 each (0.125 m), δaf0 11 (2⁻³¹ s),
  δẋ δẏ δż 8 each (2⁻¹¹ m/s), δaf1 8 (2⁻³⁹ s/s), t₀ 13 (16 s, seconds of the GPS day), IODP 2;
* MT 26 (Table A-16): band 4, block ID 4, 15 × {IGP vertical delay 9 (0.125 m), GIVEI 4},
  IODI 2, spare 7;
* MT 0: 212 zero bits ("do not use this SBAS", test mode);
* MT 9 (GEO navigation), MT 12 (network time/UTC), MT 17 (GEO almanacs), MT 27 (δUDRE service
  regions) and MT 28 (clock-ephemeris covariance): the layouts in the docstrings of ``mt9``,
  ``mt12``, ``mt17``, ``mt27`` and ``mt28`` (212 bits each, spares zero).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Final

PREAMBLES: Final = (0x53, 0x9A, 0xC6)
_POLY: Final = 0x1864CFB


def crc24q_bits(value: int, n_bits: int) -> int:
    """CRC-24Q remainder of the ``n_bits``-bit integer ``value`` (bitwise long division)."""
    reg = value << 24
    for k in range(n_bits + 23, 23, -1):
        if reg >> k & 1:
            reg ^= _POLY << (k - 24)
    return reg & 0xFFFFFF


def _field(value: int, n: int) -> int:
    """``value`` as an n-bit two's-complement (or unsigned) field; refuses what does not fit."""
    if not -(1 << (n - 1)) <= value < (1 << n):
        raise ValueError(f"{value} does not fit {n} bits")
    return value & ((1 << n) - 1)


def pack(mt: int, fields: Sequence[tuple[int, int]], preamble: int = 0) -> bytes:
    """One 250-bit message as 32 bytes (6 zero pad bits): preamble, type, the (value, bits)
    fields padded with zeros to 212 bits, CRC-24Q."""
    acc, n = PREAMBLES[preamble % 3], 8
    for value, bits in ((mt, 6), *fields):
        acc = (acc << bits) | _field(int(value), bits)
        n += bits
    if n > 226:
        raise ValueError(f"message type {mt}: {n - 14} data bits, more than 212")
    acc <<= 226 - n
    acc = (acc << 24) | crc24q_bits(acc, 226)
    return (acc << 6).to_bytes(32, "big")


def q(x: float, lsb: float) -> int:
    """Round to the field's least significant bit."""
    return round(x / lsb)


def mt1(prns: Sequence[int], iodp: int, preamble: int = 0) -> bytes:
    mask = [(1 if p in set(prns) else 0, 1) for p in range(1, 211)]
    return pack(1, [*mask, (iodp, 2)], preamble)


def mt_fast(mt: int, iodf: int, iodp: int, prc_m: Sequence[float], udrei: Sequence[int], preamble: int = 0) -> bytes:
    """MT 2–5: 13 corrections (fewer are padded with 0 m, UDREI 15)."""
    prc = [*prc_m, *[0.0] * (13 - len(prc_m))]
    ud = [*udrei, *[15] * (13 - len(udrei))]
    return pack(mt, [(iodf, 2), (iodp, 2), *[(q(v, 0.125), 12) for v in prc], *[(u, 4) for u in ud]], preamble)


def mt6(iodf: Sequence[int], udrei: Sequence[int], preamble: int = 0) -> bytes:
    ud = [*udrei, *[15] * (51 - len(udrei))]
    return pack(6, [*[(v, 2) for v in iodf], *[(u, 4) for u in ud]], preamble)


def mt7(t_lat_s: int, iodp: int, ai: Sequence[int], preamble: int = 0) -> bytes:
    a = [*ai, *[0] * (51 - len(ai))]
    return pack(7, [(t_lat_s, 4), (iodp, 2), (0, 2), *[(v, 4) for v in a]], preamble)


@dataclass(frozen=True)
class Mt10:
    """MT 10 degradation parameters in SI units (Table A-9)."""

    b_rrc: float = 0.0
    c_ltc_lsb: float = 0.0
    c_ltc_v1: float = 0.0
    i_ltc_v1: int = 0
    c_ltc_v0: float = 0.0
    i_ltc_v0: int = 0
    c_geo_lsb: float = 0.0
    c_geo_v: float = 0.0
    i_geo: int = 0
    c_er: float = 0.0
    c_iono_step: float = 0.0
    i_iono: int = 0
    c_iono_ramp: float = 0.0
    rss_udre: int = 0
    rss_iono: int = 0
    c_covariance: float = 0.0


def mt10(p: Mt10, preamble: int = 0) -> bytes:
    fields = [
        (q(p.b_rrc, 0.002), 10), (q(p.c_ltc_lsb, 0.002), 10), (q(p.c_ltc_v1, 0.00005), 10), (p.i_ltc_v1, 9),
        (q(p.c_ltc_v0, 0.002), 10), (p.i_ltc_v0, 9), (q(p.c_geo_lsb, 0.0005), 10), (q(p.c_geo_v, 0.00005), 10),
        (p.i_geo, 9), (q(p.c_er, 0.5), 6), (q(p.c_iono_step, 0.001), 10), (p.i_iono, 9),
        (q(p.c_iono_ramp, 0.000005), 10), (p.rss_udre, 1), (p.rss_iono, 1), (q(p.c_covariance, 0.1), 7),
    ]  # fmt: skip
    return pack(10, fields, preamble)


def mt18(n_bands: int, band: int, iodi: int, igp_numbers: Sequence[int], preamble: int = 0) -> bytes:
    """IGP mask of one band: ``igp_numbers`` (1–201) set."""
    on = set(igp_numbers)
    return pack(18, [(n_bands, 4), (band, 4), (iodi, 2), *[(1 if k in on else 0, 1) for k in range(1, 202)]], preamble)


def mt26(
    band: int, block: int, delays_m: Sequence[float | None], givei: Sequence[int], iodi: int, preamble: int = 0
) -> bytes:
    """Up to 15 IGP delays (None: "do not use", 511) of one block of a band."""
    d = [*delays_m, *[None] * (15 - len(delays_m))]
    g = [*givei, *[15] * (15 - len(givei))]
    cells: list[tuple[int, int]] = []
    for v, gi in zip(d, g, strict=True):
        cells += [(511 if v is None else min(q(v, 0.125), 510), 9), (gi, 4)]
    return pack(26, [(band, 4), (block, 4), *cells, (iodi, 2)], preamble)


@dataclass(frozen=True)
class LongTerm:
    """One satellite's long-term correction (SI units; velocity terms only with code 1)."""

    slot: int
    iode: int
    dx_m: float
    dy_m: float
    dz_m: float
    daf0_s: float
    ddx_mps: float = 0.0
    ddy_mps: float = 0.0
    ddz_mps: float = 0.0
    daf1_sps: float = 0.0
    t0_s: float = 0.0
    """Time of applicability, seconds of the GPS day (multiple of 16)."""


def ltc_half(velocity: bool, sats: Sequence[LongTerm], iodp: int) -> list[tuple[int, int]]:
    """The 106-bit long-term half of MT 24/25: code 1 with one satellite, code 0 with one or two."""
    if velocity:
        s = sats[0]
        return [
            (1, 1), (s.slot, 6), (s.iode, 8), (q(s.dx_m, 0.125), 11), (q(s.dy_m, 0.125), 11), (q(s.dz_m, 0.125), 11),
            (q(s.daf0_s, 2.0**-31), 11), (q(s.ddx_mps, 2.0**-11), 8), (q(s.ddy_mps, 2.0**-11), 8),
            (q(s.ddz_mps, 2.0**-11), 8), (q(s.daf1_sps, 2.0**-39), 8), (q(s.t0_s, 16.0), 13), (iodp, 2),
        ]  # fmt: skip
    out: list[tuple[int, int]] = [(0, 1)]
    for k in range(2):
        if k < len(sats):
            s = sats[k]
            out += [(s.slot, 6), (s.iode, 8), (q(s.dx_m, 0.125), 9), (q(s.dy_m, 0.125), 9), (q(s.dz_m, 0.125), 9)]
            out.append((q(s.daf0_s, 2.0**-31), 10))
        else:
            out += [(0, 6), (0, 8), (0, 9), (0, 9), (0, 9), (0, 10)]
    return [*out, (iodp, 2), (0, 1)]


def mt25(
    first: tuple[bool, Sequence[LongTerm]], second: tuple[bool, Sequence[LongTerm]], iodp: int, preamble: int = 0
) -> bytes:
    return pack(25, [*ltc_half(first[0], first[1], iodp), *ltc_half(second[0], second[1], iodp)], preamble)


def mt24(
    block: int,
    iodf: int,
    iodp: int,
    prc_m: Sequence[float],
    udrei: Sequence[int],
    ltc: tuple[bool, Sequence[LongTerm]],
    preamble: int = 0,
) -> bytes:
    """Six fast corrections of block ``block`` (slots 13·block + 1 … + 6) and one long-term half."""
    prc = [*prc_m, *[0.0] * (6 - len(prc_m))]
    ud = [*udrei, *[15] * (6 - len(udrei))]
    fast = [*[(q(v, 0.125), 12) for v in prc], *[(u, 4) for u in ud], (iodp, 2), (block, 2), (iodf, 2), (0, 4)]
    return pack(24, [*fast, *ltc_half(ltc[0], ltc[1], iodp)], preamble)


def mt0(preamble: int = 0) -> bytes:
    return pack(0, [], preamble)


@dataclass(frozen=True)
class GeoNav:
    """MT 9 GEO navigation message in SI units (ECEF WGS-84)."""

    t0_sod_s: float
    """Time of applicability, seconds of the GPS day (multiple of 16)."""
    ura: int
    x_m: float
    y_m: float
    z_m: float
    vx_mps: float
    vy_mps: float
    vz_mps: float
    ax_mps2: float
    ay_mps2: float
    az_mps2: float
    af0_s: float
    af1_sps: float


def mt9(p: GeoNav, preamble: int = 0) -> bytes:
    """MT 9: reserved 8, t₀ 13 (16 s), URA 4, X Y 30 (0.08 m), Z 25 (0.4 m), Ẋ Ẏ 17 (0.000625 m/s),
    Ż 18 (0.004 m/s), Ẍ Ÿ 10 (0.0000125 m/s²), Z̈ 10 (0.0000625 m/s²), a_Gf0 12 (2⁻³¹ s),
    a_Gf1 8 (2⁻⁴⁰ s/s)."""
    fields = [
        (0, 8), (q(p.t0_sod_s, 16.0), 13), (p.ura, 4), (q(p.x_m, 0.08), 30), (q(p.y_m, 0.08), 30),
        (q(p.z_m, 0.4), 25), (q(p.vx_mps, 0.000625), 17), (q(p.vy_mps, 0.000625), 17), (q(p.vz_mps, 0.004), 18),
        (q(p.ax_mps2, 0.0000125), 10), (q(p.ay_mps2, 0.0000125), 10), (q(p.az_mps2, 0.0000625), 10),
        (q(p.af0_s, 2.0**-31), 12), (q(p.af1_sps, 2.0**-40), 8),
    ]  # fmt: skip
    return pack(9, fields, preamble)


@dataclass(frozen=True)
class NetworkTime:
    """MT 12 SBAS network time / UTC parameters."""

    a1_sps: float
    a0_s: float
    t0t_s: int
    wn_t: int
    dt_ls: int
    wn_lsf: int
    dn: int
    dt_lsf: int
    utc_id: int
    gps_tow_s: int
    gps_week: int
    glonass: int = 0
    glonass_da_s: float = 0.0


def mt12(p: NetworkTime, preamble: int = 0) -> bytes:
    """MT 12: A1 24 (2⁻⁵⁰ s/s), A0 32 (2⁻³⁰ s), t₀t 8 (2¹² s), WN_t 8, Δt_LS 8, WN_LSF 8, DN 8,
    Δt_LSF 8, UTC standard identifier 3, GPS TOW 20 (1 s), GPS week 10, GLONASS indicator 1,
    δa_i,GLONASS 24 (2⁻³¹ s), spare 50."""
    fields = [
        (q(p.a1_sps, 2.0**-50), 24), (q(p.a0_s, 2.0**-30), 32), (p.t0t_s // 4096, 8), (p.wn_t, 8), (p.dt_ls, 8),
        (p.wn_lsf, 8), (p.dn, 8), (p.dt_lsf, 8), (p.utc_id, 3), (p.gps_tow_s, 20), (p.gps_week, 10),
        (p.glonass, 1), (q(p.glonass_da_s, 2.0**-31), 24),
    ]  # fmt: skip
    return pack(12, fields, preamble)


@dataclass(frozen=True)
class GeoAlmanac:
    """One GEO almanac of MT 17."""

    prn: int
    health: int
    x_m: float
    y_m: float
    z_m: float
    vx_mps: float
    vy_mps: float
    vz_mps: float
    data_id: int = 0


def mt17(almanacs: Sequence[GeoAlmanac], t0_sod_s: float, preamble: int = 0) -> bytes:
    """MT 17: three almanacs {data ID 2, PRN 8, health and status 8, X Y 15 (2600 m), Z 9
    (26000 m), Ẋ Ẏ 3 (10 m/s), Ż 4 (60 m/s)} (an unused one all zero), t₀ 11 (64 s)."""
    fields: list[tuple[int, int]] = []
    for k in range(3):
        if k < len(almanacs):
            a = almanacs[k]
            fields += [
                (a.data_id, 2), (a.prn, 8), (a.health, 8), (q(a.x_m, 2600.0), 15), (q(a.y_m, 2600.0), 15),
                (q(a.z_m, 26000.0), 9), (q(a.vx_mps, 10.0), 3), (q(a.vy_mps, 10.0), 3), (q(a.vz_mps, 60.0), 4),
            ]  # fmt: skip
        else:
            fields += [(0, 2), (0, 8), (0, 8), (0, 15), (0, 15), (0, 9), (0, 3), (0, 3), (0, 4)]
    return pack(17, [*fields, (q(t0_sod_s, 64.0), 11)], preamble)


@dataclass(frozen=True)
class Region:
    """An MT 27 service region: corners 1 (lat1, lon1) and 2 (lat2, lon2) [deg]; corner 3 is
    (lat1, lon2), corner 4 (square only) (lat2, lon1)."""

    lat1: int
    lon1: int
    lat2: int
    lon2: int
    square: bool


def mt27(
    iods: int,
    n_messages: int,
    number: int,
    priority: int,
    inside: int,
    outside: int,
    regions: Sequence[Region],
    preamble: int = 0,
) -> bytes:
    """MT 27: IODS 3, number of service messages 3 (count − 1), service message number 3
    (number − 1), number of regions 3, priority code 2, δUDRE indicator inside 4 and outside 4,
    five regions {lat1 8, lon1 9, lat2 8, lon2 9 (1°, signed), shape 1 (1 square)}, spare 15."""
    fields = [(iods, 3), (n_messages - 1, 3), (number - 1, 3), (len(regions), 3), (priority, 2), (inside, 4),
              (outside, 4)]  # fmt: skip
    for k in range(5):
        r = regions[k] if k < len(regions) else Region(0, 0, 0, 0, False)
        fields += [(r.lat1, 8), (r.lon1, 9), (r.lat2, 8), (r.lon2, 9), (1 if r.square else 0, 1)]
    return pack(27, fields, preamble)


@dataclass(frozen=True)
class Covariance:
    """One satellite of MT 28: the upper-triangular Cholesky factor R of its clock-ephemeris
    covariance C = RᵀR, elements E_ij (integers) scaled by 2^(scale_exponent − 5) [m]."""

    slot: int
    scale_exponent: int
    e11: int
    e22: int
    e33: int
    e44: int
    e12: int
    e13: int
    e14: int
    e23: int
    e24: int
    e34: int


def mt28(iodp: int, sats: Sequence[Covariance], preamble: int = 0) -> bytes:
    """MT 28: IODP 2, two satellites {PRN-mask number 6, scale exponent 3, E11 E22 E33 E44 9
    each (unsigned), E12 E13 E14 E23 E24 E34 10 each (signed)} (an unused one all zero)."""
    fields = [(iodp, 2)]
    for k in range(2):
        if k < len(sats):
            c = sats[k]
            fields += [(c.slot, 6), (c.scale_exponent, 3), (c.e11, 9), (c.e22, 9), (c.e33, 9), (c.e44, 9),
                       (c.e12, 10), (c.e13, 10), (c.e14, 10), (c.e23, 10), (c.e24, 10), (c.e34, 10)]  # fmt: skip
        else:
            fields += [(0, 6), (0, 3), *[(0, 9)] * 4, *[(0, 10)] * 6]
    return pack(28, fields, preamble)
