"""The matcher's segments follow ``dbtools.topology.centreline`` for tracks along a line
(gis grid) and tracks of their own (track_points): the hand-made crossover network."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dbtools.gis.track_segments import build_geometry
from dbtools.sources import read_source_set
from dbtools.topology import all_tracks, centreline

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


def test_a_trace_over_the_crossover_pair() -> None:
    # D (y = −2) → X1 → U (y = +2) → X2 → D, fixes every 5 m on the centrelines with 1 m
    # noise: the path is D1, X1, U2, X2, D3 and the fixes on D1 carry D's line km
    from fieldlogs.trackmatch.match import match_trace

    net, _ = read_source_set(CROSSOVER)
    tracks = all_tracks(net).set_index("track_id", drop=False)
    lat, lon = [], []
    for tid in ("D1", "X1", "U2", "X2", "D3"):
        c = centreline(net, tracks.loc[tid])
        grid = np.arange(0.0, c.pos_m[-1], 5.0)
        lat += list(np.interp(grid, c.pos_m, c.lat))
        lon += list(np.interp(grid, c.pos_m, c.lon))
    rng = np.random.default_rng(5)
    la = np.array(lat) + rng.normal(0, 1.0 / 111_000, len(lat))
    lo = np.array(lon) + rng.normal(0, 2.0 / 111_000, len(lon))
    r = match_trace(net, np.arange(len(la), dtype=float), la, lo)
    assert list(r.path["track_id"]) == ["D1", "X1", "U2", "X2", "D3"] and r.summary["chains"] == 1
    d1 = r.fixes[r.fixes["track_id"] == "D1"]
    assert np.allclose(d1["km_m"], d1["distance_m"], atol=1e-6) and d1["km_m"].max() > 290.0
    assert r.fixes.loc[r.fixes["track_id"] == "X1", "km_m"].notna().all()  # track_points carry km too
