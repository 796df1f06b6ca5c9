"""The route walk of ``topology.balise_ambiguous`` (:mod:`dbtools.rules.balise_groups`): from
each *walker* (a balise whose identity occurs at more than one place) along the navigable graph
(:attr:`dbtools.topology.Topology.graph`, states 2 · track + k) both ways, up to the
identification window w, every other balise of the same identity met on the way and its
route distance.

Route distance. A walk starts on the walker's track t₀ at position p₀ with the offset
−p₀ travelling towards the end (state 2t₀ + 1) and p₀ − ℓ(t₀) towards the begin (2t₀); the
offset of a state is the route distance at the track's entry end (begin when travelling up,
end when travelling down). Leaving a track of length ℓ at offset d enters each successor at
offset d + ℓ, as long as d + ℓ < w. A balise at position p on a track reached at offset d
lies at d + p (travelling up) or d + (ℓ − p) (down); it is *found* when
0 < distance ≤ w, it is not the walker and, for C balises, not of the walker's own
(line, station, track). A pair's distance is the smallest found from either of its balises.

Two implementations, the same findings:

* :func:`walk_each` — the walk as first written: a depth-first search per walker and
  direction that re-expands a state whenever it is reached at a smaller offset
  (label-correcting), each visit recording what it meets;
* :func:`walk` — all walks at once over arrays, frontier by frontier (Bellman–Ford over the
  (walk, state) pairs), each state's smallest offset d* kept; then one join of the visited
  states with the walkers on their tracks. Floating-point addition is monotone, so the
  smallest offsets and the smallest distances are the same numbers as the search's.
  The search also records from visits at a larger offset than d*, which can matter only
  where the distance at d* is ≤ 0 (then not found) but a longer route's is > 0: a walker
  where that happens away from its start is walked again by :func:`walk_each`, as is
  every walker when a track length is negative or not finite (the search's arithmetic
  on those is its own). ``tests/dbtools/test_route_walk.py`` compares both on random
  networks.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from dbtools.rules.topology_tables import int_join
from dbtools.topology import Graph

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@dataclass(frozen=True)
class Walkers:
    """The walkers, one per element: balise ``rows``, ``ident`` (equal codes: one identity)
    and ``is_c`` (a C balise: not compared with those of its own ``pair`` code)."""

    rows: I64
    ident: I64
    is_c: npt.NDArray[np.bool_]


Found = dict[tuple[int, int], float]


def walk_each(
    g: Graph,
    walkers: Walkers,
    at: I64,
    pos: F64,
    pair: Sequence[int],
    w: float,
    only: Sequence[int] | None = None,
) -> Found:
    """The depth-first walk of each walker (module doc): (row, row) → the smallest route
    distance found between two balises of one identity. ``at``: each balise row's track code
    in ``g`` (only the walkers' rows are read); ``pos``: its position on that track;
    ``pair``: the (line, station, track) code of each row (C balises of one code are not
    compared); ``only``: the walkers (their indexes) that walk, all by default (all are met
    on the way)."""
    length = g.length.tolist()
    rows, idents, c_kind = walkers.rows.tolist(), walkers.ident.tolist(), walkers.is_c.tolist()
    # identity → track → [(pos, row)] of its walkers there, in walker order
    on_track: dict[int, dict[int, list[tuple[float, int]]]] = defaultdict(lambda: defaultdict(list))
    for r, ident in zip(rows, idents, strict=True):
        on_track[ident][int(at[r])].append((float(pos[r]), r))
    ptr, succ = g.ptr.tolist(), g.succ.tolist()
    found: Found = {}
    inf = float("inf")
    for k in range(len(rows)) if only is None else only:
        r = rows[k]
        t0 = int(at[r])
        here = on_track[idents[k]]
        is_c, pair_r = c_kind[k], pair[r]
        for up in (1, 0):
            # state 2·track + up (travelling towards the end: up = 1); off: route distance at
            # the track's begin (up) / end (down)
            stack = [(2 * t0 + up, -float(pos[r]) if up else float(pos[r]) - length[t0])]
            best: dict[int, float] = {}
            while stack:
                state, off = stack.pop()
                if best.get(state, inf) <= off:
                    continue
                best[state] = off
                t = state >> 1
                ln = length[t]
                for p, o in here.get(t, ()):
                    dist = off + (p if state & 1 else ln - p)
                    if o != r and 0 < dist <= w and not (is_c and pair[o] == pair_r):
                        key = (min(r, o), max(r, o))
                        found[key] = min(found.get(key, inf), dist)
                exit_at = off + ln
                if exit_at < w:
                    stack += [(x, exit_at) for x in succ[ptr[state] : ptr[state + 1]]]
    return found


def _smallest_offsets(g: Graph, start: I64, off0: F64, w: float) -> tuple[I64, I64, F64]:
    """Every (walk, state) reachable within ``w`` from the walks' start states, with its
    smallest offset: (walk, state, d*) sorted by walk and state. Frontier by frontier: the
    states entered from the last improved ones, the smallest offset per (walk, state) kept
    where it improves on the one known."""
    n_states = len(g.ptr) - 1
    key = np.arange(len(start), dtype=np.int64) * n_states + start
    order = np.argsort(key)
    vis_key, vis_off = key[order], off0[order]
    f_key, f_off = vis_key, vis_off
    while f_key.size:
        state = f_key % n_states
        exit_at = f_off + g.length[state >> 1]
        go = np.flatnonzero(exit_at < w)
        state, walk, exit_at = state[go], f_key[go] - state[go], exit_at[go]
        lo, n = g.ptr[state], g.ptr[state + 1] - g.ptr[state]
        each = np.repeat(np.arange(go.size), n)
        nxt = g.succ[np.repeat(lo - np.cumsum(n) + n, n) + np.arange(each.size)]
        c_key, c_off = walk[each] + nxt, exit_at[each]
        first = np.lexsort((c_off, c_key))
        c_key, c_off = c_key[first], c_off[first]
        uniq = np.r_[True, c_key[1:] != c_key[:-1]] if c_key.size else np.zeros(0, dtype=bool)
        c_key, c_off = c_key[uniq], c_off[uniq]  # the smallest offset of each (walk, state)
        i = np.searchsorted(vis_key, c_key)
        j = np.minimum(i, max(vis_key.size - 1, 0))
        known = (i < vis_key.size) & (vis_key[j] == c_key)
        better = ~known | (c_off < vis_off[j])
        vis_off[j[known & better]] = c_off[known & better]
        new = ~known
        vis_key, vis_off = np.insert(vis_key, i[new], c_key[new]), np.insert(vis_off, i[new], c_off[new])
        f_key, f_off = c_key[better], c_off[better]
    return vis_key // n_states, vis_key % n_states, vis_off


def walk(g: Graph, walkers: Walkers, at: I64, pos: F64, pair: Sequence[int], w: float) -> Found:
    """:func:`walk_each`'s result, computed for all walkers at once (module doc)."""
    if not len(walkers.rows):
        return {}
    if not (np.isfinite(g.length).all() and (g.length >= 0).all()):
        return walk_each(g, walkers, at, pos, pair, w)
    rows, ident, is_c = walkers.rows, walkers.ident, walkers.is_c
    pair_code = np.asarray(pair, dtype=np.int64)
    track, p = np.asarray(at, dtype=np.int64)[rows], np.asarray(pos, dtype=float)[rows]
    # walk 2k: walker k towards the end (up), 2k + 1: towards the begin
    start = np.repeat(2 * track, 2) + np.tile([1, 0], len(rows))
    off0 = np.ravel(np.column_stack([-p, p - g.length[track]]))
    walk_id, state, d = _smallest_offsets(g, start, off0, w)
    k = walk_id // 2
    n_tracks = len(g.length)
    vi, ei = int_join(ident[k] * n_tracks + (state >> 1), ident * n_tracks + track)
    kv = k[vi]
    up = (state[vi] & 1).astype(bool)
    dist = d[vi] + np.where(up, p[ei], g.length[state[vi] >> 1] - p[ei])
    r, o = rows[kv], rows[ei]
    ok = (o != r) & ~(is_c[kv] & (pair_code[o] == pair_code[r]))
    # a distance ≤ 0 at d* away from the start: a longer route may give one > 0 (module doc)
    redo = np.zeros(len(rows), dtype=bool)
    redo[kv[ok & (dist <= 0) & (state[vi] != start[walk_id[vi]])]] = True
    hit = np.flatnonzero(ok & (dist > 0) & (dist <= w) & ~redo[kv])
    a, b, dist = np.minimum(r[hit], o[hit]), np.maximum(r[hit], o[hit]), dist[hit]
    order = np.lexsort((dist, b, a))
    a, b, dist = a[order], b[order], dist[order]
    first = np.r_[True, (a[1:] != a[:-1]) | (b[1:] != b[:-1])] if a.size else np.zeros(0, dtype=bool)
    found: Found = dict(zip(zip(a[first].tolist(), b[first].tolist(), strict=True), dist[first].tolist(), strict=True))
    if redo.any():
        for key, v in walk_each(g, walkers, at, pos, pair, w, np.flatnonzero(redo).tolist()).items():
            found[key] = min(found.get(key, v), v)
    return found
