"""GridIndex.shape: turn, Menger curvature and heading at each vertex of the 20 m grid,
computed a block of vertices at a time (dbtools.gis.index._shape_block): by hand on a small
grid, and bit for bit the same whatever the block size and as the geometry module's
turn_angle / signed_curvature of the whole polyline."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import dbtools.gis.index as index
from dbtools.gis.geometry import Projector, signed_curvature, turn_angle
from dbtools.gis.index import GridIndex

P = Projector(9)


def _grid(x: np.ndarray, y: np.ndarray, km: np.ndarray, track: list[str]) -> GridIndex:
    lon, lat = P.to_lonlat(x, y)
    frame = pd.DataFrame({"line_code": ["L"] * len(km), "track": track, "km_m": km, "lat": lat, "lon": lon})
    return GridIndex(frame, projector=P)


def test_shape_by_hand() -> None:
    """A right-angle corner at the third point, then a missing grid point (40 m step) and a
    second track: turn +π/2 (left) and κ = 2·sin(90°)/|ac| = 2/(20√2) at the corner; straight
    vertices turn 0; a vertex with one regular step takes that step's heading; none: NaN."""
    x = np.array([0.0, 20.0, 40.0, 40.0, 40.0, 40.0, 0.0, 20.0])
    y = np.array([0.0, 0.0, 0.0, 20.0, 40.0, 80.0, 500.0, 500.0])
    km = np.array([0.0, 20.0, 40.0, 60.0, 80.0, 120.0, 0.0, 20.0])
    g = _grid(x, y, km, ["D"] * 6 + ["U"] * 2)
    s = g.shape(20.0, 1e-3)
    assert s.regular.tolist() == [True, True, True, True, False, False, True]
    np.testing.assert_allclose(s.turn[[1, 2, 3]], [0.0, np.pi / 2, 0.0], atol=1e-6)
    assert np.isnan(s.turn[[0, 4, 5, 6, 7]]).all()
    np.testing.assert_allclose(s.kappa[2], 2.0 / (20.0 * np.sqrt(2.0)), rtol=1e-6)
    np.testing.assert_allclose(s.heading[[0, 2, 4, 6, 7]], [0.0, np.pi / 4, np.pi / 2, 0.0, 0.0], atol=1e-6)
    assert np.isnan(s.heading[5]) and np.isnan(s.kappa[[0, 4, 5]]).all()


@settings(max_examples=60, deadline=None)
@given(
    st.integers(0, 40),
    st.integers(0, 2**32 - 1),
    st.sampled_from([1, 2, 3, 7, 1 << 16]),
)
def test_shape_does_not_depend_on_the_blocks(n: int, seed: int, block: int) -> None:
    """Every block size gives the same bits, and they are turn_angle's and signed_curvature's
    of the whole polyline at the vertices whose two steps are regular."""
    rng = np.random.default_rng(seed)
    km = np.cumsum(rng.choice([20.0, 20.0, 20.0, 40.0, 3.0], n)) if n else np.zeros(0)
    x = np.cumsum(rng.normal(20.0, 2.0, n))
    y = np.cumsum(rng.normal(0.0, 2.0, n))
    track = sorted(rng.choice(["D", "U"], n).tolist())
    km = np.concatenate([np.sort(km[[t == "D" for t in track]]), np.sort(km[[t == "U" for t in track]])])
    g = _grid(x, y, km, track)
    ref = g._shape(20.0, 1e-3)
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(index, "BLOCK", block)
        got = g._shape(20.0, 1e-3)
    for f in ("regular", "turn", "kappa", "heading"):
        assert getattr(got, f).tobytes() == getattr(ref, f).tobytes(), f
    both = np.zeros(g.n, dtype=bool)
    both[1:-1] = ref.regular[:-1] & ref.regular[1:]
    assert turn_angle(g.x, g.y)[both].tobytes() == ref.turn[both].tobytes()
    assert signed_curvature(g.x, g.y)[both].tobytes() == ref.kappa[both].tobytes()
    assert np.isnan(ref.turn[~both]).all() and np.isnan(ref.kappa[~both]).all()
