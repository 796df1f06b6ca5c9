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
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from schemas.enums import Severity
from schemas.errors import InputError
from schemas.findings import Finding
from schemas.frames import PANDAS_DTYPE, coerce_frame, suggest
from schemas.model import Column, Table


def read_parquet_table(path: Path, columns: list[str] | None = None) -> pa.Table:
    try:
        return pq.read_table(path, columns=columns)
    except (pa.ArrowException, OSError) as exc:
        raise InputError(f"not a readable Parquet file: {exc}", path=path) from exc


def parquet_schema(path: Path) -> pa.Schema:
    try:
        return pq.read_schema(path)
    except (pa.ArrowException, OSError) as exc:
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
    schema = parquet_schema(path)
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
    fast = _fast_columns(table, path, schema)
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


def _fast_columns(table: Table, path: Path, schema: pa.Schema) -> dict[str, Any] | None:
    """The declared columns typed by :func:`_arrow_column`, each read on its own, or None
    when one cannot be (then the whole table goes through ``coerce_frame``)."""
    names = set(schema.names)
    if not all(c.name in names for c in table.columns if c.required):
        return None
    if any(c.name in names and not _arrow_fits(c, schema.field(c.name).type) for c in table.columns):
        return None
    fast: dict[str, Any] = {}
    n_rows = -1
    for col in table.columns:
        if col.name in names:
            part = read_parquet_table(path, [col.name])
            n_rows = part.num_rows
            fast[col.name] = _arrow_column(col, part.column(0))
            del part
    if n_rows < 0:
        n_rows = read_parquet_table(path, []).num_rows
    for col in table.columns:  # an optional column absent: nulls of its type
        if col.name not in fast:
            fast[col.name] = pd.Series([None] * n_rows, dtype=PANDAS_DTYPE[col.dtype]).array
    return {c.name: fast[c.name] for c in table.columns}
