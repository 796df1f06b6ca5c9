"""A Parquet stream file as the readers see it: opening it, its columns typed as declared,
its units and its row groups' ``t`` statistics.

Columns whose Arrow type already fits the declared type are turned into numpy / pandas
arrays column by column (no per-cell Python); anything else (text in a numeric column, an
odd type) must go through ``schemas.frames.coerce_frame``, which names every bad cell.
Parquet written by :func:`fieldlogs.runs.write.write_run` carries each column's unit in the
field metadata (``unit``); a file whose unit differs from the declared one is a finding.
Used by :mod:`fieldlogs.runs.cursor` and :mod:`fieldlogs.runs.parquet_reader`.
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
from schemas.frames import PANDAS_DTYPE, suggest
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
    """Whether :func:`arrow_column` types a column of Arrow type ``t``."""
    if col.dtype == "float":
        return bool(pa.types.is_floating(t) or pa.types.is_integer(t))
    if col.dtype == "int":
        return bool(pa.types.is_integer(t))
    return col.dtype == "str" and bool(pa.types.is_string(t) or pa.types.is_large_string(t))


def arrow_column(col: Column, arr: pa.ChunkedArray) -> Any:
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


def typed_frame(table: Table, fast: dict[str, Any], n_rows: int) -> pd.DataFrame:
    """The declared columns in order from ``fast`` (typed arrays); an optional column absent
    from the file: nulls of its type."""
    for col in table.columns:
        if col.name not in fast:
            fast[col.name] = pd.Series([None] * n_rows, dtype=PANDAS_DTYPE[col.dtype]).array
    return pd.DataFrame({c.name: fast[c.name] for c in table.columns}, copy=False)


def unit_findings(table: Table, schema: pa.Schema, file: str) -> list[Finding]:
    """An error for each declared column stored in another unit than the declared one."""
    findings: list[Finding] = []
    for col in table.columns:
        unit = _stored_unit(schema, col.name)
        if unit is not None and unit != col.unit:
            findings.append(
                Finding(
                    "log.unit",
                    Severity.ERROR,
                    table.name,
                    f"column is stored in '{unit}', expected '{col.unit}'",
                    file=file,
                    column=col.name,
                    value=unit,
                    limit=col.unit,
                )
            )
    return findings


def _stored_unit(schema: pa.Schema, name: str) -> str | None:
    """The unit a column's field metadata names (None: the column or the unit is absent)."""
    if name not in schema.names:
        return None
    unit = (schema.field(name).metadata or {}).get(b"unit")
    return None if unit is None else unit.decode("utf-8", "replace")


def unknown_columns(table: Table, schema: pa.Schema, file: str) -> list[Finding]:
    """A warning for each column the table does not declare (ignored)."""
    out = []
    for c in (c for c in schema.names if c not in table.column_names):
        hint = suggest(c, table.column_names)
        out.append(
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
    return out


def typed_columns(table: Table, schema: pa.Schema) -> list[Column] | None:
    """The declared columns present, when every required one is there and each can be typed
    as stored (:func:`arrow_column`); else None."""
    names = set(schema.names)
    if not all(c.name in names for c in table.columns if c.required):
        return None
    present = [c for c in table.columns if c.name in names]
    return present if all(_arrow_fits(c, schema.field(c.name).type) for c in present) else None


def window_columns(table: Table, schema: pa.Schema) -> list[Column] | None:
    """The declared columns present, when each can be typed as stored (Arrow type fits,
    unit as declared) and ``t`` and the required columns are there; else None: the file
    cannot be read by time window."""
    present = typed_columns(table, schema) if "t" in schema.names else None
    for col in present or []:
        unit = _stored_unit(schema, col.name)
        if unit is not None and unit != col.unit:
            return None
    return present


def t_ranges(pf: pq.ParquetFile) -> list[tuple[float, float] | None]:
    """Each row group's (min, max) ``t`` from its statistics (None: the group has none)."""
    col = pf.schema_arrow.get_field_index("t")
    out: list[tuple[float, float] | None] = []
    for i in range(pf.metadata.num_row_groups):
        stats = pf.metadata.row_group(i).column(col).statistics
        ok = stats is not None and stats.has_min_max and stats.min is not None and stats.max is not None
        out.append((float(stats.min), float(stats.max)) if ok else None)
    return out


def stream_t_range(path: Path) -> tuple[float, float] | None:
    """(first, last) t of a Parquet stream from its row groups' statistics (no rows read),
    or None when a group has none or the file cannot be opened."""
    try:
        pf = open_parquet(path)
    except InputError:
        return None
    if "t" not in pf.schema_arrow.names or pf.metadata.num_row_groups == 0:
        return None
    ranges = t_ranges(pf)
    if any(r is None for r in ranges):
        return None
    lo = min(r[0] for r in ranges if r is not None)
    hi = max(r[1] for r in ranges if r is not None)
    return (lo, hi) if lo <= hi else None


def parquet_rows(path: Path) -> int | None:
    """Rows of a Parquet file from its metadata (None when it cannot be opened)."""
    try:
        return int(open_parquet(path).metadata.num_rows)
    except InputError:
        return None
