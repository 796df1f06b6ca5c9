"""Reading tabular files (CSV or XLSX) as raw text cells, with clear errors.

Every reader in the suite that takes a spreadsheet-like file goes through here, so a
malformed file gives the same kind of message everywhere: file, line and what is wrong.
"""

from __future__ import annotations

import hashlib
import re
import zipfile
from pathlib import Path

import pandas as pd

from schemas.errors import InputError

TABULAR_SUFFIXES = (".csv", ".xlsx")


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def find_table_file(folder: Path, stem: str) -> Path | None:
    """``stem.csv`` or ``stem.xlsx`` in ``folder``; an error when both exist."""
    found = [folder / f"{stem}{s}" for s in TABULAR_SUFFIXES if (folder / f"{stem}{s}").is_file()]
    if len(found) > 1:
        raise InputError(f"both {found[0].name} and {found[1].name} exist; keep one", path=folder)
    return found[0] if found else None


_LINE_RE = re.compile(r"line (\d+)")


def read_raw_table(path: Path, sheet: str | None = None) -> pd.DataFrame:
    """All cells as text (leading zeros kept, empty cells as empty strings)."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such file", path=path)
    if path.suffix.lower() == ".xlsx":
        return _read_xlsx(path, sheet)
    fast = _read_csv_fast(path)
    try:
        frame = (
            fast
            if fast is not None
            else pd.read_csv(path, dtype=str, keep_default_na=False, encoding="utf-8-sig", skipinitialspace=True)
        )
    except pd.errors.EmptyDataError as exc:
        raise InputError("file is empty (no header line)", path=path) from exc
    except pd.errors.ParserError as exc:
        m = _LINE_RE.search(str(exc))
        raise InputError(f"malformed CSV: {str(exc).strip()}", path=path, row=int(m.group(1)) if m else None) from exc
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start}): save the file as UTF-8 CSV", path=path) from exc
    if any(str(c).startswith("Unnamed:") for c in frame.columns):
        bad = [i + 1 for i, c in enumerate(frame.columns) if str(c).startswith("Unnamed:")]
        raise InputError(f"header has empty column name(s) at position {bad}", path=path, row=1)
    return frame


def _read_csv_fast(path: Path) -> pd.DataFrame | None:
    """The same frame as the C parser gives, ~10× faster (pyarrow's CSV reader), or None.

    None whenever the fast reader fails or its result could differ from the C parser's
    (a field or header with leading blanks, which ``skipinitialspace`` would strip): the
    caller then reads with the C parser, which also produces the established error
    messages for malformed files.
    """
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, engine="pyarrow")
    except Exception:  # any problem at all: let the C parser read (or reject) the file
        return None
    for c in frame.columns:
        if str(c)[:1].isspace():
            return None
        col = frame[c]
        if len(col) and col.str.match(r"[ \t]").any():
            return None
    return frame


def _read_xlsx(path: Path, sheet: str | None) -> pd.DataFrame:
    try:
        book = pd.ExcelFile(path, engine="openpyxl")
    except (zipfile.BadZipFile, ValueError, OSError, KeyError) as exc:
        raise InputError(f"not a readable .xlsx workbook: {exc}", path=path) from exc
    with book:  # close the workbook (an open one leaks a ResourceWarning later)
        name = sheet if sheet in book.sheet_names else book.sheet_names[0]
        try:
            frame = pd.read_excel(book, sheet_name=name, dtype=str, keep_default_na=False)
        except (ValueError, KeyError) as exc:
            raise InputError(f"sheet '{name}' cannot be read: {exc}", path=path) from exc
    frame = frame.dropna(how="all")
    return frame.fillna("")
