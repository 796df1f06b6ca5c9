"""Track-selective truth figures (Heirich 2016's definitions) on the hand-made networks."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dbtools.network import Network
from dbtools.sources import read_source_set
from dbtools.topology import all_tracks, centreline
from fieldlogs.pipeline.track_truth import (
    TrackFigures,
    compare_tracks,
    facing_passages,
    margin_allowed,
    parallel_mask,
    selectivity_cap,
    switch_passages,
    switch_resolution,
    track_figures,
)

NETWORKS = Path(__file__).resolve().parents[2] / "data" / "networks"


@pytest.fixture(scope="module")
def junction() -> Network:
    return read_source_set(NETWORKS / "junction")[0]


@pytest.fixture(scope="module")
def crossover() -> Network:
    return read_source_set(NETWORKS / "crossover")[0]


def _local_xy(lat: np.ndarray, lon: np.ndarray, lat0: float, lon0: float) -> tuple[np.ndarray, np.ndarray]:
    """Equirectangular metres about (lat0, lon0): within 1e-4 relative over a few hundred metres."""
    r = 6_371_008.8
    return np.radians(lon - lon0) * r * np.cos(np.radians(lat0)), np.radians(lat - lat0) * r


def _brute_parallel(net: Network, track: str, pos: np.ndarray, radius: float) -> np.ndarray:
    """Independent check: every other track's centreline densified to 0.25 m, those joined to
    ``track`` by a connection other than ``none`` (read from the table) left out, the least
    distance to each true point."""
    c = net.connections
    nav = c[c["navigability"] != "none"]
    joined = set(nav.loc[nav["track_a"] == track, "track_b"]) | set(nav.loc[nav["track_b"] == track, "track_a"])
    tracks = all_tracks(net).set_index("track_id", drop=False)
    own = centreline(net, tracks.loc[track])
    lat0, lon0 = float(own.lat[0]), float(own.lon[0])
    px, py = _local_xy(np.interp(pos, own.pos_m, own.lat), np.interp(pos, own.pos_m, own.lon), lat0, lon0)
    best = np.full(len(pos), np.inf)
    for tid, row in tracks.iterrows():
        if tid == track or tid in joined:
            continue
        line = centreline(net, row)
        s = np.arange(0.0, line.pos_m[-1], 0.25)
        x, y = _local_xy(np.interp(s, line.pos_m, line.lat), np.interp(s, line.pos_m, line.lon), lat0, lon0)
        d = np.hypot(px[:, None] - x[None, :], py[:, None] - y[None, :]).min(axis=1)
        best = np.minimum(best, d)
    return best <= radius


def test_parallel_track_after_a_junction_matches_a_brute_force_search(junction: Network) -> None:
    # single track A1 before the switch: both branches are where a train on A1 may go — no
    # parallel track; after it B1 (joined to A2 by the switch's `none` relation) runs beside A2
    # until more than 20 m apart
    pos_a1 = np.arange(0.0, 400.0, 7.0)
    assert not parallel_mask(junction, np.full(len(pos_a1), "A1", dtype=object), pos_a1).any()
    pos = np.arange(2.0, 600.0, 3.0)
    got = parallel_mask(junction, np.full(len(pos), "A2", dtype=object), pos)
    want = _brute_parallel(junction, "A2", pos, 20.0)
    near_threshold = np.abs(np.diff(want.astype(int), prepend=want[0])) > 0
    assert got[0] and not got[-1]
    assert (got == want)[~near_threshold].all()


def test_unknown_tracks_are_not_parallel(junction: Network) -> None:
    out = parallel_mask(junction, np.array(["nope", "A2"], dtype=object), np.array([10.0, np.nan]))
    assert not out.any()


def _crossover_truth(net: Network) -> pd.DataFrame:
    """D1 → X1 (facing switch W1) → U2 → U3 (facing W3, through) at 10 m/s, 1 s rows."""
    tracks = all_tracks(net).set_index("track_id")
    rows = []
    t = 0.0
    for tid in ("D1", "X1", "U2", "U3"):
        length = float(tracks.loc[tid, "length_m"])
        for p in np.arange(0.0, length, 10.0):
            rows.append({"t": t, "track_id": tid, "pos_m": p, "speed_mps": 10.0})
            t += 1.0
    return pd.DataFrame(rows)


def test_facing_passages_are_the_splitting_switches(crossover: Network) -> None:
    truth = _crossover_truth(crossover)
    p = facing_passages(truth, crossover)
    # D1 → X1 at W1 and U2 → U3 at W3 are facing; X1 → U2 at W2 is trailing
    assert list(p["switch_id"]) == ["W1", "W3"]
    assert list(p["to_track"]) == ["X1", "U3"]
    # rows every 10 m at 1 s: D1 (300 m) 30 rows, X1 (60.17 m) 7 rows, U2 (240 m) 24 rows
    assert list(p["t"]) == [30.0, 30.0 + 7 + 24]


def test_switch_passages_facing_and_trailing(crossover: Network) -> None:
    p = switch_passages(_crossover_truth(crossover), crossover)
    # D1 → X1 at W1 (facing), X1 → U2 at W2 (from the crossover's branch onto U2's toe side:
    # trailing), U2 → U3 at W3 (facing, through)
    assert list(p["switch_id"]) == ["W1", "W2", "W3"]
    assert list(p["facing"]) == [True, False, True]
    assert list(p["t"]) == [30.0, 37.0, 61.0]


def test_a_plain_joint_is_no_switch_passage(junction: Network) -> None:
    # the junction's A1 → A2 as a plain joint: one connection, no switch, no branch B1
    tables = {k: v.copy() for k, v in junction.tables.items()}
    c = tables["connections"]
    joint = c[(c["track_a"] == "A1") & (c["track_b"] == "A2")].copy()
    joint["switch_id"] = pd.NA
    tables["connections"] = joint.reset_index(drop=True)
    tables["switches"] = tables["switches"].iloc[:0]
    net = Network(tables, origin="test")
    length = {r.track_id: r.length_m for r in all_tracks(net).itertuples()}
    rows = [("A1", p) for p in np.arange(0.0, length["A1"], 10.0)] + [("A2", p) for p in (0.0, 10.0)]
    truth = pd.DataFrame(
        {"t": np.arange(len(rows), dtype=float), "track_id": [r[0] for r in rows], "pos_m": [r[1] for r in rows]}
    )
    assert switch_passages(truth, net).empty
    assert switch_passages(truth, junction)["facing"].tolist() == [True]


def test_selectivity_cap_by_hand() -> None:
    # 1 km of parallel track, 2 passages, margin 2.5 m: 2 × 2 × 2.5 = 10 m ambiguous → 99 %
    assert selectivity_cap(1000.0, 2, 2.5) == pytest.approx(0.99)
    assert margin_allowed(0.995, 1000.0, 2) == pytest.approx(1.25)
    # the network bench's D-GPS runs: 160 passages on 74.36 km; D-GPS's 99.9 % error 3.29 × 0.75 m
    assert selectivity_cap(74_360.0, 160, 3.2905 * 0.75) == pytest.approx(0.98938, abs=1e-5)
    assert selectivity_cap(100.0, 10, 10.0) == 0.0
    assert margin_allowed(0.995, 1000.0, 0) == float("inf")


@given(
    st.floats(100.0, 1e6),
    st.integers(1, 1000),
    st.floats(0.9, 0.9999),
)
def test_the_allowed_margin_reaches_the_target_exactly(parallel_m: float, n: int, target: float) -> None:
    m = margin_allowed(target, parallel_m, n)
    assert selectivity_cap(parallel_m, n, m) == pytest.approx(target, rel=1e-12)
    assert selectivity_cap(parallel_m, n, 1.01 * m) < target


def test_resolution_distance_and_wrong_claims(crossover: Network) -> None:
    truth = _crossover_truth(crossover)
    t = truth["t"].to_numpy()
    state = np.full(len(t), "determined", dtype=object)
    claimed = truth["track_id"].to_numpy(dtype=object).copy()
    # after W1 (t = 30): ambiguous for 3 s, then right; after W3 (t = 61): claimed wrongly at once
    w3 = float(facing_passages(truth, crossover)["t"].iloc[1])
    state[(t >= 30) & (t < 33)] = "ambiguous"
    claimed[(t >= 30) & (t < 33)] = pd.NA
    claimed[t == w3] = "U2"
    positions = pd.DataFrame({"t": t, "state": state, "track_id": claimed})
    cmp = compare_tracks(positions, truth, crossover)
    res = switch_resolution(cmp, facing_passages(truth, crossover))
    assert list(res["resolved"]) == [True, True]
    assert list(res["correct"]) == [True, False]
    assert res["distance_m"].iloc[0] == pytest.approx(30.0)  # 3 cycles of 1 s at 10 m/s
    assert int(cmp["wrong"].sum()) == 1
    f = TrackFigures.of(cmp, res)
    assert f.passages == 2 and f.resolved_correct == 1 and f.resolved_wrong == 1
    assert f.resolution_m == (30.0,)
    # D and U 4 m apart: every true position has the other main track beside it; the 3
    # ambiguous cycles and the wrong claim are parallel distance not selected (the first
    # cycle travels 0 m): 100 cycles of 10 m, 4 not selected
    s = f.summary()
    assert f.parallel_m == pytest.approx(1000.0)
    assert s["selectivity"] == pytest.approx(0.96)
    assert (f + f).passages == 4 and (f + f).summary()["selectivity"] == pytest.approx(s["selectivity"])


def test_never_determined_after_a_switch_is_unresolved(crossover: Network) -> None:
    truth = _crossover_truth(crossover)
    t = truth["t"].to_numpy()
    state = np.where(t < 30, "determined", "ambiguous").astype(object)
    positions = pd.DataFrame({"t": t, "state": state, "track_id": np.where(t < 30, truth["track_id"], None)})
    f = track_figures(positions, truth, crossover)
    assert f.passages == 2 and f.resolved_correct == 0 and f.resolved_wrong == 0 and f.wrong_cycles == 0
    assert f.summary()["median_resolution_m"] is None


def test_compare_with_truth_judges_the_track_by_its_id_where_the_truth_has_one() -> None:
    from fieldlogs.pipeline.truth import compare_with_truth

    # a station track "3" has no U/D name: line and track agree (both empty / the line's),
    # only the id tells the claim on D2 from the truth on 3; a line-only truth row (no id)
    # still compares line and track
    truth = pd.DataFrame(
        {
            "t": [0.0, 1.0, 2.0],
            "line_code": ["0420", "0420", "0420"],
            "track": [None, None, "D"],
            "km_m": [100.0, 110.0, 120.0],
            "track_id": ["0420-3", "0420-3", None],
        }
    )
    positions = pd.DataFrame(
        {
            "t": [0.0, 1.0, 2.0],
            "state": ["determined", "determined", "determined"],
            "line_code": ["0420", "0420", "0420"],
            "track": [None, None, "U"],
            "km_m": [100.0, 110.0, 120.0],
            "margin_m": [5.0, 5.0, 5.0],
            "track_id": ["0420-3", "0420-D2", "0420-U1"],
        }
    )
    assert compare_with_truth(positions, truth)["wrong_track"].tolist() == [False, True, True]
