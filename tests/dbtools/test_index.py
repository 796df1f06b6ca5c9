"""The one grid index (dbtools/gis/index.py): points, km search, track length, shape, cuts,
and one index per loaded network shared by the rules, matching and the metric."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.geometry import GEOD, Projector
from dbtools.gis.index import GridIndex, PieceRule, grid_index
from dbtools.gis.matching import track_index_for
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.simulate.networks.synthetic import build_network, demo_line

P = Projector(9)


def _frame() -> pd.DataFrame:
    """Two tracks given out of order, a missing km, a NaN point and a point off the globe."""
    x = np.array([0.0, 20.0, 40.0, 60.0, 100.0, 0.0, 20.0, 40.0, 5.0, 7.0])
    y = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 3.8, 3.8, 3.8, 9.0, 9.0])
    lon, lat = P.to_lonlat(x, y)
    lat[8] = np.nan
    lat[9] = 95.0
    return pd.DataFrame(
        {
            "line_code": ["L"] * 5 + ["L"] * 3 + ["L", "L"],
            "track": ["D"] * 5 + ["U"] * 3 + ["U", "U"],
            "km_m": [0.0, 20.0, 40.0, 60.0, 100.0, 0.0, 20.0, 40.0, 60.0, 80.0],
            "lat": lat,
            "lon": lon,
        }
    ).iloc[[5, 0, 6, 1, 2, 7, 3, 4, 8, 9]]


def test_points_sorted_with_track_ids_and_search() -> None:
    g = _frame()
    gi = GridIndex(g)
    assert gi.keys == [("L", "D"), ("L", "U")]
    assert gi.km.tolist() == [0.0, 20.0, 40.0, 60.0, 100.0, 0.0, 20.0, 40.0]
    assert gi.tid.tolist() == [0, 0, 0, 0, 0, 1, 1, 1]
    assert (gi.start.tolist(), gi.end.tolist()) == ([0, 5], [5, 8])
    assert g.iloc[gi.pos]["km_m"].tolist() == gi.km.tolist()  # pos: rows of the frame
    assert gi.projector == P
    assert gi.searchsorted([0, 0, 1, 1, 0], [30.0, 60.0, 20.0, 500.0, -5.0]).tolist() == [2, 3, 6, 8, 0]
    assert gi.searchsorted([0], [60.0], "right").tolist() == [4]
    assert gi.track_ids(
        np.array(["L", "L", "X", None], dtype=object), np.array(["U", "D", "D", "D"], dtype=object)
    ).tolist() == [1, 0, -1, -1]
    lo, hi = gi.km_range(np.array([1, -1]))
    assert lo[0] == 0.0 and hi[0] == 40.0 and np.isnan(lo[1])


def test_track_length_is_the_geodesic_sum_and_steps_are_cut_at_holes() -> None:
    gi = GridIndex(_frame())
    _, _, d = GEOD.inv(gi.lon[:4], gi.lat[:4], gi.lon[1:5], gi.lat[1:5])
    assert gi.c[:5] == pytest.approx(np.concatenate([[0.0], np.cumsum(d)]), abs=1e-9)
    assert gi.c[5] == 0.0  # each track starts at its first km
    assert gi.c[4] - gi.c[3] == pytest.approx(40.0 / 0.9999, abs=1e-4)  # ground length: zone scale 0.9999
    # 60 → 100 on D is a missing point (40 m over 40 m): not a cut; D → U is
    cuts = gi.cuts(PieceRule())
    assert cuts.tolist() == [False, False, False, False, True, False, False]
    assert gi.cuts(PieceRule(max_segment_m=30.0))[3]
    shape = gi.shape(20.0, 1e-3)
    assert shape.regular.tolist() == [True, True, True, False, False, True, True]
    assert shape.kappa[1] == pytest.approx(0.0, abs=1e-9) and np.isnan(shape.kappa[3])
    assert shape.heading[3] == pytest.approx(shape.heading[1], abs=1e-6)  # one-sided before a hole
    assert np.isnan(shape.heading[4])  # no regular step at all


def test_one_index_per_loaded_network() -> None:
    net = build_network([demo_line()], P)
    gi = grid_index(net)
    assert grid_index(net) is gi
    assert track_index_for(net).grid is gi
    tm = track_metric(net, "0900", "D")
    t = gi.track_id("0900", "D")
    assert t is not None
    assert np.array_equal(tm.c, gi.c[gi.start[t] : gi.end[t]])
    net.tables["gis"] = net.gis.iloc[::2].reset_index(drop=True)  # a replaced table: a new index
    assert grid_index(net) is not gi
    assert grid_index(net).n == gi.n - gi.n // 2
