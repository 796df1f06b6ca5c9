"""Route distances between positions on two tracks, through the topology (SPEC §8.1, §8.3).

A train on track A at distance ``s`` from its begin leaves A at one of its ends (``s`` to
the begin, ``L_A − s`` to the end: within one track it may run either way), then runs
through whole tracks — entering each at one end and leaving at the other, only through
connections navigable that way (:meth:`dbtools.topology.Topology.next_tracks`; never a
``none`` relation, never reversing inside a track it passes through) — and enters B at one
of its ends, reaching ``s'`` after ``s'`` (entered at its begin) or ``L_B − s'``.

``D(A leaving e, B entering e')`` is the length of the tracks passed between: a bounded
Dijkstra from the source (A, e) over states (track, entry end), cost = the lengths of the
tracks passed whole, stopped at ``cutoff`` metres; results (distance and predecessor per
state) are cached per source and recomputed only when a larger cutoff is asked for.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from dbtools.topology import BEGIN, END, Topology

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: End codes in arrays: 0 begin, 1 end.
ENDS = (BEGIN, END)


@dataclass
class _Search:
    cutoff: float
    dist: dict[tuple[int, int], float]
    pred: dict[tuple[int, int], tuple[int, int] | None]


@dataclass
class Routes:
    """Bounded shortest routes between track ends (module docstring), tracks by index."""

    topo: Topology
    index: dict[str, int]
    length_m: F64
    _cache: dict[tuple[int, int], _Search] = field(default_factory=dict)
    _exits_of: dict[tuple[int, int], list[tuple[int, int]]] = field(default_factory=dict)

    def _exits(self, track: int, end: int) -> list[tuple[int, int]]:
        """Where a train leaving ``track`` at ``end`` may go: (track, entry end) states."""
        key = (track, end)
        hit = self._exits_of.get(key)
        if hit is None:
            hit = []
            for x in self.topo.exits.get((self._names[track], ENDS[end]), []):
                j = self.index.get(x.track_id)
                if j is not None:
                    hit.append((j, 0 if x.end == BEGIN else 1))
            self._exits_of[key] = hit
        return hit

    def __post_init__(self) -> None:
        self._names = [""] * len(self.index)
        for t, i in self.index.items():
            self._names[i] = t

    def clear(self) -> None:
        """Forget the cached searches (a benchmark's cold start)."""
        self._cache.clear()

    def search(self, track: int, end: int, cutoff: float) -> _Search:
        """Tracks reachable leaving ``track`` at ``end`` (0 begin, 1 end) within ``cutoff`` m:
        state (track, entry end) → length of the tracks passed whole before it."""
        hit = self._cache.get((track, end))
        if hit is not None:
            if hit.cutoff >= cutoff:
                return hit
            cutoff = max(cutoff, 2.0 * hit.cutoff)  # grow geometrically: few searches again
        dist: dict[tuple[int, int], float] = {}
        pred: dict[tuple[int, int], tuple[int, int] | None] = {}
        heap: list[tuple[float, tuple[int, int], tuple[int, int] | None]] = [
            (0.0, s, None) for s in self._exits(track, end)
        ]
        heapq.heapify(heap)
        while heap:
            d, state, before = heapq.heappop(heap)
            if state in dist:
                continue
            dist[state], pred[state] = d, before
            nd = d + float(self.length_m[state[0]])
            if nd > cutoff:
                continue
            for nxt in self._exits(state[0], 1 - state[1]):
                if nxt not in dist:
                    heapq.heappush(heap, (nd, nxt, state))
        found = _Search(cutoff, dist, pred)
        self._cache[(track, end)] = found
        return found

    def end_to_end(self, a: I64, b: I64, cutoff: F64) -> F64:
        """``D[k, e, e']`` for track pairs (a[k], b[k]): shape (n, 2, 2), inf where no route
        within ``cutoff[k]``."""
        out = np.full((len(a), 2, 2), np.inf)
        reach: dict[int, float] = {}
        for ta, c in zip(a.tolist(), cutoff.tolist(), strict=True):
            reach[ta] = max(reach.get(ta, 0.0), c)  # one search per source end, at its largest cutoff
        found = {ta: (self.search(ta, 0, c).dist, self.search(ta, 1, c).dist) for ta, c in reach.items()}
        for k, (ta, tb) in enumerate(zip(a.tolist(), b.tolist(), strict=True)):
            d0, d1 = found[ta]
            out[k, 0, 0], out[k, 0, 1] = d0.get((tb, 0), np.inf), d0.get((tb, 1), np.inf)
            out[k, 1, 0], out[k, 1, 1] = d1.get((tb, 0), np.inf), d1.get((tb, 1), np.inf)
        return out

    def passed(self, a: int, e: int, b: int, e2: int) -> list[int]:
        """The tracks passed whole between leaving ``a`` at ``e`` and entering ``b`` at ``e2``
        (in travel order; a route found by :meth:`search` before)."""
        s = self._cache[(a, e)]
        out: list[int] = []
        step = s.pred.get((b, e2))
        while step is not None:
            out.append(step[0])
            step = s.pred.get(step)
        return out[::-1]


def route_distances(
    routes: Routes, t1: I64, s1: F64, t2: I64, s2: F64, cutoff: F64
) -> tuple[F64, npt.NDArray[np.int8]]:
    """Route distance per pair (module docstring; inf beyond ``cutoff`` or without a route)
    and the exit/entry ends taken (code 2·e + e', −1 on the same track)."""
    n = len(t1)
    route = np.full(n, np.inf)
    ends = np.full(n, -1, dtype=np.int8)
    same = t1 == t2
    route[same] = np.abs(s2[same] - s1[same])
    diff = np.flatnonzero(~same)
    if not len(diff):
        return route, ends
    key = t1[diff] * (len(routes.length_m) + 1) + t2[diff]
    uniq, inv = np.unique(key, return_inverse=True)
    cut = np.zeros(len(uniq))
    np.maximum.at(cut, inv, cutoff[diff])
    ua, ub = uniq // (len(routes.length_m) + 1), uniq % (len(routes.length_m) + 1)
    d = routes.end_to_end(ua, ub, cut)[inv]  # (m, 2, 2)
    la, lb = routes.length_m[t1[diff]], routes.length_m[t2[diff]]
    leave = np.stack([s1[diff], la - s1[diff]], axis=1)  # to begin, to end
    enter = np.stack([s2[diff], lb - s2[diff]], axis=1)
    total = np.maximum(leave, 0.0)[:, :, None] + d + np.maximum(enter, 0.0)[:, None, :]
    flat = total.reshape(len(diff), 4)
    best = np.argmin(flat, axis=1)
    route[diff] = flat[np.arange(len(diff)), best]
    ends[diff] = best.astype(np.int8)
    route[route > cutoff] = np.inf
    return route, ends
