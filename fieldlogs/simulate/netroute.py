"""A simulated run's route over the network: the tracks it runs, in travel order.

A route is a list of :class:`Leg` (track, direction of travel on it, the switch passed to
enter it). Given explicitly (``network.tracks``), every track must be entered from the one
before through a connection navigable that way (:func:`dbtools.topology.topology`: ``both``,
``AB``, ``BA``; never ``none``, the pair of a switch's two branches). Given by its ends
(``network.from_track``/``to_track``/``via``), it is the shortest navigable path by length:
Dijkstra over the states (track, direction), the cost of a step the length of the track
entered, one search per stretch between consecutive waypoints, each starting in the state the
last one ended in, so a ``via`` track that is a facing switch's branch chooses that branch.
"""

from __future__ import annotations

import heapq
from dataclasses import dataclass

from dbtools.network import Network
from dbtools.topology import BEGIN, END, Topology, topology
from fieldlogs.simulate.scenario import ScenarioError
from fieldlogs.simulate.scenario_net import NetworkCfg
from schemas.frames import suggest


@dataclass(frozen=True)
class Leg:
    track_id: str
    direction: int
    """+1: travel from the track's begin to its end; −1 the other way."""
    switch_in: str | None = None
    """The switch passed on entering this track from the previous leg."""


State = tuple[str, int]


def _fail(cfg_source: str, key: str, message: str) -> ScenarioError:
    return ScenarioError(message, path=cfg_source, key=key)


def _known(topo: Topology, track_id: str, key: str, source: str) -> None:
    ids = topo.track_ids
    if track_id not in set(ids):
        hint = suggest(track_id, ids)
        extra = f" (did you mean '{hint}'?)" if hint else ""
        raise _fail(source, key, f"track '{track_id}' is not in the network{extra}")


def _why_not(topo: Topology, a: str, d: int, b: str) -> str:
    """Why track ``b`` cannot be entered leaving ``a`` in direction ``d``."""
    end = END if d > 0 else BEGIN
    for other, _, nav in topo.joined.get((a, end), []):
        if other == b:
            return f"the connection of {a} ({end}) to {b} is not navigable that way (navigability {nav})"
    return f"{b} is not connected to the {end} of {a}"


def explicit_route(topo: Topology, cfg: NetworkCfg, source: str) -> list[Leg]:
    """The legs of ``network.tracks`` (see module docstring)."""
    for i, t in enumerate(cfg.tracks):
        _known(topo, t, f"network.tracks[{i}]", source)
    first = cfg.tracks[0]
    if cfg.direction:
        d0 = cfg.direction
    elif len(cfg.tracks) > 1:
        ok = [d for d in (1, -1) if any(e.track_id == cfg.tracks[1] for e in topo.next_tracks(first, d))]
        if not ok:
            raise _fail(source, "network.tracks[1]", f"{cfg.tracks[1]}: {_why_not(topo, first, 1, cfg.tracks[1])}")
        d0 = ok[0]
    else:
        pts = [p for t, p in cfg.points if t == first]
        d0 = -1 if len(pts) >= 2 and pts[1] < pts[0] else 1
    legs = [Leg(first, d0)]
    for i, t in enumerate(cfg.tracks[1:], start=1):
        prev = legs[-1]
        step = next((e for e in topo.next_tracks(prev.track_id, prev.direction) if e.track_id == t), None)
        if step is None:
            raise _fail(source, f"network.tracks[{i}]", f"{t}: {_why_not(topo, prev.track_id, prev.direction, t)}")
        legs.append(Leg(t, step.direction, step.switch_id))
    return legs


def _dijkstra(topo: Topology, lengths: dict[str, float], start: State, goal: str) -> tuple[float, list[Leg]] | None:
    """Shortest navigable legs after ``start`` until the first state on track ``goal``."""
    if start[0] == goal:
        return 0.0, []
    best: dict[State, float] = {start: 0.0}
    back: dict[State, tuple[State, str | None]] = {}
    heap: list[tuple[float, State]] = [(0.0, start)]
    while heap:
        cost, state = heapq.heappop(heap)
        if cost > best.get(state, float("inf")):
            continue
        if state[0] == goal:
            legs: list[Leg] = []
            while state != start:
                prev, switch = back[state]
                legs.append(Leg(state[0], state[1], switch))
                state = prev
            return cost, legs[::-1]
        for e in topo.next_tracks(*state):
            nxt = (e.track_id, e.direction)
            c = cost + lengths.get(e.track_id, 0.0)
            if c < best.get(nxt, float("inf")):
                best[nxt], back[nxt] = c, (state, e.switch_id)
                heapq.heappush(heap, (c, nxt))
    return None


def shortest_route(topo: Topology, cfg: NetworkCfg, source: str) -> list[Leg]:
    """The legs from ``from_track`` through ``via`` to ``to_track`` (see module docstring)."""
    _known(topo, cfg.from_track, "network.from_track", source)
    _known(topo, cfg.to_track, "network.to_track", source)
    for i, t in enumerate(cfg.via):
        _known(topo, t, f"network.via[{i}]", source)
    lengths = dict(zip(topo.track_ids, topo.tracks["length_m"].astype(float), strict=True))
    goals = [*cfg.via, cfg.to_track]
    found: list[tuple[float, list[Leg]]] = []
    for d0 in (cfg.direction,) if cfg.direction else (1, -1):
        legs, total = [Leg(cfg.from_track, d0)], 0.0
        for goal in goals:
            step = _dijkstra(topo, lengths, (legs[-1].track_id, legs[-1].direction), goal)
            if step is None:
                break
            total += step[0]
            legs += step[1]
        else:
            found.append((total, legs))
    if not found:
        way = " via " + ", ".join(cfg.via) if cfg.via else ""
        raise _fail(
            source,
            "network.to_track",
            f"no navigable route from {cfg.from_track} to {cfg.to_track}{way} (connections of navigability "
            "'none' are never crossed)",
        )
    return min(found, key=lambda f: f[0])[1]


def resolve_route(network: Network, cfg: NetworkCfg, source: str) -> list[Leg]:
    """The route of the ``[network]`` table (explicit tracks or shortest path)."""
    topo = topology(network)
    return explicit_route(topo, cfg, source) if cfg.tracks else shortest_route(topo, cfg, source)
