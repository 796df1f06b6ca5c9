"""dbtools.rules.track_geometry: ends, outward azimuths and lengths of all tracks at once."""

from __future__ import annotations

import numpy as np
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


M_LAT, M_LON = 111_412.0, 55_800.0  # metres a degree of latitude / longitude at 60° N (approx.)


def _legs() -> pd.DataFrame:
    """Track X's track_points: 3 m east, then 4 m north (a 3-4-5 triangle's legs) at 60° N."""
    return pd.DataFrame(
        {
            "track_id": ["X", "X", "X"],
            "pos_m": [0.0, 3.0, 7.0],
            "lat": [60.0, 60.0, 60.0 + 4.0 / M_LAT],
            "lon": [24.0, 24.0 + 3.0 / M_LON, 24.0 + 3.0 / M_LON],
        }
    )


def test_track_points_length_is_the_polyline() -> None:
    """A 3-4-5 right triangle's legs as track_points: length 3 + 4 m (not the 5 m chord)."""
    pts = _legs()
    tracks = pd.DataFrame([("X", "connecting", 7.0)], columns=["track_id", "kind", "length_m"])
    net = _net({"track_points": pts, "tracks": tracks})
    g = track_geometry(net, all_tracks(net)).iloc[0]
    assert g["geo_length_m"] == pytest.approx(7.0, abs=0.01)
    assert g["az_end"] == pytest.approx(0.0, abs=0.1)  # last chord points north
    assert g["az_begin"] == pytest.approx(270.0, abs=0.1)  # out of the begin: west


def test_length_bracket_and_exact_only_where_in_doubt() -> None:
    """The same 3-4-5 legs plus a grid track: the bracket [low, high] holds the exact
    polyline/grid length and is at most 3 µm a step wide (the rounding allowance); with a ``doubtful`` that
    asks for track X only, only that row gets its exact length (the other NaN), equal
    to the one computed without ``doubtful``."""
    m_lat, m_lon = M_LAT, M_LON
    pts = _legs()
    lon_step = 20.0 / m_lon
    gis = pd.DataFrame(
        [("A", "S", 20.0 * i, 60.001, 24.0 + i * lon_step) for i in range(6)],
        columns=["line_code", "track", "km_m", "lat", "lon"],
    )
    tracks = pd.DataFrame(
        [("X", None, None, "connecting", None, None, 7.0), ("T", "A", "S", "main", 10.0, 90.0, 80.0)],
        columns=["track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m"],
    )
    net = _net({"track_points": pts, "gis": gis, "tracks": tracks})
    t = all_tracks(net)
    ids = t["track_id"].tolist()

    def col(g: pd.DataFrame, name: str) -> dict[str, float]:
        return dict(zip(ids, g[name].to_numpy(dtype=float), strict=True))

    full = track_geometry(net, t)
    _, _, legs = GEOD.inv(
        [24.0, 24.0 + 3.0 / m_lon], [60.0, 60.0], [24.0 + 3.0 / m_lon] * 2, [60.0, 60.0 + 4.0 / m_lat]
    )
    _, _, grid = GEOD.inv(24.0 + 0.5 * lon_step, 60.001, 24.0 + 4.5 * lon_step, 60.001)
    exact = col(full, "geo_length_m")
    assert exact["X"] == pytest.approx(sum(legs), abs=1e-9)
    assert exact["T"] == pytest.approx(grid, abs=1e-6)
    low, high = col(full, "geo_length_low_m"), col(full, "geo_length_high_m")
    for tid, n_steps in (("X", 2), ("T", 5)):
        assert low[tid] <= exact[tid] <= high[tid] and high[tid] - low[tid] <= n_steps * 3.1e-6
    some = col(track_geometry(net, t, lambda lo, hi: (t["track_id"] == "X").to_numpy()), "geo_length_m")
    assert some["X"] == exact["X"]
    assert np.isnan(some["T"])


def test_length_in_doubt_only_where_the_bracket_straddles_the_limit() -> None:
    """Tolerance max(2 m, 1 %): stated 100 m, bracket [99.0, 99.1] → |100 − real| ≤ 1 m < 2 m,
    decided; stated 102.5 m, bracket [100.4, 100.6] → worst 2.1 m > 2 m, in doubt; stated
    110 m on a 1000 m bracket [999.999, 1000.001] → 890 m off, in doubt (a finding needs the
    exact length); a missing length_m never; a row beyond the declared tracks never."""
    from dbtools.rules.config import ValidationConfig
    from dbtools.rules.topology_geometry import _length_in_doubt

    tracks = pd.DataFrame(
        [("A", "connecting", 100.0), ("B", "connecting", 102.5), ("C", "connecting", 110.0), ("D", "connecting", None)],
        columns=["track_id", "kind", "length_m"],
    )
    net = _net({"tracks": tracks})
    low = np.array([99.0, 100.4, 999.999, 50.0, 10.0])
    high = np.array([99.1, 100.6, 1000.001, 50.0, 10.0])
    got = _length_in_doubt(net, ValidationConfig(length_tolerance_m=2.0, length_tolerance_rel=0.01), low, high)
    assert got.tolist() == [False, True, True, False, False]
