"""The track HMM on hand-made networks (tests/fieldlogs/trackmatch/nets.py): hand-computed
posteriors, navigability, outliers, gaps and tracks passed between two fixes."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fieldlogs.trackmatch.match import MatchSettings, match_trace
from tests.fieldlogs.trackmatch.nets import fixes, make_network

#: UTM zone 35 (the plane the matcher derives here) scales distances by ≈ 0.99977 at 24.9° E.
TOL_M = 0.01


def test_fix_2_m_off_one_of_two_tracks_4_m_apart() -> None:
    # A at y = 0, B at y = 4; the fix at y = −2: 2 m off A (right of it), 6 m off B. With
    # σ = 10 m and no other evidence the posterior of A is its normalised emission:
    # e^(−2²/200) / (e^(−2²/200) + e^(−6²/200)) = 1 / (1 + e^(−32/200)) = 0.53991
    net = make_network({"A": [(0, 0), (200, 0)], "B": [(0, 4), (200, 4)]})
    r = match_trace(net, *fixes([(100, -2)]))
    f = r.fixes.iloc[0]
    assert f["track_id"] == "A" and f["status"] == "matched"
    assert f["offset_m"] == pytest.approx(-2.0, abs=TOL_M) and f["distance_m"] == pytest.approx(100.0, abs=TOL_M)
    assert f["probability"] == pytest.approx(1 / (1 + math.exp(-32 / 200)), abs=1e-4)
    assert list(r.path["track_id"]) == ["A"] and r.path["probability"].iloc[0] == pytest.approx(0.53991, abs=1e-4)


def test_sigma_of_the_fix_sharpens_the_posterior() -> None:
    # σ = 2 m: 1 / (1 + e^(−32/8)) = 0.98201
    net = make_network({"A": [(0, 0), (200, 0)], "B": [(0, 4), (200, 4)]})
    r = match_trace(net, *fixes([(100, -2)]), sigma_m=np.array([2.0]))
    assert r.fixes["probability"].iloc[0] == pytest.approx(1 / (1 + math.exp(-4)), abs=1e-4)


def _diverging() -> dict[str, list[tuple[float, float]]]:
    # A runs east to x = 100; B continues straight; C leaves at A's end and reaches y = 4
    # at x = 140, then runs parallel to B.
    return {"A": [(0, 0), (100, 0)], "B": [(100, 0), (400, 0)], "C": [(100, 0), (140, 4), (400, 4)]}


def test_a_none_relation_is_never_crossed() -> None:
    # A→B is navigability none: fixes 1.5 m off B (2.5 m off C) after the split are on C,
    # although B is the nearest track for every one of them.
    net = make_network(_diverging(), [("A", "end", "B", "begin", "none"), ("A", "end", "C", "begin", "both")])
    xy = [(x, 0.5) for x in range(0, 100, 10)] + [(x, 1.5) for x in range(150, 400, 10)]
    r = match_trace(net, *fixes(xy))
    assert list(r.path["track_id"]) == ["A", "C"] and r.summary["chains"] == 1
    assert "B" not in set(r.fixes["track_id"])
    late = r.fixes.iloc[10:]
    assert (late["offset_m"].abs() - 2.5).abs().max() < TOL_M  # the 2.5 m to C, not the 1.5 m to B


def test_the_same_trace_goes_straight_on_where_it_may() -> None:
    # the same geometry with A→B navigable: the nearer B wins
    net = make_network(_diverging(), [("A", "end", "B", "begin", "both"), ("A", "end", "C", "begin", "both")])
    xy = [(x, 0.5) for x in range(0, 100, 10)] + [(x, 1.5) for x in range(150, 400, 10)]
    assert list(match_trace(net, *fixes(xy)).path["track_id"]) == ["A", "B"]


def test_only_a_none_relation_breaks_the_chain() -> None:
    # no other way from A to B: never forced across — two chains, each on its own track
    net = make_network({"A": [(0, 0), (100, 0)], "B": [(100, 0), (400, 0)]}, [("A", "end", "B", "begin", "none")])
    xy = [(x, 0.5) for x in range(0, 100, 5)] + [(x, 0.5) for x in range(105, 400, 5)]
    r = match_trace(net, *fixes(xy))
    assert list(r.path["track_id"]) == ["A", "B"] and list(r.path["chain"]) == [0, 1]


def _line() -> dict[str, list[tuple[float, float]]]:
    return {"L": [(0, 0), (2000, 0)], "P": [(0, 300), (2000, 300)]}


@pytest.mark.parametrize("other_track", [False, True])
def test_five_fixes_300_m_off_stay_on_the_path(other_track: bool) -> None:
    # without a track there: no candidate within 50 m; with an unconnected track P 300 m
    # north: a chain of 5 fixes no route joins to the rest, set aside as outliers
    tracks = _line() if other_track else {"L": _line()["L"]}
    net = make_network(tracks)
    rng = np.random.default_rng(3)
    xy = np.column_stack([np.arange(0, 2000, 10.0), rng.normal(0, 2, 200)])
    xy[100:105, 1] += 300
    r = match_trace(net, *fixes(xy))
    assert list(r.path["track_id"]) == ["L"] and r.summary["chains"] == 1
    want = "outlier" if other_track else "no_candidate"
    assert list(r.fixes["status"].iloc[100:105]) == [want] * 5 and r.summary["matched"] == 195
    assert r.fixes["track_id"].iloc[100:105].isna().all()


def test_a_tunnel_gap_is_bridged_and_a_track_passed_whole_is_in_the_path() -> None:
    # A (0..500) → X (500..530, a short piece with no fix) → B (530..1500); no position
    # from t = 40 to 79 (x = 400 … 790): the path is A, X, B in one chain
    net = make_network(
        {"A": [(0, 0), (500, 0)], "X": [(500, 0), (530, 0)], "B": [(530, 0), (1500, 0)], "D": [(530, 0), (1500, 40)]},
        [("A", "end", "X", "begin", "both"), ("X", "end", "B", "begin", "both"), ("X", "end", "D", "begin", "both")],
    )
    xy = np.column_stack([np.arange(0, 1500, 10.0), np.zeros(150)])
    xy[40:80] = np.nan
    r = match_trace(net, *fixes(xy))
    assert list(r.path["track_id"]) == ["A", "X", "B"] and r.summary["chains"] == 1
    x = r.path.set_index("track_id").loc["X"]
    assert x["fixes"] == 0 and x["t_from"] == 39.0 and x["t_to"] == 80.0 and 0.9 < x["probability"] <= 1.0
    assert (r.fixes["status"].iloc[40:80] == "no_position").all() and r.summary["no_position"] == 40
    b = r.fixes.iloc[80]
    assert b["track_id"] == "B" and b["distance_m"] == pytest.approx(800 - 530, abs=0.1)


def test_a_reversal_inside_a_passed_track_is_not_a_route() -> None:
    # from branch L to branch R of one switch (L–R none) the only way is through the toe
    # track T reversing there; with T a whole passed track that is no route: two chains
    net = make_network(
        {"T": [(-300, 0), (0, 0)], "L": [(0, 0), (300, 30)], "R": [(0, 0), (300, -30)]},
        [("T", "end", "L", "begin", "both"), ("T", "end", "R", "begin", "both"), ("L", "begin", "R", "begin", "none")],
    )
    xy = [(x, 0.1 * x) for x in range(300, 100, -10)] + [(x, -0.1 * x) for x in range(100, 300, 10)]
    r = match_trace(net, *fixes(xy), settings=MatchSettings(radius_m=8.0))
    assert list(r.path["track_id"]) == ["L", "R"] and list(r.path["chain"]) == [0, 1]


@pytest.mark.parametrize("xy", [[(100, -200), (100, -300)], np.zeros((0, 2)), [(np.nan, np.nan)]])
def test_nothing_to_match(xy: object) -> None:
    net = make_network({"A": [(0, 0), (200, 0)]})
    r = match_trace(net, *fixes(xy))  # type: ignore[arg-type]
    assert r.summary["matched"] == 0 and r.path.empty and r.summary["chains"] == 0
    assert len(r.fixes) == len(np.asarray(xy).reshape(-1, 2)) and r.fixes["track_id"].isna().all()
