"""Many seeded runs over a network's switches, for accuracy statistics (issue 31):
:func:`network_runs` returns scenario overrides (the ``[network]`` table and the rest, as
:func:`~fieldlogs.simulate.scenario.scenario_from_dict` takes them) that a bench simulates.

Run i draws, from ``np.random.default_rng([seed, i])`` (so run i does not depend on n):

* a **feature track** to pass — uniformly among the tracks that are not ``main`` (crossovers,
  station loops, sidings) and the main tracks at a switch's diverging port (branch lines):
  every run crosses a junction, crossover or station loop;
* a direction on it and a route through it: random walks over the navigable topology
  (:func:`dbtools.topology.topology`) backwards and forwards from it until 0.8–3 km of track
  lie on either side (or a track end stops the walk), checked with
  :func:`fieldlogs.simulate.netroute.explicit_route` (a walk that is not navigable forwards is
  drawn again);
* the start and end 0.5–2.5 km before and after the feature track (within the walk);
* its GNSS: 20 % without GPS, 30 % with a tunnel of 200–600 m somewhere on the route, 15 %
  with multipath (1.5–4 m toward the neighbouring track over 300–1000 m), the rest open sky;
* 15 % turn back 100–400 m after the feature track and retrace (a cab change);
* the cab end, line speed 60–110 km/h, and 0–2 slips and slides.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from dbtools.network import Network
from dbtools.topology import Topology, all_tracks, topology
from fieldlogs.simulate.netroute import explicit_route
from fieldlogs.simulate.scenario import ScenarioError
from fieldlogs.simulate.scenario_net import NetworkCfg
from schemas.enums import Side, TrackKind

#: Length of track drawn on either side of the feature track [m] and the start/end distance.
WALK_M = (800.0, 3000.0)
APPROACH_M = (500.0, 2500.0)
ATTEMPTS = 50


@dataclass(frozen=True)
class _Walk:
    tracks: list[str]
    directions: list[int]


def feature_tracks(network: Network) -> list[str]:
    """Tracks whose passing means a switch's diverging way: not main, or a main track at a
    point switch's diverging port (a branch line)."""
    tracks = all_tracks(network)
    out = [str(t) for t, k in zip(tracks["track_id"], tracks["kind"], strict=True) if k != TrackKind.MAIN.value]
    sw = network.switches
    for side, port in ((Side.LEFT.value, "b1_track"), (Side.RIGHT.value, "b2_track")):
        div = sw.loc[sw["diverging_side"] == side, port].dropna().astype(str)
        out += [t for t in div if t not in out]
    return sorted(set(out))


def _walk(
    topo: Topology, lengths: dict[str, float], start: str, d: int, need: float, rng: np.random.Generator
) -> _Walk:
    """Tracks after ``start`` travelling ``d`` until ``need`` metres (or an end)."""
    tracks, dirs, got = [], [], 0.0
    cur, cd = start, d
    while got < need:
        nxt = topo.next_tracks(cur, cd)
        if not nxt:
            break
        e = nxt[int(rng.integers(len(nxt)))]
        cur, cd = e.track_id, e.direction
        if cur in tracks:
            break
        tracks.append(cur)
        dirs.append(cd)
        got += lengths.get(cur, 0.0)
    return _Walk(tracks, dirs)


def _route(
    topo: Topology, lengths: dict[str, float], feature: str, rng: np.random.Generator
) -> tuple[list[str], int] | None:
    """Tracks in travel order through ``feature`` and the index of ``feature`` in them."""
    d = 1 if rng.random() < 0.5 else -1
    ahead = _walk(topo, lengths, feature, d, float(rng.uniform(*WALK_M)), rng)
    behind = _walk(topo, lengths, feature, -d, float(rng.uniform(*WALK_M)), rng)
    tracks = [*behind.tracks[::-1], feature, *ahead.tracks]
    if len(set(tracks)) != len(tracks) or len(tracks) < 2:
        return None
    try:
        explicit_route(topo, NetworkCfg(tracks=tuple(tracks)), "<network_runs>")
    except ScenarioError:
        return None
    return tracks, len(behind.tracks)


def _place(
    tracks: list[str], lengths: dict[str, float], k: int, rng: np.random.Generator, topo: Topology
) -> list[list[Any]]:
    """Start before and end after track k, as [track_id, pos_m] points (turnbacks retrace)."""
    legs = explicit_route(topo, NetworkCfg(tracks=tuple(tracks)), "<network_runs>")
    starts = np.concatenate([[0.0], np.cumsum([lengths[t] for t in tracks])])
    lo, hi = starts[k], starts[k + 1]

    def point(rho: float) -> list[Any]:
        i = int(np.clip(np.searchsorted(starts, rho, side="right") - 1, 0, len(tracks) - 1))
        along = float(np.clip(rho - starts[i], 1.0, lengths[tracks[i]] - 1.0))
        pos = along if legs[i].direction > 0 else lengths[tracks[i]] - along
        return [tracks[i], round(pos, 1)]

    a = max(lo - float(rng.uniform(*APPROACH_M)), min(20.0, lo / 2))
    b = min(hi + float(rng.uniform(*APPROACH_M)), starts[-1] - min(20.0, (starts[-1] - hi) / 2))
    if rng.random() < 0.15:  # turn back after the feature and retrace
        turn = min(hi + float(rng.uniform(100.0, 400.0)), b)
        return [point(a), point(turn), point(max(a + 50.0, lo - float(rng.uniform(200.0, 800.0))))]
    return [point(a), point(b)]


def _gnss(tracks: list[str], lengths: dict[str, float], rng: np.random.Generator) -> dict[str, Any]:
    u = rng.random()
    if u < 0.2:
        return {"sensors": {"gps": False}}
    t = tracks[int(rng.integers(len(tracks)))]
    span = float(rng.uniform(200.0, 600.0)) if u < 0.5 else float(rng.uniform(300.0, 1000.0))
    a = float(rng.uniform(0.0, max(lengths[t] - span, 0.0)))
    b = min(a + span, lengths[t])
    if b - a < 10.0:
        return {}
    if u < 0.5:
        return {"network": {"gnss_outages": [[t, round(a, 1), round(b, 1)]]}}
    if u < 0.65:
        return {"network": {"multipath": [[t, round(a, 1), round(b, 1), round(float(rng.uniform(1.5, 4.0)), 2)]]}}
    return {}


def network_runs(network: Network, n: int, seed: int) -> list[dict[str, Any]]:
    """``n`` scenario overrides over ``network``'s switches (module docstring); [] without any."""
    topo = topology(network)
    lengths = dict(zip(topo.track_ids, topo.tracks["length_m"].astype(float), strict=True))
    features = feature_tracks(network)
    if not features:
        return []
    out: list[dict[str, Any]] = []
    for i in range(n):
        rng = np.random.default_rng([seed, i])
        for _ in range(ATTEMPTS):
            feature = features[int(rng.integers(len(features)))]
            found = _route(topo, lengths, feature, rng)
            if found is not None:
                break
        else:
            raise ValueError(f"no navigable route through the network's switches found for run {i}")
        tracks, k = found
        gnss = _gnss(tracks, lengths, rng)
        net = {"tracks": tracks, "points": _place(tracks, lengths, k, rng, topo), **gnss.pop("network", {})}
        slips = int(rng.integers(0, 3))
        out.append(
            {
                "name": f"network run {i} through {feature}",
                "seed": int(seed * 100_003 + i) % 2**31,
                "run": {"run_id": f"NET-{seed}-{i:04d}"},
                "route": {"start_cab": "F" if rng.random() < 0.5 else "R"},
                "running": {"line_speed_kmh": round(float(rng.uniform(60.0, 110.0)), 1)},
                "slip": {"slips": slips, "slides": int(rng.integers(0, 3)), "on_grade_curve": False},
                "network": net,
                **gnss,
            }
        )
    return out


def feature_of(run: dict[str, Any]) -> str:
    """The feature track a run of :func:`network_runs` was drawn to pass."""
    return str(run["name"]).rsplit(" ", 1)[1]


__all__ = ["feature_of", "feature_tracks", "network_runs"]
