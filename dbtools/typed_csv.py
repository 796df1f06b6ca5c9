"""Typed reading of a CSV file of a declared table (a log stream, a source file): numbers
parsed while the file is read.

The general path (:func:`dbtools.tabular.read_raw_table`, then
:func:`schemas.frames.coerce_frame`) reads every cell as text and parses it afterwards,
which for an IMU stream (seven numbers per row at 100 Hz) or a national GIS grid builds
tens of millions of strings. Here the declared number columns are parsed straight into
float64 and the frame handed to ``coerce_frame`` holds numbers where it would have held
their text. Two parsers, both correctly rounded by the same algorithm (fast_float, which
coerce_frame's fast path applies to the text through Arrow): a file of number columns
only (IMU, tacho, GPS) by pandas's C parser (pandas ≥ 3.1), ≈ 20 % faster than Arrow's on
the IMU stream, which reads any piece the C parser declines (a blank cell, ``nan``, a short
row…) and every file with a text column, as before.

It gives the same typed frame and the same findings as the general path, so it declines
(returns None, and the caller reads as text) whenever that could differ: the file does not
parse with the declared number types (a bad cell: the text path names it), a parsed
value is infinite or NaN (the text path names the cell as written), a column name is
not a declared one or repeated, a text field starts with a blank (the C parser's
``skipinitialspace`` would strip it), or any cell holds a quote (Arrow parses here without
quote handling, which is faster; the text path reads quoted cells and names an unclosed
quote's line). A header-only file, a file in another encoding or with
another delimiter declines too: the text path reports those (:mod:`dbtools.tabular`).
A file in a spreadsheet locale (``;``, tabs, decimal commas: :mod:`dbtools.csv_locale`)
is read with its :class:`Notation` once that module has judged it from the head: both
parsers take the delimiter and the decimal separator (correctly rounded with a decimal comma
too), and a cell of another notation (``12.5`` among decimal commas, ``1.234,5``) does not
parse, so the file declines and the text path names the cell.
Cells the text path treats as blank — empty, or ``nan``/``na``/``null`` in any letter
case, padded or not — are nulls here too. Text columns are read as text and coerced
exactly as before. A whole number column is parsed
as float64 and checked by ``coerce_frame`` (integral values only: a fractional one declines,
for the text path to name it).
:func:`iter_csv_typed` gives the same frame in frames of a bounded number of rows.
Measurements: bench/bench_logs.py (against pyarrow.csv, polars and typed pandas) and
bench/bench_db.py (db build).
"""

from __future__ import annotations

import csv
import io
import itertools
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, NamedTuple

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from dbtools.inputs import regular_file
from schemas.model import Table

#: Bytes Arrow's CSV reader parses per block (its default).
BLOCK_BYTES = 1 << 20
#: Bytes of CSV :func:`read_csv_typed` has the C parser read at a time (whole lines, each
#: piece with the header). One piece for any log up to a day of IMU: pieces cost the
#: copy of every number into the final arrays and the page faults of each piece's
#: fresh buffers, ≈ 10–30 % of the read at 8 h (bench/NOTES.md); :func:`iter_csv_typed`
#: reads in pieces of about its ``rows`` for bounded memory.
PIECE_BYTES = 1 << 30
#: pandas's C parser is correctly rounded from 3.1 on (fast_float for every
#: ``float_precision``, pandas-dev/pandas#64432); before, its "high" converter was not
#: (1 ulp off on some cells), so Arrow's parser reads every file.
C_PARSER_EXACT = tuple(int(p) for p in re.findall(r"\d+", pd.__version__)[:2]) >= (3, 1)


class Notation(NamedTuple):
    """The delimiter and decimal separator a file is parsed with (the machine format's by
    default)."""

    delimiter: str = ","
    decimal: str = "."


MACHINE = Notation()


def _case_variants(word: str) -> list[str]:
    return ["".join(p) for p in itertools.product(*((ch.lower(), ch.upper()) for ch in word))]


#: Cells :func:`schemas.frames._blank` takes for blank, as Arrow null values (a padded one
#: makes the file decline: see the module docstring).
BLANK_CELLS = ["", *_case_variants("nan"), *_case_variants("na"), *_case_variants("null")]


def _names_fit(names: list[str], table: Table) -> bool:
    """Every column name a declared one, none repeated (else coerce_frame's findings and
    names are needed: the caller reads as text)."""
    declared = set(table.column_names)
    return len(set(names)) == len(names) and all(n in declared for n in names)


class TextPathNeeded(Exception):
    """Raised by :func:`iter_csv_typed`'s frames when the file turns out, part-way, to need
    the text path (a bad cell, an infinity, a quote… found in a later block): the caller
    drops the frames it has and reads the file as text."""


@dataclass
class _Block:
    """Rows of the file parsed with the declared types: number columns as float64 (NaN where
    null), their null counts, text columns as Arrow strings; ``nbytes`` the bytes of CSV
    they were parsed from (to size the whole file's arrays)."""

    names: list[str]
    numbers: dict[str, np.ndarray]
    nulls: dict[str, int]
    text: dict[str, pa.Array]
    rows: int
    nbytes: int
    finite: bool = False
    """The number columns are known to hold finite numbers and the nulls only (the C
    parser's blocks: checked as they were parsed)."""


class _Growing:
    """A float64 column filled block by block (over-allocated once from the first block's
    density, grown in place if the file's rows turn out shorter, trimmed at the end)."""

    def __init__(self) -> None:
        self.values = np.empty(0)
        self.n = 0

    def add(self, values: np.ndarray, capacity: int) -> None:
        m = len(values)
        if self.n + m > self.values.size:
            self.values.resize(max(capacity, int(1.25 * (self.n + m)) + 1024), refcheck=False)
        self.values[self.n : self.n + m] = values
        self.n += m

    def done(self) -> np.ndarray:
        self.values.resize(self.n, refcheck=False)
        return self.values


def _numeric(table: Table) -> set[str]:
    return {c.name for c in table.columns if c.dtype in ("float", "int")}


def _arrow_blocks(
    source: Path | pa.NativeFile, table: Table, block_bytes: int, size: int, notation: Notation = MACHINE
) -> Iterator[_Block]:
    """Arrow's streaming parse of ``source``, one block per record batch; raises
    :class:`TextPathNeeded` when the file does not parse with the declared types or its
    columns are not declared ones (module docstring)."""
    import pyarrow.csv as pcsv

    numeric = _numeric(table)
    types = {c.name: (pa.float64() if c.name in numeric else pa.string()) for c in table.columns}  # absent: ignored
    convert = pcsv.ConvertOptions(
        column_types=types,
        null_values=BLANK_CELLS,
        strings_can_be_null=False,
        quoted_strings_can_be_null=False,
        decimal_point=notation.decimal,
    )
    try:
        reader = pcsv.open_csv(
            source,
            read_options=pcsv.ReadOptions(block_size=block_bytes, use_threads=False),
            parse_options=pcsv.ParseOptions(quote_char=False, delimiter=notation.delimiter),
            convert_options=convert,
        )
        names = reader.schema.names
        if not _names_fit(names, table):
            raise TextPathNeeded
        for batch in reader:
            cols = [batch.column(i) for i in range(len(names))]
            yield _Block(
                names,
                {n: a.to_numpy(zero_copy_only=False) for n, a in zip(names, cols, strict=True) if n in numeric},
                {n: a.null_count for n, a in zip(names, cols, strict=True) if n in numeric},
                {n: a for n, a in zip(names, cols, strict=True) if n not in numeric},
                batch.num_rows,
                min(size, block_bytes),
            )
    except (pa.ArrowException, OSError, UnicodeDecodeError) as exc:
        raise TextPathNeeded from exc


class _Range(io.RawIOBase):
    """The header line, then bytes ``start:end`` of an open file: one piece of a CSV file
    as a file of its own, read in place (``preadv`` into the parser's buffer: no copy of
    the piece is made)."""

    def __init__(self, fh: BinaryIO, header: bytes, start: int, end: int) -> None:
        super().__init__()
        self._fd, self._head, self._pos, self._end = fh.fileno(), memoryview(header), start, end

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        if self._head.nbytes:
            n = min(len(buffer), self._head.nbytes)
            buffer[:n] = self._head[:n]
            self._head = self._head[n:]
            return n
        want = min(len(buffer), self._end - self._pos)
        if want <= 0:
            return 0
        got = os.preadv(self._fd, [memoryview(buffer)[:want]], self._pos)
        self._pos += got
        return got


def _header(fh: BinaryIO, delimiter: str = ",") -> tuple[bytes, list[str]] | None:
    """The header line (BOM and line end included) and its names; None when it is not
    a plain ``delimiter``-separated UTF-8 line (Arrow's path judges those)."""
    line = fh.readline(1 << 16)
    if not line.endswith(b"\n"):
        return None
    try:
        text = line.removeprefix(b"\xef\xbb\xbf").rstrip(b"\r\n").decode("utf-8")
    except UnicodeDecodeError:
        return None
    return line, text.split(delimiter)


def _piece_ends(fh: BinaryIO, start: int, size: int, piece_bytes: int) -> list[int]:
    """Ends of the pieces of a file from ``start``: each after the first line end past
    ``piece_bytes`` more bytes (a piece holds whole lines: without quote handling a line end
    always ends a row), the last at the end of the file."""
    ends = []
    pos = start
    while pos < size:
        target = pos + piece_bytes
        if target >= size:
            break
        fh.seek(target)
        skipped = 0
        while True:  # the next line end
            chunk = fh.read(1 << 16)
            k = chunk.find(b"\n")
            if k >= 0 or not chunk:
                break
            skipped += len(chunk)
        if k < 0:
            break
        pos = target + skipped + k + 1
        ends.append(pos)
    ends.append(size)
    return ends


def _c_numbers(
    source: Path | _Range, names: list[str], notation: Notation = MACHINE
) -> tuple[dict[str, np.ndarray], dict[str, int]] | None:
    """pandas's C parser on one piece of a file of number columns only (correctly rounded
    since pandas 3.1: fast_float, the parser Arrow uses): its number columns and their
    null counts, or None for Arrow's path to read the piece.

    The blank cells are the same nulls as Arrow's (``na_values``: the same list, matched on
    the cell as written), and pandas's converter never makes a NaN of a cell (``-nan`` or
    `` nan`` do not parse), so every NaN is a null, or a field missing from a short row:
    those fill the row's last columns, so a NaN in the last column declines the piece (a
    blank last cell too: Arrow tells them apart). Declined as well: a cell that does not
    parse (the parser's error: a quote too, with ``QUOTE_NONE``), an infinity, a row of
    spaces or an empty line (``skip_blank_lines=False``: no line is dropped unseen), a row
    longer than the header. Where it accepts a cell Arrow does not (a vertical tab or form
    feed around a number: pandas's whitespace rule is C's), the text path reads the same
    number, which the hypothesis tests check.

    ``source``: the file itself when it is one piece — pandas then reads it ahead in a
    thread of its own, ≈ 35 % less wall time for ≈ 20 % more CPU than the piece read in
    place (bench/NOTES.md) — else the piece (:class:`_Range`)."""
    try:
        frame = pd.read_csv(
            source,
            sep=notation.delimiter,
            decimal=notation.decimal,
            dtype="float64",
            engine="c",
            quoting=csv.QUOTE_NONE,
            na_values=BLANK_CELLS,
            keep_default_na=False,
            skip_blank_lines=False,
            encoding="utf-8",
        )
    except (ValueError, OverflowError):  # ParserError, EmptyDataError, UnicodeDecodeError included
        return None
    if list(frame.columns) != names or not isinstance(frame.index, pd.RangeIndex):
        return None
    numbers = {n: frame[n].to_numpy() for n in names}
    if any(v.dtype != np.float64 for v in numbers.values()):
        return None
    with np.errstate(over="ignore", invalid="ignore"):  # a sum is finite when its terms are (and not beyond float64)
        if all(np.isfinite(v.sum()) for v in numbers.values()):
            return numbers, dict.fromkeys(names, 0)
    if np.isnan(numbers[names[-1]]).any() or any(np.isinf(v).any() for v in numbers.values()):
        return None
    return numbers, {n: int(np.count_nonzero(np.isnan(v))) for n, v in numbers.items()}


def _c_blocks(path: Path, table: Table, piece_bytes: int, notation: Notation = MACHINE) -> Iterator[_Block] | None:
    """The blocks of a file whose columns are all declared number columns: pandas's C
    parser piece by piece (faster than Arrow's by ≈ 15–25 %, bench/NOTES.md), Arrow's path
    for a piece it declines. None when the header is not of such a file."""
    with open(path, "rb") as fh:
        head = _header(fh, notation.delimiter)
    if head is None:
        return None
    header, names = head
    numeric = _numeric(table)
    if (
        not C_PARSER_EXACT
        or not hasattr(os, "preadv")
        or not _names_fit(names, table)
        or not all(n in numeric for n in names)
    ):
        return None
    return _c_pieces(path, table, header, names, piece_bytes, notation)


def _c_pieces(
    path: Path, table: Table, header: bytes, names: list[str], piece_bytes: int, notation: Notation = MACHINE
) -> Iterator[_Block]:
    """The pieces of a number file, one block each from the C parser, or Arrow's blocks of
    a piece it declines (the file itself when it is one piece; else the piece read in
    place, never a copy of it in memory)."""
    with open(path, "rb") as fh:
        size = os.fstat(fh.fileno()).st_size
        start = len(header)
        for end in _piece_ends(fh, start, size, piece_bytes):
            whole = start == len(header) and end == size
            parsed = _c_numbers(path if whole else _Range(fh, header, start, end), names, notation)
            if parsed is not None:
                numbers, nulls = parsed
                yield _Block(names, numbers, nulls, {}, len(numbers[names[0]]), end - start, True)
            else:
                source = path if whole else pa.PythonFile(_Range(fh, header, start, end), mode="r")
                for block in _arrow_blocks(source, table, BLOCK_BYTES, end - start, notation):
                    if block.names != names:
                        raise TextPathNeeded
                    yield block
            start = end


def _blocks(table: Table, path: Path, piece_bytes: int, notation: Notation = MACHINE) -> Iterator[_Block] | None:
    """The file's blocks, checked one by one (:func:`_fits`), or None when it is known
    from its header that the text path must read it; the iterator raises
    :class:`TextPathNeeded` when that is found later."""
    try:
        blocks = _c_blocks(path, table, piece_bytes, notation)
        if blocks is None:
            blocks = _arrow_blocks(path, table, BLOCK_BYTES, path.stat().st_size, notation)
    except OSError:
        return None
    first = _first(blocks)
    if first is None:
        return None
    return _checked_blocks(first, blocks, table)


def _first(blocks: Iterator[_Block]) -> _Block | None:
    """The first block, parsed now so that a header the file cannot be read typed with
    declines before any frame is handed out (None); an empty block when the file has no
    row past its header (a later check declines it)."""
    try:
        first = next(blocks, None)
    except TextPathNeeded:
        return None
    return first if first is not None else _Block([], {}, {}, {}, 0, 1)


def _checked_blocks(first: _Block, rest: Iterator[_Block], table: Table) -> Iterator[_Block]:
    rows = 0
    for block in itertools.chain([first], rest):
        if not _fits(block, table):
            raise TextPathNeeded
        rows += block.rows
        yield block
    if rows == 0:
        raise TextPathNeeded  # a header-only file: the text path reports it


#: A padded cell (skipinitialspace would strip it), a quote (read as text here), a line break.
_TEXT_DECLINES = r'^[ \t]|[\r\n"]'
#: The bytes of :data:`_TEXT_DECLINES`: anywhere in a cell, and at its start.
_ANY_DECLINES, _FIRST_DECLINES = (b'"', b"\r", b"\n"), np.array([ord(" "), ord("\t")], dtype=np.uint8)


def _text_declines(a: pa.Array) -> bool:
    """Whether a cell of the text column ``a`` matches :data:`_TEXT_DECLINES`, by its bytes:
    the three are ASCII, which UTF-8 never uses inside a multi-byte character, so a byte
    search of the column's data (``bytes.find``, ``memchr``) and a look at each non-empty
    cell's first byte give the regular expression's answer without running it per cell."""
    if not (pa.types.is_string(a.type) or pa.types.is_large_string(a.type)) or len(a) == 0:
        return bool(pc.any(pc.match_substring_regex(a, _TEXT_DECLINES)).as_py())
    width = np.int64 if pa.types.is_large_string(a.type) else np.int32
    offsets = np.frombuffer(a.buffers()[1], dtype=width)[a.offset : a.offset + len(a) + 1].astype(np.int64)
    data = a.buffers()[2]
    if data is None:
        return False
    raw = np.frombuffer(data, dtype=np.uint8)[offsets[0] : offsets[-1]]
    text = raw.tobytes()
    if any(text.find(b) >= 0 for b in _ANY_DECLINES):
        return True
    starts = offsets[:-1][offsets[1:] > offsets[:-1]] - offsets[0]
    return bool(np.isin(raw[starts], _FIRST_DECLINES).any())


def _fits(block: _Block, table: Table) -> bool:
    """False when the typed frame could differ from the text path's: a NaN or infinite
    parse (the text path names the cell as written), a fractional whole number (likewise),
    a text cell the text path reads otherwise. Nulls are NaN in the arrays, so "no NaN but
    the nulls and no infinity" is "as many non-finite values as nulls": one pass over each
    column (the C parser's blocks are checked as they are parsed)."""
    declared = {c.name: c for c in table.columns}
    for name, values in block.numbers.items():
        nulls = block.nulls[name]
        if not block.finite and values.size - np.count_nonzero(np.isfinite(values)) != nulls:
            return False
        if declared[name].dtype == "int" and (values[~np.isnan(values)] % 1.0 != 0.0).any():
            return False
    return not any(_text_declines(a) for a in block.text.values())


def _frame(
    names: list[str], numbers: dict[str, np.ndarray], text: dict[str, pa.ChunkedArray], start: int = 0
) -> pd.DataFrame:
    columns = {n: numbers[n] if n in numbers else text[n].to_pandas().array for n in names}
    rows = len(next(iter(columns.values())))
    return pd.DataFrame(columns, index=pd.RangeIndex(start, start + rows), copy=False)


def _chunked(chunks: list[pa.Array]) -> pa.ChunkedArray:
    return pa.chunked_array(chunks, type=pa.string())


def _joined(blocks: Iterator[_Block], size: int) -> pd.DataFrame:
    """One frame of all the blocks: a single block's arrays as they are, else every
    number column copied once into its final array (the file is held once, never as
    blocks beside their concatenation: bench/NOTES.md)."""
    first = next(blocks)
    second = next(blocks, None)
    if second is None:
        return _frame(first.names, first.numbers, {n: _chunked([a]) for n, a in first.text.items()})
    capacity = int(1.1 * size * first.rows / max(first.nbytes, 1)) + 1024  # rows at the first block's density
    numbers = {n: _Growing() for n in first.numbers}
    text: dict[str, list[pa.Array]] = {n: [] for n in first.text}
    for block in itertools.chain([first, second], blocks):
        for n, column in numbers.items():
            column.add(block.numbers[n], capacity)
        for n, chunks in text.items():
            chunks.append(block.text[n])
    return _frame(first.names, {n: c.done() for n, c in numbers.items()}, {n: _chunked(c) for n, c in text.items()})


def read_csv_typed(table: Table, path: Path, notation: Notation = MACHINE) -> pd.DataFrame | None:
    """The raw frame of a CSV file of ``table`` with its number columns already parsed
    (float64), or None when the caller must read the file as text (module docstring).

    A file of number columns only is parsed by pandas's C parser in pieces of
    :data:`PIECE_BYTES` (a piece it declines, e.g. one with blanks, by Arrow); any other
    by Arrow's streaming reader, block by block. Each block's numbers are copied into the
    final arrays, so the file is held once: a whole table beside its concatenated columns
    cost a second copy of every number and, with it, most of the time (bench/NOTES.md).
    ``notation``: the delimiter and decimal separator :mod:`dbtools.csv_locale` found.
    InputError, before it is opened, when ``path`` is not a regular file (a FIFO …)."""
    path = regular_file(Path(path), "CSV file")
    blocks = _blocks(table, path, PIECE_BYTES, notation)
    if blocks is None:
        return None
    try:
        return _joined(blocks, path.stat().st_size)
    except TextPathNeeded:
        return None


def iter_csv_typed(table: Table, path: Path, rows: int) -> Iterator[pd.DataFrame] | None:
    """:func:`read_csv_typed`'s frame in frames of at most ``rows`` rows, parsed one block
    at a time (bounded memory: one block's arrays and text, for spooling a long run), or
    None when the file must be read as text and its header says so. Concatenated
    (``pd.concat``) they are :func:`read_csv_typed`'s frame, index included (each frame's
    RangeIndex continues the previous one's). When the text path turns out to be needed
    part-way (a bad cell in a later block), the iterator raises :class:`TextPathNeeded`:
    the caller drops what it has and reads the file as text."""
    if rows < 1:
        raise ValueError(f"rows must be positive, not {rows}")
    path = regular_file(Path(path), "CSV file")
    blocks = _blocks(table, path, max(1 << 16, min(PIECE_BYTES, rows * _row_bytes(path))))
    return None if blocks is None else _frames(blocks, rows)


def _row_bytes(path: Path) -> int:
    """Bytes per line in the first 64 KB of the file (to size pieces of about ``rows``)."""
    with open(path, "rb") as fh:
        head = fh.read(1 << 16)
    return max(1, len(head) // max(1, head.count(b"\n")))


def _frames(blocks: Iterator[_Block], rows: int) -> Iterator[pd.DataFrame]:
    start = 0
    for block in blocks:
        for i in range(0, block.rows, rows):
            j = min(i + rows, block.rows)
            numbers = {n: v[i:j] for n, v in block.numbers.items()}
            text = {n: _chunked([a.slice(i, j - i)]) for n, a in block.text.items()}
            yield _frame(block.names, numbers, text, start)
            start += j - i
