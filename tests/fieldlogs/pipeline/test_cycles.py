"""Cycle means of a sampled stream (``fieldlogs.pipeline.cycles``): the shared-segment path
gives bit for bit what a direct per-column computation gives (hypothesis), with samples
beyond the last cycle, empty cycles and non-finite values; a hand-computed case; the
pipeline releasing the IMU stream it read."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.database import read_network
from fieldlogs.pipeline.cycles import cycle_index, cycle_means, segments
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.runs.handle import read_run
from tests.fieldlogs.pipeline.conftest import SAMPLE_LOGS


def reference_means(t_cycles: np.ndarray, t_samples: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The per-column computation (before segments were shared): mask, filter, reduceat."""
    idx = cycle_index(t_cycles, t_samples)
    n = t_cycles.size
    inside = idx < n
    vals, k = values[inside], idx[inside]
    ok = np.isfinite(vals)
    vals, k = vals[ok], k[ok]
    out = np.full(n, np.nan)
    if k.size == 0:
        return out
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    out[k[starts]] = np.add.reduceat(vals, starts) / np.diff(np.r_[starts, k.size])
    return out


def test_hand_computed_means() -> None:
    t = np.array([0.1, 0.2, 0.3])
    ts = np.array([0.05, 0.1, 0.15, 0.2, 0.25, 0.35])  # (−∞, .1], (.1, .2], (.2, .3], beyond
    v = np.array([1.0, 3.0, np.nan, 5.0, 7.0, 100.0])
    assert np.array_equal(cycle_means(t, ts, v), [2.0, 5.0, 7.0])
    assert np.array_equal(cycle_means(t, ts[:2], v[:2]), [2.0, np.nan, np.nan], equal_nan=True)


@settings(max_examples=200, deadline=None)
@given(
    n_cycles=st.integers(0, 40),
    gaps=st.lists(st.floats(0.0, 0.05), min_size=0, max_size=300),
    values=st.lists(
        st.one_of(st.floats(-1e6, 1e6), st.just(float("nan")), st.just(float("inf"))), min_size=300, max_size=300
    ),
    columns=st.integers(1, 3),
)
def test_shared_segments_equal_the_per_column_means(
    n_cycles: int, gaps: list[float], values: list[float], columns: int
) -> None:
    t = 0.1 * np.arange(1, n_cycles + 1)
    ts = np.cumsum(np.asarray(gaps, dtype=float))
    seg = segments(cycle_index(t, ts), t.size)
    for j in range(columns):
        v = np.roll(np.asarray(values[: ts.size], dtype=float), j)
        expected = reference_means(t, ts, v)
        assert np.array_equal(cycle_means(t, ts, v, seg=seg), expected, equal_nan=True)
        assert np.array_equal(cycle_means(t, ts, v), expected, equal_nan=True)


def test_pipeline_releases_the_imu_it_read_and_keeps_one_the_caller_loaded(sample_db: Path) -> None:
    """The 100 Hz stream is dropped once its cycle means exist (memory of a long run), unless
    the caller had loaded it; the results are the same either way."""
    net = read_network(sample_db)
    fresh = read_run(SAMPLE_LOGS / "sim-d-slips")
    a = run_pipeline(fresh, net)
    assert not fresh.loaded("imu") and fresh.loaded("tacho")
    preloaded = read_run(SAMPLE_LOGS / "sim-d-slips")
    preloaded.load_all()
    b = run_pipeline(preloaded, net)
    assert preloaded.loaded("imu")
    pd.testing.assert_frame_equal(a.positions, b.positions, check_exact=True)
    pd.testing.assert_frame_equal(a.events, b.events, check_exact=True)
    assert fresh.findings == preloaded.findings
