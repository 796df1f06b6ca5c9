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
``skipinitialspace`` would strip it), or a text field holds a line break (Arrow reads an
unclosed quote silently, swallowing the rest of the file into one cell; the text path
refuses it naming the line). A header-only file, a file in another encoding or with
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

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from schemas.model import Table


def _case_variants(word: str) -> list[str]:
    return ["".join(p) for p in itertools.product(*((ch.lower(), ch.upper()) for ch in word))]


#: Cells :func:`schemas.frames._blank` takes for blank, as Arrow null values (a padded one
#: makes the file decline: see the module docstring).
BLANK_CELLS = ["", *_case_variants("nan"), *_case_variants("na"), *_case_variants("null")]


def _numbers(data: pa.Table, table: Table) -> dict[str, np.ndarray] | None:
    """The number columns of ``data`` as float64 arrays (NaN for blank cells), or None when
    the typed frame could differ from the text path's (module docstring)."""
    names = data.column_names
    declared = {c.name: c for c in table.columns}
    if len(set(names)) != len(names) or any(n not in declared for n in names):
        return None  # repeated, padded or unknown names: coerce_frame's findings and names
    out: dict[str, np.ndarray] = {}
    for name in names:
        col, arr = declared[name], data.column(name)
        if col.dtype not in ("float", "int"):
            if pc.any(pc.match_substring_regex(arr, r"^[ \t]|[\r\n]")).as_py():
                return None  # a padded cell, or one holding a line break (an unclosed quote)
            continue
        values = np.asarray(arr.to_numpy(zero_copy_only=False), dtype=np.float64)
        nan = np.isnan(values)
        if np.count_nonzero(nan) != arr.null_count or np.isinf(values).any():
            return None  # a NaN or infinite parse: the text path names the cell as written
        if col.dtype == "int" and (values[~nan] % 1.0 != 0.0).any():
            return None  # a fractional whole number: likewise
        out[name] = values
    return out


def read_csv_typed(table: Table, path: Path) -> pd.DataFrame | None:
    """The raw frame of a CSV file of ``table`` with its number columns already parsed
    (float64), or None when the caller must read the file as text (module docstring)."""
    import pyarrow.csv as pcsv

    numeric = {c.name for c in table.columns if c.dtype in ("float", "int")}
    types = {c.name: (pa.float64() if c.name in numeric else pa.string()) for c in table.columns}  # absent: ignored
    convert = pcsv.ConvertOptions(
        column_types=types, null_values=BLANK_CELLS, strings_can_be_null=False, quoted_strings_can_be_null=False
    )
    try:
        data = pcsv.read_csv(path, convert_options=convert)
    except (pa.ArrowException, OSError, UnicodeDecodeError):
        return None
    numbers = _numbers(data, table) if data.num_rows else None
    if numbers is None:
        return None
    text = {n: data.column(n).to_pandas() for n in data.column_names if n not in numbers}  # as the text path has it
    return pd.DataFrame({n: numbers[n] if n in numbers else text[n] for n in data.column_names}, copy=False)
