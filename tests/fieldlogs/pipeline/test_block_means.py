"""Cycle means fed block by block (``fieldlogs.pipeline.block_means``): bit for bit the
whole-array means on random block boundaries (cycles split across blocks, repeated t, NaN
and inf values, samples beyond the grid); unsorted input detected and left to the
whole-array path; a hand-computed split cycle; ``build_cycles`` unchanged on a sample run."""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.block_means import BlockCycleMeans, means_by_blocks
from fieldlogs.pipeline.cycles import IMU_COLUMNS, cycle_index, cycle_means, imu_cycle_means, segments
from fieldlogs.runs.handle import read_run
from tests.fieldlogs.pipeline.conftest import SAMPLE_LOGS
from tests.fieldlogs.pipeline.test_cycles import reference_means


def fed(
    t_cycles: np.ndarray, ts: np.ndarray, cols: dict[str, np.ndarray], cuts: list[int]
) -> dict[str, np.ndarray] | None:
    acc = BlockCycleMeans(t_cycles, list(cols))
    edges = [0, *sorted(min(c, ts.size) for c in cuts), ts.size]
    for a, b in itertools.pairwise(edges):
        acc.add(ts[a:b], {c: v[a:b] for c, v in cols.items()})
    return acc.finish()


def test_a_cycle_split_across_two_blocks() -> None:
    t = np.array([0.1, 0.2, 0.3])
    ts = np.array([0.05, 0.12, 0.15, 0.18, 0.25, 0.35])  # cycle 1 = (.1, .2] is cut after 0.12
    v = np.array([1.0, 2.0, np.nan, 6.0, 7.0, 100.0])
    out = fed(t, ts, {"x": v}, [2])
    assert out is not None
    assert np.array_equal(out["x"], [1.0, 4.0, 7.0])  # (2 + 6) / 2: one mean, not two halves


def test_blocks_out_of_time_order_are_refused() -> None:
    t = np.array([0.1, 0.2, 0.3])
    acc = BlockCycleMeans(t, ["x"])
    acc.add(np.array([0.05, 0.15]), {"x": np.array([1.0, 2.0])})
    acc.add(np.array([0.12, 0.25]), {"x": np.array([3.0, 4.0])})  # 0.12 < 0.15
    assert not acc.in_order and acc.finish() is None
    nan_t = BlockCycleMeans(t, ["x"])
    nan_t.add(np.array([0.05, np.nan]), {"x": np.array([1.0, 2.0])})
    assert nan_t.finish() is None


@settings(max_examples=300, deadline=None)
@given(
    n_cycles=st.integers(0, 40),
    gaps=st.lists(st.one_of(st.just(0.0), st.floats(0.0, 0.05)), min_size=0, max_size=300),
    values=st.lists(
        st.one_of(st.floats(-1e6, 1e6), st.just(float("nan")), st.just(float("inf"))), min_size=300, max_size=300
    ),
    cuts=st.lists(st.integers(0, 300), max_size=12),
)
def test_block_means_equal_the_whole_array_means(
    n_cycles: int, gaps: list[float], values: list[float], cuts: list[int]
) -> None:
    t = 0.1 * np.arange(1, n_cycles + 1)
    ts = np.cumsum(np.asarray(gaps, dtype=float))  # non-decreasing, repeated t included
    v = np.asarray(values[: ts.size], dtype=float)
    cols = {"a": v, "b": np.roll(v, 1), "c": np.where(np.arange(ts.size) % 3 == 0, np.nan, v)}
    out = fed(t, ts, cols, cuts)
    assert out is not None
    for c, x in cols.items():
        assert np.array_equal(out[c], reference_means(t, ts, x), equal_nan=True)
        assert np.array_equal(out[c], cycle_means(t, ts, x), equal_nan=True)
    rows = max(cuts[0], 1) if cuts else 7
    by = means_by_blocks(t, ts.size, lambda a, b: (ts[a:b], {c: x[a:b] for c, x in cols.items()}), list(cols), rows)
    assert by is not None and all(np.array_equal(by[c], out[c], equal_nan=True) for c in cols)


@settings(max_examples=200, deadline=None)
@given(
    n_cycles=st.integers(1, 20),
    ts=st.lists(st.one_of(st.floats(0.0, 2.5), st.just(float("nan"))), min_size=2, max_size=120),
    rows=st.integers(1, 50),
)
def test_unsorted_imu_falls_back_to_the_whole_array_means(n_cycles: int, ts: list[float], rows: int) -> None:
    """Out of order (or a NaN t): the blocks refuse and ``imu_cycle_means`` gives what the
    whole-array computation gives on those samples."""
    t = 0.1 * np.arange(1, n_cycles + 1)
    tt = np.asarray(ts, dtype=float)
    rng = np.random.default_rng(len(ts))
    frame = pd.DataFrame({"t": tt, **{c: rng.normal(size=tt.size) for c in IMU_COLUMNS}})
    ordered = bool(np.all(tt[1:] >= tt[:-1]))
    block = lambda a, b: (tt[a:b], {c: frame[c].to_numpy()[a:b] for c in IMU_COLUMNS})  # noqa: E731
    assert (means_by_blocks(t, tt.size, block, IMU_COLUMNS, rows) is not None) == ordered
    seg = segments(cycle_index(t, tt), t.size)
    got = imu_cycle_means(t, frame)
    for c in IMU_COLUMNS:
        assert np.array_equal(got[c], cycle_means(t, tt, frame[c].to_numpy(), seg=seg), equal_nan=True)


def test_imu_cycle_means_of_a_sample_run_equal_the_whole_array_means() -> None:
    run = read_run(SAMPLE_LOGS / "sim-d-slips")
    imu, tacho = run.stream("imu"), run.stream("tacho")
    assert imu is not None and tacho is not None and len(imu) > 3 * 65536 // 10
    t = tacho["t"].to_numpy(dtype=float)
    ts = imu["t"].to_numpy(dtype=float)
    got = imu_cycle_means(t, imu)
    for c in IMU_COLUMNS:
        assert np.array_equal(got[c], cycle_means(t, ts, imu[c].to_numpy(dtype=float)), equal_nan=True)
    small = means_by_blocks(
        t, ts.size, lambda a, b: (ts[a:b], {c: imu[c].to_numpy()[a:b] for c in IMU_COLUMNS}), IMU_COLUMNS, 997
    )
    assert small is not None and all(np.array_equal(small[c], got[c], equal_nan=True) for c in IMU_COLUMNS)
