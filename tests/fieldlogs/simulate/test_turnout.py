"""Turnout reverse curves (fieldlogs.simulate.networks.turnout): hand-computed and property checks."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from fieldlogs.simulate.networks.turnout import radius_for_extent, reverse_curve_offset, reverse_curves


def test_hand_computed_crossover() -> None:
    # 1:10, 3.8 m between the tracks, 60 m between the toes: R = 22 / (2·tan(α/2))
    alpha = math.atan(0.1)
    assert radius_for_extent(60.0, 3.8, 10.0) == pytest.approx(22.0 / (2 * math.tan(alpha / 2)))
    assert radius_for_extent(60.0, 3.8, 10.0) == pytest.approx(220.55, abs=0.01)
    with pytest.raises(ValueError, match="cannot reach"):
        radius_for_extent(30.0, 3.8, 10.0)  # d·cot α = 38 m > 30 m
    with pytest.raises(ValueError, match="too long"):
        radius_for_extent(80.0, 3.8, 10.0)  # > d·cot α + d/sin α = 76.2 m: the arcs alone overshoot


@given(
    n=st.floats(6.0, 20.0),
    offset=st.floats(2.0, 6.0),
    share=st.floats(0.02, 0.98),
)
def test_offset_profile_properties(n: float, offset: float, share: float) -> None:
    # a straight between the arcs exists for d·cot α < e ≤ d·cot α + d/sin α
    alpha = math.atan(1.0 / n)
    extent = offset / math.tan(alpha) + share * offset / math.sin(alpha)
    a = np.linspace(0.0, extent, 401)
    lat = reverse_curve_offset(a, extent, offset, n)
    assert lat[0] == pytest.approx(0.0, abs=1e-9) and lat[-1] == pytest.approx(offset, abs=1e-9)
    assert np.all(np.diff(lat) >= -1e-12)  # never back
    assert lat + lat[::-1] == pytest.approx(np.full(len(a), offset), abs=1e-9)  # point-symmetric
    slope = np.diff(lat) / np.diff(a)
    assert slope.max() <= 1.0 / n + 1e-9  # never steeper than the frog angle
    # the drawn path (arc, straight, arc) lies on the profile
    p = reverse_curves(0.0, 0.0, offset, n, radius_for_extent(extent, offset, n), 1.0)
    xy = np.array([p.at(s)[:2] for s in np.linspace(0.0, p.length, 50)])
    assert reverse_curve_offset(xy[:, 0], extent, offset, n) == pytest.approx(xy[:, 1], abs=1e-9)
