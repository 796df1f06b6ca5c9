"""The typed reader of a Parquet stream file, whole or by time window
(:class:`ParquetStream`; the file itself: :mod:`fieldlogs.runs.parquet_file`).

Whole: the declared columns typed column by column, each read from the file on its own, so
that a long stream is held about once (its arrays), not twice (the whole table's row-group
chunks beside the arrays concatenated from them); a file whose columns cannot be typed as
stored goes through ``schemas.frames.coerce_frame``, which names every bad cell.

By window (:class:`fieldlogs.runs.typed.TimeWindow`): the rows with t0 ≤ t < t1, typed the
same way, reading only the row groups whose ``t`` statistics reach the window, one column of
one group at a time (memory: the window's rows and one column of a row group, not the
file's); consecutive windows through a :class:`fieldlogs.runs.cursor.StreamCursor`, which
decodes each row group once. A file that cannot be read this way gives None (the caller
reads it whole, where the findings are made).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, overload

import pandas as pd
import pyarrow as pa

from fieldlogs.runs.cursor import StreamCursor
from fieldlogs.runs.parquet_file import (
    arrow_column,
    open_parquet,
    parquet_rows,
    read_parquet_table,
    stream_t_range,
    t_ranges,
    typed_columns,
    typed_frame,
    unit_findings,
    unknown_columns,
    window_columns,
)
from fieldlogs.runs.typed import TimeWindow
from schemas.errors import InputError
from schemas.findings import Finding
from schemas.frames import coerce_frame
from schemas.model import Column, Table

if TYPE_CHECKING:
    import pyarrow.parquet as pq

Read = tuple[pd.DataFrame, list[Finding]]


class ParquetStream:
    """One Parquet stream file of a run, read whole or by time window (module docstring)."""

    def __init__(self, table: Table, path: Path) -> None:
        self.table, self.path = table, Path(path)
        self._cursor: StreamCursor | None = None

    @overload
    def read(self, window: None = None) -> Read: ...
    @overload
    def read(self, window: TimeWindow) -> Read | None: ...

    def read(self, window: TimeWindow | None = None) -> Read | None:
        """The typed stream and its findings. Whole (``window`` None): raises InputError when
        the file cannot be read at all. By window: None when the file cannot be read so — no
        ``t`` column aside, a column whose Arrow type does not fit the declared one, a unit
        that differs, an unreadable file. A table without time (the GNSS ephemerides) is read
        whole in any window. Consecutive windows whose bounds never go back are read through
        one cursor (:class:`fieldlogs.runs.cursor.StreamCursor`; ``window.carry_from`` lets it
        drop at once the rows no later window needs)."""
        if window is None:
            return read_parquet_stream(self.table, self.path)
        if "t" not in self.table.column_names:
            try:
                return read_parquet_stream(self.table, self.path)
            except InputError:
                return None
        w = window.of(self.table)
        if self._cursor is None:
            self._cursor = StreamCursor(self.table, self.path)
        read = self._cursor.between(w.t0, w.t1, w.carry_from)
        return read if read is not None else read_between(self.table, self.path, w.t0, w.t1)

    def windowable(self) -> bool:
        """Whether :meth:`read` can read the file by window (its schema alone; no rows read)."""
        if "t" not in self.table.column_names:
            return True
        try:
            return window_columns(self.table, open_parquet(self.path).schema_arrow) is not None
        except InputError:
            return False

    def t_span(self) -> tuple[float, float] | None:
        """(first, last) t from the row groups' statistics (None: not known so)."""
        return stream_t_range(self.path)

    def rows(self) -> int | None:
        """Rows of the file from its metadata (None: it cannot be opened)."""
        return parquet_rows(self.path)

    def fresh(self) -> ParquetStream:
        """This reader without the windows it has read (a cursor of its own)."""
        out = copy.copy(self)
        out._cursor = None
        return out

    def close(self) -> None:
        """Drop the rows the window cursor holds."""
        self._cursor = None


def read_parquet_stream(table: Table, path: Path) -> Read:
    """A Parquet stream, typed column by column; text or odd types go through ``coerce_frame``.

    Columns are read and converted one at a time, so that a long stream is held about once
    (its arrays), not twice (the row-group chunks of the whole table beside them). A file of
    one row group is read at once (its columns are single chunks: no copy)."""
    pf = open_parquet(path)
    schema, file = pf.schema_arrow, str(path)
    findings = unit_findings(table, schema, file)
    present = typed_columns(table, schema)
    if present is None:
        co = coerce_frame(table, read_parquet_table(path).to_pandas(), file=file)
        return co.frame, findings + co.findings
    whole = _read(pf, path, [c.name for c in present]) if pf.metadata.num_row_groups <= 1 else None

    def column(name: str) -> pa.ChunkedArray:
        return (whole if whole is not None else _read(pf, path, [name])).column(name)

    frame = _typed(table, present, pf.metadata.num_rows, column)
    return frame, findings + unknown_columns(table, schema, file)


def read_between(table: Table, path: Path, t0: float, t1: float) -> Read | None:
    """The rows with t0 ≤ t < t1 (:meth:`ParquetStream.read` by window), or None. Rows are
    kept in file order (selection by value, not by position), so
    :func:`fieldlogs.pipeline.run.clean_stream` sees every row of the window. The findings
    are those of the whole read that do not depend on the rows (unknown columns)."""
    try:
        pf = open_parquet(path)
    except InputError:
        return None
    schema = pf.schema_arrow
    present = window_columns(table, schema)
    if present is None:
        return None
    import pyarrow.compute as pc

    try:
        groups = [i for i, r in enumerate(t_ranges(pf)) if r is None or (r[1] >= t0 and r[0] < t1)]
        masks = []
        for g in groups:  # the window's rows of each group, from its t alone (no statistics: filtered)
            t = pf.read_row_group(g, columns=["t"]).column(0)
            masks.append(pc.and_(pc.greater_equal(t, t0), pc.less(t, t1)))
        n_rows = sum(int(pc.sum(m).as_py() or 0) for m in masks)

        def column(name: str) -> pa.ChunkedArray:  # a column of a group at a time: the window held about once
            parts = [
                chunk
                for g, m in zip(groups, masks, strict=True)
                for chunk in pf.read_row_group(g, columns=[name]).column(0).filter(m).chunks
            ]
            return pa.chunked_array(parts, type=schema.field(name).type)

        frame = _typed(table, present, n_rows, column)
    except (pa.ArrowException, OSError):
        return None
    finally:
        pa.default_memory_pool().release_unused()
    return frame, unknown_columns(table, schema, str(path))


def _typed(table: Table, present: list[Column], n_rows: int, column: Callable[[str], pa.ChunkedArray]) -> pd.DataFrame:
    """The frame of ``present`` columns, each read by ``column`` and typed in turn."""
    fast: dict[str, Any] = {}
    for col in present:
        fast[col.name] = arrow_column(col, column(col.name))
    return typed_frame(table, fast, n_rows)


def _read(pf: pq.ParquetFile, path: Path, columns: list[str]) -> pa.Table:
    """Columns of an open file; a failure raises what :func:`read_parquet_table` raises."""
    try:
        return pf.read(columns=columns)
    except (pa.ArrowException, OSError):
        return read_parquet_table(path, columns)
