"""The map layers' geometry: the coordinate encoding and the Douglas–Peucker simplification."""

from __future__ import annotations

import numpy as np
import shapely
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.gis.geometry import Projector
from dbtools.interchange.netmap import COORD_SCALE, TOLERANCE_M, encode, simplify

PROJ = Projector(9)  # JGD2011 zone IX (Tokyo)


def _decode(c: list[int]) -> np.ndarray:
    return np.cumsum(np.asarray(c, dtype=np.int64).reshape(-1, 2), axis=0) / COORD_SCALE


def test_encode_is_deltas_of_micro_degrees() -> None:
    lat, lon = np.array([35.0, 35.000001, 34.9999995]), np.array([139.5, 139.500002, 139.5])
    assert encode(lat, lon) == [35_000_000, 139_500_000, 1, 2, -1, -2]  # 34.9999995 rounds to even
    back = _decode(encode(lat, lon))
    assert np.abs(back[:, 0] - lat).max() <= 0.5e-6 + 1e-12


def test_straight_line_keeps_its_ends_and_a_curve_its_shape() -> None:
    x = np.arange(0.0, 1000.0 + 1e-9, 20.0)
    lon, lat = PROJ.to_lonlat(x, np.zeros_like(x))
    assert simplify(lat, lon, PROJ).tolist() == [0, x.size - 1]
    # a circle of R = 1000 m every 20 m: a chord c deviates c²/(8R) from the arc: 0.45 m over
    # 60 m, 0.8 m over 80 m; so gaps of 3 steps may go, never 4; at R = 300 m (0.67 m over
    # 40 m) every point stays
    t = np.arange(0.0, 1200.0, 20.0) / 1000.0
    lon, lat = PROJ.to_lonlat(1000.0 * np.sin(t), 1000.0 * (1 - np.cos(t)))
    keep = simplify(lat, lon, PROJ)
    assert keep[0] == 0 and keep[-1] == t.size - 1 and np.diff(keep).max() == 3
    t = np.arange(0.0, 600.0, 20.0) / 300.0
    lon, lat = PROJ.to_lonlat(300.0 * np.sin(t), 300.0 * (1 - np.cos(t)))
    assert simplify(lat, lon, PROJ).size == t.size


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-3.0, 3.0), st.floats(5.0, 40.0)), min_size=3, max_size=60))
def test_no_dropped_vertex_is_farther_than_the_tolerance(steps: list[tuple[float, float]]) -> None:
    """Whatever the line: every original vertex lies within 0.5 m of the simplified line."""
    heading = np.cumsum([a / 10.0 for a, _ in steps])
    d = np.array([b for _, b in steps])
    x, y = np.cumsum(d * np.cos(heading)), np.cumsum(d * np.sin(heading))
    lon, lat = PROJ.to_lonlat(x, y)
    keep = simplify(lat, lon, PROJ)
    assert keep[0] == 0 and keep[-1] == x.size - 1 and np.all(np.diff(keep) > 0)
    kept = shapely.linestrings(x[keep], y[keep])
    dist = shapely.distance(shapely.points(x, y), kept)
    assert float(np.max(dist)) <= TOLERANCE_M + 1e-6


def test_a_line_track_that_new_lacks_is_drawn_as_removed() -> None:
    from dbtools.diff import diff_networks, load_network
    from dbtools.interchange.leaflet_map import map_payload
    from dbtools.interchange.mapchanges import map_data
    from dbtools.network import Network
    from dbtools.sample_network import sample_source_dir

    old, _ = load_network(sample_source_dir())
    new = Network({**old.tables, "gis": old.gis[old.gis["track"] == "D"].reset_index(drop=True)})
    d = diff_networks(old, new)
    data = map_data(old, new, d)
    assert [label for label, _ in data.removed_lines] == ["0420 U"]
    payload = map_payload(new, PROJ, data)
    assert [t["id"] for t in payload["removed_tracks"]] == ["0420 U"]
    assert [t["id"] for t in payload["tracks"]] == ["0420:D"]
    kinds = {c["kind"] for c in payload["changes"]}
    assert kinds == {"removed"}  # the U grid points are gone (GIS point changes)
    # the removed track, decoded, starts at OLD's first U point
    u = old.gis[old.gis["track"] == "U"].sort_values("km_m")
    first = _decode(payload["removed_tracks"][0]["c"])[0]
    assert abs(first[0] - u["lat"].iloc[0]) <= 0.5e-6 and abs(first[1] - u["lon"].iloc[0]) <= 0.5e-6
