"""Clock-offset estimator (fieldlogs.quality.clocks): signs and sizes by hand.

A stream whose clock is LATE by L writes t = t_true + L: its samples of a signal s(t_true)
sit at t = t_true + L, i.e. x(t) = s(t − L) and x(t + L) = s(t) — the estimator returns +L.
"""

from __future__ import annotations

import itertools
import shutil
from collections.abc import Iterator
from dataclasses import astuple
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fieldlogs.quality.clocks as clocks
from fieldlogs.pipeline.config import ClockConfig
from fieldlogs.quality.clocks import (
    ClockOffset,
    block_lag,
    block_rows,
    clock_offsets,
    estimate_lag,
    gps_speed,
    step_means,
)

T = np.arange(0.0, 600.0, 0.1)


def _speed(t: np.ndarray) -> np.ndarray:
    """A train's speed: 0 → 20 m/s and back over 60 s periods (accelerations up to ~1 m/s²)."""
    return 10.0 + 10.0 * np.sin(2 * np.pi * t / 60.0) + 2.0 * np.sin(2 * np.pi * t / 17.0)


@pytest.mark.parametrize("late_s", [2.0, -1.5, 0.7, 0.0])
def test_a_late_stream_has_a_positive_lag(late_s: float) -> None:
    # the stream samples the same speed on its own clock: at its t it shows s(t − late)
    t_x = np.arange(0.0, 600.0, 1.0)
    x = _speed(t_x - late_s)
    lag = estimate_lag(T, _speed(T), t_x, x, max_lag_s=10.0)
    assert lag is not None
    assert lag.lag_s == pytest.approx(late_s, abs=0.03)
    assert lag.corr > 0.99 and not lag.at_edge
    assert lag.blocks == 4  # (600 − 2·10) s cut into 120 s blocks: 4 of 145 s
    assert lag.sigma_s < 0.03


def test_one_block_with_a_different_lag_does_not_move_the_median() -> None:
    """Five blocks, one of them (multipath, say) shifted 3 s: the median keeps 1 s."""
    t_x = np.arange(0.0, 760.0, 1.0)
    t = np.arange(0.0, 760.0, 0.1)
    x = _speed(t_x - 1.0)
    bad = (t_x > 200) & (t_x < 330)
    x[bad] = _speed(t_x[bad] - 4.0)
    lag = estimate_lag(t, _speed(t), t_x, x, max_lag_s=10.0)
    assert lag is not None and lag.blocks == 6
    assert lag.lag_s == pytest.approx(1.0, abs=0.05)


def test_block_lag_leaves_out_a_slip() -> None:
    """The reference (the wheel) reads 30 % high for 10 s: the robust passes leave it out."""
    t_x = np.arange(0.0, 200.0, 0.01)
    x = np.gradient(_speed(t_x - 0.5), t_x)
    r = np.gradient(_speed(T[T < 200]), T[T < 200])
    r[(T[T < 200] > 80) & (T[T < 200] < 90)] *= 1.3
    lag = block_lag(T[T < 200], r, t_x, x, max_lag_s=5.0)
    assert lag is not None and lag.lag_s == pytest.approx(0.5, abs=0.05)


def test_step_means_by_hand() -> None:
    # samples 0, 1, 0, 1 … at 0.01 s (linear between them): every 0.1 s window centred on a
    # grid point k·0.1 holds 10 sample spans of mean ½ → ½; a ramp's window mean is its centre
    t = np.arange(0, 101) * 0.01
    alt = (np.arange(101) % 2).astype(float)
    g = np.array([0.0, 0.1, 0.5, 0.95, 1.0])
    m = step_means(t, alt, g, 0.1)
    assert np.isnan(m[0]) and np.isnan(m[-1])  # the window reaches beyond the samples
    assert m[1:4] == pytest.approx([0.5, 0.5, 0.5])
    assert step_means(t, 3.0 * t, g[1:4], 0.1) == pytest.approx(3.0 * g[1:4])
    # a 1 Hz stream (the GPS) keeps its linear interpolation where it is straight
    t1 = np.arange(0.0, 10.0)
    assert step_means(t1, t1**2, np.array([2.5]), 0.1) == pytest.approx([6.5])  # (4 + 9)/2 on [2, 3]
    assert step_means(t1[:1], t1[:1], g, 0.1).tolist() == [pytest.approx(np.nan, nan_ok=True)] * g.size


def test_a_noisy_100_hz_imu_is_averaged_onto_the_grid_not_point_sampled() -> None:
    """a_x at 100 Hz with 1 m/s² of white noise (an IMU's vibration), 0.4 s late: the grid's
    step means hold √10 less noise than one sample in ten (point-sampled: ρ 0.90, lag 0.456 s,
    σ 0.036 s), so the blocks agree to ≈ 0.01 s."""
    rng = np.random.default_rng(0)
    t_x = np.arange(0.0, 600.0, 0.01)
    x = np.gradient(_speed(t_x - 0.4), t_x) + rng.normal(0.0, 1.0, t_x.size)
    lag = estimate_lag(T, np.gradient(_speed(T), T), t_x, x, max_lag_s=10.0)
    assert lag is not None and lag.blocks == 4
    assert lag.lag_s == pytest.approx(0.4, abs=0.03)
    assert lag.corr > 0.95
    assert lag.sigma_s < 0.02


def test_no_overlap_longer_than_the_range_gives_none() -> None:
    assert estimate_lag(T[:100], _speed(T[:100]), T[:100], _speed(T[:100]), max_lag_s=10.0) is None


def test_gps_speed_from_fixes_by_hand() -> None:
    # 20 m north per second at latitude 0: 20 m/s at the steps' midpoints
    dlat = np.degrees(20.0 / 6_371_000.0)
    gps = pd.DataFrame({"t": [0.0, 1.0, 2.0, 3.0], "lat": np.arange(4) * dlat, "lon": 0.0, "fix": 2})
    t, v = gps_speed(gps)
    assert t.tolist() == [0.5, 1.5, 2.5]
    assert v == pytest.approx([20.0, 20.0, 20.0])


def _streams(imu_late: float, gps_late: float) -> dict[str, pd.DataFrame | None]:
    """Tacho (0.86 m wheel, 90 teeth), IMU a_x and GPS fixes of the same motion, each on its clock."""
    t = np.arange(0.0, 600.0, 0.1)
    d = np.cumsum(_speed(t)) * 0.1
    m_per_pulse = np.pi * 0.86 / 90
    tacho = pd.DataFrame({"t": t, "pulses": np.floor(d / m_per_pulse).astype("int64")})
    ti = np.arange(0.0, 600.0, 0.01)
    imu = pd.DataFrame({"t": ti + imu_late, "ax": np.gradient(_speed(ti), ti)})
    tg = np.arange(0.0, 600.0, 1.0)
    north = np.interp(tg, t, d)
    gps = pd.DataFrame({"t": tg + gps_late, "lat": np.degrees(north / 6_371_000.0), "lon": 0.0, "fix": 2})
    return {"tacho": tacho, "imu": imu, "gps": gps, "cab": None}


@pytest.mark.parametrize(("imu_late", "gps_late"), [(2.0, 5.0), (-1.0, -0.8), (0.2, 0.0)])
def test_clock_offsets_of_imu_and_gps(imu_late: float, gps_late: float) -> None:
    got = {o.stream: o for o in clock_offsets(_streams(imu_late, gps_late), 0.86, 90, ClockConfig())}
    assert got["imu"].offset_s == pytest.approx(imu_late, abs=0.1)
    assert got["gps"].offset_s == pytest.approx(gps_late, abs=0.1)
    assert got["imu"].determined and got["gps"].determined
    assert got["imu"].beyond_tolerance == (abs(imu_late) > 0.5)
    assert got["gps"].beyond_tolerance == (abs(gps_late) > 0.5)


def test_the_message_names_stream_offset_and_direction() -> None:
    late = ClockOffset("imu", 2.0, 0.05, 0.9, True, True)
    early = ClockOffset("gps", -1.25, 0.05, 0.99, True, True)
    assert late.message.startswith("imu clock 2.00 s late against the tacho")
    assert early.message.startswith("gps clock 1.25 s early against the tacho")


def test_no_check_without_tacho_or_when_switched_off() -> None:
    streams = _streams(2.0, 5.0)
    assert clock_offsets({**streams, "tacho": None}, 0.86, 90, ClockConfig()) == []
    assert clock_offsets(streams, 0.86, 90, ClockConfig(max_lag_s=0.0)) == []


SAMPLE = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs" / "sim-d-slips"


def test_logs_check_names_a_late_imu_and_leaves_the_clean_run_alone(tmp_path: Path) -> None:
    from fieldlogs.quality.checks import check_run

    assert not [f for f in check_run(SAMPLE) if f.rule == "log.clock_offset"]
    run = tmp_path / "run"
    shutil.copytree(SAMPLE, run)
    imu = pd.read_parquet(run / "imu.parquet")
    imu.assign(t=imu["t"] + 2.0).to_parquet(run / "imu.parquet", index=False)
    found = [f for f in check_run(run) if f.rule == "log.clock_offset"]
    assert len(found) == 1 and found[0].table == "imu" and found[0].column == "t"
    assert found[0].value == pytest.approx(2.0, abs=0.25)
    assert "imu clock" in found[0].message and "late" in found[0].message


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(
    n=st.integers(2, 400),
    seed=st.integers(0, 2**32 - 1),
    g0=st.floats(-5.0, 60.0),
    ng=st.integers(0, 80),
    step=st.sampled_from([0.1, 0.25, 1.0]),
)
def test_step_means_reads_only_the_samples_around_its_grid(n: int, seed: int, g0: float, ng: int, step: float) -> None:
    """step_means integrates the samples that bracket its grid's windows only (a block's, not
    the whole run's: once the clock check's cost grew with the square of the run's length);
    the means and the NaN beyond the stream's ends equal the whole-stream integral's."""
    rng = np.random.default_rng(seed)
    t = np.cumsum(rng.uniform(0.005, 0.6, n))
    x = rng.standard_normal(n)
    g = g0 + step * np.arange(ng)
    area = np.concatenate(([0.0], np.cumsum(0.5 * (x[1:] + x[:-1]) * np.diff(t))))
    lo, hi = g - step / 2, g + step / 2
    whole = np.where((lo >= t[0]) & (hi <= t[-1]), (np.interp(hi, t, area) - np.interp(lo, t, area)) / step, np.nan)
    got = step_means(t, x, g, step)
    assert np.array_equal(np.isnan(got), np.isnan(whole))
    np.testing.assert_allclose(got[~np.isnan(got)], whole[~np.isnan(whole)], rtol=1e-9, atol=1e-9)


def _mask_rows(t: np.ndarray, edges: np.ndarray) -> Iterator[np.ndarray]:
    """The block selection estimate_lag made before block_rows: the mask over the whole ``t``."""
    for a, b in itertools.pairwise(edges):
        yield (t >= a) & (t <= b)


@st.composite
def _sorted_times(draw: st.DrawFn) -> tuple[np.ndarray, np.ndarray]:
    """(sorted t with repeats, block edges), some edges exactly on samples, some off them,
    some beyond the ends."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n = draw(st.integers(1, 300))
    t = np.cumsum(rng.choice([0.0, 0.05, 0.1, 0.37], n)) + draw(st.floats(-50.0, 50.0))
    on = t[rng.integers(0, n, draw(st.integers(0, 6)))]
    off = rng.uniform(t[0] - 3.0, t[-1] + 3.0, draw(st.integers(0, 6)))
    edges = np.sort(np.concatenate([on, off, [t[0], t[-1]]]))
    return t, edges


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(case=_sorted_times(), shuffle=st.booleans())
def test_block_rows_are_the_masks_rows(case: tuple[np.ndarray, np.ndarray], shuffle: bool) -> None:
    """Each block's rows are those of the mask (t >= a) & (t <= b), both ends included, on
    sorted times (slices: edges on samples, repeated samples, edges beyond the ends) and on
    unsorted ones (the mask itself)."""
    t, edges = case
    if shuffle:
        t = np.random.default_rng(t.size).permutation(t)
    got = [np.arange(t.size)[sel] for sel in block_rows(t, edges)]
    want = [np.flatnonzero(m) for m in _mask_rows(t, edges)]
    assert len(got) == len(want) == edges.size - 1
    for g, w in zip(got, want, strict=True):
        assert np.array_equal(g, w)


@settings(max_examples=60, deadline=None, derandomize=True, database=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    late=st.floats(-3.0, 3.0),
    block=st.sampled_from([40.0, 57.5, 120.0]),  # longer than the 30 s high-pass
    on_edges=st.booleans(),
)
def test_estimate_lag_by_slices_is_the_mask_computation(seed: int, late: float, block: float, on_edges: bool) -> None:
    """estimate_lag on a sorted reference (steps of 0–0.2 s, repeats; with ``on_edges`` a
    sample exactly on every block edge) gives the Lag of the whole-reference masks, exactly."""
    rng = np.random.default_rng(seed)
    t_ref = np.cumsum(rng.choice([0.0, 0.05, 0.1, 0.2], 3000))
    t_x = np.sort(rng.uniform(0.0, t_ref[-1], 1500))
    max_lag = 5.0
    if on_edges:  # the edges estimate_lag computes (t0, t1 unchanged by samples inside)
        t0, t1 = max(t_ref[0], t_x[0] - max_lag), min(t_ref[-1], t_x[-1] - max_lag)
        edges = np.linspace(t0, t1, max(int((t1 - t0) // block), 1) + 1)
        t_ref = np.sort(np.concatenate([t_ref, edges]))
    r, x = _speed(t_ref), _speed(t_x - late) + 0.3 * rng.standard_normal(t_x.size)
    weight = (rng.uniform(size=t_ref.size) > 0.1).astype(float)
    kw = {"max_lag_s": max_lag, "block_s": block, "weight": weight}
    got = estimate_lag(t_ref, r, t_x, x, **kw)  # type: ignore[arg-type]
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(clocks, "block_rows", _mask_rows)
        want = estimate_lag(t_ref, r, t_x, x, **kw)  # type: ignore[arg-type]
    assert (got is None) == (want is None)
    if got is not None and want is not None:
        assert np.array_equal(np.array(astuple(got), float), np.array(astuple(want), float), equal_nan=True)


class _Counted(np.ndarray):
    """An array that counts the elements its >= and <= comparisons read (on itself and on
    the arrays indexed from it)."""

    compared = 0

    def __array_ufunc__(self, ufunc: Any, method: str, *inputs: Any, **kwargs: Any) -> Any:
        if ufunc in (np.greater_equal, np.less_equal):
            _Counted.compared += max(np.size(i) for i in inputs)
        args = [np.asarray(i) if isinstance(i, _Counted) else i for i in inputs]
        return getattr(ufunc, method)(*args, **kwargs)


def test_the_clock_check_compares_a_sorted_reference_once_not_once_per_block() -> None:
    """On a sorted reference the blocks are found by binary search: the >= / <= comparisons
    read the reference once (its sortedness), not twice per 120 s block — which made the
    clock check grow with the square of the run's length."""
    t = np.arange(0.0, 3600.0, 0.1)  # an hour of tacho: 29 blocks
    t_x = np.arange(0.0, 3600.0, 1.0)
    _Counted.compared = 0
    lag = estimate_lag(t.view(_Counted), _speed(t), t_x, _speed(t_x - 1.0), max_lag_s=10.0)
    assert lag is not None and lag.blocks == 29 and lag.lag_s == pytest.approx(1.0, abs=0.03)
    assert _Counted.compared <= t.size
