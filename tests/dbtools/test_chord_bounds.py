"""chord_bounds (dbtools/gis/index.py): the chord brackets the GRS80 geodesic within the stated
error, and GridIndex.steps_outside finds exactly the steps the geodesic of every step finds."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import dbtools.gis.index as index_mod
from dbtools.gis.geometry import GEOD
from dbtools.gis.index import CHORD_ROUNDING_M, KAPPA_MAX, GridIndex, chord_bounds


def _geod(lon: np.ndarray, lat: np.ndarray) -> np.ndarray:
    return np.asarray(GEOD.inv(lon[:-1], lat[:-1], lon[1:], lat[1:])[2])


def test_bounds_bracket_the_geodesic_over_the_globe() -> None:
    rng = np.random.default_rng(7)
    n = 200_000
    lat0, lon0 = rng.uniform(-89.0, 89.0, n), rng.uniform(-180.0, 180.0, n)
    az, s = rng.uniform(-180.0, 180.0, n), np.exp(rng.uniform(np.log(0.01), np.log(150_000.0), n))
    lon1, lat1, _ = GEOD.fwd(lon0, lat0, az, s)
    lon = np.column_stack([lon0, lon1]).ravel()
    lat = np.column_stack([lat0, lat1]).ravel()
    low, high = (b[::2] for b in chord_bounds(lon, lat))  # the steps 2k → 2k + 1
    ok = np.isfinite(low)
    assert ok.mean() > 0.5  # the steps within 1° are bracketed, the others left to Geod
    assert (low[ok] <= s[ok]).all() and (s[ok] <= high[ok]).all()
    # the width is the arc-minus-chord term plus the rounding allowance: 3 µm + κ²s³/24
    width = high[ok] - low[ok]
    assert (width <= 3 * CHORD_ROUNDING_M + KAPPA_MAX**2 * s[ok] ** 3 / 24 * 1.01 + 1e-9).all()
    short = ok & (s < 50.0)
    assert (width[short[ok]] < 3.001e-6).all()  # 20 m steps: decided to 3 µm


def test_a_20_m_step_by_hand() -> None:
    """20 m due north at 35° N: chord and geodesic differ by κ²s³/24 < 10⁻¹¹ m."""
    lon1, lat1, _ = GEOD.fwd(139.0, 35.0, 0.0, 20.0)
    low, high = chord_bounds(np.array([139.0, lon1]), np.array([35.0, lat1]))
    assert abs(low[0] + CHORD_ROUNDING_M - 20.0) < 1e-8
    assert abs(high[0] - 2 * CHORD_ROUNDING_M - 20.0) < 1e-8  # c + ε, arc taken of c + ε


def test_far_steps_and_nan_are_left_to_geod() -> None:
    low, high = chord_bounds(np.array([139.0, 139.0, 141.5, np.nan]), np.array([35.0, 35.5, 35.5, 35.5]))
    assert np.isfinite(low[0]) and np.isnan(low[1]) and np.isnan(low[2]) and np.isnan(high[2])


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-30.0, 30.0), min_size=3, max_size=40),
    st.floats(0.0, 3.0),
    st.floats(5.0, 40.0),
)
def test_steps_outside_equals_the_full_geodesic(jitter: list[float], lo_m: float, hi_m: float) -> None:
    n = len(jitter)
    lon0, lat0, _ = GEOD.fwd(np.full(n, 139.0), np.full(n, 35.0), np.full(n, 60.0), 20.0 * np.arange(n))
    lon, lat, _ = GEOD.fwd(lon0, lat0, np.full(n, 150.0), np.asarray(jitter))
    lat[n // 2] = np.nan if n > 10 else lat[n // 2]
    g = pd.DataFrame({"line_code": "L", "track": "U", "km_m": 20.0 * np.arange(n), "lat": lat, "lon": lon})
    fresh = GridIndex(g)  # the NaN point left out
    m = fresh.n - 1
    where = np.arange(m) % 5 != 3
    lo, hi = np.full(m, lo_m), np.full(m, hi_m)
    lo[0] = np.nan
    limits = _limits(lo, hi)
    bad, d, lo_b, hi_b = fresh.steps_outside(where, limits)
    assert "dist" not in fresh.__dict__  # not the whole geodesic
    full = fresh.dist
    with np.errstate(invalid="ignore"):
        expected = np.flatnonzero(where & ((full < lo) | (full > hi) | ~np.isfinite(full)))
    assert bad.tolist() == expected.tolist()
    np.testing.assert_array_equal(d, full[bad])  # the exact lengths the messages print
    np.testing.assert_array_equal(lo_b, lo[bad])
    np.testing.assert_array_equal(hi_b, hi[bad])
    again, d2, _, _ = fresh.steps_outside(where, limits)  # dist known now: taken as it is
    assert again.tolist() == expected.tolist()
    np.testing.assert_array_equal(d2, full[bad])


def _limits(lo: np.ndarray, hi: np.ndarray) -> Callable[[int, int], tuple[np.ndarray, np.ndarray]]:
    """``steps_outside``'s limits of steps a:b from whole arrays."""
    return lambda a, b: (lo[a:b], hi[a:b])


def test_blocks_give_the_values_of_one_block(monkeypatch: pytest.MonkeyPatch) -> None:
    """Block-wise curvature and chord bounds (BLOCK points at a time) equal the whole-array ones."""
    n = 500
    g = _two_tracks(n, ("U", "D"), seed=3)
    lon, lat = g["lon"].to_numpy(), g["lat"].to_numpy()
    where = np.ones(n - 1, dtype=bool)
    lo, hi = np.full(n - 1, 18.0), np.full(n - 1, 21.0)
    whole = GridIndex(g)
    whole_shape, whole_out = whole.shape(20.0, 1e-3), whole.steps_outside(where, _limits(lo, hi))
    monkeypatch.setattr(index_mod, "BLOCK", 7)
    blocks = GridIndex(g)
    block_shape = blocks.shape(20.0, 1e-3)
    for name in ("kappa", "turn", "heading", "regular"):
        np.testing.assert_array_equal(getattr(block_shape, name), getattr(whole_shape, name))
    block_out = blocks.steps_outside(where, _limits(lo, hi))
    assert block_out[0].tolist() == whole_out[0].tolist() != []
    for a, b in zip(block_out, whole_out, strict=True):
        np.testing.assert_array_equal(a, b)
    for name in ("pos", "km", "lat", "lon", "tid", "x", "y", "dkm", "seg", "key"):
        np.testing.assert_array_equal(getattr(blocks, name), getattr(whole, name))
    np.testing.assert_array_equal(np.concatenate(chord_bounds(lon, lat)), np.concatenate(_blocked(lon, lat)))


def _two_tracks(n: int, tracks: tuple[str, str], seed: int) -> pd.DataFrame:
    """``n`` points 20 m apart jittered sideways (σ 2 m), the first half on ``tracks[0]``, the
    second on ``tracks[1]``, each track's km from 0."""
    rng = np.random.default_rng(seed)
    lon0, lat0, _ = GEOD.fwd(np.full(n, 139.0), np.full(n, 35.0), np.full(n, 60.0), 20.0 * np.arange(n))
    lon, lat, _ = GEOD.fwd(lon0, lat0, np.full(n, 150.0), rng.normal(0.0, 2.0, n))
    half = n // 2
    g = pd.DataFrame({"line_code": "L", "track": [tracks[0]] * half + [tracks[1]] * half})
    g["km_m"], g["lat"], g["lon"] = 20.0 * (np.arange(n) % half), lat, lon
    return g


def _blocked(lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    parts = [chord_bounds(lon[a : a + 8], lat[a : a + 8]) for a in range(0, lon.size - 1, 7)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


def test_a_shuffled_frame_with_rows_left_out_gives_the_index_of_the_sorted_one() -> None:
    """Rows out of order, and rows left out (a missing lat, a missing track): the index holds
    the same points as that of the sorted frame of the valid rows, ``pos`` naming each row."""
    g = _two_tracks(300, ("D", "U"), seed=5)
    bad = pd.DataFrame({"line_code": ["L", "L"], "track": ["U", None], "km_m": [5.0, 7.0], "lat": [np.nan, 35.0]})
    bad["lon"] = [139.0, 139.0]
    shuffled = pd.concat([g, bad], ignore_index=True).sample(frac=1.0, random_state=2).reset_index(drop=True)
    whole, mixed = GridIndex(g), GridIndex(shuffled)
    assert whole.whole_frame and not mixed.whole_frame
    for name in ("km", "lat", "lon", "tid", "start", "end", "x", "y", "dkm", "seg", "key"):
        np.testing.assert_array_equal(getattr(mixed, name), getattr(whole, name))
    np.testing.assert_array_equal(shuffled["km_m"].to_numpy()[mixed.pos], whole.km)
    assert mixed.keys == whole.keys == [("L", "D"), ("L", "U")]
