"""RINEX navigation files (2.x GPS/GLONASS, 3.x mixed) ↔ ``gnss_nav`` and the ``gnss`` block.

Records are parsed field by field (19-character D19.12 numbers, ``D`` exponents accepted);
navigation files are small (a few hundred records an hour), so a record loop is cheap.
Fields are named as georinex names them (``schemas.gnss``); georinex's per-system names
are mapped onto the shared columns: Galileo ``IODnav`` → ``IODE``, ``SISA`` → ``SVacc``,
``GPSWeek``/``GALWeek`` → ``week`` (RINEX 3 writes Galileo weeks in GPS numbering).
``toc_gps_s`` is the record epoch on the GPS scale (GLONASS epochs are UTC: leap seconds
added). BeiDou, SBAS and NavIC records are skipped and counted (no orbit consumer yet);
any other system letter is refused with its line.

Header → ``gnss`` block: IONOSPHERIC CORR (GPSA/GPSB, QZSA/QZSB, GAL) or RINEX 2
ION ALPHA / ION BETA, TIME SYSTEM CORR (RINEX 2: DELTA-UTC), LEAP SECONDS.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fieldlogs.recorders.common import Decoded
from fieldlogs.recorders.navweeks import WEEK_ROLLOVER
from fieldlogs.recorders.rinex_obs import epochs_to_gps, gps_calendar, label, split_header, utc_calendar
from fieldlogs.recorders.timebase import BDT_OFFSET_S, utc_to_gps
from schemas.errors import InputError
from schemas.gnss import GNSS_NAV, SYSTEMS

#: Broadcast-orbit lines after the epoch line, per system (RINEX 3).
ORBIT_LINES = {"G": 7, "E": 7, "J": 7, "C": 7, "I": 7, "R": 3, "S": 3}
KEPLER_G = (
    "SVclockBias SVclockDrift SVclockDriftRate IODE Crs DeltaN M0 Cuc Eccentricity Cus sqrtA Toe Cic "
    "Omega0 Cis Io Crc omega OmegaDot IDOT CodesL2 week L2Pflag SVacc health TGD IODC TransTime "
    "FitIntvl"
).split()
KEPLER_E = (
    "SVclockBias SVclockDrift SVclockDriftRate IODE Crs DeltaN M0 Cuc Eccentricity Cus sqrtA Toe Cic "
    "Omega0 Cis Io Crc omega OmegaDot IDOT DataSrc week spare0 SVacc health BGDe5a BGDe5b "
    "TransTime"
).split()
STATE_R = ("SVclockBias SVrelFreqBias MessageFrameTime X dX dX2 health Y dY dY2 FreqNum Z dZ dZ2 AgeOpInfo").split()
FIELDS = {"G": KEPLER_G, "J": KEPLER_G, "E": KEPLER_E, "R": STATE_R}
KM_FIELDS = {"X", "dX", "dX2", "Y", "dY", "dY2", "Z", "dZ", "dZ2"}
NAV_COLUMNS = GNSS_NAV.column_names


def _num(text: str) -> float:
    t = text.strip().replace("D", "E").replace("d", "e")
    return float(t) if t else np.nan


def _numbers(text: str, n: int) -> list[float]:
    return [_num(text[19 * k : 19 * (k + 1)]) for k in range(n)]


def _record(path: Path, lines: list[str], i: int, version: int) -> tuple[str, float, list[float]]:
    """(sat, epoch on its own scale as seconds since 1980-01-06, first three values)."""
    ln = lines[i]
    try:
        if version >= 3:
            sat = ln[:3].replace(" ", "0")
            sat[0]
            y, mo, d, h, mi, s = (
                int(ln[4:8]),
                int(ln[9:11]),
                int(ln[12:14]),
                int(ln[15:17]),
                int(ln[18:20]),
                float(ln[21:23]),
            )
            first = ln[23:80]
        else:
            sat = ""
            yy = int(ln[3:5])
            y = yy + (1900 if yy >= 80 else 2000)
            mo, d, h, mi, s = int(ln[6:8]), int(ln[9:11]), int(ln[12:14]), int(ln[15:17]), float(ln[17:22])
            first = ln[22:79]
    except ValueError as exc:
        raise InputError(f"malformed navigation record: {exc}", path=path, row=i + 1) from exc
    try:
        vals = _numbers(first.ljust(57), 3)
    except ValueError as exc:
        raise InputError(f"malformed navigation record: {exc}", path=path, row=i + 1) from exc
    fields = {
        k: np.array([float(v)])
        for k, v in zip(("year", "month", "day", "hour", "minute", "second"), (y, mo, d, h, mi, s), strict=True)
    }
    # validated as on a continuous scale (no conversion): a record epoch (toc, on 15-minute or
    # 2-hour marks) with second 60 is refused with its line, never moved into the next minute
    t = float(epochs_to_gps(path, np.array([i + 1]), fields, "GPS")[0])
    return sat, t, vals


def _orbit_values(path: Path, lines: list[str], i: int, n: int, indent: int) -> list[float]:
    if i + n > len(lines):
        raise InputError(f"navigation record cut short: {n} broadcast-orbit lines expected", path=path, row=i)
    vals: list[float] = []
    for k in range(n):
        try:
            vals += _numbers(lines[i + k][indent : indent + 76].ljust(76), 4)
        except ValueError as exc:
            raise InputError(f"malformed broadcast-orbit line: {exc}", path=path, row=i + k + 1) from exc
    return vals


def _row(sysl: str, sat: str, t_own: float, vals: list[float]) -> dict[str, Any]:
    names = FIELDS[sysl]
    row: dict[str, Any] = {"sat": sat}
    for name, v in zip(names, vals, strict=False):
        if name in NAV_COLUMNS:
            row[name] = v * 1000.0 if name in KM_FIELDS else v
    if sysl == "R":
        row["toc_gps_s"] = float(utc_to_gps(t_own))
    elif sysl == "C":
        row["toc_gps_s"] = t_own + BDT_OFFSET_S
    else:
        row["toc_gps_s"] = t_own
    return row


def _header_params(header: list[str]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    corr: list[dict[str, Any]] = []
    keys = {
        "GPSA": "klobuchar_alpha",
        "GPSB": "klobuchar_beta",
        "QZSA": "qzss_klobuchar_alpha",
        "QZSB": "qzss_klobuchar_beta",
        "GAL": "nequick_ai",
    }
    for ln in header:
        lab = label(ln)
        if lab == "IONOSPHERIC CORR":
            key = keys.get(ln[:4].strip())
            if key:
                n = 3 if key == "nequick_ai" else 4
                out[key] = [_num(ln[5 + 12 * k : 17 + 12 * k]) for k in range(n)]
        elif lab in ("ION ALPHA", "ION BETA"):
            out["klobuchar_alpha" if lab == "ION ALPHA" else "klobuchar_beta"] = [
                _num(ln[2 + 12 * k : 14 + 12 * k]) for k in range(4)
            ]
        elif lab == "TIME SYSTEM CORR":
            corr.append(
                {
                    "type": ln[:4].strip(),
                    "a0_s": _num(ln[5:22]),
                    "a1_s_per_s": _num(ln[22:38]),
                    "t_ref_s": _num(ln[38:45]),
                    "week": _num(ln[45:50]),
                }
            )
        elif lab == "DELTA-UTC: A0,A1,T,W":
            corr.append(
                {
                    "type": "GPUT",
                    "a0_s": _num(ln[3:22]),
                    "a1_s_per_s": _num(ln[22:41]),
                    "t_ref_s": _num(ln[41:50]),
                    "week": _num(ln[50:59]),
                }
            )
        elif lab == "LEAP SECONDS" and ln[:6].strip():
            out["leap_seconds"] = int(ln[:6])
    if corr:
        out["time_corrections"] = corr
    return out


def read_rinex_nav(path: Path, lines: list[str], dec: Decoded) -> None:
    header, start = split_header(path, lines)
    version = int(float(header[0][:9]))
    file_sys = header[0][40] if version < 3 else "M"
    if version < 3 and header[0][20] == "G":
        file_sys = "R"  # RINEX 2 GLONASS navigation file ('G: GLONASS NAV DATA')
    elif version < 3:
        file_sys = "G"
    dec.gnss.update(_header_params(header))
    rows: list[dict[str, Any]] = []
    i = start
    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        sat, t_own, first = _record(path, lines, i, version)
        sysl = sat[0] if version >= 3 else file_sys
        if version < 3:
            sat = f"{sysl}{int(lines[i][:2]):02d}"
        if sysl not in SYSTEMS:
            raise InputError(f"unknown satellite system '{sysl}'", path=path, row=i + 1)
        n = ORBIT_LINES[sysl]
        indent = 4 if version >= 3 else 3
        vals = first + _orbit_values(path, lines, i + 1, n, indent)
        dec.records += 1
        i += 1 + n
        if sysl not in FIELDS:
            dec.skipped[f"navigation records of system {sysl} (no orbit consumer yet)"] += 1
            continue
        rows.append(_row(sysl, sat, t_own, vals))
    frame = pd.DataFrame(rows, columns=NAV_COLUMNS) if rows else pd.DataFrame(columns=NAV_COLUMNS)
    frame = frame.astype({c: "float64" for c in NAV_COLUMNS if c != "sat"})
    dup = frame.duplicated(keep="first")
    if dup.any():
        dec.skipped["repeated navigation records"] += int(dup.sum())
        frame = frame[~dup]
    _resolve_weeks(frame, dec)
    dec.frames["gnss_nav"] = frame.sort_values(["sat", "toc_gps_s"], kind="stable").reset_index(drop=True)


def _resolve_weeks(frame: pd.DataFrame, dec: Decoded) -> None:
    """Make ``week`` the continuous GPS week RINEX 3.05 Table A6 asks for ("continuous number,
    not mod(1024)"), in place.

    A receiver that writes the broadcast 10-bit week (mod 1024, IS-GPS-200 §20.3.3.3.1.1) puts
    Toe 1024·k weeks (19.6 years) before the record's own epoch ``toc``, written as a calendar
    date: the week is resolved to the rollover nearest that epoch,
    ``w = w₁₀ + 1024·round((⌊toc/604800⌋ − w₁₀) / 1024)`` (Toe and toc lie within a week of
    each other), and the change is stated in the import's notes — never left to surface as
    0 % availability when positioning.
    """
    week = frame["week"].to_numpy(dtype=np.float64)
    toc_week = np.floor(frame["toc_gps_s"].to_numpy(dtype=np.float64) / 604_800.0)
    k = np.round((toc_week - week) / WEEK_ROLLOVER)
    moved = np.isfinite(k) & (k != 0)
    if not moved.any():
        return
    frame.loc[moved, "week"] = week[moved] + WEEK_ROLLOVER * k[moved]
    shifts = sorted({int(x) for x in k[moved]})
    dec.notes.append(
        f"navigation records with a week number {', '.join(f'{1024 * x:+d}' for x in shifts)} weeks off their "
        f"record epoch (the 10-bit broadcast week, modulo {WEEK_ROLLOVER}, IS-GPS-200 §20.3.3.3.1.1): "
        f"{int(moved.sum())} record(s) resolved to the week rollover nearest the record epoch "
        f"(weeks {int(frame.loc[moved, 'week'].min())}–{int(frame.loc[moved, 'week'].max())})"
    )


# ---------------------------------------------------------------------------------------
# writer


def _d(v: Any) -> str:
    x = float(v) if v is not None and not pd.isna(v) else 0.0
    return f"{x:19.12E}"


def _header_lines(gnss: dict[str, Any]) -> list[str]:
    def h(text: str, lab: str) -> str:
        return f"{text:<60.60}{lab:<20}"

    out = [
        h("     3.04           N: GNSS NAV DATA    M: MIXED", "RINEX VERSION / TYPE"),
        h("trainpos            trainpos", "PGM / RUN BY / DATE"),
    ]
    for key, tag in (
        ("klobuchar_alpha", "GPSA"),
        ("klobuchar_beta", "GPSB"),
        ("qzss_klobuchar_alpha", "QZSA"),
        ("qzss_klobuchar_beta", "QZSB"),
        ("nequick_ai", "GAL "),
    ):
        if key in gnss:
            vals = list(gnss[key]) + [0.0] * (4 - len(gnss[key]))
            out.append(h(f"{tag:<4} " + "".join(f"{v:12.4E}" for v in vals), "IONOSPHERIC CORR"))
    for c in gnss.get("time_corrections", []):
        out.append(
            h(
                f"{c['type']:<4} {c['a0_s']:17.10E}{c['a1_s_per_s']:16.9E} {int(c['t_ref_s']):6d} {int(c['week']):4d}",
                "TIME SYSTEM CORR",
            )
        )
    if "leap_seconds" in gnss:
        out.append(h(f"{int(gnss['leap_seconds']):6d}", "LEAP SECONDS"))
    out.append(h("", "END OF HEADER"))
    return out


def write_rinex_nav(nav: pd.DataFrame, path: Path, gnss: dict[str, Any] | None = None) -> int:
    """``gnss_nav`` (G, E, J, R rows) → RINEX 3.04 mixed navigation text; returns records.
    Missing values are written as 0 (RINEX has no blank number). The caller writes atomically."""
    lines = _header_lines(gnss or {})
    n = 0
    for r in nav.sort_values(["sat", "toc_gps_s"]).to_dict("records"):
        sysl = str(r["sat"])[0]
        if sysl not in FIELDS:
            raise ValueError(f"cannot write navigation records of system {sysl}")
        cal = utc_calendar(r["toc_gps_s"]) if sysl == "R" else gps_calendar(r["toc_gps_s"])
        y, mo, d, hh, mi, s = cal
        vals = [r.get(k, 0.0) * (0.001 if k in KM_FIELDS else 1.0) if k in r else 0.0 for k in FIELDS[sysl]]
        lines.append(
            f"{r['sat']} {y:04d} {mo:02d} {d:02d} {hh:02d} {mi:02d} {round(s):02d}" + "".join(_d(v) for v in vals[:3])
        )
        rest = vals[3:]
        for k in range(0, ORBIT_LINES[sysl] * 4, 4):
            lines.append("    " + "".join(_d(v) for v in rest[k : k + 4]).rstrip() if rest[k : k + 4] else "    ")
        n += 1
    Path(path).write_text("\n".join(lines) + "\n", encoding="ascii")
    return n
