"""RINEX dispatch (observation or navigation, 2.x or 3.x; ``.gz`` and Hatanaka ``.crx``
decompressed by ``common.read_text``) and the RINEX 2.11 observation reader.

RINEX 2.11 observations: epoch records (``yy mm dd hh mm ss.sssssss  flag n`` + up to 12
satellites per line, continued on following lines; event records, flags 2–5, are skipped with
their n header records and may leave the epoch fields blank) are walked in Python (one step
per epoch); each satellite's lines are padded to 80 columns and joined, then all fields are
converted in one vectorised pass as for RINEX 3. Observation types map onto RINEX 3 codes
(RINEX 3.04 §5.1 table): GPS/QZSS C1→C1C, P1→C1W, C2→C2L, P2→C2W, C5→C5X, band-1 phase,
Doppler, C/N0 with C1 (attribute C, else W), band 2 with P2 (W, else L); GLONASS C1/P1 →
C1C/C1P, C2/P2 → C2C/C2P, band-2 phase with P2; Galileo and SBAS attribute X (SBAS C).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from fieldlogs.recorders import rinex_obs as r3
from fieldlogs.recorders.common import Decoded, read_text
from fieldlogs.recorders.rinex_nav import read_rinex_nav
from fieldlogs.recorders.timebase import calendar_to_utc_s
from schemas.errors import InputError
from schemas.gnss import SYSTEMS


def read_rinex(path: Path) -> Decoded:
    """An observation or navigation file → gnss_obs or gnss_nav (+ gnss block)."""
    path = Path(path)
    lines = read_text(path).splitlines()
    if not lines or r3.label(lines[0]) != "RINEX VERSION / TYPE":
        raise InputError("not a RINEX file (no RINEX VERSION / TYPE on line 1)", path=path, row=1)
    try:
        version = float(lines[0][:9])
    except ValueError as exc:
        raise InputError(f"unreadable RINEX version '{lines[0][:9].strip()}'", path=path, row=1) from exc
    kind = lines[0][20]
    dec = Decoded(str(path), "rinex")
    if kind == "O":
        if version >= 3:
            r3.read_rinex_obs3(path, lines, dec)
        else:
            read_rinex_obs2(path, lines, dec)
    elif kind in ("N", "G", "E", "H", "J", "L"):
        read_rinex_nav(path, lines, dec)
    else:
        raise InputError(f"RINEX file type '{kind}' is neither observation (O) nor navigation (N)", path=path, row=1)
    return dec


V2_BAND = {"1": "1", "2": "2", "5": "5", "6": "6", "7": "7", "8": "8"}


def _attr2(letter: str, kind: str, band: str, types: list[str]) -> str:
    if letter == "E":
        return "X"
    if letter == "S":
        return "C"
    glo = letter == "R"
    if kind == "P":
        return "P" if glo else "W"
    if kind == "C":
        return {"1": "C", "2": "C" if glo else "L"}.get(band, "X")
    if band == "1":
        return "C" if "C1" in types else ("P" if glo else "W")
    if band == "2":
        return ("P" if glo else "W") if "P2" in types else ("C" if glo else "L")
    return "X"


def v2_codes(letter: str, types: list[str]) -> list[str]:
    """RINEX 3 codes of a system's RINEX 2 observation types (see module docstring)."""
    return [("C" if t[0] == "P" else t[0]) + t[1:2] + _attr2(letter, t[0], t[1:2], types) for t in types]


def _types2(path: Path, header: list[str]) -> list[str]:
    types: list[str] = []
    for ln in header:
        if r3.label(ln) == "# / TYPES OF OBSERV":
            types += ln[6:60].split()
    if not types:
        raise InputError("no # / TYPES OF OBSERV header line", path=path)
    return types


def _walk2(path: Path, body: list[str], first: int, n_lines: int) -> tuple[list[float], list[int], list[str], int]:
    """Epoch times (file scale), per satellite record its epoch and joined 80-column lines."""
    times: list[float] = []
    owner: list[int] = []
    joined: list[str] = []
    skipped = 0
    i = 0
    while i < len(body):
        ln = body[i]
        if not ln.strip():
            raise InputError("blank line where an epoch record was expected (blank epoch)", path=path, row=first + i)
        try:
            flag, n = int(ln[28]), int(ln[29:32])
            if 2 <= flag <= 5:  # n special (header) records follow; the epoch fields may be blank
                skipped += n
                i += 1 + n
                continue
            yy, mo, d, h, mi = (int(ln[k : k + 3]) for k in (0, 3, 6, 9, 12))
            s = float(ln[15:26])
        except ValueError as exc:
            raise InputError("blank or malformed epoch record", path=path, row=first + i) from exc
        sat_text = ln[32:68]
        extra = (n - 1) // 12 if n else 0
        for k in range(extra):
            sat_text += body[i + 1 + k][32:68] if i + 1 + k < len(body) else ""
        i += 1 + extra
        if flag == 6:  # cycle-slip records
            skipped += n
            i += n * n_lines
            continue
        y = yy + (1900 if yy >= 80 else 2000)
        times.append(float(calendar_to_utc_s(y, mo, d, h * 3600.0 + mi * 60.0 + s)))
        for k in range(n):
            sat = sat_text[3 * k : 3 * k + 3].replace(" ", "0")
            sat = ("G" + sat[1:]) if sat[0] == "0" else sat
            block = body[i : i + n_lines]
            if len(block) < n_lines:
                raise InputError(f"epoch record announces {n} satellites but the file ends", path=path, row=first + i)
            joined.append(sat + "".join(x[:80].ljust(80) for x in block))
            owner.append(len(times) - 1)
            i += n_lines
    return times, owner, joined, skipped


def read_rinex_obs2(path: Path, lines: list[str], dec: Decoded) -> None:
    header, start = r3.split_header(path, lines)
    types = _types2(path, header)
    n_lines = (len(types) + 4) // 5
    times, owner, joined, skipped = _walk2(path, lines[start:], start + 1, n_lines)
    dec.records = len(times)
    if skipped:
        dec.skipped["event records (epoch flags 2-6)"] += skipped
    sats = np.array([j[:3] for j in joined], dtype=object)
    letters = np.array([s[0] for s in sats], dtype=object)
    bad = np.flatnonzero(~np.isin(letters, list(SYSTEMS)))
    if len(bad):
        raise InputError(f"unknown satellite system '{letters[bad[0]]}'", path=path)
    default = "GLO" if header[0][40] == "R" else "GPS"
    named = r3.time_system(header)
    t_gps = r3.time_system_to_gps(np.array(times), named or default)
    parts = []
    for letter in sorted(set(letters)):
        sel = np.flatnonzero(letters == letter)
        codes = v2_codes(str(letter), types)
        # field j of the joined record sits at 3 + 80·(j // 5) + 16·(j % 5): re-lay it at 3 + 16·j
        recs = [
            j[:3]
            + "".join(
                j[3 + 80 * (k // 5) + 16 * (k % 5) : 3 + 80 * (k // 5) + 16 * (k % 5) + 16].ljust(16)
                for k in range(len(types))
            )
            for j in (joined[x] for x in sel)
        ]
        rows = r3.system_rows(recs, codes)
        pos = sel[rows["line_pos"].to_numpy(dtype=np.int64)]
        rows["gnss_time_s"] = t_gps[np.array(owner, dtype=np.int64)[pos]]
        rows["sat"] = sats[pos]
        parts.append(rows)
    frame = pd.concat(parts, ignore_index=True) if parts else pd.DataFrame(columns=r3.OBS_COLUMNS)
    frame["receiver"] = r3.marker(path, header)
    frame["lli"] = pd.array(np.where(frame["lli"].to_numpy(dtype=float) >= 0, frame["lli"], np.nan), dtype="Int64")
    dec.frames["gnss_obs"] = frame.sort_values(["gnss_time_s", "sat", "signal"], kind="stable")[
        r3.OBS_COLUMNS
    ].reset_index(drop=True)
