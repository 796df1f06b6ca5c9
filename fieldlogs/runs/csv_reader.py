"""The typed reader of a CSV stream file, whole or — once spooled — by time window
(:class:`CsvStream`).

Whole: the numbers parsed while reading (:func:`dbtools.typed_csv.read_csv_typed`, the
parser source sets use too) or, when that parser declines the file, every cell as text
(:func:`dbtools.tabular.read_raw_table`); either way checked against the declared table by
:func:`fieldlogs.runs.typed.coerce_stream`, which names every bad cell.

By window: a CSV file has no index by time, so a long CSV run is first *spooled*
(:meth:`CsvStream.spool`): the stream is parsed block by block
(:func:`dbtools.typed_csv.iter_csv_typed`, the same parser and values as the whole read) and
each block written as a row group of a Parquet file in a temporary folder; the windows then
read that copy (:class:`fieldlogs.runs.parquet_reader.ParquetStream`), the run keeps its
folder, files and findings. Memory: one block. A stream the block parser declines (text in
a number column, a quote, a padded cell: the text path names those cells), or a block with
type findings, is not spooled: the run is then replayed whole, where the findings are made.
"""

from __future__ import annotations

import contextlib
import copy
from collections.abc import Iterator
from pathlib import Path
from typing import overload

import pandas as pd

from dbtools.tabular import read_raw_table
from dbtools.typed_csv import read_csv_typed
from fieldlogs.runs.parquet_reader import ParquetStream, Read
from fieldlogs.runs.typed import TimeWindow, arrow_stream_table, coerce_stream
from schemas.model import Table

#: Rows per spooled block (and row group).
SPOOL_ROWS = 1 << 17
#: Bytes read from each end of a CSV file to find its first and last t.
EDGE_BYTES = 1 << 14


class CsvStream:
    """One CSV stream file of a run (module docstring)."""

    def __init__(self, table: Table, path: Path) -> None:
        self.table, self.path = table, Path(path)
        self.spooled: ParquetStream | None = None
        """The Parquet copy windows read (:meth:`spool`), None before."""

    @overload
    def read(self, window: None = None) -> Read: ...
    @overload
    def read(self, window: TimeWindow) -> Read | None: ...

    def read(self, window: TimeWindow | None = None) -> Read | None:
        """The typed stream and its findings. Whole (``window`` None): raises InputError when
        the file cannot be read at all (empty, not CSV). By window: the spooled copy's rows,
        None when the stream is not spooled."""
        if window is not None:
            return self.spooled.read(window) if self.spooled is not None else None
        typed = read_csv_typed(self.table, self.path)  # numbers parsed while reading; None: read as text
        raw = typed if typed is not None else read_raw_table(self.path)
        return coerce_stream(self.table, raw, str(self.path))

    def windowable(self) -> bool:
        """Whether :meth:`read` can read by window: spooled, and the copy can."""
        return self.spooled is not None and self.spooled.windowable()

    def t_span(self) -> tuple[float, float] | None:
        """(first, last) t: the spooled copy's, else from the file's first and last lines
        (None when they do not parse: no ``t`` column, a quoted header, a short file) —
        enough to decide whether to spool."""
        if self.spooled is not None:
            return self.spooled.t_span()
        return csv_t_span(self.path)

    def rows(self) -> int | None:
        """Rows of the spooled copy (None: not spooled; a CSV file is not counted)."""
        return self.spooled.rows() if self.spooled is not None else None

    def fresh(self) -> CsvStream:
        """This reader without the windows it has read (the same spooled copy)."""
        out = copy.copy(self)
        out.spooled = self.spooled.fresh() if self.spooled is not None else None
        return out

    def close(self) -> None:
        """Drop what the windows hold."""
        if self.spooled is not None:
            self.spooled.close()

    def spool(self, folder: Path, rows: int = SPOOL_ROWS) -> bool:
        """Write the stream as ``folder/NAME.parquet``, block by block (module docstring);
        True when it is (:meth:`read` then reads windows from it)."""
        from dbtools.typed_csv import TextPathNeeded, iter_csv_typed

        if self.spooled is not None:
            return True
        frames = iter_csv_typed(self.table, self.path, rows)
        if frames is None:
            return False
        out = Path(folder) / f"{self.table.name}.parquet"
        try:
            if not _write(frames, self.table, self.path, out):
                return False
        except TextPathNeeded:
            with contextlib.suppress(FileNotFoundError):
                out.unlink()
            return False
        self.spooled = ParquetStream(self.table, out)
        return True


def csv_t_span(path: Path) -> tuple[float, float] | None:
    """(first, last) t of a CSV stream from its first and last lines (:meth:`CsvStream.t_span`)."""
    try:
        with Path(path).open("rb") as f:
            head = f.read(EDGE_BYTES).decode("utf-8", "replace").splitlines()
            f.seek(0, 2)
            size = f.tell()
            f.seek(max(size - EDGE_BYTES, 0))
            tail = f.read().decode("utf-8", "replace").splitlines()
    except OSError:
        return None
    if len(head) < 2 or len(tail) < 2:
        return None
    names = [c.strip() for c in head[0].split(",")]
    if "t" not in names:
        return None
    i = names.index("t")
    last = next((line for line in reversed(tail) if line.strip()), "")
    try:
        return float(head[1].split(",")[i]), float(last.split(",")[i])
    except (ValueError, IndexError):
        return None


def _write(frames: Iterator[pd.DataFrame], table: Table, path: Path, out: Path) -> bool:
    """The frames of ``path`` as the row groups of ``out``; False (nothing usable written) when
    a frame has type findings or there is none."""
    import pyarrow.parquet as pq

    writer = None
    try:
        for raw in frames:
            typed, findings = coerce_stream(table, raw, str(path))
            if findings:
                return False
            arrow = arrow_stream_table(table, typed)
            if writer is None:
                writer = pq.ParquetWriter(out, arrow.schema, compression="lz4")
            writer.write_table(arrow, row_group_size=len(typed) or None)
    finally:
        if writer is not None:
            writer.close()
    return writer is not None
