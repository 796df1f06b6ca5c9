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

import itertools
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

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
    fast = _fast_columns(table, path, pf)
    if fast is not None:
        return pd.DataFrame(fast, copy=False), findings + _unknown_columns(table, schema, file)
    co = coerce_frame(table, read_parquet_table(path).to_pandas(), file=file)
    return co.frame, findings + co.findings


def _unknown_columns(table: Table, schema: pa.Schema, file: str) -> list[Finding]:
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


def _typed_columns(table: Table, schema: pa.Schema) -> list[Column] | None:
    """The declared columns present, when every required one is there and each can be typed
    as stored (:func:`_arrow_fits`); else None."""
    names = set(schema.names)
    if not all(c.name in names for c in table.columns if c.required):
        return None
    present = [c for c in table.columns if c.name in names]
    return present if all(_arrow_fits(c, schema.field(c.name).type) for c in present) else None


def _fast_columns(table: Table, path: Path, pf: pq.ParquetFile) -> dict[str, Any] | None:
    """The declared columns typed by :func:`_arrow_column`, or None when one cannot be
    (then the whole table goes through ``coerce_frame``). A file of one row group is read
    at once (its columns are single chunks: no copy); a longer one a column at a time."""
    present = _typed_columns(table, pf.schema_arrow)
    if present is None:
        return None
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


def _t_ranges(pf: pq.ParquetFile) -> list[tuple[float, float] | None]:
    """Each row group's (min, max) ``t`` from its statistics (None: the group has none)."""
    col = pf.schema_arrow.get_field_index("t")
    out: list[tuple[float, float] | None] = []
    for i in range(pf.metadata.num_row_groups):
        stats = pf.metadata.row_group(i).column(col).statistics
        ok = stats is not None and stats.has_min_max and stats.min is not None and stats.max is not None
        out.append((float(stats.min), float(stats.max)) if ok else None)
    return out


def _row_groups_between(pf: pq.ParquetFile, t0: float, t1: float) -> list[int]:
    """The row groups whose ``t`` statistics reach into [t0, t1); a group without statistics
    is always read (its rows are then filtered one by one)."""
    return [i for i, r in enumerate(_t_ranges(pf)) if r is None or (r[1] >= t0 and r[0] < t1)]


def _window_columns(table: Table, schema: pa.Schema) -> list[Column] | None:
    """The declared columns present, when each can be typed as stored (Arrow type fits,
    unit as declared) and ``t`` and the required columns are there; else None."""
    present = _typed_columns(table, schema) if "t" in schema.names else None
    for col in present or []:
        unit = (schema.field(col.name).metadata or {}).get(b"unit")
        if unit is not None and unit.decode("utf-8", "replace") != col.unit:
            return None
    return present


def parquet_windowable(table: Table, path: Path) -> bool:
    """Whether :func:`read_parquet_stream_between` can read the file (its schema alone)."""
    try:
        return _window_columns(table, open_parquet(path).schema_arrow) is not None
    except InputError:
        return False


def read_parquet_stream_between(
    table: Table, path: Path, t0: float, t1: float
) -> tuple[pd.DataFrame, list[Finding]] | None:
    """The rows of a Parquet stream with t0 ≤ t < t1, typed as :func:`read_parquet_stream`
    types them, reading only the row groups whose ``t`` statistics reach the window, one
    column of one group at a time (memory: the window's rows and one column of a row group,
    not the file's).

    None when the file cannot be read this way — no ``t`` column, a column whose Arrow type
    does not fit the declared one (``coerce_frame`` must name its cells), a declared unit
    that differs, an unreadable file: the caller then reads the stream whole, where the
    findings are made. Rows are kept in file order (selection by value, not by position),
    so :func:`fieldlogs.pipeline.run.clean_stream` sees every row of the window. The findings
    are those of the whole read that do not depend on the rows (unknown columns)."""
    try:
        pf = open_parquet(path)
    except InputError:
        return None
    schema = pf.schema_arrow
    present = _window_columns(table, schema)
    if present is None:
        return None
    import pyarrow.compute as pc

    fast: dict[str, Any] = {}
    try:
        groups = _row_groups_between(pf, t0, t1)
        masks = []
        for g in groups:  # the window's rows of each group, from its t alone
            t = pf.read_row_group(g, columns=["t"]).column(0)
            masks.append(pc.and_(pc.greater_equal(t, t0), pc.less(t, t1)))
        n_rows = sum(int(pc.sum(m).as_py() or 0) for m in masks)
        for col in present:  # a column of a group at a time: the window is held about once
            parts = [
                chunk
                for g, m in zip(groups, masks, strict=True)
                for chunk in pf.read_row_group(g, columns=[col.name]).column(0).filter(m).chunks
            ]
            fast[col.name] = _arrow_column(col, pa.chunked_array(parts, type=schema.field(col.name).type))
            del parts
    except (pa.ArrowException, OSError):
        return None
    finally:
        pa.default_memory_pool().release_unused()
    for col in table.columns:  # an optional column absent: nulls of its type
        if col.name not in fast:
            fast[col.name] = pd.Series([None] * n_rows, dtype=PANDAS_DTYPE[col.dtype]).array
    frame = pd.DataFrame({c.name: fast[c.name] for c in table.columns}, copy=False)
    return frame, _unknown_columns(table, schema, str(path))


def stream_t_range(path: Path) -> tuple[float, float] | None:
    """(first, last) t of a Parquet stream from its row groups' statistics (no rows read),
    or None when a group has none or the file cannot be opened."""
    try:
        pf = open_parquet(path)
    except InputError:
        return None
    if "t" not in pf.schema_arrow.names or pf.metadata.num_row_groups == 0:
        return None
    ranges = _t_ranges(pf)
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


class StreamCursor:
    """Consecutive time windows of one Parquet stream, each row group decoded once.

    :func:`read_parquet_stream_between` decodes every row group that reaches a window, so
    the windows of a long run decode a group once per window it reaches (a file of one
    row group once per window). A cursor reads windows whose bounds never go back: it keeps
    the rows already decoded that a later window may still need (t ≥ the last window's
    start, the overlap and the rest of the last group decoded) and decodes the next groups
    in file order only as far as the window reaches. The rows of a window are
    :func:`read_parquet_stream_between`'s (every row with t0 ≤ t < t1, in file order, typed
    the same way): groups whose ``t`` statistics follow one another (each group's first t ≥
    the previous group's last) make that hold; any other file (or a window that goes back)
    gives None from :meth:`between` — the caller reads the window by the function.
    """

    def __init__(self, table: Table, path: Path) -> None:
        self.table, self.path = table, path
        self.pf: pq.ParquetFile | None = None
        self.present: list[Column] | None = None
        self.ranges: list[tuple[float, float]] = []
        self.reset()

    def reset(self) -> None:
        self.next_group = 0
        self.t0 = self.t1 = -math.inf
        self.buf: dict[str, pa.ChunkedArray] = {}

    def _open(self) -> bool:
        if self.pf is not None:
            return self.present is not None
        try:
            self.pf = open_parquet(self.path)
        except InputError:
            return False
        self.present = _window_columns(self.table, self.pf.schema_arrow)
        ranges = _t_ranges(self.pf)
        self.ranges = [r for r in ranges if r is not None]
        if len(self.ranges) < len(ranges) or any(b[0] < a[1] for a, b in itertools.pairwise(self.ranges)):
            self.present = None  # groups overlapping in t: read window by window
        return self.present is not None

    def between(
        self, t0: float, t1: float, carry_from: float | None = None
    ) -> tuple[pd.DataFrame, list[Finding]] | None:
        """The rows with t0 ≤ t < t1 (class docstring), or None. ``carry_from``: where the
        next window will start — rows before it are dropped as soon as a column is read,
        so that the cursor holds, beside the window's frame, one column's decoded rows at
        most and then the overlap with the next window."""
        if not self._open():
            return None
        assert self.pf is not None and self.present is not None
        if t0 < self.t0 or t1 < self.t1:
            self.reset()
        self.t0, self.t1 = t0, t1
        fast: dict[str, Any] = {}
        try:
            self._trim(t0)  # rows before this window are never needed again
            carry = t0 if carry_from is None else min(max(carry_from, t0), t1)
            groups = self._groups(t0, t1)
            rows: Selection = (0, 0)
            keep: Selection = (0, 0)
            held = True
            for col in sorted(self.present, key=lambda c: c.name != "t"):  # t first: it selects
                self._append(col.name, groups)
                if col.name == "t":
                    rows, keep = self._rows(t0, t1), self._rows(carry, math.inf)
                    held = _count(keep) <= MAX_CARRY * _count(rows)
                fast[col.name] = _arrow_column(col, _selected(self.buf[col.name], rows))
                if held:  # only the overlap with the next window stays
                    self.buf[col.name] = _selected(self.buf[col.name], keep, compact=True)
                else:  # none: the next window decodes its groups again
                    del self.buf[col.name]
            n_rows = len(fast["t"])
            if held:
                self.t0 = carry
            else:
                self.buf, self.next_group = {}, 0
        except (pa.ArrowException, OSError):
            self.reset()
            return None
        finally:
            pa.default_memory_pool().release_unused()
        for col in self.table.columns:  # an optional column absent: nulls of its type
            if col.name not in fast:
                fast[col.name] = pd.Series([None] * n_rows, dtype=PANDAS_DTYPE[col.dtype]).array
        frame = pd.DataFrame({c.name: fast[c.name] for c in self.table.columns}, copy=False)
        return frame, _unknown_columns(self.table, self.pf.schema_arrow, str(self.path))

    def _groups(self, t0: float, t1: float) -> list[int]:
        """The groups not decoded yet that reach [t0, t1) (those wholly before are skipped)."""
        while self.next_group < len(self.ranges) and self.ranges[self.next_group][1] < t0:
            self.next_group += 1
        first = self.next_group
        while self.next_group < len(self.ranges) and self.ranges[self.next_group][0] < t1:
            self.next_group += 1
        return list(range(first, self.next_group))

    def _append(self, name: str, groups: list[int]) -> None:
        """One column of ``groups`` decoded after the column's buffered rows."""
        assert self.pf is not None
        old = self.buf.get(name)
        chunks = list(old.chunks) if old is not None else []
        for g in groups:
            chunks.extend(self.pf.read_row_group(g, columns=[name]).column(0).chunks)
        self.buf[name] = pa.chunked_array(chunks, type=self.pf.schema_arrow.field(name).type)

    def _rows(self, t0: float, t1: float) -> Selection:
        """The buffered rows with t0 ≤ t < t1: (offset, length) when ``t`` is sorted (they
        follow one another: a zero-copy slice), else a mask."""
        import pyarrow.compute as pc

        t = self.buf["t"].to_numpy()
        if t.size < 2 or bool(np.all(t[1:] >= t[:-1])):  # sorted (no NaN)
            i0, i1 = (int(i) for i in np.searchsorted(t, [t0, t1], side="left"))
            return i0, i1 - i0
        mask: Selection = pc.and_(pc.greater_equal(self.buf["t"], t0), pc.less(self.buf["t"], t1))
        return mask

    def _trim(self, t0: float) -> None:
        """Drop the buffered rows with t < t0 (no later window needs them)."""
        if self.buf:
            keep = self._rows(t0, math.inf)
            self.buf = {k: _selected(v, keep, compact=True) for k, v in self.buf.items()}
            self.t0 = max(self.t0, t0)


#: Rows of a cursor's buffer: (offset, length) or a boolean mask.
Selection: TypeAlias = tuple[int, int] | Any
#: Most rows a cursor keeps for the next window, as a share of the window's rows: more (a
#: long row group decoded beyond the window — the simulator's tacho, GPS and truth files
#: are one group up to a day) and the group is decoded again by the next window instead,
#: so the memory a cursor holds stays a fraction of a window's.
MAX_CARRY = 0.5


def _count(rows: Selection) -> int:
    import pyarrow.compute as pc

    return rows[1] if isinstance(rows, tuple) else int(pc.sum(rows).as_py() or 0)


def _selected(arr: pa.ChunkedArray, rows: Selection, *, compact: bool = False) -> pa.ChunkedArray:
    """``rows`` of ``arr``: a zero-copy slice, or the masked rows; ``compact``: in buffers of
    their own (what a cursor keeps: a slice would keep its whole row group's buffers)."""
    if isinstance(rows, tuple):
        if rows == (0, len(arr)):
            return arr
        out = arr.slice(*rows)
        return _compact(out) if compact else out
    out = arr.filter(rows)
    return _compact(out) if compact else out


def _compact(arr: pa.ChunkedArray) -> pa.ChunkedArray:
    """The rows kept in buffers of their own (a filtered chunk may share its group's)."""
    return pa.chunked_array([pa.concat_arrays(arr.chunks)] if arr.num_chunks else [], type=arr.type)
