"""u-blox UBX binary → ``gps`` (NAV-PVT, NAV-HPPOSLLH, NAV-DOP), ``gnss_obs`` / ``gnss_nav``
(RXM-RAWX, RXM-SFRBX: ``ubx_raw``), ``imu`` / ``tacho`` (ESF-RAW, ESF-MEAS: ``ubx_esf``).

Framing. The usual file is a clean chain of frames from byte 0: walked by the length
fields, then all checksums verified at once with two ``reduceat`` sums. Any other file
takes the general path, vectorised: every ``B5 62`` is a candidate frame (class, id, little-endian length
L, payload, CK_A, CK_B); the 8-bit Fletcher checksum over class…payload of all candidates
at once from two wrapping prefix sums, ``CK_A = S1[b] − S1[a]`` and
``CK_B = b·(S1[b] − S1[a]) − (S2[b] − S2[a])`` (mod 256, with S2 the prefix sum of j·byte_j;
uint64 wrap-around keeps the residues mod 256). Frames are then chained from the start:
a candidate inside an accepted frame is payload; one with a bad checksum is skipped and
counted; bytes between frames (e.g. interleaved NMEA) are counted. A candidate whose
declared length runs past the end of the file, with no valid frame after it, is a
truncated file: refused, naming the byte offset. Payloads of one message type are
gathered into one array and decoded with numpy structured dtypes.

NAV-PVT: ``fix`` 2 (D-GPS) with diffSoln or an RTK carrier solution, 1 with gnssFixOK and
a 2-D/3-D/GNSS+DR fix, else 0 (latitude and longitude empty when fixType is 0); epoch =
GPS week (from the UTC date and the leap seconds) · 604800 + iTOW; frames without a valid
UTC date and time are skipped and counted. hAcc
and vAcc give the 1-σ sigmas (hAcc for both latitude and longitude). NAV-HPPOSLLH
replaces latitude, longitude and height of the NAV-PVT with the same iTOW by its
high-precision values; NAV-DOP gives the HDOP (empty where it is 99.99, "unknown").

pyubx2 parses frame by frame in Python; it is the independent reader of the round-trip
tests (``tests/fieldlogs/recorders``).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.recorders.common import Decoded, known_dop, read_bytes
from fieldlogs.recorders.timebase import calendar_to_utc_s, utc_to_gps
from fieldlogs.recorders.ubx_frames import SYNC, Frames, frame
from schemas.errors import InputError

NAV_PVT = (0x01, 0x07)
NAV_DOP = (0x01, 0x04)
NAV_HPPOSLLH = (0x01, 0x14)
RXM_RAWX = (0x02, 0x15)
RXM_SFRBX = (0x02, 0x13)
ESF_MEAS = (0x10, 0x02)
ESF_RAW = (0x10, 0x03)
NAMES = {
    NAV_PVT: "NAV-PVT",
    NAV_DOP: "NAV-DOP",
    NAV_HPPOSLLH: "NAV-HPPOSLLH",
    RXM_RAWX: "RXM-RAWX",
    RXM_SFRBX: "RXM-SFRBX",
    ESF_MEAS: "ESF-MEAS",
    ESF_RAW: "ESF-RAW",
}

PVT_DTYPE = np.dtype(
    [
        ("iTOW", "<u4"),
        ("year", "<u2"),
        ("month", "u1"),
        ("day", "u1"),
        ("hour", "u1"),
        ("min", "u1"),
        ("sec", "u1"),
        ("valid", "u1"),
        ("tAcc", "<u4"),
        ("nano", "<i4"),
        ("fixType", "u1"),
        ("flags", "u1"),
        ("flags2", "u1"),
        ("numSV", "u1"),
        ("lon", "<i4"),
        ("lat", "<i4"),
        ("height", "<i4"),
        ("hMSL", "<i4"),
        ("hAcc", "<u4"),
        ("vAcc", "<u4"),
        ("velN", "<i4"),
        ("velE", "<i4"),
        ("velD", "<i4"),
        ("gSpeed", "<i4"),
        ("headMot", "<i4"),
        ("sAcc", "<u4"),
        ("headAcc", "<u4"),
        ("pDOP", "<u2"),
        ("flags3", "<u2"),
        ("reserved0", "<u4"),
        ("headVeh", "<i4"),
        ("magDec", "<i2"),
        ("magAcc", "<u2"),
    ]
)
HPPOSLLH_DTYPE = np.dtype(
    [
        ("version", "u1"),
        ("reserved0", "u1", 2),
        ("flags", "u1"),
        ("iTOW", "<u4"),
        ("lon", "<i4"),
        ("lat", "<i4"),
        ("height", "<i4"),
        ("hMSL", "<i4"),
        ("lonHp", "i1"),
        ("latHp", "i1"),
        ("heightHp", "i1"),
        ("hMSLHp", "i1"),
        ("hAcc", "<u4"),
        ("vAcc", "<u4"),
    ]
)
DOP_DTYPE = np.dtype(
    [
        ("iTOW", "<u4"),
        ("gDOP", "<u2"),
        ("pDOP", "<u2"),
        ("tDOP", "<u2"),
        ("vDOP", "<u2"),
        ("hDOP", "<u2"),
        ("nDOP", "<u2"),
        ("eDOP", "<u2"),
    ]
)


def _candidates(arr: npt.NDArray[np.uint8]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(start, end, checksum ok) of every B5 62 in the file."""
    n = len(arr)
    if n < 8:
        return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0, bool)
    s = np.flatnonzero((arr[:-1] == 0xB5) & (arr[1:] == 0x62)).astype(np.int64)
    s = s[s + 6 <= n]
    length = arr[np.minimum(s + 4, n - 1)].astype(np.int64) | (arr[np.minimum(s + 5, n - 1)].astype(np.int64) << 8)
    end = s + 8 + length
    inside = end <= n
    b = arr.astype(np.uint64)
    s1 = np.concatenate(([0], np.cumsum(b, dtype=np.uint64))).astype(np.uint64)
    s2 = np.concatenate(([0], np.cumsum(b * np.arange(n, dtype=np.uint64), dtype=np.uint64))).astype(np.uint64)
    lo = (s + 2).astype(np.uint64)
    hi = np.where(inside, end - 2, s + 2).astype(np.uint64)
    with np.errstate(over="ignore"):
        a = s1[hi] - s1[lo]
        ck_b = hi * a - (s2[hi] - s2[lo])
    ck_a = (a & np.uint64(0xFF)).astype(np.int64)
    ck_b = (ck_b & np.uint64(0xFF)).astype(np.int64)
    ok = inside.copy()
    ok[inside] = (ck_a[inside] == arr[end[inside] - 2]) & (ck_b[inside] == arr[end[inside] - 1])
    return s, end, ok


def _chain(s: np.ndarray, end: np.ndarray, ok: np.ndarray, n: int) -> tuple[list[int], int, int, int | None]:
    """(accepted frame starts, stray bytes, bad checksums, start of a truncated last frame)."""
    starts: list[int] = []
    pos, stray, bad = 0, 0, 0
    trunc: int | None = None
    for a, b, good in zip(s.tolist(), end.tolist(), ok.tolist(), strict=True):
        if a < pos:
            continue
        if good:
            stray += a - pos
            starts.append(a)
            pos, trunc = b, None
        elif b > n:
            trunc = a if trunc is None else trunc
        else:
            bad += 1
    return starts, stray + (n - pos), bad, trunc


def _frame_checksums(arr: npt.NDArray[np.uint8], s: np.ndarray, end: np.ndarray) -> np.ndarray:
    """Checksum ok of non-overlapping frames [s, end): two ``reduceat`` passes, mod 256.

    CK_A = Σ b_j, CK_B = Σ (hi − j)·b_j = hi·CK_A − Σ (j mod 256)·b_j (mod 256) over
    j ∈ [s + 2, end − 2)."""
    n = len(arr)
    lo, hi = s + 2, end - 2
    idx = np.empty(2 * len(s), dtype=np.int64)
    idx[0::2], idx[1::2] = lo, hi
    idx = np.minimum(idx, n - 1)
    weights = np.tile(np.arange(256, dtype=np.uint16), n // 256 + 1)[:n] * arr  # (j mod 256)·b_j < 2^16
    a = np.add.reduceat(arr, idx, dtype=np.uint64)[0::2]
    w = np.add.reduceat(weights, idx, dtype=np.uint64)[0::2]
    empty = hi <= lo  # zero-length payload and no class/id: cannot happen (hi − lo ≥ 4)
    a[empty], w[empty] = 0, 0
    ck_a = a & np.uint64(0xFF)
    with np.errstate(over="ignore"):
        ck_b = (hi.astype(np.uint64) * a - w) & np.uint64(0xFF)
    ok: np.ndarray = (ck_a == arr[end - 2]) & (ck_b == arr[end - 1])
    return ok


def _fast_chain(arr: npt.NDArray[np.uint8]) -> list[int] | None:
    """Frame starts when the file is a clean chain of valid frames from byte 0 (the usual
    case), else None and the caller takes the general path."""
    n = len(arr)
    starts: list[int] = []
    pos = 0
    data = arr.tobytes()
    while pos + 8 <= n and data[pos : pos + 2] == SYNC:
        starts.append(pos)
        pos += 8 + (data[pos + 4] | (data[pos + 5] << 8))
    if pos != n or not starts:
        return None
    st = np.array(starts, dtype=np.int64)
    end = np.append(st[1:], n)
    return starts if bool(_frame_checksums(arr, st, end).all()) else None


def scan(path: Path, dec: Decoded) -> Frames:
    """Chain the valid frames; count bad checksums and stray bytes; refuse a truncated file."""
    arr = np.frombuffer(read_bytes(path), dtype=np.uint8)
    fast = _fast_chain(arr)
    if fast is not None:
        starts, stray, bad, trunc = fast, 0, 0, None
    else:
        s, end, ok = _candidates(arr)
        starts, stray, bad, trunc = _chain(s, end, ok, len(arr))
    if trunc is not None:
        declared = int(arr[trunc + 4]) | (int(arr[trunc + 5]) << 8)
        raise InputError(
            f"truncated UBX file: the frame at byte {trunc} declares {declared} payload "
            f"bytes, only {len(arr) - trunc - 8 if len(arr) > trunc + 8 else 0} are left",
            path=path,
            row=None,
        )
    if bad:
        dec.skipped["UBX frames with a bad checksum"] += bad
    if stray:
        dec.skipped["bytes outside valid UBX frames (NMEA, damaged frames)"] += stray
    st = np.array(starts, dtype=np.int64)
    if not len(st):
        raise InputError("no valid UBX frame (sync B5 62 with a good checksum)", path=path)
    cls = arr[st + 2].astype(np.int64)
    mid = arr[st + 3].astype(np.int64)
    length = arr[st + 4].astype(np.int64) | (arr[st + 5].astype(np.int64) << 8)
    dec.records = len(st)
    known = set(NAMES)
    pairs, counts = np.unique(cls * 256 + mid, return_counts=True)
    for cm, n in zip(pairs.tolist(), counts.tolist(), strict=True):
        c, m = divmod(int(cm), 256)
        if (c, m) not in known:
            dec.skipped[f"UBX message 0x{c:02X} 0x{m:02X} not imported"] += int(n)
    return Frames(arr, st, cls, mid, length)


def _check_length(path: Path, f: Frames, idx: np.ndarray, need: int, name: str) -> np.ndarray:
    short = idx[f.length[idx] < need]
    if len(short):
        raise InputError(
            f"{name} frame at byte {int(f.start[short[0]])} has {int(f.length[short[0]])} payload bytes, "
            f"{need} expected",
            path=path,
        )
    return idx


def _pvt(path: Path, f: Frames, dec: Decoded) -> pd.DataFrame | None:
    idx = f.of(NAV_PVT)
    if not len(idx):
        return None
    r = f.fixed(_check_length(path, f, idx, PVT_DTYPE.itemsize, "NAV-PVT"), PVT_DTYPE)
    valid = (r["valid"] & 0x3) == 0x3
    if (~valid).any():
        dec.skipped["NAV-PVT without a valid UTC date and time"] += int((~valid).sum())
    r = r[valid]
    offset = f.start[idx][valid]
    utc = calendar_to_utc_s(r["year"], r["month"], r["day"], r["hour"] * 3600.0 + r["min"] * 60.0 + r["sec"])
    utc = utc + r["nano"] * 1e-9
    tow = r["iTOW"] / 1000.0
    week = np.round((utc_to_gps(utc) - tow) / 604_800.0)
    flags = r["flags"].astype(np.int64)
    fix_ok = (flags & 1).astype(bool) & np.isin(r["fixType"], [2, 3, 4])
    diff = ((flags & 2) > 0) | ((flags >> 6) & 3 > 0)
    no_fix = r["fixType"] == 0  # no position at all (dead reckoning, fixType 1, keeps its estimate)
    return pd.DataFrame(
        {
            "itow": r["iTOW"].astype(np.int64),
            "offset": offset,
            "gnss_time_s": week * 604_800.0 + tow,
            "lat": np.where(no_fix, np.nan, r["lat"] * 1e-7),
            "lon": np.where(no_fix, np.nan, r["lon"] * 1e-7),
            "fix": np.where(fix_ok, np.where(diff, 2, 1), 0).astype(np.int64),
            "nsat": r["numSV"].astype(np.int64),
            "hdop": np.full(len(r), np.nan),
            "height_m": r["height"] * 1e-3,
            "speed_mps": r["gSpeed"] * 1e-3,
            "course_deg": r["headMot"] * 1e-5,
            "sigma_lat_m": r["hAcc"] * 1e-3,
            "sigma_lon_m": r["hAcc"] * 1e-3,
            "sigma_height_m": r["vAcc"] * 1e-3,
        }
    )


def _refine(path: Path, f: Frames, gps: pd.DataFrame) -> pd.DataFrame:
    idx = f.of(NAV_HPPOSLLH)
    if len(idx):
        h = f.fixed(_check_length(path, f, idx, HPPOSLLH_DTYPE.itemsize, "NAV-HPPOSLLH"), HPPOSLLH_DTYPE)
        h = h[(h["flags"] & 1) == 0]
        hp = pd.DataFrame(
            {
                "itow": h["iTOW"].astype(np.int64),
                "lat_hp": h["lat"] * 1e-7 + h["latHp"] * 1e-9,
                "lon_hp": h["lon"] * 1e-7 + h["lonHp"] * 1e-9,
                "h_hp": h["height"] * 1e-3 + h["heightHp"] * 1e-4,
            }
        ).drop_duplicates("itow", keep="last")
        m = gps[["itow"]].merge(hp, on="itow", how="left")
        has = m["lat_hp"].notna().to_numpy()
        gps.loc[has, "lat"] = m.loc[has, "lat_hp"].to_numpy()
        gps.loc[has, "lon"] = m.loc[has, "lon_hp"].to_numpy()
        gps.loc[has, "height_m"] = m.loc[has, "h_hp"].to_numpy()
    idx = f.of(NAV_DOP)
    if len(idx):
        d = f.fixed(_check_length(path, f, idx, DOP_DTYPE.itemsize, "NAV-DOP"), DOP_DTYPE)
        dop = pd.DataFrame({"itow": d["iTOW"].astype(np.int64), "h": d["hDOP"] * 0.01}).drop_duplicates("itow")
        m = gps[["itow"]].merge(dop, on="itow", how="left")
        gps["hdop"] = known_dop(m["h"].to_numpy())
    return gps


def _rawx_epochs(f: Frames) -> tuple[np.ndarray, np.ndarray]:
    from fieldlogs.recorders.ubx_raw import RAWX_HEAD

    idx = f.of(RXM_RAWX)
    head = f.fixed(idx, RAWX_HEAD)
    return f.start[idx], head["week"].astype(np.float64) * 604_800.0 + head["rcvTow"]


def read_ubx(path: Path) -> Decoded:
    """A UBX file → gps, gnss_obs, gnss_nav, imu, tacho (those it holds)."""
    from fieldlogs.recorders.ubx_esf import read_esf
    from fieldlogs.recorders.ubx_raw import read_rawx, read_sfrbx

    path = Path(path)
    dec = Decoded(str(path), "ubx")
    f = scan(path, dec)
    receiver = path.name.split(".")[0]
    gps = _pvt(path, f, dec)
    epochs: tuple[np.ndarray, np.ndarray] | None = None
    if gps is not None:
        gps = _refine(path, f, gps)
        epochs = gps["offset"].to_numpy(), gps["gnss_time_s"].to_numpy()
        dec.frames["gps"] = (
            gps.drop(columns=["itow", "offset"]).sort_values("gnss_time_s", kind="stable").reset_index(drop=True)
        )
    week_hint = read_rawx(path, f, dec, receiver)
    if epochs is None and "gnss_obs" in dec.frames:
        epochs = _rawx_epochs(f)
    if week_hint is None and gps is not None and len(gps):
        week_hint = int(gps["gnss_time_s"].iloc[0] // 604_800)
    read_sfrbx(path, f, dec, week_hint)
    read_esf(path, f, dec, epochs)
    if not dec.frames:
        raise InputError(
            "no UBX message that logs import reads (NAV-PVT, RXM-RAWX, RXM-SFRBX, ESF-RAW, ESF-MEAS)", path=path
        )
    return dec


# ---------------------------------------------------------------------------------------
# writer


def pvt_frames(gps: pd.DataFrame) -> Iterable[tuple[float, bytes]]:
    """(GPS time, frames) of NAV-PVT + NAV-HPPOSLLH + NAV-DOP for every gps row (with ``gnss_time_s``)."""
    from fieldlogs.recorders.timebase import gps_to_utc

    for r in gps.to_dict("records"):
        g = float(r["gnss_time_s"])
        itow = round((g % 604_800.0) * 1000.0)
        utc = float(gps_to_utc(g))
        day = np.datetime64("1980-01-06") + np.timedelta64(int(utc // 86400), "D")
        y, mo, d = (int(x) for x in str(day).split("-"))
        sod = utc - (utc // 86400) * 86400
        whole = int(np.floor(sod + 1e-9))
        nano = round((sod - whole) * 1e9)
        fix = int(r["fix"])
        lat = float(r["lat"]) if pd.notna(r["lat"]) else 0.0
        lon = float(r["lon"]) if pd.notna(r["lon"]) else 0.0
        hgt = float(r.get("height_m", 0.0) or 0.0) if pd.notna(r.get("height_m", np.nan)) else 0.0
        rec = np.zeros(1, dtype=PVT_DTYPE)
        flags = (1 if fix >= 1 else 0) | (2 if fix == 2 else 0)
        lat_i, lon_i = int(np.floor(lat * 1e7)), int(np.floor(lon * 1e7))
        h_mm = int(np.floor(hgt * 1e3))
        sig_h = r.get("sigma_lat_m", np.nan)
        sig_v = r.get("sigma_height_m", np.nan)
        spd, crs = r.get("speed_mps", np.nan), r.get("course_deg", np.nan)
        vals = {
            "iTOW": itow,
            "year": y,
            "month": mo,
            "day": d,
            "hour": whole // 3600,
            "min": (whole % 3600) // 60,
            "sec": whole % 60,
            "valid": 0x7,
            "nano": nano,
            "fixType": 3 if fix else (1 if pd.notna(r["lat"]) else 0),  # a position without a fix: DR
            "flags": flags,
            "numSV": int(r["nsat"]),
            "lon": lon_i,
            "lat": lat_i,
            "height": h_mm,
            "hMSL": h_mm,
            "hAcc": round(sig_h * 1e3) if pd.notna(sig_h) else 0,
            "vAcc": round(sig_v * 1e3) if pd.notna(sig_v) else 0,
            "gSpeed": round(spd * 1e3) if pd.notna(spd) else 0,
            "headMot": round(crs * 1e5) if pd.notna(crs) else 0,
        }
        for k, v in vals.items():
            rec[k] = v
        hp = np.zeros(1, dtype=HPPOSLLH_DTYPE)
        for k, v in {
            "iTOW": itow,
            "lon": lon_i,
            "lat": lat_i,
            "height": h_mm,
            "hMSL": h_mm,
            "lonHp": round((lon * 1e7 - lon_i) * 100),
            "latHp": round((lat * 1e7 - lat_i) * 100),
            "heightHp": round((hgt * 1e3 - h_mm) * 10),
            "hMSLHp": round((hgt * 1e3 - h_mm) * 10),
            "flags": 0 if fix else 1,
        }.items():
            hp[k] = min(v, 99) if k.endswith("Hp") else v
        out = frame(*NAV_PVT, rec.tobytes()) + frame(*NAV_HPPOSLLH, hp.tobytes())
        if pd.notna(r.get("hdop", np.nan)):
            dop = np.zeros(1, dtype=DOP_DTYPE)
            dop["iTOW"] = itow
            dop["hDOP"] = round(float(r["hdop"]) * 100)
            out += frame(*NAV_DOP, dop.tobytes())
        yield g, out


def write_ubx(
    path: Path,
    *,
    gps: pd.DataFrame | None = None,
    obs: pd.DataFrame | None = None,
    nav: pd.DataFrame | None = None,
    imu: pd.DataFrame | None = None,
    tacho: pd.DataFrame | None = None,
    esf_drift: float = 0.0,
    gnss: dict[str, Any] | None = None,
    sbas: pd.DataFrame | None = None,
) -> int:
    """One UBX file from any of the frames (each with ``gnss_time_s``; ``nav`` G/J/E rows).

    Frames are written in time order; at equal times sensor data come before the epoch's
    NAV-PVT, as the reader's clock pairing expects. ESF time tags are ms of a recorder
    clock started at the first GNSS time and running ``1 + esf_drift`` times GNSS time.
    ``gnss`` (run.json's block: Klobuchar α/β, leap seconds, a GPUT correction) is sent as
    GPS subframe 4 page 18 at the first epoch. ``sbas`` (``gnss_sbas`` rows) become RXM-SFRBX
    frames of gnssId 1, each before the epochs of its time (the reader times an SBAS frame by
    the next RXM-RAWX epoch: ``ubx_raw._sbas_frame``).
    Returns the number of frames; the caller writes atomically."""
    from fieldlogs.recorders.ubx_esf import esf_frames
    from fieldlogs.recorders.ubx_raw import iono_frames, rawx_frames, sbas_sfrbx_frames, sfrbx_frames

    items: list[tuple[float, int, bytes]] = []
    starts = [float(x["gnss_time_s"].min()) for x in (gps, obs, imu, tacho) if x is not None and len(x)]
    if gps is not None and len(gps):
        items += [(g, 2, b) for g, b in pvt_frames(gps)]
    if obs is not None and len(obs):
        items += [(g, 3, b) for g, b in rawx_frames(obs)]
    if nav is not None and len(nav):
        ai = list((gnss or {}).get("nequick_ai", [0.0, 0.0, 0.0]))
        items += [(g, 4, b) for g, b in sfrbx_frames(nav, ai)]
    if gnss and starts:
        items += [(g, 4, b) for g, b in iono_frames(gnss, min(starts))]
    if sbas is not None and len(sbas):
        items += [(g, 0, b) for g, b in sbas_sfrbx_frames(sbas)]
    if starts and ((imu is not None and len(imu)) or (tacho is not None and len(tacho))):
        items += [(g, 1, b) for g, b in esf_frames(imu, tacho, t_ref_gps=min(starts), drift=esf_drift)]
    items.sort(key=lambda x: (x[0], x[1]))
    Path(path).write_bytes(b"".join(b for _, _, b in items))
    return len(items)
