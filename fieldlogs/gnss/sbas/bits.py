"""Bit access and the CRC-24Q of SBAS L1 messages, vectorised over messages.

A message is 250 bits, MSB first (RTCA DO-229 §A.4.3, Figure A-2): an 8-bit preamble
(0x53, 0x9A, 0xC6 in turn over three messages), the 6-bit message type, 212 data bits and
24 parity bits. Here N messages are an (N, 256) array of 0/1 bits, the 250 left-aligned in
32 bytes (as u-blox RXM-SFRBX's eight 32-bit words carry them); bits 250–255 are ignored.

Parity (DO-229 §A.4.3.3): CRC-24Q, generator g(X) = X²⁴ + X²³ + X¹⁸ + X¹⁷ + X¹⁴ + X¹¹ + X¹⁰ +
X⁷ + X⁶ + X⁵ + X⁴ + X³ + X + 1 (0x1864CFB), register initialised to 0, no reflection, no final
XOR, over the first 226 bits; the 24 parity bits are the remainder, MSB first. Leading zero
bits leave such a CRC unchanged, so the 226 bits are taken as 29 bytes after 6 zero bits.
"""

from __future__ import annotations

from typing import Final

import numpy as np
import numpy.typing as npt

Bits = npt.NDArray[np.uint8]
IntArray = npt.NDArray[np.int64]

MESSAGE_BITS: Final = 250
DATA_BITS: Final = 226
PREAMBLES: Final = (0x53, 0x9A, 0xC6)
CRC24Q_POLY: Final = 0x1864CFB


def _crc_table() -> IntArray:
    """Byte-wise CRC-24Q table: the remainder of each byte value shifted into the top."""
    table = np.zeros(256, dtype=np.int64)
    for b in range(256):
        c = b << 16
        for _ in range(8):
            c <<= 1
            if c & 0x1000000:
                c ^= CRC24Q_POLY
        table[b] = c & 0xFFFFFF
    return table


_TABLE: Final = _crc_table()


def crc24q_bytes(data: npt.NDArray[np.uint8]) -> IntArray:
    """CRC-24Q of each row of ``data`` (N, L) bytes (table-driven, vectorised over rows)."""
    d = np.atleast_2d(np.asarray(data, dtype=np.uint8)).astype(np.int64)
    crc = np.zeros(d.shape[0], dtype=np.int64)
    for k in range(d.shape[1]):
        crc = ((crc << 8) & 0xFFFFFF) ^ _TABLE[((crc >> 16) ^ d[:, k]) & 0xFF]
    return crc


def hex_to_bits(hex_digits: npt.ArrayLike) -> tuple[Bits, npt.NDArray[np.bool_]]:
    """(N, 256) bits of hex strings and whether each was well formed (63 or 64 hex digits)."""
    s = np.asarray(hex_digits, dtype=object)
    ok = np.zeros(s.size, dtype=bool)
    raw = np.zeros((s.size, 32), dtype=np.uint8)
    for i, h in enumerate(s.ravel()):  # parsing text is per message by nature
        if not isinstance(h, str):
            continue
        h = h.strip()
        if len(h) not in (63, 64):
            continue
        try:
            raw[i] = np.frombuffer(bytes.fromhex(h.ljust(64, "0")), dtype=np.uint8)
        except ValueError:
            continue
        ok[i] = True
    return np.unpackbits(raw, axis=1), ok


def bits_to_hex(bits: Bits) -> list[str]:
    """64 hex digits per row of (N, 256) bits."""
    return [row.tobytes().hex().upper() for row in np.packbits(np.asarray(bits, dtype=np.uint8), axis=1)]


def getbitu(bits: Bits, start: int, n: int) -> IntArray:
    """Unsigned field of ``n`` bits at bit ``start`` (0 = first bit of the preamble) of each row."""
    w = (1 << np.arange(n - 1, -1, -1, dtype=np.int64)).astype(np.int64)
    return np.asarray(bits[:, start : start + n].astype(np.int64) @ w, dtype=np.int64)


def getbits(bits: Bits, start: int, n: int) -> IntArray:
    """Two's-complement signed field of ``n`` bits at ``start``."""
    u = getbitu(bits, start, n)
    return np.where(u >= (1 << (n - 1)), u - (1 << n), u)


def parity_ok(bits: Bits) -> npt.NDArray[np.bool_]:
    """The CRC-24Q of bits 0–225 equals bits 226–249 (module docstring)."""
    b = np.asarray(bits, dtype=np.uint8)
    padded = np.concatenate([np.zeros((b.shape[0], 6), dtype=np.uint8), b[:, :DATA_BITS]], axis=1)
    crc = crc24q_bytes(np.packbits(padded, axis=1))
    return np.asarray(crc == getbitu(b, DATA_BITS, 24), dtype=bool)


def message_type(bits: Bits) -> IntArray:
    """The 6-bit message type (bits 8–13)."""
    return getbitu(bits, 8, 6)


def preamble_ok(bits: Bits) -> npt.NDArray[np.bool_]:
    """The first 8 bits are one of the three preambles."""
    return np.asarray(np.isin(getbitu(bits, 0, 8), PREAMBLES), dtype=bool)
