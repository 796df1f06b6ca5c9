"""Properties of the track HMM on a small network with switches, crossovers and a ``none``
relation, for random traces (hypothesis): the path is connected navigably within each
chain, every matched fix lies on a track of its chain's path, probabilities are
probabilities, and the run's σ comes from the receiver's own figures."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.topology import topology
from fieldlogs.trackmatch.match import match_trace
from fieldlogs.trackmatch.trace import MIN_SIGMA_M, UERE_M, gps_fixes
from tests.fieldlogs.trackmatch.nets import fixes, make_network

# double track U (y = 4) and D (y = 0) with a crossover D1 → X → U2 and a branch B off D2
NET = make_network(
    {
        "D1": [(0, 0), (300, 0)],
        "D2": [(300, 0), (1000, 0)],
        "U1": [(0, 4), (360, 4)],
        "U2": [(360, 4), (1000, 4)],
        "X": [(300, 0), (360, 4)],
        "B": [(300, 0), (600, -40), (1000, -60)],
    },
    [
        ("D1", "end", "D2", "begin", "both"),
        ("D1", "end", "X", "begin", "both"),
        ("X", "begin", "D2", "begin", "none"),
        ("U1", "end", "U2", "begin", "both"),
        ("X", "end", "U2", "begin", "both"),
        ("X", "end", "U1", "end", "none"),
        ("D1", "end", "B", "begin", "AB"),
        ("B", "begin", "D2", "begin", "none"),
        ("B", "begin", "X", "begin", "none"),
    ],
)


def _connected(path: pd.DataFrame) -> bool:
    topo = topology(NET)
    rows = list(zip(path["chain"], path["track_id"], strict=True))
    for (ca, a), (cb, b) in pairwise(rows):
        if ca == cb and b not in {x.track_id for d in (1, -1) for x in topo.next_tracks(a, d)}:
            return False
    return True


@settings(max_examples=40, deadline=None)
@given(
    ys=st.lists(st.floats(-70, 10), min_size=2, max_size=12),
    noise=st.floats(0.0, 8.0),
    seed=st.integers(0, 1000),
    step=st.floats(5.0, 40.0),
)
def test_paths_are_connected(ys: list[float], noise: float, seed: int, step: float) -> None:
    rng = np.random.default_rng(seed)
    x = np.arange(0.0, 1000.0, step)
    y = np.interp(x, np.linspace(0, 1000, len(ys)), ys) + rng.normal(0, noise, len(x))
    r = match_trace(NET, *fixes(np.column_stack([x, y])))
    assert _connected(r.path)
    assert r.path["probability"].between(0, 1).all() and r.fixes["probability"].dropna().between(0, 1).all()
    on = r.fixes[r.fixes["status"] == "matched"]
    assert on["track_id"].notna().all() and set(on["track_id"]) <= set(r.path["track_id"])
    assert (on["offset_m"].abs() <= 50.0 + 1e-6).all()
    assert sum(r.summary[k] for k in ("matched", "no_candidate", "outlier", "no_position")) == len(x)
    assert r.path["fixes"].sum() == len(on)


def test_sigma_of_each_fix() -> None:
    gps = pd.DataFrame(
        {
            "t": [0.0, 1.0, 2.0, 3.0, 4.0],
            "lat": [60.0] * 5,
            "lon": [25.0] * 5,
            "fix": [1, 1, 1, 0, 1],
            "hdop": [0.8, 2.0, np.nan, 1.0, 0.1],
            "sigma_lat_m": [3.0, np.nan, np.nan, np.nan, np.nan],
            "sigma_lon_m": [4.0, np.nan, np.nan, np.nan, np.nan],
        }
    )
    _, lat, _, sigma = gps_fixes(gps)
    # RMS of the two sigmas; HDOP × UERE; nothing known; (no fix); HDOP × UERE below the floor
    assert sigma[0] == pytest.approx(np.sqrt((9 + 16) / 2))
    assert sigma[1] == pytest.approx(2.0 * UERE_M) and np.isnan(sigma[2]) and sigma[4] == MIN_SIGMA_M
    assert np.isnan(lat[3]) and not np.isnan(lat[2])
    _, lat, _, sigma = gps_fixes(gps[["t", "lat", "lon"]])  # a vendor trace: position only
    assert np.isfinite(lat).all() and np.isnan(sigma).all()
