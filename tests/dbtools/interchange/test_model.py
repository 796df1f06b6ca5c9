"""Properties of the mileage model and the WKB/GeoPackage geometry encoding."""

from __future__ import annotations

import struct

import shapely
from hypothesis import given
from hypothesis import strategies as st

from dbtools.interchange.model import Mileage
from dbtools.interchange.wkb import gpkg_geometry, wkb

finite = st.floats(min_value=-1e5, max_value=1e5, allow_nan=False)


@given(
    km0=finite,
    segments=st.lists(st.tuples(st.floats(1.0, 2000.0), st.floats(-300.0, 300.0)), min_size=1, max_size=6),
    frac=st.floats(0.0, 1.0),
)
def test_mileage_runs_at_slope_one_with_jumps(km0: float, segments: list[tuple[float, float]], frac: float) -> None:
    """A rising mileage with mileage changes: km(pos) = km0 + pos + Σ jumps before pos, the
    outgoing km at a change, and jumps() recovers the jumps between two positions."""
    knots = [(0.0, km0)]
    pos, km = 0.0, km0
    for length, jump in segments:
        pos, km = pos + length, km + length
        knots += [(pos, km), (pos, km + jump)]
        km += jump
    m = Mileage(knots)
    p = frac * pos
    changes = list(zip(_ends(segments), (j for _, j in segments), strict=True))
    assert abs(m.km(p) - (km0 + p + sum(j for at, j in changes if at <= p))) < 1e-6
    assert abs(m.jumps(0.0, p) - sum(j for at, j in changes if 0 < at <= p)) < 1e-6
    assert abs(m.jumps(p, 0.0) + m.jumps(0.0, p)) < 1e-9


def _ends(segments: list[tuple[float, float]]) -> list[float]:
    out, pos = [], 0.0
    for length, _ in segments:
        pos += length
        out.append(pos)
    return out


def test_mileage_single_knot_and_falling() -> None:
    assert Mileage([(0.0, 100.0)]).km(5.0) == 105.0
    falling = Mileage([(0.0, 5000.0), (1000.0, 4000.0)])
    assert falling.km(250.0) == 4750.0 and falling.km(1200.0) == 3800.0


coords = st.tuples(st.floats(-180, 180), st.floats(-90, 90))


@given(pts=st.lists(coords, min_size=2, max_size=20), z=st.booleans())
def test_wkb_line_strings_round_trip_through_shapely(pts: list[tuple[float, float]], z: bool) -> None:
    c = [[x, y, 1.5] if z else [x, y] for x, y in pts]
    g = shapely.from_wkb(wkb({"type": "LineString", "coordinates": c}))
    assert g.geom_type == "LineString" and g.has_z == z
    assert [list(p) for p in g.coords] == c


@given(p=coords, srs=st.integers(-1, 40000))
def test_gpkg_point_header(p: tuple[float, float], srs: int) -> None:
    blob = gpkg_geometry({"type": "Point", "coordinates": list(p)}, srs)
    assert blob is not None and blob[:4] == b"GP\x00\x03"
    assert struct.unpack("<i", blob[4:8])[0] == srs
    assert struct.unpack("<4d", blob[8:40]) == (p[0], p[0], p[1], p[1])
    g = shapely.from_wkb(blob[40:])
    assert (g.x, g.y) == p
    assert gpkg_geometry(None, srs) is None
