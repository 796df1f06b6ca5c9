"""RINEX 3.x observation files ↔ ``gnss_obs`` (RINEX 2.11 through ``rinex2``).

Reader, vectorised: the epoch records (``>`` lines) are parsed with pandas; the satellite
records of each system are laid into one fixed-width byte matrix (3 + 16·n columns for n
observation types) whose 14-character fields are converted to float in one numpy cast —
georinex parses line by line in Python, about 40× slower (``bench/bench_import.py``), and
is the independent reader in the round-trip tests.

An epoch with flag 0/1 is followed by exactly its number of satellite records; flags 2–5
by that many header records (skipped, counted; their epoch fields may be blank, as receivers
write them for "start of kinematic data"); flag 6 (cycle slips) is skipped. An epoch
whose records are missing or blank, a satellite of an unknown system, or a system without
``SYS / # / OBS TYPES`` is refused with its line. Epoch times are converted to GPS time
from the file's time system (GPS, GAL, QZS: same scale; BDS: +14 s; GLO/UTC: leap seconds).

Long format: one row per satellite × signal, the signal named by its pseudorange code
(``C`` + band + attribute); the phase (L), Doppler (D) and C/N0 (S) of the same band and
attribute share the row; ``lli`` is the phase's loss-of-lock indicator.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from fieldlogs.recorders.common import Decoded
from fieldlogs.recorders.timebase import (
    BDT_OFFSET_S,
    calendar_to_utc_s,
    ends_with_leap_second,
    gps_to_utc,
    utc_to_gps,
)
from schemas.errors import InputError
from schemas.gnss import SYSTEMS

OBS_KINDS = {"C": "pseudorange_m", "L": "carrier_cycles", "D": "doppler_hz", "S": "cn0_dbhz"}
OBS_COLUMNS = [
    "gnss_time_s",
    "receiver",
    "sat",
    "signal",
    "pseudorange_m",
    "carrier_cycles",
    "doppler_hz",
    "cn0_dbhz",
    "lli",
]


def label(line: str) -> str:
    return line[60:80].strip()


def split_header(path: Path, lines: list[str]) -> tuple[list[str], int]:
    for i, ln in enumerate(lines):
        if label(ln) == "END OF HEADER":
            return lines[:i], i + 1
    raise InputError("no END OF HEADER: not a RINEX file, or truncated", path=path)


def time_system_to_gps(utc_like: np.ndarray, system: str) -> np.ndarray:
    """File epochs (seconds since 1980-01-06 on the file's scale) → GPS seconds."""
    if system in ("GLO", "UTC"):
        return utc_to_gps(utc_like)
    if system == "BDS":
        return utc_like + BDT_OFFSET_S
    return utc_like


#: Time systems of a RINEX file that count leap seconds (RINEX 3.05 §6.3: GPS, GAL, QZS, BDS
#: and IRN time are continuous; GLONASS time is UTC(SU) + 3 h).
UTC_SCALES = ("GLO", "UTC")
_EPOCH_KEYS = (
    ("year", "y", 1980.0),
    ("month", "mo", 1.0),
    ("day", "d", 6.0),
    ("hour", "h", 0.0),
    ("minute", "mi", 0.0),
    ("second", "s", 0.0),
)
_RANGES = (("month", 1, 12), ("day", 1, 31), ("hour", 0, 23), ("minute", 0, 59))


def _check_calendar(path: Path, rows: np.ndarray, fields: dict[str, np.ndarray]) -> None:
    """Refuse the first epoch whose month, day (of that month), hour or minute is out of range."""
    for name, lo, hi in _RANGES:
        v = fields[name]
        bad = np.flatnonzero((v < lo) | (v > hi) | (v != np.floor(v)))
        if len(bad):
            k = int(bad[0])
            raise InputError(
                f"epoch record out of range: {name} {v[k]:g} (RINEX: {lo}-{hi})", path=path, row=int(rows[k])
            )
    y, mo = fields["year"].astype(np.int64), fields["month"].astype(np.int64)
    first = (y - 1970).astype("datetime64[Y]").astype("datetime64[M]") + (mo - 1).astype("timedelta64[M]")
    days = ((first + np.timedelta64(1, "M")).astype("datetime64[D]") - first.astype("datetime64[D]")).astype(np.int64)
    bad = np.flatnonzero(fields["day"] > days)
    if len(bad):
        k = int(bad[0])
        raise InputError(
            f"epoch record out of range: day {fields['day'][k]:g} of a {days[k]}-day month",
            path=path,
            row=int(rows[k]),
        )


def epochs_to_gps(path: Path, rows: np.ndarray, fields: dict[str, np.ndarray], system: str) -> np.ndarray:
    """Validated epoch fields (``year month day hour minute second`` arrays, ``rows`` their
    file lines) of a file on time system ``system`` → continuous GPS seconds.

    RINEX 3.05 §6.3 / 2.11 §7: 0 ≤ minute < 60, 0 ≤ hour < 24, 0 ≤ second < 61, where
    60 ≤ s < 61 exists only as an inserted leap second, 23:59:60 UTC at the end of a day that
    ends with one (IERS Bulletin C, ``timebase.LEAP_SECONDS``), and so only on a UTC-like
    scale (``UTC_SCALES``). Such a second is placed exactly: ``gps = utc→gps(23:59:(s−1)) + 1 s``
    (the leap second is the last second with the old GPS − UTC). Any other s ≥ 60 is refused
    with its line and field, never carried into the next minute (which would move the epoch).
    """
    _check_calendar(path, rows, fields)
    s = fields["second"]
    bad = np.flatnonzero(~((s >= 0) & (s < 61)))
    if len(bad):
        k = int(bad[0])
        raise InputError(
            f"epoch record out of range: second {s[k]:.7f} (RINEX: 0 ≤ s < 61)", path=path, row=int(rows[k])
        )
    day0 = calendar_to_utc_s(fields["year"], fields["month"], fields["day"], 0.0)
    sixty = s >= 60
    leap = sixty & (fields["hour"] == 23) & (fields["minute"] == 59) & ends_with_leap_second(day0)
    wrong = np.flatnonzero(sixty & ~(leap & (system in UTC_SCALES)))
    if len(wrong):
        k = int(wrong[0])
        raise InputError(
            f"epoch record: second {s[k]:.7f} is a leap second, which exists only at 23:59:60 UTC at the end "
            f"of a day that ends with one (IERS Bulletin C) on a UTC time scale; this epoch on {system} time is "
            "not one (refused rather than carried into the next minute, which would move the epoch)",
            path=path,
            row=int(rows[k]),
        )
    step = leap.astype(np.float64)
    t_file = day0 + fields["hour"] * 3600.0 + fields["minute"] * 60.0 + s - step
    out: np.ndarray = time_system_to_gps(t_file, system) + step
    return out


def _obs_types(path: Path, header: list[str]) -> dict[str, list[str]]:
    types: dict[str, list[str]] = {}
    current = ""
    for i, ln in enumerate(header):
        if label(ln) != "SYS / # / OBS TYPES":
            continue
        if ln[0] != " ":
            current = ln[0]
            if current not in SYSTEMS:
                raise InputError(f"unknown system '{current}' in SYS / # / OBS TYPES", path=path, row=i + 1)
            types[current] = []
        types[current] += ln[7:60].split()
    return types


def time_system(header: list[str]) -> str:
    """The TIME OF FIRST OBS time system ('' when not named)."""
    for ln in header:
        if label(ln) == "TIME OF FIRST OBS":
            return ln[48:51].strip()
    return ""


def marker(path: Path, header: list[str]) -> str:
    for ln in header:
        if label(ln) == "MARKER NAME" and ln[:60].strip():
            return ln[:60].strip()
    return Path(path).name.split(".")[0]


def _epochs(path: Path, body: pd.Series, first_line: int) -> tuple[np.ndarray, pd.DataFrame]:
    """(owner epoch of each body line, −1 for epoch lines; epoch table) — counts verified."""
    is_ep = body.str.startswith(">").to_numpy()
    ep_idx = np.flatnonzero(is_ep)
    if not len(ep_idx):
        raise InputError("no epoch records ('>' lines)", path=path, row=first_line)
    if ep_idx[0] != 0:
        raise InputError("data before the first epoch record", path=path, row=first_line)
    e = body.iloc[ep_idx]
    f = pd.DataFrame(
        {
            k: pd.to_numeric(e.str.slice(a, b), errors="coerce").to_numpy()
            for k, (a, b) in {
                "y": (2, 6),
                "mo": (7, 9),
                "d": (10, 12),
                "h": (13, 15),
                "mi": (16, 18),
                "s": (18, 29),
                "flag": (31, 32),
                "n": (32, 35),
            }.items()
        }
    )
    event = f["flag"].between(2, 5).to_numpy()  # special events: the epoch fields may be blank
    f.loc[event, ["y", "mo", "d", "h", "mi", "s"]] = f.loc[event, ["y", "mo", "d", "h", "mi", "s"]].fillna(
        {"y": 1980, "mo": 1, "d": 6, "h": 0, "mi": 0, "s": 0.0}
    )
    bad = f[["y", "mo", "d", "h", "mi", "s", "flag", "n"]].isna().any(axis=1).to_numpy()
    if bad.any():
        j = int(ep_idx[np.flatnonzero(bad)[0]])
        raise InputError("blank or malformed epoch record", path=path, row=first_line + j)
    following = np.diff(np.concatenate((ep_idx, [len(body)]))) - 1
    short = np.flatnonzero(following != f["n"].to_numpy())
    if len(short):
        k = int(short[0])
        raise InputError(
            f"epoch record announces {int(f['n'].iloc[k])} records but {int(following[k])} follow "
            "(blank, missing or extra satellite lines)",
            path=path,
            row=first_line + int(ep_idx[k]),
        )
    owner = np.cumsum(is_ep) - 1
    owner[is_ep] = -1
    f["line"] = ep_idx + first_line
    return owner, f


def _fixed(lines: Sequence[str], width: int) -> np.ndarray:
    """Lines as an (n, width) byte matrix, padded with spaces."""
    a = np.array([ln.encode("ascii", "replace") for ln in lines], dtype=f"S{width}")
    u = a.view(np.uint8).reshape(len(lines), width).copy() if len(lines) else np.zeros((0, width), np.uint8)
    u[u == 0] = 32
    return u


_NAN14 = np.frombuffer(b"           nan", dtype=np.uint8)


def _floats(u: np.ndarray, start: int) -> np.ndarray:
    f = np.ascontiguousarray(u[:, start : start + 14])
    blank = (f == 32).all(axis=1)
    f[blank] = _NAN14
    try:
        return f.view("S14").ravel().astype(np.float64)
    except ValueError:
        out = np.full(len(f), np.nan)
        for i, b in enumerate(f.view("S14").ravel()):  # only a malformed file gets here
            try:
                out[i] = float(b)
            except ValueError:
                out[i] = np.nan
        return out


def _digit(u: np.ndarray, col: int) -> np.ndarray:
    c = u[:, col].astype(np.int64) - 48
    return np.where((c >= 0) & (c <= 9), c, -1)


def signal_groups(types: list[str]) -> dict[str, dict[str, int]]:
    """'1C' → {'C': index of C1C, 'L': index of L1C, ...} for one system's obs types."""
    groups: dict[str, dict[str, int]] = {}
    for k, code in enumerate(types):
        if len(code) == 3 and code[0] in OBS_KINDS:
            groups.setdefault(code[1:], {})[code[0]] = k
    return groups


def system_rows(lines: list[str], types: list[str]) -> pd.DataFrame:
    """Long-format rows of one system's satellite records (vectorised)."""
    width = 3 + 16 * len(types)
    u = _fixed(lines, width)
    parts = []
    for band, kinds in signal_groups(types).items():
        part: dict[str, np.ndarray] = {"line_pos": np.arange(len(lines))}
        for kind, name in OBS_KINDS.items():
            part[name] = _floats(u, 3 + 16 * kinds[kind]) if kind in kinds else np.full(len(lines), np.nan)
        lli = _digit(u, 3 + 16 * kinds["L"] + 14) if "L" in kinds else np.full(len(lines), -1)
        part["lli"] = lli
        frame = pd.DataFrame(part)
        frame["signal"] = "C" + band
        keep = frame[list(OBS_KINDS.values())].notna().any(axis=1)
        parts.append(frame[keep])
    if not parts:
        return pd.DataFrame(columns=["line_pos", *OBS_KINDS.values(), "lli", "signal"])
    return pd.concat(parts, ignore_index=True)


def read_rinex_obs3(path: Path, lines: list[str], dec: Decoded) -> None:
    header, start = split_header(path, lines)
    types = _obs_types(path, header)
    receiver = marker(path, header)
    body = pd.Series(lines[start:], dtype=object)
    owner, ep = _epochs(path, body, start + 1)
    dec.records = len(ep)
    flags = ep["flag"].to_numpy()
    for fl, why in ((6, "cycle-slip records (epoch flag 6)"), (2, "event records (epoch flags 2-5)")):
        n = int(ep["n"][(flags == fl) | ((fl == 2) & (flags >= 2) & (flags <= 5))].sum())
        if n:
            dec.skipped[why] += n
    empty = int(((ep["n"] == 0) & (flags <= 1)).sum())
    if empty:
        dec.skipped["epochs without satellites"] += empty
    sat_pos = np.flatnonzero((owner >= 0) & (flags[np.maximum(owner, 0)] <= 1))
    sats = body.iloc[sat_pos]
    blank = np.flatnonzero(sats.str.strip().str.len().to_numpy() == 0)
    if len(blank):
        raise InputError(
            "blank satellite record inside an epoch (blank epoch)", path=path, row=start + 1 + int(sat_pos[blank[0]])
        )
    sys_letter = sats.str[0].to_numpy(dtype=object)
    unknown = np.flatnonzero(~np.isin(sys_letter, list(SYSTEMS)))
    if len(unknown):
        raise InputError(
            f"unknown satellite system '{sys_letter[unknown[0]]}'", path=path, row=start + 1 + int(sat_pos[unknown[0]])
        )
    timed = (flags <= 1) | (flags == 6)
    fields = {name: np.where(timed, ep[k].to_numpy(dtype=np.float64), default) for name, k, default in _EPOCH_KEYS}
    t_gps = epochs_to_gps(path, ep["line"].to_numpy(), fields, time_system(header) or "GPS")
    out = []
    for letter in sorted(set(sys_letter)):
        if letter not in types:
            j = int(np.flatnonzero(sys_letter == letter)[0])
            raise InputError(
                f"system '{letter}' has no SYS / # / OBS TYPES header line", path=path, row=start + 1 + int(sat_pos[j])
            )
        sel = np.flatnonzero(sys_letter == letter)
        rows = system_rows(sats.iloc[sel].tolist(), types[letter])
        pos = sat_pos[sel][rows["line_pos"].to_numpy(dtype=np.int64)]
        rows["gnss_time_s"] = t_gps[owner[pos]]
        rows["sat"] = body.iloc[pos].str.slice(0, 3).str.replace(" ", "0").to_numpy()
        out.append(rows)
    frame = pd.concat(out, ignore_index=True) if out else pd.DataFrame(columns=OBS_COLUMNS)
    frame["receiver"] = receiver
    frame["lli"] = pd.array(np.where(frame["lli"].to_numpy(dtype=float) >= 0, frame["lli"], np.nan), dtype="Int64")
    frame = frame.sort_values(["gnss_time_s", "sat", "signal"], kind="stable")
    dec.frames["gnss_obs"] = frame[OBS_COLUMNS].reset_index(drop=True)


# ---------------------------------------------------------------------------------------
# writer


def _hline(text: str, lab: str) -> str:
    return f"{text:<60.60}{lab:<20}"


def _types_of(obs: pd.DataFrame) -> dict[str, list[str]]:
    sig = obs[["sat", "signal"]].drop_duplicates()
    out: dict[str, list[str]] = {}
    for letter, g in sig.groupby(sig["sat"].str[0]):
        out[str(letter)] = [k + s[1:] for s in sorted(g["signal"].unique()) for k in OBS_KINDS]
    return out


def _header(obs: pd.DataFrame, types: dict[str, list[str]], receiver: str) -> list[str]:
    lines = [
        _hline("     3.04           OBSERVATION DATA    M", "RINEX VERSION / TYPE"),
        _hline("trainpos            trainpos", "PGM / RUN BY / DATE"),
        _hline(receiver, "MARKER NAME"),
    ]
    for letter, ts in types.items():
        for k in range(0, len(ts), 13):
            head = f"{letter}  {len(ts):3d}" if k == 0 else "      "
            lines.append(_hline(head + "".join(f" {c}" for c in ts[k : k + 13]), "SYS / # / OBS TYPES"))
    t0 = float(obs["gnss_time_s"].min())
    y, mo, d, h, mi, s = _calendar(t0)
    lines.append(
        _hline(f"  {y:04d}    {mo:02d}    {d:02d}    {h:02d}    {mi:02d}   {s:10.7f}     GPS", "TIME OF FIRST OBS")
    )
    lines.append(_hline("", "END OF HEADER"))
    return lines


def _calendar(gps_s: float) -> tuple[int, int, int, int, int, float]:
    """GPS seconds → calendar fields on the GPS scale (RINEX epochs in GPS time)."""
    day = np.datetime64("1980-01-06") + np.timedelta64(int(gps_s // 86400), "D")
    sod = gps_s - (gps_s // 86400) * 86400
    y, mo, d = (int(x) for x in str(day).split("-"))
    return y, mo, d, int(sod // 3600), int((sod % 3600) // 60), sod % 60


def _field(v: float, lli: int | None = None) -> str:
    if not np.isfinite(v):
        return " " * 16
    return f"{v:14.3f}{'' if lli is None or lli < 0 else lli:1}".ljust(16)[:16]


def write_rinex_obs(obs: pd.DataFrame, path: Path, *, receiver: str | None = None) -> int:
    """``gnss_obs`` rows of one receiver → RINEX 3.04 observation text (epochs in GPS time).
    Returns the number of epochs. The caller writes atomically."""
    if obs["receiver"].nunique() > 1:
        raise ValueError("one RINEX file per receiver")
    rec = receiver or str(obs["receiver"].iloc[0])
    types = _types_of(obs)
    lines = _header(obs, types, rec)
    n_ep = 0
    for t, g in obs.sort_values(["gnss_time_s", "sat"]).groupby("gnss_time_s", sort=True):
        y, mo, d, h, mi, s = _calendar(float(t))  # type: ignore[arg-type]
        sats = sorted(g["sat"].unique())
        lines.append(f"> {y:04d} {mo:02d} {d:02d} {h:02d} {mi:02d}{s:11.7f}  0{len(sats):3d}")
        by = {(r.sat, r.signal): r for r in g.itertuples(index=False)}
        for sat in sats:
            cells = []
            for code in types[sat[0]]:
                r = by.get((sat, "C" + code[1:]))
                v = np.nan if r is None else float(getattr(r, OBS_KINDS[code[0]]))
                lli = None if r is None else r.lli
                li = None if lli is None or code[0] != "L" or pd.isna(lli) else int(lli)  # type: ignore[arg-type]
                cells.append(_field(v, li))
            lines.append((sat + "".join(cells)).rstrip())
        n_ep += 1
    Path(path).write_text("\n".join(lines) + "\n", encoding="ascii")
    return n_ep


def gps_calendar(gps_s: float) -> tuple[int, int, int, int, int, float]:
    return _calendar(gps_s)


def utc_calendar(gps_s: float) -> tuple[int, int, int, int, int, float]:
    return _calendar(float(gps_to_utc(gps_s)))
