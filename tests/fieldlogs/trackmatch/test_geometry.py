"""The matcher's segments follow ``dbtools.topology.centreline`` for tracks along a line
(gis grid) and tracks of their own (track_points): the hand-made crossover network."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dbtools.sources import read_source_set
from dbtools.topology import all_tracks, centreline
from fieldlogs.trackmatch.geometry import build_geometry

CROSSOVER = Path(__file__).resolve().parents[2] / "data" / "networks" / "crossover"


def test_segments_follow_the_centrelines() -> None:
    net, _ = read_source_set(CROSSOVER)
    geo = build_geometry(net)
    tracks = all_tracks(net)
    assert geo.track_ids == [str(t) for t in tracks["track_id"]]
    for k, row in tracks.iterrows():
        c = centreline(net, row)
        seg = geo.seg_track == k
        s0, ds, km0, dkm = geo.s0[seg], geo.ds[seg], geo.km0[seg], geo.dkm[seg]
        ends = np.r_[s0, s0[-1] + ds[-1]]
        # every centreline vertex is a segment end (segments ≤ 25 m split a 20 m grid never)
        assert np.allclose(np.interp(c.pos_m, ends, ends), c.pos_m)
        assert ends[0] == c.pos_m[0] and np.isclose(ends[-1], c.pos_m[-1])
        assert np.allclose(np.interp(c.pos_m, ends, np.r_[km0, km0[-1] + dkm[-1]]), c.km_m, equal_nan=True)
        assert np.isclose(geo.length_m[k], float(row["length_m"]))
    assert (np.hypot(geo.dx, geo.dy) <= 25.0 + 1e-9).all()
