"""The ``[network]`` scenario table: a run over a network's tracks instead of one line/track.

Set ``tracks`` (the tracks in travel order) or ``from_track``/``to_track`` (with ``via``:
resolved by :mod:`fieldlogs.simulate.netroute`) and the run follows that route through its
switches; every other table of the scenario keeps its meaning. Positions on the network are
``[track_id, pos_m]`` pairs, ``pos_m`` the distance along the track from its begin (as in the
``track_points`` table and the truth's ``pos_m``). The knobs are documented with their units in
``fieldlogs/simulate/scenarios/default.toml``; :func:`check_network` holds the range checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class NetworkCfg:
    tracks: tuple[str, ...] = ()
    from_track: str = ""
    to_track: str = ""
    via: tuple[str, ...] = ()
    direction: int = 0
    points: tuple[tuple[str, float], ...] = ()
    gnss_outages: tuple[tuple[str, float, float], ...] = ()
    multipath: tuple[tuple[str, float, float, float], ...] = ()
    multipath_search_m: float = 25.0
    switch_speed_kmh: float = 0.0
    train_length_m: float = 60.0

    @property
    def active(self) -> bool:
        """Whether the run is routed over the network (else: one line/track as ``[route]``)."""
        return bool(self.tracks or self.from_track)


def check_network(n: NetworkCfg) -> tuple[str, str] | None:
    """(dotted key, message) of the first bad ``[network]`` knob, or None."""
    if n.tracks and (n.from_track or n.to_track or n.via):
        return "network.tracks", "give either tracks or from_track/to_track/via, not both"
    if bool(n.from_track) != bool(n.to_track):
        return "network.from_track", "from_track and to_track go together"
    if n.direction not in (-1, 0, 1):
        return "network.direction", "must be 1 (begin → end of the first track), -1 or 0 (automatic)"
    for i, (_, pos) in enumerate(n.points):
        if not (math.isfinite(pos) and pos >= 0):
            return f"network.points[{i}]", f"pos_m must be ≥ 0, got {pos}"
    ranges = [("network.gnss_outages", i, a, b) for i, (_, a, b) in enumerate(n.gnss_outages)]
    ranges += [("network.multipath", i, a, b) for i, (_, a, b, _) in enumerate(n.multipath)]
    for key, i, a, b in ranges:
        if not (math.isfinite(a) and math.isfinite(b) and 0 <= a < b):
            return f"{key}[{i}]", f"needs [track_id, from_pos_m, to_pos_m] with 0 ≤ from < to, got [{a}, {b}]"
    return _check_values(n)


def _check_values(n: NetworkCfg) -> tuple[str, str] | None:
    """The numeric knobs of ``[network]``."""
    for i, m in enumerate(n.multipath):
        if not (math.isfinite(m[3]) and abs(m[3]) <= 100):
            return f"network.multipath[{i}]", f"bias_m must be within ±100 m, got {m[3]}"
    positive = {"network.multipath_search_m": n.multipath_search_m}
    non_negative = {"network.switch_speed_kmh": n.switch_speed_kmh, "network.train_length_m": n.train_length_m}
    for k, v in positive.items():
        if not (math.isfinite(v) and v > 0):
            return k, f"must be > 0, got {v}"
    for k, v in non_negative.items():
        if not (math.isfinite(v) and v >= 0):
            return k, f"must be ≥ 0, got {v}"
    return None
