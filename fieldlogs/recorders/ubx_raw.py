"""UBX RXM-RAWX ↔ ``gnss_obs``, RXM-SFRBX ↔ ``gnss_nav`` (GPS and QZSS LNAV, ``lnav``) and SBAS
SFRBX (gnssId 1) → ``gnss_sbas``.

RAWX, vectorised: the 16-byte headers and the 32-byte measurement blocks of all frames
are gathered into two structured arrays. Epoch = week · 604800 + rcvTow (receiver time,
GPS scale). (gnssId, sigId) → RINEX 3 signal code by the u-blox signal table (GPS L1C/A →
C1C, L2CL → C2L, L2CM → C2S, L5I → C5I, L5Q → C5Q; Galileo E1C → C1C, E1B → C1B, E5aI/Q →
C5I/C5Q, E5bI/Q → C7I/C7Q; QZSS L1C/A → C1C, L1S → C1Z, L2CM → C2S, L2CL → C2L, L5I/Q →
C5I/C5Q; GLONASS L1OF → C1C, L2OF → C2C; BeiDou B1I → C2I, B2I → C7I, B1C → C1P, B2a → C5P;
SBAS L1 → C1C). trkStat: pseudorange kept when prValid, carrier when cpValid; ``lli`` bit 0
when the lock time is 0 (a new lock), bit 1 when the half-cycle ambiguity is unresolved.
C/N0 is whole dB-Hz, Doppler single precision: the round-trip resolution.

SFRBX: GPS and QZSS L1 C/A subframes (10 words) are assembled per satellite into an
ephemeris when subframes 1, 2 and 3 agree on IODC/IODE (``lnav.assemble``); Galileo I/NAV
pages (8 words) when word types 1–4 share their IODnav and word type 5 has come
(``inav.assemble``, CRC-24Q checked); repeats of an ephemeris already decoded are dropped.
GPS (QZSS) subframe 4 page 18 gives the ``gnss`` block: Klobuchar α/β
(``qzss_klobuchar_*``), ΔtLS → ``leap_seconds`` and A0, A1, tot, WNt → a GPUT
``time_corrections`` entry (``lnav.decode_iono_utc``); Galileo word type 5 its NeQuick
ai0–ai2. GLONASS strings, BeiDou D1/D2, the almanac pages and the other Galileo word types
are counted as skipped (not decoded).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from fieldlogs.recorders import inav, lnav
from fieldlogs.recorders.common import Decoded
from fieldlogs.recorders.rinex_obs import OBS_COLUMNS
from schemas.gnss import GNSS_NAV

if TYPE_CHECKING:
    from fieldlogs.recorders.ubx_frames import Frames

RAWX_HEAD = np.dtype(
    [
        ("rcvTow", "<f8"),
        ("week", "<u2"),
        ("leapS", "i1"),
        ("numMeas", "u1"),
        ("recStat", "u1"),
        ("version", "u1"),
        ("reserved1", "u1", 2),
    ]
)
RAWX_MEAS = np.dtype(
    [
        ("prMes", "<f8"),
        ("cpMes", "<f8"),
        ("doMes", "<f4"),
        ("gnssId", "u1"),
        ("svId", "u1"),
        ("sigId", "u1"),
        ("freqId", "u1"),
        ("locktime", "<u2"),
        ("cno", "u1"),
        ("prStdev", "u1"),
        ("cpStdev", "u1"),
        ("doStdev", "u1"),
        ("trkStat", "u1"),
        ("reserved2", "u1"),
    ]
)
SFRBX_HEAD = np.dtype(
    [
        ("gnssId", "u1"),
        ("svId", "u1"),
        ("sigId", "u1"),
        ("freqId", "u1"),
        ("numWords", "u1"),
        ("chn", "u1"),
        ("version", "u1"),
        ("reserved0", "u1"),
    ]
)
#: u-blox gnssId → RINEX system letter.
GNSS_LETTER = {0: "G", 1: "S", 2: "E", 3: "C", 5: "J", 6: "R", 7: "I"}
LETTER_GNSS = {v: k for k, v in GNSS_LETTER.items()}
#: (gnssId, sigId) → RINEX band + attribute.
SIGNALS = {
    (0, 0): "1C",
    (0, 3): "2L",
    (0, 4): "2S",
    (0, 6): "5I",
    (0, 7): "5Q",
    (1, 0): "1C",
    (2, 0): "1C",
    (2, 1): "1B",
    (2, 3): "5I",
    (2, 4): "5Q",
    (2, 5): "7I",
    (2, 6): "7Q",
    (3, 0): "2I",
    (3, 2): "7I",
    (3, 5): "1P",
    (3, 7): "5P",
    (5, 0): "1C",
    (5, 1): "1Z",
    (5, 4): "2S",
    (5, 5): "2L",
    (5, 8): "5I",
    (5, 9): "5Q",
    (6, 0): "1C",
    (6, 2): "2C",
    (7, 0): "5A",
}
SIGID = {(g, "C" + code): s for (g, s), code in SIGNALS.items()}


def _sat_names(gnss: np.ndarray, sv: np.ndarray) -> np.ndarray:
    num = np.where(gnss == 1, sv - 100, sv)  # SBAS PRN 120… → S20…
    letters = np.array([GNSS_LETTER.get(int(g), "?") for g in range(8)], dtype=object)[np.minimum(gnss, 7)]
    return np.char.add(letters.astype(str), np.char.zfill(num.astype(str), 2)).astype(object)


def read_rawx(path: Path, f: Frames, dec: Decoded, receiver: str) -> int | None:
    """RAWX → dec.frames['gnss_obs']; returns the first epoch's GPS week (or None)."""
    idx = f.of((0x02, 0x15))
    if not len(idx):
        return None
    head = f.fixed(idx, RAWX_HEAD)
    n = head["numMeas"].astype(np.int64)
    short = idx[f.length[idx] < 16 + 32 * n]
    if len(short):
        from schemas.errors import InputError

        raise InputError(f"RXM-RAWX frame at byte {int(f.start[short[0]])} is shorter than its numMeas", path=path)
    owner = np.repeat(np.arange(len(idx)), n)
    k = np.arange(len(owner)) - np.repeat(np.cumsum(n) - n, n)
    pos = f.start[idx][owner] + 6 + 16 + 32 * k
    m = np.ascontiguousarray(f.data[pos[:, None] + np.arange(32)[None, :]]).view(RAWX_MEAS).ravel()
    gnss, sig = m["gnssId"].astype(np.int64), m["sigId"].astype(np.int64)
    code = pd.Series(list(zip(gnss.tolist(), sig.tolist(), strict=True)), dtype=object).map(SIGNALS)
    known = code.notna().to_numpy() & ~((gnss == 6) & (m["svId"] == 255))
    if (~known).any():
        dec.skipped["RAWX measurements of an unknown signal or satellite"] += int((~known).sum())
    trk = m["trkStat"].astype(np.int64)
    obs = pd.DataFrame(
        {
            "gnss_time_s": (head["week"].astype(np.float64) * 604_800.0 + head["rcvTow"])[owner],
            "receiver": receiver,
            "sat": _sat_names(gnss, m["svId"].astype(np.int64)),
            "signal": "C" + code.fillna("").astype(str),
            "pseudorange_m": np.where(trk & 1, m["prMes"], np.nan),
            "carrier_cycles": np.where(trk & 2, m["cpMes"], np.nan),
            "doppler_hz": m["doMes"].astype(np.float64),
            "cn0_dbhz": m["cno"].astype(np.float64),
            "lli": pd.array(
                (np.where(m["locktime"] == 0, 1, 0) | np.where(((trk & 2) > 0) & ((trk & 4) == 0), 2, 0)).astype(
                    np.int64
                ),
                dtype="Int64",
            ),
        }
    )[known]
    dec.frames["gnss_obs"] = (
        obs[OBS_COLUMNS].sort_values(["gnss_time_s", "sat", "signal"], kind="stable").reset_index(drop=True)
    )
    return int(head["week"][0])


def _skip_reason(gnss: int, words: int) -> str:
    names = {
        2: "Galileo pages of other than 8 words (F/NAV)",
        6: "GLONASS strings",
        3: "BeiDou D1/D2 subframes",
        1: "SBAS messages",
    }
    return (
        f"SFRBX {names.get(gnss, f'gnssId {gnss} messages')} not decoded"
        if gnss not in (0, 5)
        else (f"SFRBX GPS/QZSS frames of {words} words (not L1 C/A LNAV)")
    )


def _other_subframe(dec: Decoded, gnss: int, sf: int, words: list[int], week_hint: int | None) -> None:
    """Subframe 4 page 18 → the ``gnss`` block (first one kept); others counted as skipped."""
    iono = lnav.decode_iono_utc(words, week_hint) if sf == 4 and week_hint is not None else None
    if iono is None:
        reason = "SFRBX LNAV almanac subframes not decoded" if sf in (4, 5) else "SFRBX words without a preamble"
        dec.skipped[reason] += 1
        return
    prefix = "qzss_" if gnss == 5 else ""
    dec.gnss.setdefault(f"{prefix}klobuchar_alpha", iono["alpha"])
    dec.gnss.setdefault(f"{prefix}klobuchar_beta", iono["beta"])
    if gnss == 0:
        dec.gnss.setdefault("leap_seconds", iono["leap_seconds"])
        dec.gnss.setdefault("time_corrections", [{"type": "GPUT", **iono["correction"]}])


def _lnav(
    cur: dict[int, dict[str, float]], words: list[int], sf: int, sat: str, week_hint: int | None
) -> dict[str, Any] | None:
    """Keep subframe ``sf``; the ephemeris once subframes 1–3 agree on IODC/IODE."""
    cur[sf] = lnav.decode_subframe(words)
    if week_hint is None or not all(k in cur for k in (1, 2, 3)):
        return None
    s1, s2, s3 = cur[1], cur[2], cur[3]
    if int(s1["IODC"]) & 0xFF == int(s2["IODE"]) == int(s3["IODE3"]):
        return {"sat": sat, **lnav.assemble(s1, s2, s3, week_hint)}
    return None


def _inav(
    dec: Decoded, cur: dict[int, dict[str, float]], words: list[int], sat: str, sig: int
) -> dict[str, Any] | None:
    """Keep a Galileo word; the ephemeris once word types 1–5 are there (``inav.assemble``)."""
    got = inav.word_of_page(words)
    if got is None or got[0] not in (1, 2, 3, 4, 5):
        dec.skipped["SFRBX Galileo pages not decoded (alert, CRC, word types 0, 6-10)"] += 1
        return None
    cur[got[0]] = inav.decode_word(got[1])
    if got[0] == 5:
        dec.gnss.setdefault("nequick_ai", [cur[5]["ai0"], cur[5]["ai1"], cur[5]["ai2"]])
    eph = inav.assemble(cur, e5b=sig == 5) if got[0] == 5 else None
    return None if eph is None else {"sat": sat, **eph}


def read_sfrbx(path: Path, f: Frames, dec: Decoded, week_hint: int | None) -> None:
    """SFRBX → dec.frames['gnss_nav'] (GPS, QZSS LNAV; Galileo I/NAV)."""
    idx = f.of((0x02, 0x13))
    if not len(idx):
        return
    head = f.fixed(idx, SFRBX_HEAD)
    last: dict[str, dict[int, dict[str, float]]] = {}
    rows: dict[tuple[str, float, float], dict[str, Any]] = {}
    sbas: list[tuple[int, int, list[int]]] = []
    for i, h in zip(idx.tolist(), head.tolist(), strict=True):
        gnss, sv, sig, nwords = int(h[0]), int(h[1]), int(h[2]), int(h[4])
        sat = f"{GNSS_LETTER.get(gnss, '?')}{sv:02d}"
        if gnss == 2 and nwords == 8:
            words = np.frombuffer(f.payload(i)[8 : 8 + 32], dtype="<u4").tolist()
            eph = _inav(dec, last.setdefault(sat, {}), words, sat, sig)
        elif gnss == 1 and nwords == 8:
            sbas.append((i, sv, np.frombuffer(f.payload(i)[8 : 8 + 32], dtype="<u4").tolist()))
            continue
        elif gnss in (0, 5) and nwords == 10:
            words = np.frombuffer(f.payload(i)[8 : 8 + 40], dtype="<u4").tolist()
            sf = lnav.subframe_id(words)
            if sf not in (1, 2, 3):
                _other_subframe(dec, gnss, sf, words, week_hint)
                continue
            eph = _lnav(last.setdefault(sat, {}), words, sf, sat, week_hint)
        else:
            dec.skipped[_skip_reason(gnss, nwords)] += 1
            continue
        if eph is not None:
            rows.setdefault((sat, eph["toc_gps_s"], eph["IODE"]), eph)
    if sbas:
        _sbas_frame(f, sbas, dec)
    cols = GNSS_NAV.column_names
    frame = pd.DataFrame(list(rows.values()), columns=cols) if rows else pd.DataFrame(columns=cols)
    frame = frame.astype({c: "float64" for c in cols if c != "sat"})
    if len(frame):
        dec.frames["gnss_nav"] = frame.sort_values(["sat", "toc_gps_s"], kind="stable").reset_index(drop=True)


def _sbas_frame(f: Frames, found: list[tuple[int, int, list[int]]], dec: Decoded) -> None:
    """SBAS SFRBX (gnssId 1, eight words: the 250 bits MSB first) → dec.frames['gnss_sbas'].

    SFRBX carries no time: a frame is timed by the first RXM-RAWX epoch after it in the file.
    The receiver sends a message once it has received it, before the epoch that follows, so
    that epoch's time is an upper bound of the reception (a correction is never used before it
    was received). With 1 Hz epochs on whole seconds a message of time of applicability T,
    received at T + 1.12…1.14 s, gets the epoch T + 2 s and ``messages``' t_of = ⌊t − 1.1⌋ = T
    (the epoch before, T + 1 s, would give T − 1). Frames after the last epoch are skipped and
    counted. Screening and decoding are ``fieldlogs.gnss.sbas``'s."""
    rawx = f.of((0x02, 0x15))
    if not len(rawx):
        dec.skipped["SFRBX SBAS messages without an RXM-RAWX epoch to time them"] += len(found)
        return
    head = f.fixed(rawx, RAWX_HEAD)
    t_ep = head["week"].astype(np.float64) * 604_800.0 + head["rcvTow"]
    at = np.searchsorted(rawx, [i for i, _, _ in found], side="right")
    late = at >= len(rawx)
    if late.any():
        dec.skipped["SFRBX SBAS messages after the last RXM-RAWX epoch (no epoch to time them)"] += int(late.sum())
    keep = [x for x, bad in zip(found, late.tolist(), strict=True) if not bad]
    if not keep:
        return
    hexes = [np.array(w, dtype=">u4").tobytes().hex().upper() for _, _, w in keep]
    dec.frames["gnss_sbas"] = pd.DataFrame(
        {
            "gnss_time_s": t_ep[at[~late]],
            "prn": np.array([sv for _, sv, _ in keep], dtype=np.int64),
            "msg_type": np.array([(w[0] >> 18) & 0x3F for _, _, w in keep], dtype=np.int64),
            "message_hex": hexes,
            "valid": pd.array([None] * len(keep), dtype="Int64"),
        }
    )


# ---------------------------------------------------------------------------------------
# writers


def rawx_frames(obs: pd.DataFrame) -> list[tuple[float, bytes]]:
    """(GPS time, RXM-RAWX frame) per epoch of ``gnss_obs`` rows (one receiver)."""
    from fieldlogs.recorders.ubx_frames import frame

    out = []
    for t, g in obs.groupby("gnss_time_s", sort=True):
        gt = float(t)  # type: ignore[arg-type]
        head = np.zeros(1, dtype=RAWX_HEAD)
        head["rcvTow"] = gt % 604_800.0
        head["week"] = int(gt // 604_800.0)
        head["leapS"] = 18
        head["numMeas"] = len(g)
        head["version"] = 1
        meas = np.zeros(len(g), dtype=RAWX_MEAS)
        letters = g["sat"].str[0].to_numpy(dtype=object)
        gnss = np.array([LETTER_GNSS[x] for x in letters], dtype=np.int64)
        num = g["sat"].str[1:].astype(int).to_numpy()
        meas["gnssId"] = gnss
        meas["svId"] = np.where(gnss == 1, num + 100, num)
        meas["sigId"] = [SIGID[(int(a), str(b))] for a, b in zip(gnss, g["signal"], strict=True)]
        pr = g["pseudorange_m"].to_numpy(dtype=float, na_value=np.nan)
        cp = g["carrier_cycles"].to_numpy(dtype=float, na_value=np.nan)
        lli = g["lli"].to_numpy(dtype=float, na_value=0.0).astype(np.int64)
        meas["prMes"] = np.nan_to_num(pr)
        meas["cpMes"] = np.nan_to_num(cp)
        meas["doMes"] = np.nan_to_num(g["doppler_hz"].to_numpy(dtype=float, na_value=np.nan))
        meas["cno"] = np.round(np.nan_to_num(g["cn0_dbhz"].to_numpy(dtype=float, na_value=np.nan)))
        meas["locktime"] = np.where(lli & 1, 0, 64_500)
        meas["trkStat"] = np.isfinite(pr) * 1 | np.isfinite(cp) * 2 | np.where(lli & 2, 0, 4)
        out.append((gt, frame(0x02, 0x15, head.tobytes() + meas.tobytes())))
    return out


def _sfrbx(gnss: int, sv: int, words: list[int], sig: int = 0) -> bytes:
    from fieldlogs.recorders.ubx_frames import frame

    head = np.zeros(1, dtype=SFRBX_HEAD)
    head["gnssId"] = gnss
    head["svId"] = sv
    head["sigId"] = sig
    head["numWords"] = len(words)
    head["version"] = 2
    return frame(0x02, 0x13, head.tobytes() + np.array(words, dtype="<u4").tobytes())


def sbas_sfrbx_frames(sbas: pd.DataFrame) -> list[tuple[float, bytes]]:
    """(GPS time of reception, RXM-SFRBX frame) of each ``gnss_sbas`` row: gnssId 1, svId the
    SBAS PRN, the 64 hex digits as eight words (bits 250–255 zero). Written before any RXM-RAWX
    epoch of the same or a later time, the reader times it by that epoch (``_sbas_frame``)."""
    out = []
    for t, prn, hx in zip(sbas["gnss_time_s"], sbas["prn"], sbas["message_hex"], strict=True):
        words = np.frombuffer(bytes.fromhex(str(hx).ljust(64, "0")), dtype=">u4").astype(np.int64).tolist()
        out.append((float(t), _sfrbx(1, int(prn), words)))
    return out


def iono_frames(gnss_block: dict[str, Any], t_gps: float) -> list[tuple[float, bytes]]:
    """Subframe 4 page 18 (GPS) from run.json's ``gnss`` block, sent at ``t_gps``."""
    need = ("klobuchar_alpha", "klobuchar_beta", "leap_seconds", "time_corrections")
    if not all(k in gnss_block for k in need):
        return []
    corr = next((c for c in gnss_block["time_corrections"] if c.get("type") == "GPUT"), None)
    if corr is None:
        return []
    tow6 = round((t_gps % 604_800.0) / 6.0) + 1
    words = lnav.encode_iono_utc(
        list(gnss_block["klobuchar_alpha"]),
        list(gnss_block["klobuchar_beta"]),
        int(gnss_block["leap_seconds"]),
        corr,
        tow6,
    )
    return [(t_gps, _sfrbx(0, 1, words))]


def sfrbx_frames(nav: pd.DataFrame, ai: list[float] | None = None) -> list[tuple[float, bytes]]:
    """(GPS time of transmission, RXM-SFRBX frame): subframes 1–3 of each G/J ephemeris,
    I/NAV word types 1–5 of each E one (``ai``: NeQuick ai0–ai2 for word type 5)."""
    out = []
    for r in nav.to_dict("records"):
        sat = str(r["sat"])
        eph = {str(k): v for k, v in r.items()}
        t0 = float(r["week"]) * 604_800.0 + float(r["TransTime"])
        if sat[0] in ("G", "J"):  # subframe 1 starts at TransTime, 6 s each
            pages, offsets, sig = lnav.encode(eph), [0.0, 6.0, 12.0], 0
        elif sat[0] == "E":  # word type 5 (its TOW is TransTime) last, 2 s pages
            pages, offsets, sig = inav.encode(eph, ai), [-8.0, -6.0, -4.0, -2.0, 0.0], 1
        else:
            raise ValueError(f"the UBX writer encodes GPS/QZSS LNAV and Galileo I/NAV only, not {sat}")
        for dt, words in zip(offsets, pages, strict=True):
            out.append((t0 + dt, _sfrbx(LETTER_GNSS[sat[0]], int(sat[1:]), words, sig)))
    return out
