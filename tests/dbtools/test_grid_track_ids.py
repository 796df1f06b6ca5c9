"""``grid_track_ids``: the declared track whose km span holds each line-grid point, against
a brute-force search (hypothesis), and the implied ``LINE:TRACK`` where none is declared."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import Network
from dbtools.topology import grid_track_ids


def _network(spans: list[tuple[float, float]], reversed_km: list[bool]) -> Network:
    tracks = pd.DataFrame(
        {
            "track_id": [f"T{i}" for i in range(len(spans))],
            "line_code": "L1",
            "track": "D",
            # a track may run against the km: its begin km above its end km
            "km_begin_m": [b if r else a for (a, b), r in zip(spans, reversed_km, strict=True)],
            "km_end_m": [a if r else b for (a, b), r in zip(spans, reversed_km, strict=True)],
        }
    )
    return Network({"tracks": tracks})


@settings(max_examples=60, deadline=None)
@given(
    cuts=st.lists(st.integers(0, 10_000), min_size=1, max_size=6, unique=True),
    km=st.lists(st.floats(-2_000.0, 12_000.0, allow_nan=False), min_size=1, max_size=30),
    rev=st.lists(st.booleans(), min_size=7, max_size=7),
)
def test_each_point_takes_the_track_begun_last_at_or_below_it(
    cuts: list[int], km: list[float], rev: list[bool]
) -> None:
    starts = sorted(float(c) for c in cuts)
    spans = [(a, b) for a, b in zip(starts, [*starts[1:], starts[-1] + 500.0], strict=True)]
    net = _network(spans, rev[: len(spans)])
    got = grid_track_ids(net, ["L1"] * len(km), ["D"] * len(km), km)
    # brute force: the last span whose low end is at or below km; below the first, the first
    want = [f"T{max([i for i, (a, _) in enumerate(spans) if a <= k] or [0])}" for k in km]
    assert got.tolist() == want


def test_undeclared_line_tracks_keep_their_implied_id() -> None:
    net = _network([(0.0, 100.0)], [False])
    got = grid_track_ids(net, ["L1", "L1", "L2"], ["D", "U", "D"], np.array([50.0, 50.0, 50.0]))
    assert got.tolist() == ["T0", "L1:U", "L2:D"]
    assert grid_track_ids(Network({}), ["L1"], ["D"], [5.0]).tolist() == ["L1:D"]
