"""Galileo I/NAV word types 1–5 ↔ broadcast ephemeris (Galileo OS SIS ICD §4.3.5, Tables
40–46) as u-blox RXM-SFRBX carries them.

An SFRBX Galileo message holds one nominal page in 8 words (256 bits, MSB first): the even
part in bits 0–127 (even/odd bit, page type, data bits 1–112, tail), the odd part in bits
128–255 (even/odd bit, page type, data bits 113–128, reserved fields, CRC-24Q over the
4 pad bits + 114 even + 82 odd bits, …) — the layout RTKLIB's ``decode_enav`` reads. Pages
whose CRC fails, alert pages and word types other than 1–5 are not decoded.

Scale factors (ICD Table 60): toe, toc 60 s; M0, Ω0, i0, ω 2⁻³¹ semicircles; e 2⁻³³;
√A 2⁻¹⁹; Ω̇, Δn, IDOT 2⁻⁴³ semicircles/s; Cuc, Cus, Cic, Cis 2⁻²⁹ rad; Crc, Crs 2⁻⁵ m;
af0 2⁻³⁴ s, af1 2⁻⁴⁶, af2 2⁻⁵⁹; BGD 2⁻³² s; ai0 2⁻², ai1 2⁻⁸, ai2 2⁻¹⁵. The GST week of word
type 5 is turned into GPS numbering (+1024, RINEX 3), ``TransTime`` is its TOW, ``SVacc``
the SISA index in metres (ICD §5.1.11; 255 "no accuracy prediction" → −1 as RINEX writes
it), ``health`` the RINEX bit layout (E1-B DVS bit 0, E1-B HS bits 1–2, E5b DVS bit 6,
E5b HS bits 7–8), ``DataSrc`` I/NAV E1-B (bit 0) or E5b (bit 2) with the E5b/E1 clock (bit 9).
"""

from __future__ import annotations

import math
from typing import Any

PI = math.pi
GST_TO_GPS_WEEK = 1024
CRC24Q_POLY = 0x1864CFB

# (name, bit offset in the 128-bit word, length, scale, signed, semicircles)
_W = tuple[str, int, int, float, bool, bool]
WORDS: dict[int, list[_W]] = {
    1: [
        ("IODE", 6, 10, 1.0, False, False),
        ("toe", 16, 14, 60.0, False, False),
        ("M0", 30, 32, 2.0**-31, True, True),
        ("Eccentricity", 62, 32, 2.0**-33, False, False),
        ("sqrtA", 94, 32, 2.0**-19, False, False),
    ],
    2: [
        ("IODE", 6, 10, 1.0, False, False),
        ("Omega0", 16, 32, 2.0**-31, True, True),
        ("Io", 48, 32, 2.0**-31, True, True),
        ("omega", 80, 32, 2.0**-31, True, True),
        ("IDOT", 112, 14, 2.0**-43, True, True),
    ],
    3: [
        ("IODE", 6, 10, 1.0, False, False),
        ("OmegaDot", 16, 24, 2.0**-43, True, True),
        ("DeltaN", 40, 16, 2.0**-43, True, True),
        ("Cuc", 56, 16, 2.0**-29, True, False),
        ("Cus", 72, 16, 2.0**-29, True, False),
        ("Crc", 88, 16, 2.0**-5, True, False),
        ("Crs", 104, 16, 2.0**-5, True, False),
        ("sisa", 120, 8, 1.0, False, False),
    ],
    4: [
        ("IODE", 6, 10, 1.0, False, False),
        ("svid", 16, 6, 1.0, False, False),
        ("Cic", 22, 16, 2.0**-29, True, False),
        ("Cis", 38, 16, 2.0**-29, True, False),
        ("toc", 54, 14, 60.0, False, False),
        ("SVclockBias", 68, 31, 2.0**-34, True, False),
        ("SVclockDrift", 99, 21, 2.0**-46, True, False),
        ("SVclockDriftRate", 120, 6, 2.0**-59, True, False),
    ],
    5: [
        ("ai0", 6, 11, 2.0**-2, False, False),
        ("ai1", 17, 11, 2.0**-8, True, False),
        ("ai2", 28, 14, 2.0**-15, True, False),
        ("BGDe5a", 47, 10, 2.0**-32, True, False),
        ("BGDe5b", 57, 10, 2.0**-32, True, False),
        ("e5b_hs", 67, 2, 1.0, False, False),
        ("e1b_hs", 69, 2, 1.0, False, False),
        ("e5b_dvs", 71, 1, 1.0, False, False),
        ("e1b_dvs", 72, 1, 1.0, False, False),
        ("wn", 73, 12, 1.0, False, False),
        ("tow", 85, 20, 1.0, False, False),
    ],
}


def _crc24q(bits: int, n: int) -> int:
    """CRC-24Q of the ``n`` most significant bits of ``bits`` (n a multiple of 8)."""
    crc = 0
    for k in range(n // 8):
        byte = (bits >> (n - 8 * (k + 1))) & 0xFF
        crc ^= byte << 16
        for _ in range(8):
            crc <<= 1
            if crc & 0x1000000:
                crc ^= CRC24Q_POLY
    return crc & 0xFFFFFF


def _page_bits(words: list[int]) -> int:
    v = 0
    for w in words[:8]:
        v = (v << 32) | (w & 0xFFFFFFFF)
    return v


def _get(v: int, start: int, length: int, total: int = 256) -> int:
    return (v >> (total - start - length)) & ((1 << length) - 1)


def _crc_input(page: int) -> int:
    """4 zero bits + even bits 0–113 + odd bits 0–81 (200 bits, 25 bytes)."""
    return (_get(page, 0, 114) << 82) | _get(page, 128, 82)


def word_of_page(words: list[int]) -> tuple[int, int] | None:
    """(word type, 128-bit word) of a nominal page with a good CRC, else None."""
    page = _page_bits(words)
    if _get(page, 0, 1) != 0 or _get(page, 128, 1) != 1 or _get(page, 1, 1) or _get(page, 129, 1):
        return None  # not even/odd in order, or an alert page
    if _crc24q(_crc_input(page), 200) != _get(page, 128 + 82, 24):
        return None
    word = (_get(page, 2, 112) << 16) | _get(page, 130, 16)
    return word >> 122, word


def decode_word(word: int) -> dict[str, float]:
    wtype = word >> 122
    out: dict[str, float] = {}
    for name, start, length, scale, signed, semi in WORDS.get(wtype, []):
        x = _get(word, start, length, 128)
        if signed and x >= 1 << (length - 1):
            x -= 1 << length
        out[name] = x * scale * (PI if semi else 1.0)
    return out


def sisa_m(index: int) -> float:
    """SISA index → metres (ICD §5.1.11); 255 (no accuracy prediction) → −1."""
    if index < 50:
        return index * 0.01
    if index < 75:
        return 0.5 + (index - 50) * 0.02
    if index < 100:
        return 1.0 + (index - 75) * 0.04
    if index < 126:
        return 2.0 + (index - 100) * 0.16
    return -1.0


def sisa_index(metres: float) -> int:
    if not math.isfinite(metres) or metres < 0:
        return 255
    for i in range(126):
        if sisa_m(i) >= metres - 1e-9:
            return i
    return 125


def assemble(w: dict[int, dict[str, float]], e5b: bool = False) -> dict[str, Any] | None:
    """One ephemeris from word types 1–5 (None unless types 1–4 share their IODnav)."""
    if not all(k in w for k in (1, 2, 3, 4, 5)) or len({int(w[k]["IODE"]) for k in (1, 2, 3, 4)}) != 1:
        return None
    w5 = w[5]
    week = int(w5["wn"]) + GST_TO_GPS_WEEK
    tow = w5["tow"]
    toc_week = week + (1 if w[4]["toc"] - tow < -302_400 else 0) - (1 if w[4]["toc"] - tow > 302_400 else 0)
    toe_week = week + (1 if w[1]["toe"] - tow < -302_400 else 0) - (1 if w[1]["toe"] - tow > 302_400 else 0)
    eph: dict[str, Any] = {
        k: v for n in (1, 2, 3, 4) for k, v in w[n].items() if k not in ("toe", "toc", "sisa", "svid")
    }
    eph.update(
        toc_gps_s=toc_week * 604_800.0 + w[4]["toc"],
        Toe=w[1]["toe"],
        week=float(toe_week),
        TransTime=tow,
        SVacc=sisa_m(int(w[3]["sisa"])),
        BGDe5a=w5["BGDe5a"],
        BGDe5b=w5["BGDe5b"],
        health=float(int(w5["e1b_dvs"]) | int(w5["e1b_hs"]) << 1 | int(w5["e5b_dvs"]) << 6 | int(w5["e5b_hs"]) << 7),
        DataSrc=float((4 if e5b else 1) | 512),
    )
    return eph


# ---------------------------------------------------------------------------------------
# writer


def _val(eph: dict[str, Any], name: str) -> float:
    v = eph.get(name)
    return 0.0 if v is None or (isinstance(v, float) and math.isnan(v)) else float(v)


def _values(eph: dict[str, Any], ai: list[float]) -> dict[str, float]:
    week = int(_val(eph, "week"))
    toc_sow = (_val(eph, "toc_gps_s") - week * 604_800.0) % 604_800.0
    health = int(_val(eph, "health"))
    v = {k: _val(eph, k) for _, fields in WORDS.items() for k, *_ in fields}
    v.update(
        toe=_val(eph, "Toe"),
        toc=toc_sow,
        sisa=float(sisa_index(_val(eph, "SVacc") if "SVacc" in eph else -1)),
        svid=float(int(str(eph.get("sat", "E00"))[1:])),
        ai0=ai[0],
        ai1=ai[1],
        ai2=ai[2],
        e1b_dvs=health & 1,
        e1b_hs=(health >> 1) & 3,
        e5b_dvs=(health >> 6) & 1,
        e5b_hs=(health >> 7) & 3,
        wn=(week - GST_TO_GPS_WEEK) % 4096,
        tow=_val(eph, "TransTime"),
    )
    return v


def encode_word(wtype: int, values: dict[str, float]) -> int:
    word = wtype << 122
    for name, start, length, scale, _signed, semi in WORDS[wtype]:
        x = values[name] / (PI if semi else 1.0)
        word |= (round(x / scale) & ((1 << length) - 1)) << (128 - start - length)
    return word


def page_words(word: int) -> list[int]:
    """The 8 SFRBX words of a nominal page carrying a 128-bit word (CRC-24Q filled in)."""
    even = (0 << 127) | (0 << 126) | ((word >> 16) << 14)  # even/odd 0, page type 0, data 1–112, tail 0
    odd = (1 << 127) | ((word & 0xFFFF) << 110)  # even/odd 1, page type 0, data 113–128
    page = (even << 128) | odd
    crc = _crc24q(_crc_input(page), 200)
    page |= crc << (256 - (128 + 82) - 24)
    return [(page >> (32 * (7 - k))) & 0xFFFFFFFF for k in range(8)]


def encode(eph: dict[str, Any], ai: list[float] | None = None) -> list[list[int]]:
    """Pages of word types 1–5 (each 8 SFRBX words) of one Galileo ephemeris."""
    values = _values(eph, ai or [0.0, 0.0, 0.0])
    return [page_words(encode_word(t, values)) for t in (1, 2, 3, 4, 5)]
