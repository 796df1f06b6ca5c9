"""Spreadsheet locales of CSV inputs: which delimiter and which decimal separator a file uses.

The suite's own CSV format is the machine one: fields separated by commas, decimal points,
no thousands separators. A spreadsheet saved as CSV in a German, French or Finnish locale
(Excel's "CSV (semicolon delimited)", or "Unicode text") has fields separated by ``;`` or
tabs and decimal commas (``12,5``), often behind a UTF-8 byte-order mark. Every reader of a
user-given table that accepts such files — source sets (``db build``, ``db validate``),
possession plans (``possession check``), vendor CSV with a mapping (``logs import``) — goes
through this module, so one file is judged the same way everywhere:

* **Declared** (:class:`CsvLocale`: ``--delimiter`` / ``--decimal``, or ``[csv]`` in a source
  set's ``network.toml``): the file is read so; a file that contradicts the declaration is
  refused (InputError naming file, line and column), never read another way. A decimal
  comma in a comma-separated file cannot be (UsageError).
* **Detected** (nothing declared): the delimiter is the one of ``,``, ``;``, tab and ``|``
  that splits the header into two fields or more and every one of the first
  :data:`SNIFF_LINES` lines of the head (:func:`dbtools.inputs.read_head`) into as many
  (quotes respected); two such delimiters are ambiguous and refused; none — a row too short
  or too long early on — falls back to the header's (a comma if it has one), for the parser
  to name the line. The decimal separator matters only when the delimiter is not a comma
  (a comma-separated file has decimal points by construction); it is judged on **every**
  cell of the declared number columns (not the head only: a decimal comma at row 10⁶ is
  seen): cells with one comma are decimal commas, with one point decimal points. Both in
  one file is a mix and refused, naming the first cell of the later kind. When every such
  cell has exactly three digits after its separator (``1,234``, ``1.234``) it may as well
  be a thousands separator: ambiguous, refused until ``--decimal`` says which.
* **Excel's ``sep=;`` hint line** (some exports put it before the header) is refused,
  naming it: delete that line.
* **Thousands separators are never read as decimals**: a number cell with both a comma
  and a point (``1.234,5``, ``1,234.5``), two of either (``1.234.567``), or a space,
  no-break space or apostrophe between digits (``1 234,5``, ``1'234.5``) is refused in a
  file that is not comma-separated, whatever is declared.

A file read in a detected non-machine convention gives **one** finding naming it (not one
per cell). A source file whose head settles its notation (:func:`head_dialect`) is parsed
by the typed reader in it (:class:`dbtools.typed_csv.Notation`: every cell is parsed, so a
cell of another notation or with a thousands separator further down declines the file);
any other file is read as text, judged on every cell (:func:`read_dialect`) and its number
cells turned into the machine notation (:func:`machine_numbers`: ``12,5`` → ``12.5``)
before the usual coercion. Both give the numbers of the machine-format copy bit for bit
(fast_float, correctly rounded with either separator), so a source set in a locale builds
the same DB — the same content hash. The suite's own outputs stay in the machine format.

Findings:

* ``source.locale`` (warning) — a CSV file is not in the machine format (comma-separated,
  decimal points) but in a spreadsheet locale's, detected without ambiguity (e.g.
  ``;``-separated with decimal commas); it was read in that convention. Fix: nothing if that
  is what the file is; declare the convention (``--delimiter``/``--decimal``, or ``[csv]`` in
  the source set's ``network.toml``) to read it without this warning, or save it as CSV
  (comma delimited) with decimal points.
* ``source.delimiter`` (error) — the fields of a CSV that must be in the machine format (a
  run folder's stream, a ``gis grid`` input) are separated by semicolons, tabs or vertical
  bars, not commas. Fix: save the file as CSV (comma delimited).
"""

from __future__ import annotations

import csv
import re
from collections.abc import Collection
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.inputs import read_head
from schemas.enums import Severity
from schemas.errors import InputError, UsageError
from schemas.findings import Finding

#: Delimiters recognised, with their names for messages.
DELIMITERS = {",": "comma", ";": "semicolon", "\t": "tab", "|": "vertical bar"}
#: Names a delimiter may be given by on the command line (a tab is hard to type).
DELIMITER_WORDS = {"comma": ",", "semicolon": ";", "tab": "\t", "\\t": "\t", "pipe": "|"}
#: Decimal separators, with their names for messages.
DECIMALS = {".": "decimal points", ",": "decimal commas"}
#: Lines of the head whose field counts decide the delimiter.
SNIFF_LINES = 50
#: Bytes of the head read for it.
SNIFF_BYTES = 1 << 16
UTF8_BOM = b"\xef\xbb\xbf"
_UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")
#: Where a declaration comes from, unless said otherwise (messages).
OPTIONS = "--delimiter/--decimal"


def _shown(sep: str) -> str:
    return "tab" if sep == "\t" else f"'{sep}'"


def _said(given: CsvLocale, option: str) -> str:
    """Who declared it, for messages: ``--decimal``, or the file and table of a setting."""
    return f"--{option}" if given.origin == OPTIONS else given.origin


@dataclass(frozen=True)
class CsvLocale:
    """A declared convention; None: detect it. ``origin`` names the declaration in messages
    (``--decimal``, ``network.toml [csv]``). UsageError on anything else than a delimiter of
    :data:`DELIMITERS` (or a word of :data:`DELIMITER_WORDS`) and ``.`` or ``,``."""

    delimiter: str | None = None
    decimal: str | None = None
    origin: str = OPTIONS

    def __post_init__(self) -> None:
        if self.delimiter is not None:
            sep = DELIMITER_WORDS.get(self.delimiter.lower(), self.delimiter)
            if sep not in DELIMITERS:
                raise UsageError(
                    f"{self.origin}: delimiter {self.delimiter!r} is not one of ',', ';', tab (or 'tab'), '|'"
                )
            object.__setattr__(self, "delimiter", sep)
        if self.decimal is not None and self.decimal not in DECIMALS:
            raise UsageError(f"{self.origin}: decimal separator {self.decimal!r} is not '.' or ','")
        if self.delimiter == "," and self.decimal == ",":
            raise UsageError(
                f"{self.origin}: a decimal comma needs another delimiter than the comma (a comma separates the fields)"
            )

    def over(self, other: CsvLocale) -> CsvLocale:
        """This declaration, with ``other``'s where this one says nothing (options over a
        source set's ``network.toml``)."""
        if other.delimiter is None and other.decimal is None:
            return self
        if self.delimiter is None and self.decimal is None:
            return other
        return CsvLocale(
            self.delimiter if self.delimiter is not None else other.delimiter,
            self.decimal if self.decimal is not None else other.decimal,
            f"{self.origin} with {other.origin}",
        )


def csv_table(table: object, path: Path | str) -> CsvLocale:
    """The convention a ``[csv]`` table of a TOML file declares (``delimiter``: ``,``, ``;``,
    ``tab``, ``|``; ``decimal``: ``.``, ``,``; a source set's ``network.toml``, a mapping);
    InputError naming the file on an unknown key or value."""
    unknown = sorted(set(table) - {"delimiter", "decimal"}) if isinstance(table, dict) else ["csv"]
    if unknown or not isinstance(table, dict):
        raise InputError(f"[csv]: unknown key(s) {', '.join(unknown)} (known: delimiter, decimal)", path=path)
    if not all(isinstance(v, str) for v in table.values()):
        raise InputError('[csv]: delimiter and decimal are text (delimiter = ";", decimal = ",")', path=path)
    try:
        return CsvLocale(table.get("delimiter"), table.get("decimal"), f"{Path(path).name} [csv]")
    except UsageError as exc:
        raise InputError(exc.message, path=path, column="csv") from exc


@dataclass(frozen=True)
class Dialect:
    """How a file was read: its delimiter, decimal separator, whether it had a UTF-8
    byte-order mark, and which of the two were detected rather than declared."""

    delimiter: str
    decimal: str = "."
    bom: bool = False
    detected: frozenset[str] = frozenset()

    @property
    def machine(self) -> bool:
        """Comma-separated with decimal points: the suite's own format."""
        return self.delimiter == "," and self.decimal == "."

    def describe(self) -> str:
        """``;``-separated with decimal commas (and a UTF-8 byte-order mark)."""
        sep = "tab" if self.delimiter == "\t" else f"`{self.delimiter}`"
        decimal = f" with {DECIMALS[self.decimal]}" if self.decimal == "," or "decimal" in self.detected else ""
        bom = " (UTF-8 with a byte-order mark)" if self.bom else ""
        return f"{sep}-separated{decimal}{bom}"

    def finding(self, path: Path, table: str) -> Finding | None:
        """The one ``source.locale`` warning of a file read in a detected non-machine
        convention; None when the file is in the machine format or all was declared."""
        if self.machine or not self.detected:
            return None
        return Finding(
            "source.locale",
            Severity.WARNING,
            table,
            f"{self.describe()}: read in that convention (a spreadsheet locale's CSV); declare it "
            f"({OPTIONS}, or a [csv] table in the source set's network.toml or the CSV's mapping) to read it "
            "without this warning",
            file=str(path),
            value=self.describe(),
            limit="`,`-separated with decimal points",
        )


def _head_lines(head: bytes) -> list[str]:
    """The complete, non-blank lines of a head (the last one dropped when the head was cut)."""
    cut = len(head) >= SNIFF_BYTES
    if head.startswith(_UTF16_BOMS):
        text = head[: len(head) // 2 * 2].decode("utf-16", errors="replace")
    else:
        text = head.removeprefix(UTF8_BOM).decode("utf-8", errors="replace")
    lines = text.splitlines()
    if cut and lines:
        lines.pop()
    return [ln for ln in lines if ln.strip()][:SNIFF_LINES]


def _field_counts(lines: list[str], sep: str) -> list[int]:
    try:
        return [len(row) for row in csv.reader(lines, delimiter=sep)]
    except csv.Error:
        return []


def consistent_delimiters(head: bytes) -> dict[str, int]:
    """Delimiter → fields per line, for each delimiter that splits the header into two fields
    or more and every line of the head into as many."""
    lines = _head_lines(head)
    out = {}
    for sep in DELIMITERS:
        counts = _field_counts(lines, sep)
        if counts and counts[0] >= 2 and len(set(counts)) == 1:
            out[sep] = counts[0]
    return out


def header_delimiter(head: bytes) -> str:
    """``,`` unless the header line has no comma and another delimiter is in it."""
    lines = _head_lines(head) or [""]
    first = lines[0]
    if "," in first:
        return ","
    return next((sep for sep in DELIMITERS if sep in first), ",")


def sniff_delimiter(path: Path, given: CsvLocale) -> tuple[str, bool, bool]:
    """(delimiter, detected, UTF-8 BOM) of a CSV file from its head (module docstring);
    InputError when the head contradicts the declared delimiter or splits evenly on two."""
    head = read_head(path, SNIFF_BYTES)
    bom = head.startswith(UTF8_BOM)
    lines = _head_lines(head)
    if lines and re.fullmatch(r'"?sep=.?"?', lines[0].strip(), flags=re.IGNORECASE):
        raise InputError(
            f"line 1 ({lines[0].strip()!r}) is Excel's delimiter hint, not the header: delete that line (the delimiter "
            f"is detected, or declared with {OPTIONS})",
            path=path,
            row=1,
        )
    found = consistent_delimiters(head)
    n = len(lines)
    if given.delimiter is not None:
        if found and given.delimiter not in found:
            sep, fields = next(iter(found.items()))
            raise InputError(
                f"the first {n} line(s) are {DELIMITERS[sep]}-separated ({fields} fields each), not "
                f"{DELIMITERS[given.delimiter]}-separated as {_said(given, 'delimiter')} says",
                path=path,
                row=1,
            )
        return given.delimiter, False, bom
    if len(found) > 1:
        both = " and ".join(f"{_shown(s)} ({k} fields)" for s, k in found.items())
        raise InputError(
            f"ambiguous delimiter: each of the first {n} line(s) splits evenly on {both}; declare it ({OPTIONS})",
            path=path,
            row=1,
        )
    sep = next(iter(found)) if found else header_delimiter(head)
    return sep, sep != ",", bom


def machine_delimiter_finding(path: Path, table: str) -> tuple[str, Finding | None]:
    """For a file that must be in the machine format: the delimiter to read it with (so that
    the other findings name the right cells) and the ``source.delimiter`` error when it is
    not a comma."""
    sep = header_delimiter(read_head(path, SNIFF_BYTES))
    if sep == ",":
        return sep, None
    return sep, Finding(
        "source.delimiter",
        Severity.ERROR,
        table,
        f"fields are separated by {DELIMITERS[sep]}s ({sep!r}), not commas: save the file as CSV (comma delimited)",
        file=str(path),
        row=1,
        value=sep,
        limit=",",
    )


# ----------------------------------------------------------------------- decimal separators


@dataclass(frozen=True)
class _Cell:
    line: int
    column: str
    text: str


@dataclass
class _Kinds:
    """The first cell of each kind over the number columns, and whether every decimal
    cell of a kind looks like a thousands group (three digits after the separator)."""

    thousands: _Cell | None = None
    comma: _Cell | None = None
    point: _Cell | None = None
    comma_grouped: bool = True
    point_grouped: bool = True


def _first(current: _Cell | None, mask: np.ndarray, s: pd.Series, column: str, first_line: int) -> _Cell | None:
    """The earlier of ``current`` and the first cell of ``s`` where ``mask`` holds."""
    if not mask.any():
        return current
    i = int(mask.argmax())
    cell = _Cell(i + first_line, column, str(s.iat[i]).strip())
    return cell if current is None or cell.line < current.line else current


#: Digits with a space, no-break space, narrow no-break space or apostrophe between them.
_SPACED = r"\d[ \x{a0}\x{202f}']+\d"
#: One separator with exactly three digits after it and at most three before: a thousands group?
_GROUPED = r"^\s*[+-]?\d{1,3}[.,]\d{3}\s*$"


def _masks(s: pd.Series) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(thousands separator, one decimal comma, one decimal point, grouped) per cell, by
    Arrow's string kernels (one pass each over the column's buffer)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    arr = pa.array(s, type=pa.large_string(), from_pandas=True)
    commas = pc.count_substring(arr, ",").to_numpy(zero_copy_only=False)
    points = pc.count_substring(arr, ".").to_numpy(zero_copy_only=False)

    def mask(regex: str) -> np.ndarray:
        return np.asarray(pc.fill_null(pc.match_substring_regex(arr, regex), False).to_numpy(zero_copy_only=False))

    commas, points = np.nan_to_num(commas.astype(float)), np.nan_to_num(points.astype(float))
    thousands = ((commas > 0) & (points > 0)) | (commas > 1) | (points > 1) | mask(_SPACED)
    return thousands, (commas == 1) & ~thousands, (points == 1) & ~thousands, mask(_GROUPED)


def _classify(frame: pd.DataFrame, numeric: Collection[str], first_line: int) -> _Kinds:
    out = _Kinds()
    for column in (c for c in frame.columns if c in numeric):
        s = frame[column]
        thousands, comma, point, grouped = _masks(s)
        out.thousands = _first(out.thousands, thousands, s, str(column), first_line)
        out.comma = _first(out.comma, comma, s, str(column), first_line)
        out.point = _first(out.point, point, s, str(column), first_line)
        out.comma_grouped &= bool(grouped[comma].all())
        out.point_grouped &= bool(grouped[point].all())
    return out


def _refuse(path: Path, cell: _Cell, message: str) -> InputError:
    return InputError(f"'{cell.text}' {message}", path=path, row=cell.line, column=cell.column)


def decide_decimal(
    frame: pd.DataFrame,
    numeric: Collection[str],
    delimiter: str,
    given: CsvLocale,
    path: Path,
    first_line: int = 2,
) -> tuple[str, bool]:
    """(decimal separator, seen: whether a number cell showed it) of a file read as text
    cells with ``delimiter``, judged on every cell of its ``numeric`` columns (module
    docstring); InputError naming the cell that is a thousands separator, contradicts the
    declaration, mixes conventions or leaves the separator ambiguous. ``first_line``: the
    file line of the frame's first row."""
    if delimiter == ",":
        if given.decimal == ",":
            raise InputError(
                f"the file is comma-separated, so its decimal separator cannot be a comma "
                f"({_said(given, 'decimal')} says ',')",
                path=path,
                row=1,
            )
        return ".", False
    kinds = _classify(frame, numeric, first_line)
    if kinds.thousands is not None:
        raise _refuse(
            path,
            kinds.thousands,
            "has a thousands separator, which is never guessed: save the numbers without one (Excel: the "
            "column's number format without the 1000 separator)",
        )
    if given.decimal is not None:
        wrong = kinds.point if given.decimal == "," else kinds.comma
        if wrong is not None:
            raise _refuse(
                path,
                wrong,
                f"has a decimal {'point' if given.decimal == ',' else 'comma'}, but {_said(given, 'decimal')} says "
                f"the decimal separator is '{given.decimal}'",
            )
        return given.decimal, False
    if kinds.comma is not None and kinds.point is not None:
        later, earlier = (
            (kinds.comma, kinds.point) if kinds.comma.line > kinds.point.line else (kinds.point, kinds.comma)
        )
        raise _refuse(
            path,
            later,
            f"mixes decimal separators with '{earlier.text}' (line {earlier.line}, column '{earlier.column}'): "
            "use one throughout",
        )
    for sep, cell, grouped in ((",", kinds.comma, kinds.comma_grouped), (".", kinds.point, kinds.point_grouped)):
        if cell is not None and grouped:
            other = "." if sep == "," else ","
            raise _refuse(
                path,
                cell,
                f"is ambiguous: every number with a '{sep}' has three digits after it, so '{sep}' may be the decimal "
                f"separator or a thousands separator; declare it ({OPTIONS}: --decimal '{sep}', or '{other}' …)",
            )
    return ("," if kinds.comma is not None else "."), kinds.comma is not None or kinds.point is not None


def machine_numbers(frame: pd.DataFrame, numeric: Collection[str], decimal: str) -> pd.DataFrame:
    """The text frame with its number columns' decimal commas as points (``12,5`` → ``12.5``)
    when ``decimal`` is ``,``; the frame itself otherwise."""
    cols = [c for c in frame.columns if c in numeric]
    if decimal == "." or not cols:
        return frame
    import pyarrow as pa
    import pyarrow.compute as pc

    out = frame.copy()
    for c in cols:
        arr = pc.replace_substring(pa.array(frame[c], type=pa.large_string(), from_pandas=True), ",", ".")
        out[c] = pd.Series(arr.to_pandas(), index=frame.index).astype(frame[c].dtype)
    return out


def read_dialect(
    frame: pd.DataFrame, numeric: Collection[str], path: Path, given: CsvLocale, sniffed: tuple[str, bool, bool]
) -> tuple[pd.DataFrame, Dialect]:
    """The text frame in machine notation and the dialect it was read in, from the sniffed
    delimiter (:func:`sniff_delimiter`) and the decimal separator its cells show."""
    sep, sep_detected, bom = sniffed
    decimal, dec_detected = decide_decimal(frame, numeric, sep, given, path)
    detected = frozenset(k for k, d in (("delimiter", sep_detected), ("decimal", dec_detected)) if d)
    return machine_numbers(frame, numeric, decimal), Dialect(sep, decimal, bom, detected)


def head_dialect(path: Path, numeric: Collection[str], given: CsvLocale) -> Dialect | None:
    """The dialect of a CSV file settled by its head alone, for the typed reader
    (:mod:`dbtools.typed_csv`, which parses every cell in it: a cell of another notation or
    with a thousands separator does not parse, and the file goes to the text path, which
    names it); None when the head cannot settle it — a decimal comma declared for a
    comma-separated file, no decimal separator in the head's number cells, a mix, every one
    a three-digit group, a thousands separator: the text path (:func:`read_dialect`)
    judges every cell. InputError as :func:`sniff_delimiter`."""
    sep, sep_detected, bom = sniff_delimiter(path, given)
    detected = {"delimiter"} if sep_detected else set()
    if sep == ",":
        return None if given.decimal == "," else Dialect(",", ".", bom)
    if given.decimal is not None:
        return Dialect(sep, given.decimal, bom, frozenset(detected))
    rows = _field_rows(_head_lines(read_head(path, SNIFF_BYTES)), sep)
    if len(rows) < 2 or len(set(rows[0])) != len(rows[0]):
        return None
    head = pd.DataFrame([r for r in rows[1:] if len(r) == len(rows[0])], columns=rows[0], dtype=object)
    kinds = _classify(head, numeric, 2)
    if kinds.thousands is not None or (kinds.comma is not None and kinds.point is not None):
        return None
    if kinds.comma is not None and not kinds.comma_grouped:
        return Dialect(sep, ",", bom, frozenset({*detected, "decimal"}))
    if kinds.point is not None and not kinds.point_grouped:
        return Dialect(sep, ".", bom, frozenset({*detected, "decimal"}))
    return None


def _field_rows(lines: list[str], sep: str) -> list[list[str]]:
    try:
        return [[c.strip() for c in row] for row in csv.reader(lines, delimiter=sep)]
    except csv.Error:
        return []
