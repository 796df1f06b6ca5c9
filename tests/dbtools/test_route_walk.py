"""The route walk of ``topology.balise_ambiguous`` (:mod:`dbtools.rules.route_walk`): the
walk over arrays gives the depth-first walk's findings, number for number."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.rules.route_walk import Walkers, walk, walk_each
from dbtools.topology import Graph


def graph(lengths: list[float], edges: list[tuple[int, int]]) -> Graph:
    """Tracks 0…n−1 of the given lengths; ``edges``: (from state, to state), a state being
    2 · track + 1 travelling towards the end, 2 · track towards the begin."""
    n_states = 2 * len(lengths)
    src = np.array([a for a, _ in edges], dtype=np.int64)
    dst = np.array([b for _, b in edges], dtype=np.int64)
    order = np.argsort(src, kind="stable")
    ptr = np.searchsorted(src[order], np.arange(n_states + 1)).astype(np.int64)
    names = pd.Index([f"T{i}" for i in range(len(lengths))], dtype=object)
    return Graph(names, np.asarray(lengths, dtype=float), ptr, dst[order])


def walkers(*items: tuple[int, int, bool]) -> Walkers:
    """Walkers from (row, identity code, is a C balise)."""
    rows, ident, is_c = zip(*items, strict=True) if items else ((), (), ())
    return Walkers(np.array(rows, dtype=np.int64), np.array(ident, dtype=np.int64), np.array(is_c, dtype=bool))


def test_two_tracks_in_line_by_hand() -> None:
    """A (100 m) end → B begin (200 m): G balises of one identity at A 50 m and B 30 m are
    50 + 30 = 80 m apart; a third at B 190 m is 50 + 190 = 240 m from the first (beyond a
    window of 200 m) and 160 m from the second."""
    g = graph([100.0, 200.0], [(2 * 0 + 1, 2 * 1 + 1), (2 * 1 + 0, 2 * 0 + 0)])
    at = np.array([0, 1, 1])
    pos = np.array([50.0, 30.0, 190.0])
    group = walkers((0, 0, False), (1, 0, False), (2, 0, False))
    want = {(0, 1): 80.0, (1, 2): 160.0}
    assert walk_each(g, group, at, pos, [0, 1, 2], 200.0) == want
    assert walk(g, group, at, pos, [0, 1, 2], 200.0) == want


def test_c_balises_of_one_pair_are_not_compared() -> None:
    g = graph([100.0], [])
    home = walkers((0, 0, True), (1, 0, True))
    at, pos = np.array([0, 0]), np.array([10.0, 60.0])
    assert walk(g, home, at, pos, [7, 7], 500.0) == {}
    assert walk(g, home, at, pos, [7, 8], 500.0) == {(0, 1): 50.0}
    assert walk(g, walkers((0, 0, False), (1, 0, False)), at, pos, [7, 7], 500.0) == {(0, 1): 50.0}  # G: compared


def test_a_longer_route_is_reported_where_the_shortest_gives_zero() -> None:
    """B's begin is reached from A's end directly (0 m from a walker standing at A's end) and
    around a 30 m loop: the depth-first walk may meet the other balise first by the loop
    (30 m, found) and then directly (0 m, not found); the array walk hands such a walker to it."""
    lengths = [100.0, 0.0, 30.0]
    edges = [(1, 3), (1, 5), (5, 3)]  # A end → B begin; A end → L begin; L end → B begin
    g = graph(lengths, edges)
    group = walkers((0, 0, False), (1, 0, False))
    at, pos = np.array([0, 1]), np.array([100.0, 0.0])
    assert walk_each(g, group, at, pos, [0, 1], 500.0) == {(0, 1): 30.0}  # the loop's, met first
    assert walk(g, group, at, pos, [0, 1], 500.0) == {(0, 1): 30.0}


@st.composite
def networks(draw: st.DrawFn) -> tuple[Graph, Walkers, np.ndarray, np.ndarray, list[int]]:
    n = draw(st.integers(1, 8))
    lengths = draw(st.lists(st.sampled_from([0.0, 1.0, 20.0, 40.0, 95.5, 250.0]), min_size=n, max_size=n))
    edges = draw(st.lists(st.tuples(st.integers(0, 2 * n - 1), st.integers(0, 2 * n - 1)), max_size=3 * n))
    m = draw(st.integers(1, 10))
    at = np.array(draw(st.lists(st.integers(0, n - 1), min_size=m, max_size=m)))
    frac = draw(st.lists(st.sampled_from([0.0, 0.25, 0.5, 1.0, 1.004]), min_size=m, max_size=m))
    pos = np.array([lengths[t] * f + (0.5 if f > 1 else 0.0) for t, f in zip(at, frac, strict=True)])
    ident = draw(st.lists(st.integers(0, 3), min_size=m, max_size=m))  # codes 2 and 3: C balises
    pair = draw(st.lists(st.integers(0, 2), min_size=m, max_size=m))
    return graph(lengths, edges), walkers(*((i, c, c >= 2) for i, c in enumerate(ident))), at, pos, pair


@settings(max_examples=300, deadline=None)
@given(networks(), st.sampled_from([0.0, 30.0, 100.0, 500.0]))
def test_the_array_walk_equals_the_depth_first_walk(net: tuple, w: float) -> None:  # type: ignore[type-arg]
    g, group, at, pos, pair = net
    assert walk(g, group, at, pos, pair, w) == walk_each(g, group, at, pos, pair, w)


def test_negative_or_missing_lengths_take_the_depth_first_walk() -> None:
    g = graph([100.0, float("nan")], [(1, 3)])
    group = walkers((0, 0, False), (1, 0, False))
    at, pos = np.array([0, 1]), np.array([40.0, 10.0])
    assert walk(g, group, at, pos, [0, 1], 500.0) == walk_each(g, group, at, pos, [0, 1], 500.0) == {(0, 1): 70.0}
