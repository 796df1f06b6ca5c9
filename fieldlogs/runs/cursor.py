"""Consecutive time windows of one Parquet stream, each row group decoded once: the
windowed read of :class:`fieldlogs.runs.parquet_reader.ParquetStream` over a long run's
replay (:mod:`fieldlogs.pipeline.windows`)."""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeAlias

import numpy as np
import pandas as pd
import pyarrow as pa

from fieldlogs.runs.parquet_file import (
    arrow_column,
    open_parquet,
    t_ranges,
    typed_frame,
    unknown_columns,
    window_columns,
)
from schemas.errors import InputError
from schemas.findings import Finding
from schemas.model import Column, Table

if TYPE_CHECKING:
    import pyarrow.parquet as pq


class StreamCursor:
    """Consecutive time windows of one Parquet stream, each row group decoded once.

    :func:`fieldlogs.runs.parquet_reader.read_between` decodes every row group that reaches a window, so
    the windows of a long run decode a group once per window it reaches (a file of one
    row group once per window). A cursor reads windows whose bounds never go back: it keeps
    the rows already decoded that a later window may still need (t ≥ the last window's
    start, the overlap and the rest of the last group decoded) and decodes the next groups
    in file order only as far as the window reaches. The rows of a window are
    :func:`fieldlogs.runs.parquet_reader.read_between`'s (every row with t0 ≤ t < t1, in file order, typed
    the same way): groups whose ``t`` statistics follow one another (each group's first t ≥
    the previous group's last) make that hold; any other file (or a window that goes back)
    gives None from :meth:`between` — the reader then reads the window by the function.
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
        self.present = window_columns(self.table, self.pf.schema_arrow)
        ranges = t_ranges(self.pf)
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
                fast[col.name] = arrow_column(col, _selected(self.buf[col.name], rows))
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
        frame = typed_frame(self.table, fast, n_rows)
        return frame, unknown_columns(self.table, self.pf.schema_arrow, str(self.path))

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
