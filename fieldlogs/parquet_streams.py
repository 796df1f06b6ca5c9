"""Typed reading of a Parquet stream file (the fast path of :mod:`fieldlogs.io`).

Columns whose Arrow type already fits the declared type are turned into numpy / pandas
arrays column by column (no per-cell Python), each column read from the file on its own
so that a long stream is held about once (its arrays), not twice (the whole table's
row-group chunks beside the arrays concatenated from them). Anything else (text in a
numeric column, an odd type) goes through ``schemas.frames.coerce_frame``, which names
every bad cell. Parquet written by :func:`fieldlogs.io.write_run` carries each column's
unit in the field metadata (``unit``); a file whose unit differs from the declared one is
a finding.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
import pyarrow as pa

from schemas.enums import Severity
from schemas.errors import InputError
from schemas.findings import Finding
from schemas.frames import PANDAS_DTYPE, coerce_frame, suggest
from schemas.model import Column, Table

if TYPE_CHECKING:
    import pyarrow.parquet as pq


def read_parquet_table(path: Path, columns: list[str] | None = None) -> pa.Table:
    import pyarrow.parquet as pq  # lazy: heavy

    try:
        return pq.read_table(path, columns=columns)
    except (pa.ArrowException, OSError) as exc:
        raise InputError(f"not a readable Parquet file: {exc}", path=path) from exc


def open_parquet(path: Path) -> pq.ParquetFile:
    """The file's reader; an unreadable file raises the InputError :func:`read_parquet_table`
    raises (the same message, whichever way the file is opened)."""
    import pyarrow.parquet as pq  # lazy: heavy

    try:
        return pq.ParquetFile(path)
    except (pa.ArrowException, OSError) as exc:
        read_parquet_table(path)  # raises with the reader's own message
        raise InputError(f"not a readable Parquet file: {exc}", path=path) from exc


def _arrow_fits(col: Column, t: pa.DataType) -> bool:
    """Whether :func:`_arrow_column` types a column of Arrow type ``t``."""
    if col.dtype == "float":
        return bool(pa.types.is_floating(t) or pa.types.is_integer(t))
    if col.dtype == "int":
        return bool(pa.types.is_integer(t))
    return col.dtype == "str" and bool(pa.types.is_string(t) or pa.types.is_large_string(t))


def _arrow_column(col: Column, arr: pa.ChunkedArray) -> Any:
    """A typed pandas array for a column whose Arrow type fits the declared one, else None."""
    t = arr.type
    if col.dtype == "float" and (pa.types.is_floating(t) or pa.types.is_integer(t)):
        return arr.to_numpy().astype(np.float32 if col.float32 else np.float64, copy=False)  # nulls → NaN
    if col.dtype == "int" and pa.types.is_integer(t):
        if arr.null_count == 0:
            values = arr.to_numpy().astype(np.int64, copy=False)
            return pd.arrays.IntegerArray(values, np.zeros(len(values), dtype=bool))
        mask = arr.is_null().to_numpy(zero_copy_only=False)
        values = arr.fill_null(0).to_numpy().astype(np.int64, copy=False)
        return pd.arrays.IntegerArray(values, mask)
    if col.dtype == "str" and (pa.types.is_string(t) or pa.types.is_large_string(t)):
        s = arr.to_pandas().astype("string").str.strip()
        return s.mask(s == "").array
    return None


def read_parquet_stream(table: Table, path: Path) -> tuple[pd.DataFrame, list[Finding]]:
    """A Parquet stream, typed column by column; text or odd types go through ``coerce_frame``.

    Columns are read and converted one at a time, so that a long stream is held about once
    (its arrays), not twice (the row-group chunks of the whole table beside them)."""
    pf = open_parquet(path)
    schema = pf.schema_arrow
    file = str(path)
    findings: list[Finding] = []
    for col in table.columns:
        if col.name not in schema.names:
            continue
        meta = schema.field(col.name).metadata or {}
        unit = meta.get(b"unit")
        if unit is not None and unit.decode("utf-8", "replace") != col.unit:
            findings.append(
                Finding(
                    "log.unit",
                    Severity.ERROR,
                    table.name,
                    f"column is stored in '{unit.decode('utf-8', 'replace')}', expected '{col.unit}'",
                    file=file,
                    column=col.name,
                    value=unit.decode("utf-8", "replace"),
                    limit=col.unit,
                )
            )
    extras = [c for c in schema.names if c not in table.column_names]
    fast = _fast_columns(table, path, pf)
    if fast is not None:
        frame = pd.DataFrame(fast, copy=False)
        for c in extras:
            hint = suggest(c, table.column_names)
            findings.append(
                Finding(
                    "schema.unknown_column",
                    Severity.WARNING,
                    table.name,
                    f"unknown column '{c}' ignored" + (f" (did you mean '{hint}'?)" if hint else ""),
                    file=file,
                    column=c,
                    value=c,
                    limit=hint,
                )
            )
        return frame, findings
    co = coerce_frame(table, read_parquet_table(path).to_pandas(), file=file)
    return co.frame, findings + co.findings


def _fast_columns(table: Table, path: Path, pf: pq.ParquetFile) -> dict[str, Any] | None:
    """The declared columns typed by :func:`_arrow_column`, or None when one cannot be
    (then the whole table goes through ``coerce_frame``). A file of one row group is read
    at once (its columns are single chunks: no copy); a longer one a column at a time."""
    schema = pf.schema_arrow
    names = set(schema.names)
    if not all(c.name in names for c in table.columns if c.required):
        return None
    if any(c.name in names and not _arrow_fits(c, schema.field(c.name).type) for c in table.columns):
        return None
    present = [c for c in table.columns if c.name in names]
    whole = _read(pf, path, [c.name for c in present]) if pf.metadata.num_row_groups <= 1 else None
    fast: dict[str, Any] = {}
    for col in present:
        part = whole if whole is not None else _read(pf, path, [col.name])
        fast[col.name] = _arrow_column(col, part.column(col.name))
        del part
    n_rows = pf.metadata.num_rows
    for col in table.columns:  # an optional column absent: nulls of its type
        if col.name not in fast:
            fast[col.name] = pd.Series([None] * n_rows, dtype=PANDAS_DTYPE[col.dtype]).array
    return {c.name: fast[c.name] for c in table.columns}


def _read(pf: pq.ParquetFile, path: Path, columns: list[str]) -> pa.Table:
    """Columns of an open file; a failure raises what :func:`read_parquet_table` raises."""
    try:
        return pf.read(columns=columns)
    except (pa.ArrowException, OSError):
        return read_parquet_table(path, columns)
