"""One typed reader per stream format (fieldlogs/runs/): the whole read and the read by time
window are options of the same ``read``, a CSV stream readable by window once spooled."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
import pytest

from fieldlogs.runs.csv_reader import CsvStream
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.parquet_reader import ParquetStream
from fieldlogs.runs.typed import TimeWindow
from schemas.logs import LOG_STREAMS
from tests.fieldlogs.make_runs import make_run

TACHO, CAB = LOG_STREAMS["tacho"], LOG_STREAMS["cab"]


def test_a_held_stream_is_read_from_the_start_of_the_run() -> None:
    """A held stream (the cab: its last state holds) takes every row before the window's end;
    the others keep their bounds and carry."""
    w = TimeWindow(2.0, 5.0, carry_from=4.0)
    assert w.of(CAB) == TimeWindow(-math.inf, 5.0)
    assert w.of(TACHO) is w


def test_a_parquet_window_is_the_whole_read_cut_to_its_bounds(tmp_path: Path) -> None:
    """10 s of tacho at 10 Hz (t = 0.0 … 9.9): the window [2, 5) holds t = 2.0 … 4.9, 30 rows."""
    run = make_run(tmp_path / "r", 10, fmt="parquet")
    reader = ParquetStream(TACHO, run / "tacho.parquet")
    whole, _ = reader.read()
    read = reader.fresh().read(TimeWindow(2.0, 5.0))
    assert read is not None
    part, findings = read
    assert len(whole) == 100 and len(part) == 30 and findings == []
    t = whole["t"].to_numpy()
    pd.testing.assert_frame_equal(part, whole[(t >= 2.0) & (t < 5.0)].reset_index(drop=True))
    assert reader.t_span() == pytest.approx((0.0, 9.9)) and reader.rows() == 100


def test_a_csv_stream_is_read_by_window_only_once_spooled(tmp_path: Path) -> None:
    """Before spooling a CSV stream has no window (None); after, its windows are those of its
    Parquet twin, and its whole read is still the CSV file's."""
    csv_run, pq_run = make_run(tmp_path / "c", 10, fmt="csv"), make_run(tmp_path / "p", 10, fmt="parquet")
    reader = CsvStream(TACHO, csv_run / "tacho.csv")
    window = TimeWindow(2.0, 5.0)
    assert reader.read(window) is None and not reader.windowable() and reader.rows() is None
    assert reader.t_span() == pytest.approx((0.0, 9.9))  # from the file's first and last lines
    (tmp_path / "spool").mkdir()
    assert reader.spool(tmp_path / "spool") and reader.windowable() and reader.rows() == 100
    read, twin = reader.read(window), ParquetStream(TACHO, pq_run / "tacho.parquet").read(window)
    assert read is not None and twin is not None
    pd.testing.assert_frame_equal(read[0], twin[0])
    pd.testing.assert_frame_equal(reader.read()[0], ParquetStream(TACHO, pq_run / "tacho.parquet").read()[0])


def test_a_run_spools_its_csv_streams_and_then_reads_windows(tmp_path: Path) -> None:
    """The run's handle: not windowable as CSV, windowable once spooled; a window view holds
    the window's rows of each stream and every cab row before its end."""
    run = read_run(make_run(tmp_path / "r", 10, fmt="csv"))
    assert not run.windowable() and run.window(2.0, 5.0) is None
    (tmp_path / "spool").mkdir()
    assert run.spool(tmp_path / "spool") and run.windowable()
    assert set(run.spooled()) == set(run.streams_present())
    view = run.window(2.0, 5.0)
    assert view is not None
    tacho, cab = view.stream("tacho"), view.stream("cab")
    assert tacho is not None and cab is not None
    assert len(tacho) == 30 and tacho["t"].min() == pytest.approx(2.0)
    whole_cab = run.stream("cab")
    assert whole_cab is not None
    assert len(cab) == int((whole_cab["t"] < 5.0).sum())
