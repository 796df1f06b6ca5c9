"""Geodesic polylines (:mod:`dbtools.interchange.polyline`) and the switch sides of
:mod:`dbtools.interchange.rtm_switches` under rotation."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Geod

from dbtools.interchange.polyline import grid_positions, polyline, resample
from dbtools.interchange.rtm_read import read
from dbtools.interchange.rtm_switches import infer_switches
from tests.dbtools.interchange.rtm_samples import E0, N0, collection, element, relation, write

GEOD = Geod(ellps="WGS84")


def test_a_meridian_arc() -> None:
    """1° of latitude at the equator on WGS 84: 110 574.39 m (the meridian arc, standard value)."""
    line = polyline([0.0, 0.0, 0.0], [0.0, 0.5, 1.0])
    assert line.length == pytest.approx(110_574.39, abs=0.01)
    pos, lon, lat = resample(line, 20_000.0)
    assert list(pos) == [0.0, 20_000.0, 40_000.0, 60_000.0, 80_000.0, 100_000.0, line.length]
    assert np.all(lon == 0.0) and lat[-1] == 1.0


@given(st.floats(0.001, 5000.0), st.floats(1.0, 50.0))
def test_grid_positions(length: float, step: float) -> None:
    pos = grid_positions(length, step)
    assert pos[0] == 0.0 and pos[-1] == pytest.approx(length, abs=1e-6)
    gaps = np.diff(pos)
    assert np.all(gaps > 0) and np.all(gaps <= step + 1e-9) and np.allclose(gaps[:-1], step)


@settings(max_examples=30, deadline=None)
@given(
    st.lists(st.tuples(st.floats(-50.0, 50.0), st.floats(-50.0, 50.0)), min_size=2, max_size=8),
    st.floats(-60.0, 60.0),
)
def test_resampled_points_lie_at_their_distance(offsets: list[tuple[float, float]], lat0: float) -> None:
    """Each resampled point is ``pos`` metres along the polyline: the geodesic from the
    previous vertex plus that vertex's distance."""
    lon = 10.0 + np.cumsum([1e-4 * abs(o[0]) + 1e-5 for o in offsets])  # steps of 1 to 500 m
    lat = lat0 + 1e-3 * np.array([o[1] for o in offsets])
    line = polyline(lon, lat)
    pos, plon, plat = resample(line)
    for s, x, y in zip(pos, plon, plat, strict=True):
        i = min(int(np.searchsorted(line.cum, s, side="right")) - 1, len(line.cum) - 2)
        d = GEOD.inv(line.lon[i], line.lat[i], x, y)[2]
        assert line.cum[i] + d == pytest.approx(s, abs=1e-6)


@settings(max_examples=20, deadline=None)
@given(st.floats(0.0, 359.0), st.booleans())
def test_switch_sides_do_not_depend_on_the_heading(
    tmp_path_factory: pytest.TempPathFactory, heading: float, left: bool
) -> None:
    """The turnout of rtm_samples rotated by any heading: the branch that leaves to the left
    of the toe's direction is b1 and diverging left (mirrored: b2, right)."""
    h = math.radians(heading)
    side = 1.0 if left else -1.0

    def at(x: float, y: float) -> list[float]:  # (along, across) → easting, northing
        return [E0 + x * math.sin(h) - side * y * math.cos(h), N0 + x * math.cos(h) + side * y * math.sin(h)]

    feats = [
        element("T", [at(0, 0), at(100, 0)]),
        element("S", [at(100, 0), at(200, 0)]),
        element("D", [at(100, 0), at(150, 2.75), at(200, 11)]),
        relation("r1", "T", 1, "S", 0, "both"),
        relation("r2", "T", 1, "D", 0, "both"),
        relation("r3", "S", 0, "D", 0, "none"),
    ]
    path: Path = tmp_path_factory.mktemp("rot") / "t.geojson"
    doc = read(write(path, collection(feats)))
    (sw,) = infer_switches(doc.elements, doc.relations, doc.file).switches
    # "across" is to the left of "along" when side = +1 (y rotated counter-clockwise of x)
    assert (sw["b1_track"], sw["b2_track"]) == (("D", "S") if left else ("S", "D"))
    assert sw["diverging_side"] == ("left" if left else "right")
