"""The 3-D polyline of a network track off the line grid, from its ``track_points``."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dbtools.database import read_network
from fieldlogs.gnss.geodesy import geodetic_to_ecef
from fieldlogs.gnss.gis import GnssTrackError, gis_track, points_track


def test_station_track_from_its_track_points(sample_network_db: Path) -> None:
    net = read_network(sample_network_db)
    with pytest.raises(GnssTrackError) as exc:  # station track 3 of line 0420 has no grid points
        gis_track(net, "0420", "3")
    assert exc.value.reason == "unknown_track"
    gt = points_track(net, "0420-3")
    tp = net.track_points[net.track_points["track_id"] == "0420-3"].sort_values("pos_m")
    assert (gt.line_code, gt.track) == ("", "0420-3")
    assert gt.km[0] == 0.0 and gt.km[-1] == pytest.approx(float(tp["pos_m"].iloc[-1]))
    # vertex j is the ECEF of point j (lat, lon, rail height), and s runs with pos within the
    # chord shortening of a 20 m-spaced polyline
    first = tp.iloc[0]
    want = geodetic_to_ecef(np.radians(first["lat"]), np.radians(first["lon"]), float(first["height_m"]))
    assert np.allclose(gt.line.xyz[0], want, atol=1e-6)
    assert gt.line.s[-1] == pytest.approx(gt.km[-1], rel=2e-3)
    assert float(gt.km_of_s(gt.line.s[5])) == pytest.approx(float(tp["pos_m"].iloc[5]))


def test_a_track_without_points_is_refused(sample_network_db: Path) -> None:
    with pytest.raises(GnssTrackError) as exc:
        points_track(read_network(sample_network_db), "0420-D1")  # a grid track: no track_points
    assert exc.value.reason == "unknown_track" and "0 track_points point(s)" in str(exc.value)
