"""Hand-computed geometry of the alignment model (independent of the code paths)."""

from __future__ import annotations

import numpy as np
import pytest

from dbtools.gis.geometry import signed_curvature
from fieldlogs.simulate.networks.alignment import Alignment, Curve


def test_quarter_circle_left_ends_at_r_r() -> None:
    r = 400.0
    a = Alignment(length_m=np.pi * r / 2, curves=[Curve(0.0, 0.0, np.pi * r / 2, r, left=True)], step_m=0.25)
    x, y = a.xy([a.length_m])
    assert x[0] == pytest.approx(r, abs=0.01)
    assert y[0] == pytest.approx(r, abs=0.01)
    assert a.heading([a.length_m])[0] == pytest.approx(np.pi / 2)


def test_deflection_of_clothoid_arc_clothoid() -> None:
    # deflection = (arc + transition) / R for symmetric linear transitions
    c = Curve(100.0, 50.0, 200.0, 500.0, left=False)
    a = Alignment(length_m=500.0, curves=[c])
    assert a.heading([c.end_m])[0] == pytest.approx(-(200.0 + 50.0) / 500.0)
    assert a.curvature([c.start_m + 25.0])[0] == pytest.approx(-0.5 / 500.0)
    assert a.curvature([c.sc_m + 1.0])[0] == pytest.approx(-1 / 500.0)


def test_parallel_track_radius_and_sampled_curvature() -> None:
    r = 600.0
    a = Alignment(length_m=1000.0, curves=[Curve(0.0, 0.0, 1000.0, r, left=True)])
    s = np.arange(0.0, 1000.0, 20.0)
    # left track (inside of a left curve) has the smaller radius
    assert 1 / a.track_curvature([500.0], 1.9)[0] == pytest.approx(r - 1.9)
    x, y = a.xy(s, 1.9)
    k = signed_curvature(x, y)
    assert np.nanmedian(k) == pytest.approx(1 / (r - 1.9), rel=1e-3)


def test_overlapping_curves_rejected() -> None:
    with pytest.raises(ValueError):
        Alignment(1000.0, [Curve(0.0, 50.0, 100.0, 300.0, True), Curve(150.0, 50.0, 100.0, 300.0, True)])


def test_height_integrates_grade() -> None:
    a = Alignment(2000.0, grade_knots=[(0.0, 0.01), (1000.0, 0.01), (1200.0, -0.01)], height0=10.0)
    assert a.height([1000.0])[0] == pytest.approx(20.0)
    assert a.height([1200.0])[0] == pytest.approx(20.0)  # symmetric vertical curve: rises then falls, net 0
    assert a.height([2000.0])[0] == pytest.approx(12.0)
