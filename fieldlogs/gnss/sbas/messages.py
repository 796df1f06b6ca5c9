"""A ``gnss_sbas`` stream → its valid messages, decoded by type (:class:`SbasMessages`).

Each row (``schemas.gnss.GNSS_SBAS``) is checked: the hex text (63 or 64 hex digits), the
SBAS PRN (120–158), the preamble (0x53, 0x9A or 0xC6), the CRC-24Q over the first 226 bits
(``bits.parity_ok``), the receiver's ``valid`` flag where logged (0: it found the CRC bad) and
the ``msg_type`` column against the type in the bits. A row failing any of these is dropped and
counted under its first failure in ``dropped`` — a bad message is what a radio link delivers, so
it never stops the run (the same convention as the UBX reader's frames with a bad checksum).
Only a frame that is not the stream at all (a required column missing) raises
:class:`SbasStreamError`.

Time of applicability (DO-229 §A.4.4.3): a message's corrections apply from the start of the
second in which its first symbol left the GEO. The stream logs the reception of its last bit,
one second (the message block) plus the GEO's path delay (0.12–0.14 s) later, so
t_of = ⌊gnss_time_s − 1.1⌋ here.

Several GEOs: each GEO's messages are decoded apart (``read_geos``); which GEO's set applies
when is ``geo_select``'s (DO-229 §2.1.1.4.5: one GEO's set, consistently). ``read_messages``
gives one GEO's: ``prn`` or the one with the most valid messages.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

import fieldlogs.gnss.sbas.decode as d
from fieldlogs.gnss.sbas.bits import hex_to_bits, message_type, parity_ok, preamble_ok
from schemas.errors import InputError
from schemas.gnss import GNSS_SBAS, SBAS_PRN_RANGE

#: Delay from a message's first symbol at the GEO to its last bit at the receiver, less a margin.
RECEPTION_DELAY_S = 1.1
DECODED_TYPES = (0, 1, 2, 3, 4, 5, 6, 7, 9, 10, 12, 17, 18, 24, 25, 26, 27, 28)


class SbasStreamError(InputError):
    """A ``gnss_sbas`` frame that is not one (a required column missing)."""


def _empty() -> pd.DataFrame:
    return pd.DataFrame()


@dataclass
class SbasMessages:
    """Decoded valid messages of one GEO (``decode`` module docstring for the frames)."""

    geo: int | None
    masks: pd.DataFrame = field(default_factory=_empty)
    fast: pd.DataFrame = field(default_factory=_empty)
    integrity: pd.DataFrame = field(default_factory=_empty)
    degradation: pd.DataFrame = field(default_factory=_empty)
    mt10: pd.DataFrame = field(default_factory=_empty)
    long_term: pd.DataFrame = field(default_factory=_empty)
    igp_mask: pd.DataFrame = field(default_factory=_empty)
    iono: pd.DataFrame = field(default_factory=_empty)
    mt0: pd.DataFrame = field(default_factory=_empty)
    geo_nav: pd.DataFrame = field(default_factory=_empty)
    network_time: pd.DataFrame = field(default_factory=_empty)
    almanacs: pd.DataFrame = field(default_factory=_empty)
    service: pd.DataFrame = field(default_factory=_empty)
    covariance: pd.DataFrame = field(default_factory=_empty)
    dropped: Counter[str] = field(default_factory=Counter)
    """Rows dropped by reason (module docstring)."""
    not_decoded: Counter[int] = field(default_factory=Counter)
    """Valid messages of types this decoder leaves (``decode`` docstring), by type."""
    n_valid: int = 0


def _screen(frame: pd.DataFrame) -> tuple[np.ndarray, np.ndarray, Counter[str]]:
    """Bits of every row, which rows pass, and the drop counts (module docstring)."""
    bits, well_formed = hex_to_bits(frame["message_hex"].to_numpy(dtype=object))
    prn = pd.to_numeric(frame["prn"], errors="coerce").to_numpy(dtype=float)
    t = pd.to_numeric(frame["gnss_time_s"], errors="coerce").to_numpy(dtype=float)
    mt_col = (
        pd.to_numeric(frame["msg_type"], errors="coerce").to_numpy(dtype=float)
        if "msg_type" in frame
        else np.full(len(frame), np.nan)
    )
    valid_col = (
        pd.to_numeric(frame["valid"], errors="coerce").to_numpy(dtype=float)
        if "valid" in frame
        else np.full(len(frame), np.nan)
    )
    mt = message_type(bits)
    checks = (
        ("no_time", ~np.isfinite(t)),
        ("bad_prn", ~((prn >= SBAS_PRN_RANGE[0]) & (prn <= SBAS_PRN_RANGE[1]))),
        ("bad_length", ~well_formed),
        ("receiver_flagged_invalid", valid_col == 0),
        ("bad_preamble", ~preamble_ok(bits)),
        ("bad_crc", ~parity_ok(bits)),
        ("type_mismatch", np.isfinite(mt_col) & (mt_col != mt)),
    )
    ok = np.ones(len(frame), dtype=bool)
    counts: Counter[str] = Counter()
    for reason, bad in checks:
        hit = ok & bad
        if hit.any():
            counts[reason] += int(hit.sum())
        ok &= ~bad
    return bits, ok, counts


def read_geos(frame: pd.DataFrame | None) -> dict[int, SbasMessages]:
    """Screen a ``gnss_sbas`` frame once and decode each GEO's valid messages apart (module
    docstring); every GEO's ``dropped`` holds the counts of the whole stream. Empty without a
    valid message."""
    if frame is None or not len(frame):
        return {}
    missing = [c for c in GNSS_SBAS.required_columns if c not in frame.columns and c != "t"]
    if missing:
        raise SbasStreamError("missing column", path="gnss_sbas frame", column=missing[0])
    bits, ok, dropped = _screen(frame)
    geo_all = pd.to_numeric(frame["prn"], errors="coerce").fillna(-1).to_numpy(dtype=np.int64)
    t_all = pd.to_numeric(frame["gnss_time_s"], errors="coerce").to_numpy(dtype=float)
    out: dict[int, SbasMessages] = {}
    for prn in np.unique(geo_all[ok]).tolist():
        sel = ok & (geo_all == prn)
        one = SbasMessages(int(prn), dropped=Counter(dropped), n_valid=int(sel.sum()))
        b, t, geo = bits[sel], t_all[sel], geo_all[sel]
        mt = message_type(b)
        for k, n in zip(*np.unique(mt[~np.isin(mt, DECODED_TYPES)], return_counts=True), strict=True):
            one.not_decoded[int(k)] = int(n)
        _decode_all(one, b, t, geo, mt)
        out[int(prn)] = one
    return out


def read_messages(frame: pd.DataFrame | None, prn: int | None = None) -> SbasMessages:
    """One GEO's decoded messages (``prn``, else the one with the most valid messages)."""
    geos = read_geos(frame)
    if not geos:
        if frame is not None and len(frame):
            _, _, dropped = _screen(frame)
            return SbasMessages(prn, dropped=dropped)
        return SbasMessages(None)
    if prn is None:
        prn = max(geos, key=lambda g: (geos[g].n_valid, -g))
    if prn not in geos:
        return SbasMessages(prn, dropped=Counter(next(iter(geos.values())).dropped))
    return geos[prn]


def _decode_all(out: SbasMessages, b: np.ndarray, t: np.ndarray, geo: np.ndarray, mt: np.ndarray) -> None:
    def part(types: tuple[int, ...]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        m = np.isin(mt, types)
        return b[m], t[m], geo[m], mt[m]

    def t_of(frame: pd.DataFrame) -> pd.DataFrame:
        return frame.assign(t_of=np.floor(frame["t_rx"].to_numpy(dtype=float) - RECEPTION_DELAY_S))

    bb, tt, gg, mm = part((1,))
    out.masks = d.decode_mt1(bb, tt, gg)
    bb, tt, gg, mm = part((2, 3, 4, 5))
    fast = [d.decode_fast(bb, tt, gg, mm)]
    bb, tt, gg, _ = part((24,))
    fast.append(d.decode_mt24_fast(bb, tt, gg))
    lt = [d.decode_long_term(bb, tt, gg, (120,))]
    out.fast = t_of(pd.concat(fast, ignore_index=True))
    bb, tt, gg, _ = part((25,))
    lt.append(d.decode_long_term(bb, tt, gg, (14, 120)))
    out.long_term = pd.concat(lt, ignore_index=True)
    bb, tt, gg, _ = part((6,))
    out.integrity = t_of(d.decode_mt6(bb, tt, gg))
    bb, tt, gg, _ = part((7,))
    out.degradation = d.decode_mt7(bb, tt, gg)
    bb, tt, gg, _ = part((10,))
    out.mt10 = d.decode_mt10(bb, tt, gg)
    bb, tt, gg, _ = part((18,))
    out.igp_mask = d.decode_mt18(bb, tt, gg)
    bb, tt, gg, _ = part((26,))
    out.iono = d.decode_mt26(bb, tt, gg)
    out.mt0 = pd.DataFrame({"t_rx": t[mt == 0], "geo": geo[mt == 0]})
    for name, k, fn in (
        ("geo_nav", 9, d.decode_mt9), ("network_time", 12, d.decode_mt12), ("almanacs", 17, d.decode_mt17),
        ("service", 27, d.decode_mt27), ("covariance", 28, d.decode_mt28),
    ):  # fmt: skip
        if (mt == k).any():
            bb, tt, gg, _ = part((k,))
            setattr(out, name, fn(bb, tt, gg))
