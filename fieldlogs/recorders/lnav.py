"""GPS/QZSS L1 C/A LNAV subframes 1–3 ↔ broadcast ephemeris (IS-GPS-200 §20.3.3.3–4,
Tables 20-I, 20-III; IS-QZSS-PNT uses the same layout).

A subframe is 10 words of 30 bits (24 data bits, 6 parity bits). u-blox RXM-SFRBX carries
each word in the low 30 bits of a 32-bit word with the data bits 29…6 already corrected
for the D30* inversion (as RTKLIB's ``decode_nav`` reads them); the parity is not
checked here (the UBX checksum guards the frame). The writer computes the parity of
Table 20-XIV with D29* = D30* = 0 for every word (it never inverts).

Scale factors are those of Table 20-III; angles in semicircles are converted to radians
(×π) as RINEX stores them. Week: the 10-bit WN is resolved to the full GPS week nearest
``week_hint`` (the receiver's week). ``TransTime`` is the start of subframe 1
(HOW TOW-count · 6 s − 6 s), ``FitIntvl`` 4 h (fit flag 0) or 6 h (flag 1, the usual
IODC range), ``SVacc`` the URA index's nominal value (Table 20-I note).
"""

from __future__ import annotations

import math
from typing import Any

#: Nominal URA [m] per URA index (IS-GPS-200 §20.3.3.3.1.3).
URA_M = (2.4, 3.4, 4.85, 6.85, 9.65, 13.65, 24.0, 48.0, 96.0, 192.0, 384.0, 768.0, 1536.0, 3072.0, 6144.0, 6144.0)
PI = math.pi
PREAMBLE = 0x8B

# (name, [(word, first data bit 1..24, length), ...] MSB first, scale, signed, semicircles)
_F = tuple[str, list[tuple[int, int, int]], float, bool, bool]
SF1: list[_F] = [
    ("wn", [(3, 1, 10)], 1.0, False, False),
    ("ura", [(3, 13, 4)], 1.0, False, False),
    ("health", [(3, 17, 6)], 1.0, False, False),
    ("IODC", [(3, 23, 2), (8, 1, 8)], 1.0, False, False),
    ("TGD", [(7, 17, 8)], 2.0**-31, True, False),
    ("toc", [(8, 9, 16)], 16.0, False, False),
    ("SVclockDriftRate", [(9, 1, 8)], 2.0**-55, True, False),
    ("SVclockDrift", [(9, 9, 16)], 2.0**-43, True, False),
    ("SVclockBias", [(10, 1, 22)], 2.0**-31, True, False),
]
SF2: list[_F] = [
    ("IODE", [(3, 1, 8)], 1.0, False, False),
    ("Crs", [(3, 9, 16)], 2.0**-5, True, False),
    ("DeltaN", [(4, 1, 16)], 2.0**-43, True, True),
    ("M0", [(4, 17, 8), (5, 1, 24)], 2.0**-31, True, True),
    ("Cuc", [(6, 1, 16)], 2.0**-29, True, False),
    ("Eccentricity", [(6, 17, 8), (7, 1, 24)], 2.0**-33, False, False),
    ("Cus", [(8, 1, 16)], 2.0**-29, True, False),
    ("sqrtA", [(8, 17, 8), (9, 1, 24)], 2.0**-19, False, False),
    ("Toe", [(10, 1, 16)], 16.0, False, False),
    ("fit", [(10, 17, 1)], 1.0, False, False),
]
SF3: list[_F] = [
    ("Cic", [(3, 1, 16)], 2.0**-29, True, False),
    ("Omega0", [(3, 17, 8), (4, 1, 24)], 2.0**-31, True, True),
    ("Cis", [(5, 1, 16)], 2.0**-29, True, False),
    ("Io", [(5, 17, 8), (6, 1, 24)], 2.0**-31, True, True),
    ("Crc", [(7, 1, 16)], 2.0**-5, True, False),
    ("omega", [(7, 17, 8), (8, 1, 24)], 2.0**-31, True, True),
    ("OmegaDot", [(9, 1, 24)], 2.0**-43, True, True),
    ("IODE3", [(10, 1, 8)], 1.0, False, False),
    ("IDOT", [(10, 9, 14)], 2.0**-43, True, True),
]
LAYOUT = {1: SF1, 2: SF2, 3: SF3}


def _bits(data: list[int], segs: list[tuple[int, int, int]]) -> tuple[int, int]:
    v, n = 0, 0
    for w, b, length in segs:
        word = data[w - 1]
        v = (v << length) | ((word >> (24 - (b - 1) - length)) & ((1 << length) - 1))
        n += length
    return v, n


def _put(data: list[int], segs: list[tuple[int, int, int]], value: int) -> None:
    total = sum(s[2] for s in segs)
    value &= (1 << total) - 1
    shift = total
    for w, b, length in segs:
        shift -= length
        part = (value >> shift) & ((1 << length) - 1)
        data[w - 1] |= part << (24 - (b - 1) - length)


def subframe_id(words: list[int]) -> int:
    """Subframe ID (HOW bits 20–22) of 10 SFRBX words; 0 when the TLM preamble is wrong."""
    data = [(w >> 6) & 0xFFFFFF for w in words]
    if (data[0] >> 16) != PREAMBLE:
        return 0
    return (data[1] >> 2) & 0x7


def decode_subframe(words: list[int]) -> dict[str, float]:
    """Fields of subframe 1, 2 or 3 (RINEX units) plus ``sf`` and ``tow`` (HOW, seconds)."""
    data = [(w >> 6) & 0xFFFFFF for w in words]
    sf = (data[1] >> 2) & 0x7
    out: dict[str, float] = {"sf": float(sf), "tow": float((data[1] >> 7) * 6)}
    for name, segs, scale, signed, semi in LAYOUT.get(sf, []):
        v, n = _bits(data, segs)
        if signed and v >= 1 << (n - 1):
            v -= 1 << n
        x = v * scale
        out[name] = x * PI if semi else x
    return out


def assemble(sf1: dict[str, float], sf2: dict[str, float], sf3: dict[str, float], week_hint: int) -> dict[str, Any]:
    """One ephemeris (gnss_nav fields, without ``sat``) from matching subframes 1–3."""
    wn = int(sf1["wn"])
    week = week_hint + ((wn - week_hint) % 1024 + 512) % 1024 - 512
    trans = sf1["tow"] - 6.0
    toe_week = week + (1 if sf2["Toe"] - trans < -302_400 else 0)
    toc_week = week + (1 if sf1["toc"] - trans < -302_400 else 0)
    eph: dict[str, Any] = {
        k: v for k, v in {**sf1, **sf2, **sf3}.items() if k not in {"sf", "tow", "wn", "ura", "fit", "toc", "IODE3"}
    }
    eph.update(
        toc_gps_s=toc_week * 604_800.0 + sf1["toc"],
        week=float(toe_week),
        TransTime=trans % 604_800.0,
        SVacc=URA_M[int(sf1["ura"])],
        FitIntvl=6.0 if sf2["fit"] else 4.0,
    )
    return eph


def _parity(d: int) -> int:
    """Six parity bits of 24 data bits (IS-GPS-200 Table 20-XIV, D29* = D30* = 0)."""
    bit = [(d >> (24 - i)) & 1 for i in range(1, 25)]  # bit[0] = d1
    eqs = (
        (1, 2, 3, 5, 6, 10, 11, 12, 13, 14, 17, 18, 20, 23),
        (2, 3, 4, 6, 7, 11, 12, 13, 14, 15, 18, 19, 21, 24),
        (1, 3, 4, 5, 7, 8, 12, 13, 14, 15, 16, 19, 20, 22),
        (2, 4, 5, 6, 8, 9, 13, 14, 15, 16, 17, 20, 21, 23),
        (1, 3, 5, 6, 7, 9, 10, 14, 15, 16, 17, 18, 21, 22, 24),
        (3, 5, 6, 8, 9, 10, 11, 13, 15, 19, 22, 23, 24),
    )
    p = 0
    for eq in eqs:
        x = 0
        for i in eq:
            x ^= bit[i - 1]
        p = (p << 1) | x
    return p


def _ura_index(acc: float) -> int:
    for i, v in enumerate(URA_M[:-1]):
        if not math.isfinite(acc) or acc <= v:
            return i
    return 14


def _value(name: str, eph: dict[str, Any]) -> float:
    v = eph.get(name)
    return 0.0 if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)


def encode(eph: dict[str, Any]) -> list[list[int]]:
    """Subframes 1–3 (each 10 SFRBX words) of one ephemeris (gnss_nav row of G or J)."""
    week = int(_value("week", eph))
    tow6 = round((_value("TransTime", eph) + 6.0) / 6.0)
    toc_sow = (_value("toc_gps_s", eph) - week * 604_800.0) % 604_800.0
    ints: dict[str, float] = {
        "wn": week % 1024,
        "ura": _ura_index(_value("SVacc", eph)),
        "toc": toc_sow,
        "fit": 1.0 if _value("FitIntvl", eph) > 4.0 else 0.0,
        "IODE3": _value("IODE", eph),
    }
    out = []
    for sf, layout in LAYOUT.items():
        data = [0] * 10
        data[0] = PREAMBLE << 16
        data[1] = (((tow6 + sf - 1) % 100_800) << 7) | (sf << 2)
        for name, segs, scale, _signed, semi in layout:
            x = ints[name] if name in ints else _value(name, eph)
            if semi:
                x /= PI
            _put(data, segs, round(x / scale))
        out.append([(d << 6) | _parity(d) for d in data])
    return out


# Subframe 4, page 18 (SV ID 56): ionosphere and UTC parameters (IS-GPS-200 §20.3.3.5.1.6–7).
IONO_UTC: list[_F] = [
    ("page", [(3, 3, 6)], 1.0, False, False),
    ("a0", [(3, 9, 8)], 2.0**-30, True, False),
    ("a1", [(3, 17, 8)], 2.0**-27, True, False),
    ("a2", [(4, 1, 8)], 2.0**-24, True, False),
    ("a3", [(4, 9, 8)], 2.0**-24, True, False),
    ("b0", [(4, 17, 8)], 2.0**11, True, False),
    ("b1", [(5, 1, 8)], 2.0**14, True, False),
    ("b2", [(5, 9, 8)], 2.0**16, True, False),
    ("b3", [(5, 17, 8)], 2.0**16, True, False),
    ("A1", [(6, 1, 24)], 2.0**-50, True, False),
    ("A0", [(7, 1, 24), (8, 1, 8)], 2.0**-30, True, False),
    ("tot", [(8, 9, 8)], 2.0**12, False, False),
    ("WNt", [(8, 17, 8)], 1.0, False, False),
    ("dtLS", [(9, 1, 8)], 1.0, True, False),
]
IONO_UTC_PAGE = 56


def decode_iono_utc(words: list[int], week_hint: int) -> dict[str, Any] | None:
    """The ``gnss`` block entries of subframe 4 page 18, or None for any other page."""
    data = [(w >> 6) & 0xFFFFFF for w in words]
    if (data[1] >> 2) & 0x7 != 4:
        return None
    v: dict[str, float] = {}
    for name, segs, scale, signed, _semi in IONO_UTC:
        x, n = _bits(data, segs)
        if signed and x >= 1 << (n - 1):
            x -= 1 << n
        v[name] = x * scale
    if int(v["page"]) != IONO_UTC_PAGE:
        return None
    wnt = week_hint + ((int(v["WNt"]) - week_hint) % 256 + 128) % 256 - 128
    return {
        "alpha": [v["a0"], v["a1"], v["a2"], v["a3"]],
        "beta": [v["b0"], v["b1"], v["b2"], v["b3"]],
        "leap_seconds": int(v["dtLS"]),
        "correction": {"a0_s": v["A0"], "a1_s_per_s": v["A1"], "t_ref_s": v["tot"], "week": float(wnt)},
    }


def encode_iono_utc(
    alpha: list[float], beta: list[float], leap_seconds: int, corr: dict[str, float], tow6: int
) -> list[int]:
    """Subframe 4 page 18 (10 SFRBX words) from Klobuchar α/β, ΔtLS and the GPS−UTC correction."""
    data = [0] * 10
    data[0] = PREAMBLE << 16
    data[1] = ((tow6 % 100_800) << 7) | (4 << 2)
    values = {
        "page": IONO_UTC_PAGE,
        "a0": alpha[0],
        "a1": alpha[1],
        "a2": alpha[2],
        "a3": alpha[3],
        "b0": beta[0],
        "b1": beta[1],
        "b2": beta[2],
        "b3": beta[3],
        "A1": corr["a1_s_per_s"],
        "A0": corr["a0_s"],
        "tot": corr["t_ref_s"],
        "WNt": int(corr["week"]) % 256,
        "dtLS": leap_seconds,
    }
    data[2] |= 1 << 22  # data ID 01
    for name, segs, scale, _signed, _semi in IONO_UTC:
        _put(data, segs, round(float(values[name]) / scale))
    return [(d << 6) | _parity(d) for d in data]
