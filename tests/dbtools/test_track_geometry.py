"""dbtools.rules.track_geometry: ends, outward azimuths and lengths of all tracks at once."""

from __future__ import annotations

import pandas as pd
import pytest

from dbtools.gis.geometry import GEOD
from dbtools.network import Network, canonical, empty_frame
from dbtools.rules.track_geometry import track_geometry
from dbtools.topology import all_tracks
from schemas.tables import DB_TABLES


def _net(frames: dict[str, pd.DataFrame]) -> Network:
    tables = {t.name: canonical(t, frames[t.name]) if t.name in frames else empty_frame(t) for t in DB_TABLES}
    return Network(tables, origin="test")


def test_off_grid_end_km_is_interpolated_and_grids_do_not_mix() -> None:
    """Two grids due east (lines A and B); track T on A from km 10 to km 50 (both off the 20 m
    grid): begin halfway between km 0 and 20, end halfway between 40 and 60, length 40 m;
    outward azimuths west (270°) at the begin and east (90°) at the end. Line B's grid, 1 km
    north, must not leak into the interpolation."""
    lon_step = 20.0 / 55_800.0
    rows = [("A", "S", 20.0 * i, 60.0, 24.0 + i * lon_step) for i in range(4)]
    rows += [("B", "S", 20.0 * i, 60.009, 24.0 + i * lon_step) for i in range(4)]
    gis = pd.DataFrame(rows, columns=["line_code", "track", "km_m", "lat", "lon"])
    tracks = pd.DataFrame(
        [("T", "A", "S", "main", 10.0, 50.0, 40.0)],
        columns=["track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m"],
    )
    net = _net({"gis": gis, "tracks": tracks})
    t = all_tracks(net)
    g = track_geometry(net, t).iloc[0]
    assert g["lat_begin"] == pytest.approx(60.0) and g["lat_end"] == pytest.approx(60.0)
    assert g["lon_begin"] == pytest.approx(24.0 + 0.5 * lon_step)
    assert g["lon_end"] == pytest.approx(24.0 + 2.5 * lon_step)
    _, _, two_steps = GEOD.inv(24.0, 60.0, 24.0 + 2 * lon_step, 60.0)
    assert g["geo_length_m"] == pytest.approx(two_steps, rel=1e-9)
    assert g["az_begin"] % 360 == pytest.approx(270.0, abs=0.01)
    assert g["az_end"] == pytest.approx(90.0, abs=0.01)


def test_track_points_length_is_the_polyline() -> None:
    """A 3-4-5 right triangle's legs as track_points: length 3 + 4 m (not the 5 m chord)."""
    m_lat, m_lon = 111_412.0, 55_800.0
    pts = pd.DataFrame(
        {
            "track_id": ["X", "X", "X"],
            "pos_m": [0.0, 3.0, 7.0],
            "lat": [60.0, 60.0, 60.0 + 4.0 / m_lat],
            "lon": [24.0, 24.0 + 3.0 / m_lon, 24.0 + 3.0 / m_lon],
        }
    )
    tracks = pd.DataFrame([("X", "connecting", 7.0)], columns=["track_id", "kind", "length_m"])
    net = _net({"track_points": pts, "tracks": tracks})
    g = track_geometry(net, all_tracks(net)).iloc[0]
    assert g["geo_length_m"] == pytest.approx(7.0, abs=0.01)
    assert g["az_end"] == pytest.approx(0.0, abs=0.1)  # last chord points north
    assert g["az_begin"] == pytest.approx(270.0, abs=0.1)  # out of the begin: west
