"""A long run replayed in time windows (fieldlogs.pipeline.windows): the windows, reading a
stream by time, the mergeable summary, and the replay against the whole-run replay."""

from __future__ import annotations

import itertools
import json
import math
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.csvwrite import write_csv
from dbtools.database import read_network
from fieldlogs.pipeline.config import PipelineConfig, WindowConfig
from fieldlogs.pipeline.outputs import streamed_results
from fieldlogs.pipeline.run import PipelineResult, run_pipeline
from fieldlogs.pipeline.summary import RunParts, summarise, summarise_parts
from fieldlogs.pipeline.windows import plan_run, plan_windows, replay_bounded, run_bounded
from fieldlogs.runs.cursor import StreamCursor
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.parquet_file import stream_t_range
from fieldlogs.runs.parquet_reader import ParquetStream, read_between
from fieldlogs.runs.write import convert_run
from schemas.logs import CAB, GPS, TACHO
from schemas.model import Column, Table

SAMPLE_LOGS = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"
HOUR = 3600.0


# --- the windows -------------------------------------------------------------------------


def test_no_windows_for_a_run_up_to_one_and_a_half_lengths() -> None:
    cfg = WindowConfig(length_h=2.0)
    assert plan_windows(0.0, 3 * HOUR, cfg) == []
    assert plan_windows(0.0, 100 * HOUR, WindowConfig(length_h=0.0)) == []
    assert len(plan_windows(0.0, 3 * HOUR + 1.0, cfg)) == 2


def test_windows_cover_the_run_and_read_around_their_part() -> None:
    cfg = WindowConfig(length_h=2.0, overlap_min=30.0, lookahead_min=5.0)
    w = plan_windows(100.0, 100.0 + 24.2 * HOUR, cfg)
    assert len(w) == 12
    assert w[0].keep_from == -math.inf and w[-1].keep_to == math.inf
    assert [x.keep_from for x in w[1:]] == [100.0 + k * 2 * HOUR for k in range(1, 12)]
    assert all(a.keep_to == b.keep_from for a, b in itertools.pairwise(w))
    assert w[3].read_from == w[3].keep_from - 1800.0 and w[3].read_to == w[3].keep_to + 300.0
    assert w[-1].keep_to - w[-1].keep_from == math.inf  # the rest of the run, 2.2 h here


@settings(max_examples=200, deadline=None)
@given(
    start=st.floats(-1e5, 1e5),
    span_h=st.floats(0.0, 50.0),
    length_h=st.floats(0.1, 5.0),
    t=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=20),
)
def test_every_time_is_kept_by_exactly_one_window(start: float, span_h: float, length_h: float, t: list[float]) -> None:
    windows = plan_windows(start, start + span_h * HOUR, WindowConfig(length_h=length_h))
    times = np.array([start - 10.0, *(start + f * span_h * HOUR for f in t), start + span_h * HOUR + 10.0])
    if windows:
        counts = sum(w.keeps(times).astype(int) for w in windows)
        assert (counts == 1).all()
        assert all(w.keep_to - w.keep_from >= 0.5 * length_h * HOUR - 1e-6 for w in windows[1:])


# --- reading a stream by time --------------------------------------------------------------

SMALL = Table(
    name="small",
    kind="log",
    description="test stream",
    columns=(
        Column("t", "float", "time", unit="s"),
        Column("x", "float", "value", unit="m"),
        Column("n", "int", "count", required=False, nullable=True),
        Column("s", "str", "label", required=False, nullable=True),
        Column("absent", "float", "not in the file", required=False, nullable=True),
    ),
)


def _small_stream(tmp_path: Path, t: list[float], group: int) -> Path:
    """A Parquet stream with these t, a float, a nullable int and a nullable text column (nulls
    on a fixed pattern), ``group`` rows per row group."""
    n = len(t)
    rng = np.random.default_rng(n)
    frame = pd.DataFrame(
        {
            "t": t,
            "x": rng.normal(size=n),
            "n": pd.array([None if i % 7 == 3 else i for i in range(n)], dtype="Int64"),
            "s": [None if i % 5 == 1 else f"v{i % 3}" for i in range(n)],
        }
    )
    path = tmp_path / "small.parquet"
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path, row_group_size=group)
    return path


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    t=st.lists(st.one_of(st.floats(0.0, 100.0), st.just(float("nan"))), min_size=1, max_size=80),
    group=st.integers(1, 30),
    a=st.floats(-10.0, 110.0),
    width=st.floats(0.0, 120.0),
)
def test_a_window_is_the_rows_of_the_whole_read_in_it(
    tmp_path: Path, t: list[float], group: int, a: float, width: float
) -> None:
    """Any order, repeated and missing t, nulls, several row groups: the window's rows are
    those of the whole read with a ≤ t < b, in file order, typed the same."""
    path = _small_stream(tmp_path, t, group)
    whole, _ = ParquetStream(SMALL, path).read()
    b = a + width
    read = read_between(SMALL, path, a, b)
    assert read is not None
    part, findings = read
    tt = whole["t"].to_numpy(dtype=float)
    expected = whole[(tt >= a) & (tt < b)].reset_index(drop=True)
    pd.testing.assert_frame_equal(part, expected)
    assert findings == []


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    t=st.lists(st.one_of(st.floats(0.0, 100.0), st.just(float("nan"))), min_size=1, max_size=80),
    group=st.integers(1, 30),
    starts=st.lists(st.floats(-10.0, 110.0), min_size=1, max_size=6),
    width=st.floats(0.0, 40.0),
    ahead=st.floats(0.0, 10.0),
    order=st.sampled_from(["sorted", "groups", "any"]),
)
def test_a_cursor_reads_each_window_as_the_window_reader(
    tmp_path: Path, t: list[float], group: int, starts: list[float], width: float, ahead: float, order: str
) -> None:
    """Windows one after the other (and one going back), each told where the next starts:
    the cursor's rows are read_between's — sorted t with repeats and NaN,
    groups in time order but rows unsorted inside, or any order (then the cursor declines)."""
    if order == "sorted":
        t = sorted(t, key=lambda x: (math.isnan(x), x))
        t = [x for x in t if not math.isnan(x)] or [0.0]
    elif order == "groups":
        t = [x for x in t if not math.isnan(x)] or [0.0]
        t = sorted(t)
        t = [x for k in range(0, len(t), group) for x in reversed(t[k : k + group])]
    path = _small_stream(tmp_path, t, group)
    cursor = StreamCursor(SMALL, path)
    bounds = sorted(starts)
    windows = [(a, a + width + ahead) for a in bounds] + [(bounds[0], bounds[0] + width)]  # the last one goes back
    for k, (a, b) in enumerate(windows):
        nxt = windows[k + 1][0] if k + 1 < len(windows) else None
        got = cursor.between(a, b, nxt)
        want = read_between(SMALL, path, a, b)
        assert want is not None
        if got is None:
            assert order == "any"
            continue
        pd.testing.assert_frame_equal(got[0], want[0])
        assert got[1] == want[1]


def test_a_cursor_decodes_each_row_group_once(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Consecutive overlapping windows over 10 groups: each column of each group decoded
    once (the window reader decodes a group once per window it reaches); a file of one
    group much longer than a window is decoded again by each window instead of being held."""
    t = np.arange(1000, dtype=float) / 10.0
    frame = pd.DataFrame({"t": t, "x": t * 2.0, "n": pd.array(np.arange(1000), dtype="Int64"), "s": ["a"] * 1000})
    reads: list[int] = []
    original = pq.ParquetFile.read_row_group

    def counted(self: pq.ParquetFile, i: int, *args: object, **kwargs: object) -> pa.Table:
        reads.append(i)
        return original(self, i, *args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(pq.ParquetFile, "read_row_group", counted)
    starts = [0.0, 40.0, 80.0]  # 40 s windows reading 5 s before and 3 s after: groups of 10 s
    for group, decoded in ((100, [g for g in range(10) for _ in range(4)]), (1000, [0] * 4 * len(starts))):
        path = tmp_path / f"small-{group}.parquet"
        pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), path, row_group_size=group)
        cursor = StreamCursor(SMALL, path)
        reads.clear()
        rows = 0
        for k, a in enumerate(starts):
            last = k + 1 == len(starts)
            t0, t1 = (a - 5.0 if k else -math.inf), (math.inf if last else a + 43.0)
            got = cursor.between(t0, t1, None if last else a + 35.0)
            assert got is not None
            rows += len(got[0])
        assert sorted(reads) == sorted(decoded)  # t, x, n, s
        assert rows == 1000 + 2 * 80  # the windows overlap by 8 s


def test_a_stream_that_must_be_coerced_is_not_read_by_window(tmp_path: Path) -> None:
    path = tmp_path / "tacho.parquet"
    pq.write_table(pa.table({"t": ["0.0", "0.1"], "pulses": [0, 1]}), path)
    assert read_between(TACHO, path, 0.0, 1.0) is None


def test_stream_t_range_is_read_from_the_statistics(tmp_path: Path) -> None:
    path = tmp_path / "imu.parquet"
    pq.write_table(pa.table({"t": [5.0, 1.0, 9.5, 3.0]}), path, row_group_size=2)
    assert stream_t_range(path) == (1.0, 9.5)
    pq.write_table(pa.table({"t": [5.0, 1.0]}), path, write_statistics=False)
    assert stream_t_range(path) is None


# --- runs ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def parquet_runs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample runs as Parquet (the format read by window)."""
    root = tmp_path_factory.mktemp("pq-runs")
    for name in ("sim-d-slips", "sim-u-tunnel", "sim-road-rail", "sim-d-reversal"):
        convert_run(SAMPLE_LOGS / name, root / name, "parquet")
    return root


def _with_t(src: Path, dst: Path, stream: str, change: Callable[[pa.ChunkedArray], pa.ChunkedArray]) -> Path:
    """A copy of the run ``src`` whose ``stream`` has its t changed by ``change``."""
    dst.mkdir()
    for f in src.iterdir():
        if f.name == f"{stream}.parquet":
            table = pq.read_table(f)
            pq.write_table(
                table.set_column(table.schema.get_field_index("t"), "t", change(table.column("t"))), dst / f.name
            )
        else:
            (dst / f.name).write_bytes(f.read_bytes())
    return dst


def _small_windows(length_h: float = 0.05, overlap_min: float = 4.0) -> PipelineConfig:
    return replace(PipelineConfig(), window=WindowConfig(length_h=length_h, overlap_min=overlap_min, lookahead_min=1.0))


def test_a_csv_run_is_replayed_whole(tmp_path: Path, parquet_runs: Path) -> None:
    assert read_run(parquet_runs / "sim-d-slips").windowable()
    convert_run(SAMPLE_LOGS / "sim-d-slips", tmp_path / "csv", "csv")
    run = read_run(tmp_path / "csv")
    assert not run.windowable()
    assert plan_run(run, _small_windows().window) == []
    assert run.window(0.0, 60.0) is None


@pytest.mark.slow
@pytest.mark.parametrize("name", ["sim-d-slips", "sim-u-tunnel", "sim-road-rail", "sim-d-reversal"])
def test_windowed_replay_holds_its_margin_and_agrees_with_the_whole_run(
    parquet_runs: Path, sample_db: Path, name: str
) -> None:
    """3-minute windows with 4-minute overlaps (a 2 h window's proportions are gentler):
    the same cycles, in the same states but for a few, as the whole replay, every claimed
    cycle inside its margin against the truth, and the km of the two replays within a few
    metres (the GPS analysis of a road-rail vehicle has the longest memory)."""
    net = read_network(sample_db)
    whole = run_pipeline(read_run(parquet_runs / name), net)
    cfg = _small_windows()
    win = run_bounded(read_run(parquet_runs / name), net, cfg)
    assert win.summary["windows"]["count"] >= 3
    a, b = whole.positions, win.positions
    np.testing.assert_array_equal(a["t"].to_numpy(), b["t"].to_numpy())
    # the same states but where a 3-minute window's clock check differs from the run's (the
    # tunnel run's middle window "finds" a GPS offset of −0.96 s in 8 minutes of data)
    assert (a["state"].to_numpy() == b["state"].to_numpy()).mean() >= 0.99
    assert win.summary["truth"]["within_margin_share"] == 1.0
    assert win.summary["truth"]["wrong_track_cycles"] == 0
    both = (a["km_m"].notna() & b["km_m"].notna()).to_numpy()
    diff = np.abs(a["km_m"].to_numpy()[both] - b["km_m"].to_numpy()[both])
    assert diff.max() < 3.0
    for key in ("line_code", "track", "n_slips", "first_determined_t"):
        assert win.summary[key] == whole.summary[key], key
    assert win.summary["duration_s"] == pytest.approx(whole.summary["duration_s"])
    assert win.summary["distance_m"] == pytest.approx(whole.summary["distance_m"], abs=0.05)  # slip corrections
    assert len(win.odometry.d) == len(b) and np.all(np.diff(win.odometry.d) >= 0)


@pytest.mark.slow
def test_with_overlap_enough_the_slips_run_is_the_whole_run(parquet_runs: Path, sample_db: Path) -> None:
    """5-minute windows, 6-minute overlaps: the replay of the whole run to the micrometre."""
    net = read_network(sample_db)
    whole = run_pipeline(read_run(parquet_runs / "sim-d-slips"), net)
    win = run_bounded(read_run(parquet_runs / "sim-d-slips"), net, _small_windows(length_h=0.08, overlap_min=6.0))
    assert win.summary["windows"]["count"] == 2
    for col in ("km_m", "margin_m", "speed_mps"):
        np.testing.assert_allclose(win.positions[col], whole.positions[col], atol=1e-6, equal_nan=True)
    kinds = whole.events["type"].value_counts().to_dict()
    assert win.events["type"].value_counts().to_dict() == kinds


def test_a_held_stream_gives_a_window_the_state_in_force(parquet_runs: Path) -> None:
    """A window between two changes of the cab's direction still has the direction in force
    (a cab row holds until the next); a sampled stream gives only the window's rows."""
    run = read_run(parquet_runs / "sim-road-rail")
    cab = run.stream("cab")
    assert cab is not None and len(cab) >= 2 and CAB.held and not GPS.held
    t_cab = cab["t"].to_numpy(dtype=float)
    a, b = t_cab[0] + 1.0, min(t_cab[0] + 61.0, t_cab[1])
    view = run.window(a, b)
    assert view is not None
    seen = view.stream("cab")
    assert seen is not None
    pd.testing.assert_frame_equal(seen, cab[cab["t"] < b].reset_index(drop=True))
    gps = view.stream("gps")
    assert gps is not None and len(gps) and (gps["t"] >= a).all() and (gps["t"] < b).all()


def test_a_window_too_short_to_find_the_imu_clock_takes_its_neighbours(
    tmp_path: Path, parquet_runs: Path, sample_db: Path
) -> None:
    """The IMU clock 2 s late on 3-minute windows: a window with too little motion to
    determine it takes the nearest window's offset (without it 2.2 % of the claimed cycles
    fell outside their margin); every window says so at its start, naming the window."""
    run_dir = _with_t(parquet_runs / "sim-d-slips", tmp_path / "late", "imu", lambda t: pa.compute.add(t, 2.0))
    win = run_bounded(read_run(run_dir), read_network(sample_db), _small_windows(length_h=0.05, overlap_min=4.0))
    offsets = win.events[win.events["type"] == "clock_offset"]
    assert len(offsets) == win.summary["windows"]["count"] == 3
    details = [json.loads(d) for d in offsets["detail"]]
    assert all(d["stream"] == "imu" and abs(d["offset_s"] - 2.0) < 0.3 for d in details)
    assert "window" not in details[0] and offsets["t"].iloc[0] == 0.0
    assert all(t == d["window"][0] > 0.0 for t, d in zip(offsets["t"].iloc[1:], details[1:], strict=True))
    assert any("determined_from_t" in d for d in details)
    assert win.summary["truth"]["within_margin_share"] == 1.0


# --- the summary from parts ------------------------------------------------------------------


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cuts=st.lists(st.floats(0.0, 1.0), min_size=1, max_size=6))
def test_the_summary_of_merged_parts_is_the_whole_runs(
    slips_result: tuple[PipelineResult, object], cuts: list[float]
) -> None:
    """Positions cut anywhere into spans: the merged parts give the whole summary's figures
    (shares, route, first claim, largest margin, duration) exactly."""
    res, (run, net) = slips_result  # type: ignore[misc]
    pos = res.positions
    n = len(pos)
    edges = sorted({0, n, *(int(c * n) for c in cuts)})
    parts = [
        RunParts.of(pos.iloc[a:b], replace(res.odometry, episodes=[]), None, None, distance_m=0.0)
        for a, b in itertools.pairwise(edges)
    ]
    merged = summarise_parts(run, net, PipelineConfig(), RunParts.merged(parts), res.events)
    whole = summarise(run, net, PipelineConfig(), pos, res.events, replace(res.odometry, episodes=[]), None)
    for key in ("state_share", "line_code", "track", "first_determined_t", "max_margin_m", "duration_s"):
        assert merged[key] == whole[key], key
    assert json.dumps(merged["state_share"]) == json.dumps(whole["state_share"])  # the order too


@pytest.fixture(scope="module")
def slips_result(sample_db: Path) -> tuple[PipelineResult, tuple[object, object]]:
    run = read_run(SAMPLE_LOGS / "sim-d-slips")
    net = read_network(sample_db)
    return run_pipeline(run, net), (run, net)


# --- outputs written as they come -------------------------------------------------------------


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(cuts=st.lists(st.integers(0, 40), min_size=0, max_size=4))
def test_outputs_written_in_parts_are_the_whole_frames(
    tmp_path_factory: pytest.TempPathFactory, cuts: list[int]
) -> None:
    """The CSV bytes of the whole frame; the Parquet table equal, also when a column is all
    missing in the first part."""
    tmp = tmp_path_factory.mktemp("parts")
    n = 40
    frame = pd.DataFrame(
        {
            "t": np.arange(n) * 0.1,
            "state": ["undetermined"] * 12 + ["determined"] * (n - 12),
            "line_code": [None] * 12 + ["0900"] * (n - 12),
            "km_m": [np.nan] * 12 + list(np.linspace(1000.0, 1100.0, n - 12)),
        }
    )
    edges = sorted({0, n, *cuts})
    with streamed_results(tmp / "out", force=True) as sink:
        for a, b in itertools.pairwise(edges):
            sink.add_positions(frame.iloc[a:b])
        sink.finish(pd.DataFrame({"t": [0.0], "type": ["x"]}), {"ok": True})
    write_csv(frame, tmp / "whole.csv")
    assert (tmp / "out" / "positions.csv").read_bytes() == (tmp / "whole.csv").read_bytes()
    back = pq.read_table(tmp / "out" / "positions.parquet").to_pandas()
    pd.testing.assert_frame_equal(back, frame, check_dtype=False)


@pytest.mark.slow
def test_trainpos_run_of_a_windowed_run_writes_what_the_joined_replay_holds(
    tmp_path: Path, parquet_runs: Path, sample_db: Path
) -> None:
    net = read_network(sample_db)
    cfg = _small_windows()
    joined = run_bounded(read_run(parquet_runs / "sim-d-slips"), net, cfg)
    with streamed_results(tmp_path / "out") as sink:
        done = replay_bounded(
            read_run(parquet_runs / "sim-d-slips"), net, cfg, lambda p: sink.add_positions(p.positions)
        )
        sink.finish(done.events, done.summary)
    write_csv(joined.positions, tmp_path / "joined.csv")
    assert (tmp_path / "out" / "positions.csv").read_bytes() == (tmp_path / "joined.csv").read_bytes()
    summary = json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))
    assert summary["windows"]["count"] == done.windows >= 3
    assert done.cycles == len(joined.positions)
    assert done.last_position is not None
    assert done.last_position[0] == pytest.approx(float(joined.positions["km_m"].dropna().iloc[-1]))


@pytest.mark.slow
def test_an_audit_worker_keeps_the_trace_and_direction_of_a_windowed_run(parquet_runs: Path, sample_db: Path) -> None:
    """The audit's worker on a run replayed in windows: the record as for the whole run (route,
    direction, correction counts), the 1 Hz trace over the whole run, the events of every window."""
    from fieldlogs.audit.runner import audit_one
    from fieldlogs.audit.store import decode_trace
    from fieldlogs.replay.network import open_db

    ref, _ = open_db(sample_db)
    run = str(parquet_runs / "sim-d-slips")
    whole = audit_one(run, ref, json.dumps(PipelineConfig().to_dict()), "whole")
    cfg = _small_windows(length_h=0.08, overlap_min=6.0)
    win = audit_one(run, ref, json.dumps(cfg.to_dict()), "windows")
    a, b = whole["record"], win["record"]
    assert b["status"] == "ok", b.get("error")
    for key in ("track_id", "line_code", "track", "direction", "n_corrections"):
        assert a[key] == b[key], key
    assert json.loads(b["summary_json"])["windows"]["count"] == 2
    ta, tb = decode_trace(whole["trace"]), decode_trace(win["trace"])
    assert abs(len(ta) - len(tb)) <= 2 and tb["t"].is_monotonic_increasing
    np.testing.assert_allclose(tb["t"].iloc[[0, -1]], ta["t"].iloc[[0, -1]], atol=1.0)
    assert tb["v_pulse_mps"].notna().mean() > 0.99  # the kept cycles carry their pulse speed


def test_a_tacho_time_base_its_rows_do_not_cover_is_not_windowed(tmp_path: Path, parquet_runs: Path) -> None:
    """t in milliseconds (610 s of rows spanning 7 days): no windows — the run goes whole to the
    usability rule, which refuses it with the reason (a window per 2 h of a wrong span would be
    hundreds of replays of nothing)."""
    run_dir = _with_t(parquet_runs / "sim-d-slips", tmp_path / "ms", "tacho", lambda t: pa.compute.multiply(t, 1000.0))
    run = read_run(run_dir)
    assert run.windowable()
    assert plan_run(run, WindowConfig(length_h=2.0)) == []
    assert plan_run(read_run(parquet_runs / "sim-d-slips"), WindowConfig(length_h=0.05))


@pytest.mark.slow
def test_a_long_csv_run_is_spooled_and_replayed_as_its_parquet_twin(
    tmp_path: Path, parquet_runs: Path, sample_db: Path
) -> None:
    """The CSV conversion of a run, windowed: its streams spooled to Parquet block by block,
    the positions those of the Parquet run's windowed replay; nothing left of the spool."""
    convert_run(parquet_runs / "sim-d-slips", tmp_path / "csv", "csv")
    net = read_network(sample_db)
    cfg = _small_windows()
    pq_res = run_bounded(read_run(parquet_runs / "sim-d-slips"), net, cfg)
    before = {f.name: f.read_bytes() for f in (tmp_path / "csv").iterdir()}
    run = read_run(tmp_path / "csv")
    csv_res = run_bounded(run, net, cfg)
    assert csv_res.summary["windows"] == pq_res.summary["windows"]
    assert set(run.spooled()) == set(run.streams_present())
    assert not any(p.exists() for p in run.spooled().values())  # the spool folder is removed
    pd.testing.assert_frame_equal(csv_res.positions, pq_res.positions)
    assert {f.name: f.read_bytes() for f in (tmp_path / "csv").iterdir()} == before  # the input untouched


def test_a_csv_stream_the_block_parser_declines_keeps_the_run_whole(tmp_path: Path, parquet_runs: Path) -> None:
    """A quoted cell in the IMU: that stream needs the text path, the run is not spooled."""
    convert_run(parquet_runs / "sim-d-slips", tmp_path / "csv", "csv")
    imu = tmp_path / "csv" / "imu.csv"
    lines = imu.read_text(encoding="utf-8").splitlines(keepends=True)
    first = lines[5].split(",")
    lines[5] = ",".join([first[0], f'"{first[1]}"', *first[2:]])
    imu.write_text("".join(lines), encoding="utf-8")
    run = read_run(tmp_path / "csv")
    span = run.t_span("tacho")  # from the CSV file's first and last lines
    assert span is not None and span[1] - span[0] > 600.0
    (tmp_path / "spool").mkdir()
    assert not run.spool(tmp_path / "spool")
    assert "imu" not in run.spooled() and not run.windowable()
