"""What every stream reader and the writer share: a stream frame checked against its
declared table (``schemas.logs``), the frame as Arrow with the declared types and units, and
the time window a reader may be asked for.

The lowest layer of :mod:`fieldlogs.runs`: it imports nothing of the package.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pandas as pd
import pyarrow as pa

from schemas.findings import Finding
from schemas.frames import PANDAS_DTYPE, coerce_frame
from schemas.model import Table

LogFormat = Literal["csv", "parquet"]


@dataclass(frozen=True)
class TimeWindow:
    """The rows with ``t0 ≤ t < t1`` of a stream (a held stream, :attr:`Table.held`: every
    row before ``t1``). ``carry_from``: where the next window of a sequence will start (a
    reader may drop at once the rows no later window needs); None: unknown."""

    t0: float
    t1: float
    carry_from: float | None = None

    def of(self, table: Table) -> TimeWindow:
        """The window a table is read by: a held stream from −∞, without a carry."""
        return TimeWindow(-math.inf, self.t1) if table.held else self


def coerce_stream(table: Table, raw: pd.DataFrame, file: str) -> tuple[pd.DataFrame, list[Finding]]:
    """Typed stream + type findings (no range/order checks: those are ``logs check``)."""
    if all(c in raw.columns for c in table.column_names) and all(
        str(raw[c.name].dtype) == PANDAS_DTYPE[c.dtype] or (c.dtype == "float" and raw[c.name].dtype == "float64")
        for c in table.columns
    ):
        return raw[table.column_names], []  # already typed: nothing to coerce
    co = coerce_frame(table, raw, file=file)
    return co.frame, co.findings


def arrow_stream_table(table: Table, frame: pd.DataFrame) -> pa.Table:
    """Declared columns with declared Arrow types and each column's unit in its metadata."""
    arrays, fields = [], []
    for c in table.columns:
        if c.name not in frame.columns:
            continue
        s = frame[c.name]
        if c.dtype == "float":
            typ = pa.float32() if c.float32 else pa.float64()
            arr = pa.array(s.to_numpy(dtype=typ.to_pandas_dtype(), na_value=np.nan), type=typ)
        elif c.dtype == "int":
            vals = pd.to_numeric(s).astype("Int64")
            mask = vals.isna().to_numpy()
            ints = vals.to_numpy(dtype=np.int64, na_value=0)
            arr = pa.array(ints, mask=mask if mask.any() else None, type=pa.int64())
            typ = pa.int64()
        elif c.dtype == "bool":
            arr = pa.array(s.astype("boolean"), type=pa.bool_())
            typ = pa.bool_()
        else:
            arr = pa.array(s.astype("string").astype(object).where(s.notna(), None), type=pa.string())
            typ = pa.string()
        arrays.append(arr)
        fields.append(pa.field(c.name, typ, nullable=True, metadata={"unit": c.unit} if c.unit else None))
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))
