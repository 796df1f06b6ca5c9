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
Refused with the line of the epoch record: a blank or malformed epoch record (fields out of
range), fewer satellites listed than announced, an epoch record read as satellite data (its
predecessor announced more satellites than it has records), the file ending inside an epoch,
a satellite of an unknown system.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from fieldlogs.recorders import rinex_obs as r3
from fieldlogs.recorders.common import Decoded, read_text
from fieldlogs.recorders.rinex_nav import read_rinex_nav
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


#: A RINEX 2.11 epoch record with its fields filled: `` yy mm dd hh mm ss.sssssss  f`` (a
#: satellite data line, F14.3 fields, has its decimal points at columns 10, 26, …, never at 18).
EPOCH2 = r"^ [ \d]\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d [ \d]\d\.\d{7}  [0-6]"


def _epoch_fields2(path: Path, ln: str, row: int) -> tuple[int, int]:
    """(flag, number of satellites or special records) of an epoch record line."""
    try:
        flag, n = int(ln[28]), int(ln[29:32])
    except (ValueError, IndexError) as exc:
        raise InputError("blank or malformed epoch record (no epoch flag and count)", path=path, row=row) from exc
    if not 0 <= flag <= 6 or n < 0:
        raise InputError(f"malformed epoch record: epoch flag {flag} (0-6 expected)", path=path, row=row)
    return flag, n


def _epoch_time2(path: Path, ln: str, row: int) -> list[float]:
    """The epoch fields (year, month, day, hour, minute, second) of a flag 0/1/6 record;
    their ranges are checked by ``rinex_obs.epochs_to_gps``."""
    try:
        yy, mo, d, h, mi = (int(ln[k : k + 3]) for k in (0, 3, 6, 9, 12))
        s = float(ln[15:26])
    except ValueError as exc:
        raise InputError("blank or malformed epoch record", path=path, row=row) from exc
    y = yy + (1900 if yy >= 80 else 2000)
    return [float(y), float(mo), float(d), float(h), float(mi), s]


def _data_block2(path: Path, shaped: np.ndarray, first: int, i: int, end: int, n: int, row: int) -> None:
    """Refuse an epoch's satellite data lines ``body[i:end]`` (body line 0 is file line
    ``first``) that run past the end of the file or hold a line shaped like an epoch record
    (the epoch announced more satellites than it has records)."""
    if end > len(shaped):
        raise InputError(f"epoch record announces {n} satellites but the file ends", path=path, row=row)
    lost = np.flatnonzero(shaped[i:end])
    if len(lost):
        raise InputError(
            f"epoch record announces {n} satellites but has fewer records: the epoch record on line "
            f"{first + i + int(lost[0])} would be read as satellite data",
            path=path,
            row=row,
        )


def _sat_list2(path: Path, body: list[str], i: int, n: int, row: int) -> tuple[list[str], int]:
    """The n satellite ids of the epoch record at body[i] (continued on following lines, 12 per
    line) and the number of continuation lines."""
    text = body[i][32:68]
    extra = (n - 1) // 12 if n else 0
    for k in range(extra):
        text += body[i + 1 + k][32:68] if i + 1 + k < len(body) else ""
    if len(text.rstrip()) < 3 * n:
        raise InputError(
            f"epoch record announces {n} satellites but lists {len(text.rstrip()) // 3}", path=path, row=row
        )
    sats = [text[3 * k : 3 * k + 3].replace(" ", "0") for k in range(n)]
    return [("G" + s[1:]) if s[0] == "0" else s for s in sats], extra


def _walk2(
    path: Path, body: list[str], first: int, n_lines: int
) -> tuple[list[list[float]], list[int], list[str], list[int], int]:
    """Epoch fields and their file lines, per satellite record its epoch, joined 80-column lines and
    the file line of its epoch record; and the number of skipped special records."""
    shaped = pd.Series(body, dtype=object).str.match(EPOCH2).to_numpy(dtype=bool)
    times: list[list[float]] = []
    owner: list[int] = []
    joined: list[str] = []
    rows: list[int] = []
    skipped = 0
    i = 0
    while i < len(body):
        row = first + i
        if not body[i].strip():
            raise InputError("blank line where an epoch record was expected (blank epoch)", path=path, row=row)
        flag, n = _epoch_fields2(path, body[i], row)
        if 2 <= flag <= 5:  # n special (header) records follow; the epoch fields may be blank
            skipped += n
            i += 1 + n
            continue
        t = _epoch_time2(path, body[i], row)
        sats, extra = _sat_list2(path, body, i, n, row)
        i += 1 + extra
        _data_block2(path, shaped, first, i, i + n * n_lines, n, row)
        if flag == 6:  # cycle-slip records
            skipped += n
            i += n * n_lines
            continue
        times.append([*t, float(row)])
        for sat in sats:
            joined.append(sat + "".join(x[:80].ljust(80) for x in body[i : i + n_lines]))
            i += n_lines
        owner += [len(times) - 1] * n
        rows += [row] * n
    return times, owner, joined, rows, skipped


def read_rinex_obs2(path: Path, lines: list[str], dec: Decoded) -> None:
    header, start = r3.split_header(path, lines)
    types = _types2(path, header)
    n_lines = (len(types) + 4) // 5
    times, owner, joined, rec_rows, skipped = _walk2(path, lines[start:], start + 1, n_lines)
    dec.records = len(times)
    if skipped:
        dec.skipped["event records (epoch flags 2-6)"] += skipped
    sats = np.array([j[:3] for j in joined], dtype=object)
    letters = np.array([s[0] for s in sats], dtype=object)
    bad = np.flatnonzero(~np.isin(letters, list(SYSTEMS)))
    if len(bad):
        raise InputError(f"unknown satellite system '{letters[bad[0]]}'", path=path, row=rec_rows[int(bad[0])])
    default = "GLO" if header[0][40] == "R" else "GPS"
    named = r3.time_system(header)
    cols = np.array(times, dtype=np.float64).reshape(-1, 7).T
    fields = dict(zip(("year", "month", "day", "hour", "minute", "second"), cols[:6], strict=True))
    t_gps = r3.epochs_to_gps(path, cols[6].astype(np.int64), fields, named or default)
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
