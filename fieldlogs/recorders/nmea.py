"""NMEA 0183 → ``gps`` (GGA, RMC, GST, GSA, VTG; talkers GP, GN, QZ, GA, GL, GB, BD).

Vectorised over the whole file: the checksum (XOR of the bytes between ``$`` and ``*``)
comes from one prefix-XOR of the file, ``x(a..b) = P[b+1] ⊕ P[a]``; fields are split per
sentence type with pandas. Sentences with a bad or missing checksum, unknown types and
sentences before the first timed one are skipped and counted, never imported.

Epochs: a GGA, RMC or GST carries the UTC time of day; GSA and VTG belong to the epoch of
the last timed sentence before them. The date comes from RMC; a time of day more than
12 h earlier than the previous one is a midnight roll-over (next day); any other step
back is refused (sentences out of order). Two talkers giving GGA (or RMC) for one epoch
are refused (two receivers in one file?). UTC → GPS time with the leap seconds
(``timebase``).

``fix`` (SPEC §4): GGA quality 1 and 3 → 1 (GPS); 2 (DGPS), 4 (RTK fixed), 5 (RTK float)
→ 2; 0, 6 (dead reckoning), 7 (manual), 8 (simulator) → 0. Without GGA: RMC status A → 1,
with mode D/R/F → 2. ``nsat`` and ``hdop`` from GGA, else from the epoch's GSA sentences
(satellites used, summed over the systems; HDOP, empty where the receiver writes 99.99
for "unknown"). GST's 1-σ latitude, longitude and height
errors are kept (``sigma_*_m``), as are the GGA ellipsoidal height (altitude + geoid
separation), RMC/VTG speed and course.

pynmea2 parses the same sentences one at a time in Python (``bench/bench_import.py``
prints both throughputs); it is the independent reader of the writer's round-trip tests.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.recorders.common import Decoded, known_dop, read_bytes
from fieldlogs.recorders.timebase import calendar_to_utc_s, gps_to_utc, utc_to_gps
from schemas.errors import InputError

KNOT_MPS = 1852.0 / 3600.0
KMH_MPS = 1000.0 / 3600.0
TALKERS = ("GP", "GN", "QZ", "GA", "GL", "GB", "BD")
TYPES = ("GGA", "RMC", "GST", "GSA", "VTG")
#: GGA quality → SPEC fix (0 none, 1 GPS, 2 D-GPS).
GGA_FIX = {0: 0, 1: 1, 2: 2, 3: 1, 4: 2, 5: 2, 6: 0, 7: 0, 8: 0}
_GGA_FIX = np.array([GGA_FIX[k] for k in range(9)], dtype=np.float64)
_HEX = np.full(256, -1, dtype=np.int16)
for _i, _c in enumerate(b"0123456789ABCDEF"):
    _HEX[_c] = _i
for _i, _c in enumerate(b"abcdef"):
    _HEX[_c] = 10 + _i
HALF_DAY_S = 43_200.0


def _lines(data: bytes) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], npt.NDArray[np.uint8]]:
    arr = np.frombuffer(data, dtype=np.uint8)
    nl = np.flatnonzero(arr == 10)
    starts = np.concatenate(([0], nl + 1)).astype(np.int64)
    ends = np.concatenate((nl, [len(arr)])).astype(np.int64)
    keep = ends > starts
    starts, ends = starts[keep], ends[keep]
    # strip trailing CR / spaces (one pass is enough for CRLF files)
    while True:
        last = arr[np.maximum(ends - 1, 0)]
        trim = (ends > starts) & ((last == 13) | (last == 32))
        if not trim.any():
            break
        ends = ends - trim
    return starts, ends, arr


def _checksums(starts: np.ndarray, ends: np.ndarray, arr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(ok mask, reason code per line, '*' position): 0 ok, 1 not a sentence, 2 no checksum, 3 bad checksum."""
    n = len(starts)
    reason = np.zeros(n, dtype=np.int8)
    first = arr[np.minimum(starts, len(arr) - 1)] if len(arr) else np.zeros(n, dtype=np.uint8)
    reason[first != ord("$")] = 1
    stars = np.flatnonzero(arr == ord("*"))
    idx = np.searchsorted(stars, ends) - 1
    star = np.where(idx >= 0, stars[np.maximum(idx, 0)] if len(stars) else -1, -1)
    has = (star > starts) & (star + 3 == ends)  # exactly two hex digits after '*'
    reason[(reason == 0) & ~has] = 2
    px = np.concatenate(([0], np.bitwise_xor.accumulate(arr))).astype(np.uint8) if len(arr) else np.zeros(1, np.uint8)
    s = np.where(has, star, starts + 1)
    calc = px[np.clip(s, 0, len(px) - 1)] ^ px[np.clip(starts + 1, 0, len(px) - 1)]
    hi = _HEX[arr[np.clip(star + 1, 0, len(arr) - 1)]] if len(arr) else np.zeros(n, np.int16)
    lo = _HEX[arr[np.clip(star + 2, 0, len(arr) - 1)]] if len(arr) else np.zeros(n, np.int16)
    given = hi * 16 + lo
    bad = has & ((hi < 0) | (lo < 0) | (given != calc))
    reason[(reason == 0) & bad] = 3
    return reason == 0, reason, star


def _num(col: pd.Series) -> np.ndarray:
    return pd.to_numeric(col, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)


def _tod(col: pd.Series) -> np.ndarray:
    """hhmmss.ss → seconds of the day (NaN when blank or malformed)."""
    v = _num(col)
    hh = np.floor(v / 10000.0)
    mm = np.floor((v - hh * 10000.0) / 100.0)
    ss = v - hh * 10000.0 - mm * 100.0
    bad = (hh > 23) | (mm > 59) | (ss >= 61)
    return np.where(bad, np.nan, hh * 3600.0 + mm * 60.0 + ss)


def _angle(value: pd.Series, hemi: pd.Series, neg: str) -> np.ndarray:
    """ddmm.mmmm + N/S (dddmm.mmmm + E/W) → signed degrees."""
    v = _num(value)
    deg = np.floor(v / 100.0)
    out = deg + (v - deg * 100.0) / 60.0
    return np.where(hemi.to_numpy(dtype=object) == neg, -out, out)


def _fields(bodies: pd.Series, n: int) -> pd.DataFrame:
    parts = bodies.str.split(",", expand=True, n=n)
    for k in range(parts.shape[1], n + 1):
        parts[k] = None
    return parts


class _Sentences:
    """The valid sentences of a file: body text, talker, type, file line and byte order."""

    def __init__(self, path: Path, dec: Decoded) -> None:
        starts, ends, arr = _lines(read_bytes(path))
        ok, reason, star = _checksums(starts, ends, arr)
        dec.records = len(starts)
        for code, why in ((1, "not an NMEA sentence"), (2, "no checksum"), (3, "bad checksum")):
            n = int((reason == code).sum())
            if n:
                dec.skipped[why] += n
        data = arr.tobytes()
        idx = np.flatnonzero(ok)
        self.line = idx + 1
        body = [data[a + 1 : b].decode("ascii", "replace") for a, b in zip(starts[idx], star[idx], strict=True)]
        self.body = pd.Series(body, dtype=object)
        self.talker = self.body.str[:2]
        self.type = self.body.str[2:5]
        known = self.type.isin(TYPES).to_numpy() & self.talker.isin(TALKERS).to_numpy()
        for t, n in self.body[~known].str.split(",").str[0].value_counts().items():
            dec.skipped[f"sentence {t} not imported"] += int(n)
        self.known = known

    def of(self, kind: str) -> np.ndarray:
        return np.flatnonzero(self.known & (self.type == kind).to_numpy())


def _epochs(path: Path, s: _Sentences, dec: Decoded) -> tuple[np.ndarray, np.ndarray, dict[str, pd.DataFrame]]:
    """Per valid sentence its epoch number (−1 none); per epoch the time of day; parsed tables."""
    tables: dict[str, pd.DataFrame] = {}
    tod = np.full(len(s.body), np.nan)
    for kind, n in (("GGA", 15), ("RMC", 13), ("GST", 9), ("GSA", 19), ("VTG", 10)):
        i = s.of(kind)
        tables[kind] = _fields(s.body.iloc[i].reset_index(drop=True), n)
        tables[kind].index = i
        if kind in ("GGA", "RMC", "GST"):
            tod[i] = _tod(tables[kind][1])
    timed = np.flatnonzero(~np.isnan(tod))
    if not len(timed):
        raise InputError("no GGA, RMC or GST sentence with a valid time: nothing to import", path=path)
    tt = tod[timed]
    step = np.diff(tt)
    back = np.flatnonzero((step < 0) & (step > -HALF_DAY_S))
    if len(back):
        j = timed[back[0] + 1]
        raise InputError(
            f"sentences out of order: time {tt[back[0] + 1]:.2f} s of day is earlier than {tt[back[0]]:.2f} s "
            "on the line before",
            path=path,
            row=int(s.line[j]),
        )
    day = np.concatenate(([0], np.cumsum(step <= -HALF_DAY_S)))
    key = day * 86400.0 + tt
    new = np.concatenate(([True], np.diff(key) > 0))
    epoch_of_timed = np.cumsum(new) - 1
    epoch = np.full(len(s.body), -1, dtype=np.int64)
    pos = np.searchsorted(timed, np.arange(len(s.body)), side="right") - 1
    has = pos >= 0
    epoch[has] = epoch_of_timed[pos[has]]
    before = int((~has & s.known).sum())
    if before:
        dec.skipped["before the first timed sentence"] += before
    return epoch, key[new], tables


def _one_talker(path: Path, s: _Sentences, epoch: np.ndarray, kind: str) -> None:
    i = s.of(kind)
    if not len(i):
        return
    f = pd.DataFrame({"epoch": epoch[i], "talker": s.talker.iloc[i].to_numpy(), "line": s.line[i]})
    n = f.groupby("epoch")["talker"].nunique()
    mixed = n[n > 1]
    if len(mixed):
        rows = f[f["epoch"] == mixed.index[0]]
        talkers = "/".join(sorted(rows["talker"].unique()))
        raise InputError(
            f"mixed talkers: {talkers}{kind} both give the epoch of this line (two receivers in one file? "
            "split it and import each with its own receiver)",
            path=path,
            row=int(rows["line"].iloc[1]),
        )


def _dates(path: Path, rmc: pd.DataFrame, epoch: np.ndarray, key: np.ndarray, s: _Sentences) -> np.ndarray:
    """Days since 1980-01-06 (UTC) of each epoch, from the RMC dates."""
    if not len(rmc):
        raise InputError("no RMC sentence: the date of the fixes is unknown", path=path)
    d = _num(rmc[9])
    ok = ~np.isnan(d)
    if not ok.any():
        raise InputError("no RMC sentence with a date", path=path, row=int(s.line[rmc.index[0]]))
    i = rmc.index.to_numpy()[ok]
    dd = np.floor(d[ok] / 10000.0)
    mm = np.floor((d[ok] - dd * 10000.0) / 100.0)
    yy = d[ok] - dd * 10000.0 - mm * 100.0
    day0 = calendar_to_utc_s(2000 + yy, mm, dd, 0.0) / 86400.0  # two-digit years: 2000–2099
    ep = epoch[i]
    base = day0 - np.floor(key[ep] / 86400.0)
    if np.ptp(base) > 0:
        bad = int(np.flatnonzero(base != base[0])[0])
        raise InputError(
            "RMC date does not follow the earlier sentences' date and time", path=path, row=int(s.line[i[bad]])
        )
    return np.full(len(key), base[0]) + np.floor(key / 86400.0)


def _put(out: pd.DataFrame, name: str, epochs: np.ndarray, values: np.ndarray) -> None:
    col = out[name].to_numpy(dtype=np.float64, copy=True)
    fill = np.isnan(col[epochs]) if len(epochs) else np.zeros(0, dtype=bool)
    col[epochs[fill]] = values[fill]
    out[name] = col


def _gps_frame(tables: dict[str, pd.DataFrame], epoch: np.ndarray, n: int) -> pd.DataFrame:
    cols = (
        "lat",
        "lon",
        "fix",
        "nsat",
        "hdop",
        "height_m",
        "speed_mps",
        "course_deg",
        "sigma_lat_m",
        "sigma_lon_m",
        "sigma_height_m",
    )
    out = pd.DataFrame({c: np.full(n, np.nan) for c in cols})
    gga, rmc, gst, gsa, vtg = (tables[k] for k in ("GGA", "RMC", "GST", "GSA", "VTG"))
    if len(gga):
        e = epoch[gga.index.to_numpy()]
        q = _num(gga[6])
        _put(out, "lat", e, _angle(gga[2], gga[3], "S"))
        _put(out, "lon", e, _angle(gga[4], gga[5], "W"))
        qi = np.where(np.isfinite(q) & (q >= 0) & (q < len(_GGA_FIX)), q, 0).astype(np.int64)
        _put(out, "fix", e, _GGA_FIX[qi])
        _put(out, "nsat", e, _num(gga[7]))
        _put(out, "hdop", e, known_dop(_num(gga[8])))
        _put(out, "height_m", e, _num(gga[9]) + np.nan_to_num(_num(gga[11])))
    if len(rmc):
        e = epoch[rmc.index.to_numpy()]
        valid = rmc[2].to_numpy(dtype=object) == "A"
        mode = rmc[12].fillna("").astype(str).str[:1].to_numpy(dtype=object)
        lat, lon = _angle(rmc[3], rmc[4], "S"), _angle(rmc[5], rmc[6], "W")
        _put(out, "lat", e, np.where(valid, lat, np.nan))
        _put(out, "lon", e, np.where(valid, lon, np.nan))
        _put(out, "fix", e, np.where(valid, np.where(np.isin(mode, ["D", "R", "F"]), 2.0, 1.0), 0.0))
        _put(out, "speed_mps", e, _num(rmc[7]) * KNOT_MPS)
        _put(out, "course_deg", e, _num(rmc[8]))
    if len(vtg):
        e = epoch[vtg.index.to_numpy()]
        _put(out, "speed_mps", e, _num(vtg[7]) * KMH_MPS)
        _put(out, "course_deg", e, _num(vtg[1]))
    if len(gst):
        e = epoch[gst.index.to_numpy()]
        for k, name in ((6, "sigma_lat_m"), (7, "sigma_lon_m"), (8, "sigma_height_m")):
            _put(out, name, e, _num(gst[k]))
    if len(gsa):
        e = epoch[gsa.index.to_numpy()]
        prn = gsa[list(range(3, 15))]
        used = prn.notna() & (prn != "")
        per = pd.Series(used.sum(axis=1).to_numpy(), index=e).groupby(level=0).sum()
        _put(out, "nsat", per.index.to_numpy(), per.to_numpy(dtype=float))
        _put(out, "hdop", e, known_dop(_num(gsa[16])))
        fix3 = _num(gsa[2])
        _put(out, "fix", e, np.where(fix3 >= 2, 1.0, 0.0))
    out["fix"] = np.nan_to_num(out["fix"].to_numpy(), nan=0.0)
    out["nsat"] = np.nan_to_num(out["nsat"].to_numpy(), nan=0.0)
    return out


def read_nmea(path: Path) -> Decoded:
    """An NMEA file → ``gps`` with ``gnss_time_s``; InputError on out-of-order sentences,
    mixed talkers, a missing date or no timed sentence (file and line named)."""
    path = Path(path)
    dec = Decoded(str(path), "nmea")
    s = _Sentences(path, dec)
    epoch, key, tables = _epochs(path, s, dec)
    _one_talker(path, s, epoch, "GGA")
    _one_talker(path, s, epoch, "RMC")
    days = _dates(path, tables["RMC"], epoch, key, s)
    utc = days * 86400.0 + (key - np.floor(key / 86400.0) * 86400.0)
    gps = _gps_frame(tables, epoch, len(key))
    gps.insert(0, "gnss_time_s", utc_to_gps(utc))
    gps["fix"] = gps["fix"].astype(np.int64)
    gps["nsat"] = gps["nsat"].astype(np.int64)
    dec.frames["gps"] = gps
    return dec


# ---------------------------------------------------------------------------------------
# writer


def _checksum(body: str) -> str:
    x = 0
    for b in body.encode("ascii"):
        x ^= b
    return f"{x:02X}"


def _dm(value: float, width: int, pos: str, neg: str) -> tuple[str, str]:
    if not np.isfinite(value):
        return "", ""
    a = abs(value)
    d = int(a)
    m = (a - d) * 60.0
    if round(m, 6) >= 60.0:
        d, m = d + 1, 0.0
    return f"{d:0{width}d}{m:09.6f}", pos if value >= 0 else neg


def _opt(x: float, fmt: str) -> str:
    return format(x, fmt) if np.isfinite(x) else ""


def _epoch_sentences(r: dict[str, float], talker: str) -> list[str]:
    utc = float(gps_to_utc(r["gnss_time_s"]))
    day = np.datetime64("1980-01-06") + np.timedelta64(int(utc // 86400), "D")
    sod = utc - (utc // 86400) * 86400
    hh, rem = divmod(sod, 3600.0)
    mm, ss = divmod(rem, 60.0)
    hms = f"{int(hh):02d}{int(mm):02d}{ss:05.2f}"
    y, mo, d = str(day).split("-")
    lat, ns = _dm(r["lat"], 2, "N", "S")
    lon, ew = _dm(r["lon"], 3, "E", "W")
    fix = int(r["fix"])
    q = {0: 0, 1: 1, 2: 2}[fix] if np.isfinite(r["lat"]) else 0
    h = r.get("height_m", np.nan)
    spd, crs = r.get("speed_mps", np.nan), r.get("course_deg", np.nan)
    bodies = [
        f"{talker}RMC,{hms},{'A' if q else 'V'},{lat},{ns},{lon},{ew},{_opt(spd / KNOT_MPS, '.3f')},"
        f"{_opt(crs, '.2f')},{d}{mo}{y[2:]},,,{'D' if q == 2 else ('A' if q else 'N')}",
        f"{talker}VTG,{_opt(crs, '.2f')},T,,M,{_opt(spd / KNOT_MPS, '.3f')},N,{_opt(spd / KMH_MPS, '.3f')},K,"
        f"{'D' if q == 2 else ('A' if q else 'N')}",
        f"{talker}GGA,{hms},{lat},{ns},{lon},{ew},{q},{int(r['nsat']):02d},{_opt(r['hdop'], '.2f')},"
        f"{_opt(h, '.3f')},M,0.000,M,,",
        f"{talker}GSA,A,{3 if q else 1},,,,,,,,,,,,,,{_opt(r['hdop'], '.2f')},",
    ]
    sig = [r.get(k, np.nan) for k in ("sigma_lat_m", "sigma_lon_m", "sigma_height_m")]
    if any(np.isfinite(v) for v in sig):
        bodies.append(f"{talker}GST,{hms},,,,,{_opt(sig[0], '.3f')},{_opt(sig[1], '.3f')},{_opt(sig[2], '.3f')}")
    return [f"${b}*{_checksum(b)}" for b in bodies]


def write_nmea(gps: pd.DataFrame, path: Path, *, talker: str = "GN") -> int:
    """Write ``gps`` (with ``gnss_time_s``) as NMEA: RMC, VTG, GGA, GSA (+ GST where sigmas
    exist) per epoch; heights are written as altitude with a zero geoid separation.
    Returns the number of sentences. The caller writes atomically (``dbtools.atomic``)."""
    lines: list[str] = []
    for r in gps.to_dict(orient="records"):
        lines += _epoch_sentences(
            {str(k): float(v) if v is not None and not pd.isna(v) else np.nan for k, v in r.items() if k != "receiver"},
            talker,
        )
    Path(path).write_text("\r\n".join(lines) + "\r\n", encoding="ascii")
    return len(lines)
