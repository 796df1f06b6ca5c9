"""Typed reading of a CSV file of a declared table (a log stream, a source file): numbers
parsed while the file is read.

The general path (:func:`dbtools.tabular.read_raw_table`, then
:func:`schemas.frames.coerce_frame`) reads every cell as text and parses it afterwards,
which for an IMU stream (seven numbers per row at 100 Hz) or a national GIS grid builds
tens of millions of strings. Here Arrow's CSV reader parses the declared number columns straight into
float64 — the same parser that coerce_frame's fast path applies to the text — and the
frame handed to ``coerce_frame`` holds numbers where it would have held their text.

It gives the same typed frame and the same findings as the general path, so it declines
(returns None, and the caller reads as text) whenever that could differ: the file does not
parse with the declared number types (a bad cell: the text path names it), a parsed
value is infinite or NaN (the text path names the cell as written), a column name is
not a declared one or repeated, a text field starts with a blank (the C parser's
``skipinitialspace`` would strip it), or any cell holds a quote (Arrow parses here without
quote handling, which is faster; the text path reads quoted cells and names an unclosed
quote's line). A header-only file, a file in another encoding or with
another delimiter declines too: the text path reports those (:mod:`dbtools.tabular`).
Cells the text path treats as blank — empty, or ``nan``/``na``/``null`` in any letter
case, padded or not — are nulls here too. Text columns are read as text and coerced
exactly as before. A whole number column is parsed
as float64 and checked by ``coerce_frame`` (integral values only: a fractional one declines,
for the text path to name it).
Measurements: bench/bench_logs.py (against pyarrow.csv, polars and typed pandas) and
bench/bench_db.py (db build).
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from schemas.model import Table

if TYPE_CHECKING:
    import pyarrow.csv as pcsv

#: Bytes Arrow's CSV reader parses per block (its default).
BLOCK_BYTES = 1 << 20


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


class _Growing:
    """A float64 column filled batch by batch (over-allocated once from the first batch's
    density, grown in place if the file's rows turn out shorter, trimmed at the end)."""

    def __init__(self) -> None:
        self.values = np.empty(0)
        self.n = 0
        self.nulls = 0

    def add(self, arr: pa.Array, capacity: int) -> None:
        m = len(arr)
        if self.n + m > self.values.size:
            self.values.resize(max(capacity, int(1.25 * (self.n + m)) + 1024), refcheck=False)
        self.values[self.n : self.n + m] = arr.to_numpy(zero_copy_only=False)
        self.nulls += arr.null_count
        self.n += m

    def done(self) -> np.ndarray:
        self.values.resize(self.n, refcheck=False)
        return self.values


def _read_batches(
    reader: pcsv.CSVStreamingReader, table: Table, size: int
) -> tuple[dict[str, _Growing], dict[str, list[pa.Array]]]:
    """Number columns as growing float64 arrays, text columns as their Arrow chunks: the
    file is held once (its arrays), never as a table beside them."""
    names = reader.schema.names
    numeric = {c.name for c in table.columns if c.dtype in ("float", "int")}
    numbers = {n: _Growing() for n in names if n in numeric}
    text: dict[str, list[pa.Array]] = {n: [] for n in names if n not in numeric}
    capacity = 0
    for batch in reader:
        if not capacity and batch.num_rows:  # rows the whole file holds at the first block's density
            capacity = int(1.1 * size * batch.num_rows / min(size, BLOCK_BYTES)) + 1024
        for i, name in enumerate(names):
            if name in numbers:
                numbers[name].add(batch.column(i), capacity)
            else:
                text[name].append(batch.column(i))
    return numbers, text


def _checked(numbers: dict[str, _Growing], table: Table) -> dict[str, np.ndarray] | None:
    """The number columns, or None when the typed frame could differ from the text path's:
    a NaN or infinite parse (the text path names the cell as written), a fractional whole
    number (likewise). Nulls are NaN in the arrays, so "no NaN but the nulls and no
    infinity" is "as many non-finite values as nulls": one pass over each column."""
    declared = {c.name: c for c in table.columns}
    out: dict[str, np.ndarray] = {}
    for name, col in numbers.items():
        values = col.done()
        if values.size - np.count_nonzero(np.isfinite(values)) != col.nulls:
            return None
        if declared[name].dtype == "int" and (values[~np.isnan(values)] % 1.0 != 0.0).any():
            return None
        out[name] = values
    return out


def read_csv_typed(table: Table, path: Path) -> pd.DataFrame | None:
    """The raw frame of a CSV file of ``table`` with its number columns already parsed
    (float64), or None when the caller must read the file as text (module docstring).

    Arrow's streaming reader parses the file block by block (the same parser and options
    as ``pyarrow.csv.read_csv``) and each block's numbers are copied into the final
    arrays, so the file is held once: a whole table beside its concatenated columns cost a
    second copy of every number and, with it, most of the time (bench/NOTES.md)."""
    import pyarrow.csv as pcsv

    numeric = {c.name for c in table.columns if c.dtype in ("float", "int")}
    types = {c.name: (pa.float64() if c.name in numeric else pa.string()) for c in table.columns}  # absent: ignored
    convert = pcsv.ConvertOptions(
        column_types=types, null_values=BLANK_CELLS, strings_can_be_null=False, quoted_strings_can_be_null=False
    )
    try:
        reader = pcsv.open_csv(
            path,
            read_options=pcsv.ReadOptions(block_size=BLOCK_BYTES, use_threads=False),
            parse_options=pcsv.ParseOptions(quote_char=False),
            convert_options=convert,
        )
        if not _names_fit(reader.schema.names, table):
            return None
        batches, chunks = _read_batches(reader, table, Path(path).stat().st_size)
    except (pa.ArrowException, OSError, UnicodeDecodeError):
        return None
    n_rows = next(iter(batches.values())).n if batches else sum(len(a) for a in next(iter(chunks.values()), []))
    if n_rows == 0:
        return None
    text = {n: pa.chunked_array(a, type=pa.string()) for n, a in chunks.items()}
    if any(pc.any(pc.match_substring_regex(arr, r'^[ \t]|[\r\n"]')).as_py() for arr in text.values()):
        return None  # a padded cell (skipinitialspace would strip it), a quote (read as text here), a line break
    numbers = _checked(batches, table)
    if numbers is None:
        return None
    columns = {n: numbers[n] if n in numbers else text[n].to_pandas() for n in reader.schema.names}
    return pd.DataFrame(columns, copy=False)
