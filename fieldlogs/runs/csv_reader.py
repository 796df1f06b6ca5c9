"""A long CSV run's streams written once as Parquet, so its replay can read them by window.

The windowed replay (:mod:`fieldlogs.pipeline.windows`) reads every stream by time from
Parquet row groups. A CSV stream has no such index, so a long CSV run is first *spooled*:
each CSV stream is parsed block by block (:func:`dbtools.typed_csv.iter_csv_typed`, the
same parser and values as the whole read) and each block written as a row group of a
Parquet file in a temporary folder (:attr:`fieldlogs.io.Run.spooled`); the run keeps its
folder, files and findings — only the windows read the spooled copies. Memory: one block.

A stream the block parser declines (text in a number column, a quote, a padded cell: the text
path names those cells), or a block with type findings, is not spooled: the run is then
replayed whole, where the findings are made.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from pathlib import Path

import pandas as pd

from fieldlogs.io import Run, arrow_stream_table, coerce_stream
from schemas.logs import LOG_STREAMS
from schemas.model import Table

#: Rows per spooled block (and row group).
SPOOL_ROWS = 1 << 17
#: Bytes read from each end of a CSV file to find its first and last t.
EDGE_BYTES = 1 << 14


def csv_t_span(path: Path) -> tuple[float, float] | None:
    """(first, last) t of a CSV stream from its first and last lines (None when they do not
    parse: no ``t`` column, a quoted header, a short file) — enough to decide whether to spool."""
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


def spool_csv_streams(run: Run, folder: Path, rows: int = SPOOL_ROWS) -> bool:
    """Spool every CSV stream of ``run`` into ``folder`` (module docstring); True when all of
    them are (the run can then be read by window), False when one is not."""
    from dbtools.typed_csv import TextPathNeeded, iter_csv_typed

    for name in run.streams_present():
        path = run.stream_file(name)
        if path is None or path.suffix == ".parquet" or name in run.spooled:
            continue
        table = LOG_STREAMS[name]
        frames = iter_csv_typed(table, path, rows)
        if frames is None:
            return False
        out = Path(folder) / f"{name}.parquet"
        try:
            if not _write(frames, table, path, out):
                return False
        except TextPathNeeded:
            with contextlib.suppress(FileNotFoundError):
                out.unlink()
            return False
        run.spooled[name] = out
    return True


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
