"""Reading tabular files (CSV or XLSX) as raw text cells, with clear errors.

Every reader in the suite that takes a spreadsheet-like file goes through here, so a
malformed file gives the same kind of message everywhere: file, line and what is wrong.
What spreadsheet tools commonly get wrong, and what happens to it here:

* **encoding** — UTF-8, with or without a byte-order mark, is read as it is. A file that
  is not UTF-8 but decodes as Shift-JIS (CP932: what Japanese Excel writes as "CSV") or
  starts with a UTF-16 byte-order mark (Excel's "Unicode text") is read in that encoding,
  with a warning (``source.encoding``) naming it and the first line that is not UTF-8;
  anything else is refused (InputError) naming that line.
* **delimiter and decimal separator** — a reader given a :class:`~dbtools.csv_locale.CsvLocale`
  (source sets, possession plans) reads a spreadsheet locale's CSV (``;`` or tab, decimal
  commas) as :mod:`dbtools.csv_locale` decides, with one ``source.locale`` finding; for the
  others (run folders' streams, ``gis grid`` inputs) a header without a comma that splits on
  ``;``, tab or ``|`` is read with that delimiter, so that the other findings name the right
  cells, and is an error (``source.delimiter``): their format is comma-separated.
* **quotes** — an opening quote that is never closed, and a quoted cell that spans lines
  (a stray quote that swallowed the rows up to the next quote), are refused (InputError)
  naming the line and the column: no cell of a table holds a line break.
* **duplicated header names** — an error (``source.duplicate_column``) naming the column
  and its positions; only the first of them is read.
* **codes in .xlsx** — a number in a code column has lost its leading zeros in the
  workbook (01 → 1): an error (``source.numeric_code``) naming the cell, unless the cell's
  number format displays the zeros (``00``), in which case the cell is read as displayed.
* **dates in text columns of .xlsx** — a date or time in a text column (a code such as
  ``2026-01`` that Excel turned into a date): an error (``source.date_in_text``) naming the
  sheet and the cell; format the column as Text.
* **which sheet of an .xlsx** — the sheet named like the table, else the first *visible*
  sheet. A hidden (or very hidden) sheet is never read silently: the sheet named like the
  table being hidden is an error (``source.hidden_sheet``), hidden sheets before the first
  visible one are skipped with a warning naming them; a workbook without a visible sheet is
  refused.

:func:`read_table_file` returns the frame with these findings; :func:`read_raw_table`
(log streams, plans, survey files) raises the first error as an InputError instead.

Findings:

* ``source.encoding`` (warning) — the file is not UTF-8; it was read in another encoding.
  Fix: check the text in the output and save the file as UTF-8.
* ``source.duplicate_column`` (error) — a column name appears twice in the header; only the
  first is read. Fix: rename or delete the others.
* ``source.numeric_code`` (error) — an .xlsx cell of a code column holds a number, which has
  lost its leading zeros (01 → 1). Fix: format the column as Text and type the codes again.
* ``source.date_in_text`` (error) — an .xlsx cell of a text column holds a date: Excel turned
  the value typed there into one. Fix: format the column as Text and type the value again.
* ``source.hidden_sheet`` (warning / error) — a sheet of the workbook is hidden: an error
  when it is the sheet that was read (a hidden sheet often holds old data), a warning when it
  was skipped for the first visible one. Fix: unhide the sheet if it holds the current data,
  else delete it, or name the sheet to read like the table.
"""

from __future__ import annotations

import csv
import datetime as dt
import hashlib
import io
import re
import zipfile
from collections.abc import Collection
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from dbtools.csv_locale import CsvLocale, machine_delimiter_finding, read_dialect, sniff_delimiter
from dbtools.inputs import check_zip, regular_file
from schemas.enums import Severity
from schemas.errors import InputError
from schemas.findings import Finding

if TYPE_CHECKING:
    from schemas.model import Table

TABULAR_SUFFIXES = (".csv", ".xlsx")
#: Cells named one by one per column for numeric codes; beyond, one finding counts the rest.
MAX_CELLS_NAMED = 10


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def find_table_file(folder: Path, stem: str) -> Path | None:
    """``stem.csv`` or ``stem.xlsx`` in ``folder``; an error when both exist. Anything of
    that name but a folder counts: a FIFO or device is then refused by name when read
    (:func:`dbtools.inputs.regular_file`), not reported missing."""
    found = [p for s in TABULAR_SUFFIXES if (p := folder / f"{stem}{s}").exists() and not p.is_dir()]
    if len(found) > 1:
        raise InputError(f"both {found[0].name} and {found[1].name} exist; keep one", path=folder)
    return found[0] if found else None


@dataclass
class TableFile:
    """The raw text cells of a file and what was found while reading it."""

    frame: pd.DataFrame
    findings: list[Finding] = field(default_factory=list)


def read_table_file(
    path: Path,
    *,
    table: str = "",
    sheet: str | None = None,
    code_columns: Collection[str] = (),
    text_columns: Collection[str] = (),
    locale: CsvLocale | None = None,
    numeric_columns: Collection[str] = (),
) -> TableFile:
    """All cells as text (leading zeros kept, empty cells as empty strings), plus findings
    (module docstring) for ``table``. ``code_columns``: the columns whose numeric .xlsx
    cells are reported; ``text_columns``: those whose date cells are. ``locale``: a CSV in a
    spreadsheet locale is read as :mod:`dbtools.csv_locale` decides (None: the machine
    format only), its ``numeric_columns`` turned into machine notation. InputError when the
    file cannot be read at all."""
    path = regular_file(Path(path), "CSV or .xlsx file")
    if path.suffix.lower() == ".xlsx":
        tf = _read_xlsx(path, sheet, table, _TextColumns(frozenset(code_columns), frozenset(text_columns)))
    else:
        tf = _read_csv(path, table, locale, numeric_columns)
    empty = [i + 1 for i, c in enumerate(tf.frame.columns) if str(c).startswith("Unnamed:") or not str(c).strip()]
    if empty:
        raise InputError(f"header has empty column name(s) at position {empty}", path=path, row=1)
    return tf


def read_checked_table(
    path: Path, sheet: str | None = None, declared: Table | None = None, locale: CsvLocale | None = None
) -> TableFile:
    """:func:`read_table_file` of a file of ``declared`` (its :func:`code_columns` checked in
    a workbook, its number columns read in ``locale``); its first error finding raised as an
    InputError, the warnings returned with the frame."""
    codes = code_columns(declared) if declared is not None else ()
    texts = text_columns(declared) if declared is not None else ()
    numbers = [c.name for c in declared.columns if c.dtype in ("float", "int")] if declared is not None else ()
    tf = read_table_file(
        path,
        table=declared.name if declared is not None else "",
        sheet=sheet,
        code_columns=codes,
        text_columns=texts,
        locale=locale,
        numeric_columns=numbers,
    )
    for f in tf.findings:
        if f.severity == Severity.ERROR:
            raise InputError(f.message, path=path, row=f.row, column=f.column)
    return tf


def read_raw_table(path: Path, sheet: str | None = None, declared: Table | None = None) -> pd.DataFrame:
    """:func:`read_checked_table`'s frame of a file in the machine format (run folders'
    streams, ``gis grid`` inputs)."""
    return read_checked_table(path, sheet, declared).frame


def code_columns(table: Table) -> list[str]:
    """Text columns holding codes (keys, ``*_code``, ``*_id``): a number there has lost its
    leading zeros in a workbook (:mod:`dbtools.tabular`)."""
    return [
        c.name
        for c in table.columns
        if c.dtype == "str" and (c.name in table.primary_key or c.name.endswith(("_code", "_id")))
    ]


def text_columns(table: Table) -> list[str]:
    """Every text column of ``table``: a date there is a value Excel turned into a date."""
    return [c.name for c in table.columns if c.dtype == "str"]


# ------------------------------------------------------------------------------------ CSV


def _read_csv(path: Path, table: str, locale: CsvLocale | None, numeric: Collection[str]) -> TableFile:
    findings: list[Finding] = []
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    if not head.strip():
        raise InputError("file is empty (no header line)", path=path)
    if locale is None:
        sep, wrong = machine_delimiter_finding(path, table)
        findings += [wrong] if wrong is not None else []
    else:
        sniffed = sniff_delimiter(path, locale)
        sep = sniffed[0]
    fast = _read_csv_fast(path) if sep == "," else None  # checked for line breaks already
    utf8 = None if head.startswith((b"\xff\xfe", b"\xfe\xff")) else fast if fast is not None else _utf8(path, sep)
    if utf8 is None:  # not UTF-8: the whole file decoded in the encoding it has
        decoded, note = _decode_other(path, table)
        findings.append(note)
        frame = _parse_text(path, decoded, sep)
        header = decoded.lstrip("\ufeff").split("\n", 1)[0]
    else:
        frame = utf8
        header = head.decode("utf-8", errors="replace").lstrip("\ufeff").split("\n", 1)[0]
    if fast is None:
        _refuse_multiline(frame, path)
    frame, dups = _drop_duplicates(frame, _header_names(header, sep), path, table)
    if locale is not None:
        frame, dialect = read_dialect(frame, numeric, path, locale, sniffed)
        found = dialect.finding(path, table)
        findings += [found] if found is not None else []
    return TableFile(frame, findings + dups)


def _utf8(path: Path, sep: str) -> pd.DataFrame | None:
    """The frame of a UTF-8 file (BOM or not) by the C parser; None when it is not UTF-8."""
    try:
        return _parse(path, sep, lambda: pd.read_csv(path, **_csv_options(sep), encoding="utf-8-sig"))
    except UnicodeDecodeError:
        return None


def _csv_options(sep: str) -> dict[str, Any]:
    return {"dtype": str, "keep_default_na": False, "skipinitialspace": True, "sep": sep}


def _parse(path: Path, sep: str, read: Any) -> pd.DataFrame:
    """``read()`` with the parser's errors as InputErrors naming the line."""
    try:
        frame: pd.DataFrame = read()
    except pd.errors.EmptyDataError as exc:
        raise InputError("file is empty (no header line)", path=path) from exc
    except pd.errors.ParserError as exc:
        raise _parser_error(path, str(exc), sep) from exc
    return frame


def _parse_text(path: Path, text: str, sep: str) -> pd.DataFrame:
    return _parse(path, sep, lambda: pd.read_csv(io.StringIO(text.lstrip("\ufeff")), **_csv_options(sep)))


_EOF_RE = re.compile(r"EOF inside string starting at row (\d+)")
_FIELDS_RE = re.compile(r"Expected (\d+) fields in line (\d+), saw (\d+)")


def _parser_error(path: Path, msg: str, sep: str) -> InputError:
    m = _EOF_RE.search(msg)
    if m:  # the parser's row is the 0-based line the quoted cell starts on
        line = int(m.group(1)) + 1
        return InputError(
            'a quote (") opens a cell here and is never closed: the rest of the file would be one cell',
            path=path,
            row=line,
            column=_column_at_quote(path, line, sep),
        )
    m = _FIELDS_RE.search(msg)
    if m:
        return InputError(
            f"{m.group(3)} fields where the header has {m.group(1)}: a cell holding "
            f"{'a comma' if sep == ',' else repr(sep)} needs quotes",
            path=path,
            row=int(m.group(2)),
        )
    return InputError(f"malformed CSV: {msg.strip()}", path=path)


def _column_at_quote(path: Path, line: int, sep: str) -> str | None:
    """The header name of the column whose cell opens the unclosed quote on ``line``."""
    with open(path, encoding="utf-8-sig", errors="replace") as fh:
        lines = [next(fh, "") for _ in range(line)]
    row = lines[-1]
    pos = row.rfind('"')  # the quotes before it (if any) pair up
    if pos < 0:
        return None
    idx = max(len(_header_names(row[:pos], sep)) - 1, 0)  # the cell the quote opens
    names = _header_names(lines[0], sep)
    return names[idx] if 0 <= idx < len(names) else None


#: What CP932 decodes its unassigned bytes (0x80, 0xA0, 0xFD–0xFF) and user-defined
#: characters to: control and private-use code points, never in a maintenance file.
_CP932_UNUSED = re.compile("[\x80-\x9f\ue000-\uf8ff]")


def _decode_other(path: Path, table: str) -> tuple[str, Finding]:
    """A non-UTF-8 file's text and the warning naming its encoding; InputError when it is
    neither UTF-16 (with BOM) nor Shift-JIS (CP932)."""
    raw = path.read_bytes()
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        encoding, line = "UTF-16", 1
        try:
            text = raw.decode("utf-16")
        except UnicodeDecodeError as exc:
            raise InputError("starts with a UTF-16 byte-order mark but is not UTF-16 text", path=path) from exc
    else:
        try:
            raw.decode("utf-8")
            raise InputError("not readable as text", path=path)  # pragma: no cover - UTF-8 was refused
        except UnicodeDecodeError as exc:
            line = raw[: exc.start].count(b"\n") + 1
        encoding = "Shift-JIS (CP932)"
        try:
            text = raw.decode("cp932")
        except UnicodeDecodeError:
            text = ""
        if not text or _CP932_UNUSED.search(text):  # bytes no Japanese text has: another encoding
            raise InputError(
                f"not UTF-8 text (line {line} is the first that is not), nor Shift-JIS (CP932): "
                "save the file as UTF-8 CSV",
                path=path,
                row=line,
            )
    note = Finding(
        "source.encoding",
        Severity.WARNING,
        table,
        f"not UTF-8 (line {line} is the first that is not): read as {encoding}; "
        "check the text in the output, and save the file as UTF-8 to be sure",
        file=str(path),
        row=line,
        value=encoding,
        limit="UTF-8",
    )
    return text.replace("\r\n", "\n"), note


def _header_names(header: str, sep: str) -> list[str]:
    """The names of a header line as the csv module splits it (none if it cannot)."""
    try:
        return [c.strip() for c in next(csv.reader([header.rstrip("\r\n")], delimiter=sep), [])]
    except csv.Error:  # e.g. a lone carriage return: the parser's own findings follow
        return []


def _drop_duplicates(
    frame: pd.DataFrame, names: list[str], path: Path, table: str
) -> tuple[pd.DataFrame, list[Finding]]:
    """The frame without the later copies of a repeated header name, and one finding per name."""
    seen: dict[str, list[int]] = {}
    for i, n in enumerate(names):
        seen.setdefault(n, []).append(i)
    repeated = {n: pos for n, pos in seen.items() if len(pos) > 1 and n}
    if not repeated or len(names) != frame.shape[1]:
        return frame, []
    findings = [
        Finding(
            "source.duplicate_column",
            Severity.ERROR,
            table,
            f"column '{n}' appears {len(pos)} times in the header (columns {', '.join(str(p + 1) for p in pos)}); "
            "only the first is read: rename or delete the others",
            file=str(path),
            row=1,
            column=n,
            value=len(pos),
            limit=1,
        )
        for n, pos in repeated.items()
    ]
    drop = {p for pos in repeated.values() for p in pos[1:]}
    keep = [i for i in range(frame.shape[1]) if i not in drop]
    out = frame.iloc[:, keep]
    out.columns = [names[i] for i in keep]
    return out, findings


def _refuse_multiline(frame: pd.DataFrame, path: Path) -> None:
    """InputError naming line and column of the first cell that holds a line break."""
    first: tuple[int, str] | None = None
    for c in frame.columns:
        s = frame[c]
        if s.dtype != object and not pd.api.types.is_string_dtype(s.dtype):
            continue
        hit = s.astype("string").str.contains(r"[\r\n]", regex=True, na=False).to_numpy(dtype=bool)
        if hit.any():
            r = int(hit.argmax())
            if first is None or r < first[0]:
                first = (r, str(c))
    if first is None:
        return
    r, col = first
    breaks = sum(int(frame[c].iloc[:r].astype("string").str.count("\n").fillna(0).sum()) for c in frame.columns)
    line = r + 2 + breaks  # header line 1, first data line 2, plus the line breaks inside earlier cells
    span = int(str(frame[col].iat[r]).count("\n"))
    raise InputError(
        f'a quoted cell spans lines {line}–{line + span}: a quote (") is not closed where it should be, so those '
        "lines were read as one cell (no cell may hold a line break): remove the stray quote",
        path=path,
        row=line,
        column=col,
    )


def _read_csv_fast(path: Path) -> pd.DataFrame | None:
    """The same frame as the C parser gives, ~10× faster (pyarrow's CSV reader), or None.

    None whenever the fast reader fails or its result could differ from the C parser's
    (a field or header with leading blanks, which ``skipinitialspace`` would strip; a cell
    holding a line break, which pyarrow reads silently — an unclosed quote swallows the
    rest of the file): the caller then reads with the C parser, which also produces the
    established error messages for malformed files.
    """
    try:
        frame = pd.read_csv(path, dtype=str, keep_default_na=False, engine="pyarrow")
    except Exception:  # any problem at all: let the C parser read (or reject) the file
        return None
    for c in frame.columns:
        if str(c)[:1].isspace():
            return None
        col = frame[c]
        if len(col) and (col.str.match(r"[ \t]").any() or col.str.contains(r"[\r\n]", regex=True).any()):
            return None
    return frame


# ----------------------------------------------------------------------------------- XLSX


@dataclass(frozen=True)
class _TextColumns:
    """The columns of a sheet whose cells are checked: codes (numbers) and text (dates)."""

    codes: frozenset[str]
    texts: frozenset[str]


def _read_xlsx(path: Path, sheet: str | None, table: str, columns: _TextColumns) -> TableFile:
    import openpyxl
    from openpyxl.utils.exceptions import InvalidFileException

    check_zip(path)  # a zip bomb is refused before openpyxl reads a member
    try:
        book = openpyxl.load_workbook(path, read_only=True, data_only=True, keep_links=False)
    except (zipfile.BadZipFile, InvalidFileException, ValueError, OSError, KeyError) as exc:
        raise InputError(f"not a readable .xlsx workbook: {exc}", path=path) from exc
    try:
        ws, chosen = _choose_sheet(book, sheet, path, table)
        try:
            tf = _sheet(ws, path, table, columns)
        except (ValueError, KeyError, TypeError, AttributeError, zipfile.BadZipFile) as exc:
            raise InputError(f"sheet '{ws.title}' cannot be read: {exc}", path=path) from exc
        return TableFile(tf.frame, chosen + tf.findings)
    finally:
        book.close()  # an open workbook leaks a ResourceWarning later


def _choose_sheet(book: Any, wanted: str | None, path: Path, table: str) -> tuple[Any, list[Finding]]:
    """The worksheet to read (module docstring) and the findings of that choice."""
    sheets = list(book.worksheets)
    named = [ws for ws in sheets if wanted is not None and ws.title == wanted]
    if named:
        ws = named[0]
        if ws.sheet_state == "visible":
            return ws, []
        return ws, [
            Finding(
                "source.hidden_sheet",
                Severity.ERROR,
                table,
                f"sheet '{ws.title}' is hidden ({ws.sheet_state}): a hidden sheet often holds old data; unhide it "
                "if it holds the current data, else delete it",
                file=str(path),
                value=ws.title,
                limit="visible",
            )
        ]
    visible = [ws for ws in sheets if ws.sheet_state == "visible"]
    if not visible:
        raise InputError("the workbook has no visible worksheet: unhide the sheet to read", path=path)
    ws = visible[0]
    skipped = sheets[: sheets.index(ws)]
    return ws, [
        Finding(
            "source.hidden_sheet",
            Severity.WARNING,
            table,
            f"sheet '{h.title}' is hidden ({h.sheet_state}) and was not read; sheet '{ws.title}', the first visible "
            "one, was: delete the hidden sheet, or name the sheet to read like the table",
            file=str(path),
            value=h.title,
            limit="visible",
        )
        for h in skipped
    ]


def _cell_text(v: object) -> str:
    """A cell's value as pandas' ``read_excel(dtype=str)`` gives it (whole floats as ints)."""
    if v is None:
        return ""
    if isinstance(v, float) and v.is_integer():
        return str(int(v))
    return str(v)


_ZEROS = re.compile(r"0+")
#: Cell values of a date, time or duration (what Excel makes of a code typed as ``01-02``).
_DATES = (dt.date, dt.time, dt.timedelta)
#: Cells of one column recorded for a finding: (row, cell reference, text).
_Cells = dict[str, list[tuple[int, str, str]]]


def _sheet(ws: Any, path: Path, table: str, columns: _TextColumns) -> TableFile:
    rows = ws.iter_rows()
    header = next(rows, None)
    if header is None:
        raise InputError(f"sheet '{ws.title}' is empty (no header row)", path=path)
    names = [_cell_text(c.value).strip() for c in header]
    while names and not names[-1]:
        names.pop()
    codes = {i for i, n in enumerate(names) if n in columns.codes}
    texts = {i for i, n in enumerate(names) if n in columns.texts or n in columns.codes}
    data: list[list[str]] = []
    numeric: _Cells = {}
    dates: _Cells = {}
    for r, cells in enumerate(rows, start=2):
        vals = [_cell_text(c.value) for c in cells]
        if not any(v.strip() for v in vals):
            continue  # an empty row (as pandas skips it)
        if any(v.strip() for v in vals[len(names) :]):
            names += [""] * (len(vals) - len(names))  # data beyond the header: an empty header name
        for i in codes:
            if i < len(cells) and cells[i].data_type == "n" and cells[i].value is not None:
                vals[i] = _numeric_code(cells[i], vals[i], names[i], r, numeric)
        for i in texts:
            if i < len(cells) and isinstance(cells[i].value, _DATES):
                dates.setdefault(names[i], []).append((r, f"{cells[i].column_letter}{r}", vals[i]))
        data.append((vals + [""] * len(names))[: len(names)])
    names = [n if n else f"Unnamed: {i}" for i, n in enumerate(names)]  # refused by the caller
    frame, findings = _drop_duplicates(pd.DataFrame(data, columns=names, dtype=object), names, path, table)
    return TableFile(frame, findings + _cell_findings(numeric, dates, path, table, ws.title))


def _numeric_code(cell: Any, text: str, name: str, row: int, numeric: _Cells) -> str:
    """A numeric cell of a code column: as displayed when its format shows the zeros
    (``00`` → 01), else recorded for a finding and read as its digits."""
    fmt = str(cell.number_format or "")
    value = float(cell.value)
    if _ZEROS.fullmatch(fmt) and value.is_integer() and value >= 0:
        return str(int(value)).zfill(len(fmt))
    numeric.setdefault(name, []).append((row, f"{cell.column_letter}{row}", text))
    return text


def _cell_findings(numeric: _Cells, dates: _Cells, path: Path, table: str, sheet: str) -> list[Finding]:
    """``source.numeric_code`` and ``source.date_in_text`` errors, one per cell up to
    :data:`MAX_CELLS_NAMED` a column, then one counting the rest."""
    kinds = (
        (
            "source.numeric_code",
            numeric,
            "the number {text}, not text: a code stored as a number has lost its leading zeros (01 → 1)",
            "numbers",
        ),
        (
            "source.date_in_text",
            dates,
            "a date ({text}), not text: Excel turned the value typed there into a date",
            "dates",
        ),
    )
    out: list[Finding] = []
    for rule, found, what, plural in kinds:
        for name, cells in found.items():
            for row, ref, text in cells[:MAX_CELLS_NAMED]:
                out.append(
                    Finding(
                        rule,
                        Severity.ERROR,
                        table,
                        f"cell {ref} holds {what.format(text=text)}; format the column as Text and type the "
                        f"values again (sheet '{sheet}')",
                        file=str(path),
                        row=row,
                        column=name,
                        value=text,
                        limit="text",
                    )
                )
            if len(cells) > MAX_CELLS_NAMED:
                out.append(
                    Finding(
                        rule,
                        Severity.ERROR,
                        table,
                        f"{len(cells) - MAX_CELLS_NAMED} more cells of '{name}' (sheet '{sheet}') hold {plural}, "
                        "not text",
                        file=str(path),
                        column=name,
                        value=len(cells),
                        limit=0,
                    )
                )
    return out
