"""Connections and switches at the nodes where tracks meet (SPEC §8.1; OSM tagging:
``railway=switch`` with ``railway:switch``, ``railway:turnout_side``, ``railway:radius``,
``railway:maxspeed:diverging``, ``ref``; ``railway=railway_crossing``).

The ends meeting at a node (directions d pointing *away* from the node along each track,
:func:`~dbtools.interchange.osm_split.end_frame`):

* **1 end** — a dead end; a ``railway=buffer_stop`` there marks it (``tracks``'
  ``begin_buffer_stop``/``end_buffer_stop``).
* **2 ends** — a plain joint: one connection ``both``, no switch (a switch node with only
  two tracks is reported: its third track is not in the file). A buffer stop between two
  tracks (OSM maps the buffer's own stub as a way beyond it): both ends marked, joined
  ``none``.
* **3 ends** — a point switch (tagged or not — an untagged junction is reported). The toe is
  the end whose direction is opposite the two others: the one with the smallest
  dᵢ·dⱼ + dᵢ·dₖ. Seen from the toe (travel direction t = −d_toe) the branch b is *left* of the
  other branch c when the cross product d_c × d_b = c_x b_y − c_y b_x > 0 (x east, y north:
  b lies counter-clockwise of c). Ports a1 toe, b1 left, b2 right; connections toe↔branch
  ``both``, branch↔branch ``none``. ``diverging_side`` from ``railway:turnout_side``; where
  untagged, guessed: the branch turning more from t (smaller t·d) diverges. A tagged side
  that the geometry contradicts by more than :data:`SIDE_MARGIN_DEG` is reported.
* **4 ends** with ``railway=railway_crossing`` or ``railway:switch=single_slip|double_slip``
  — a crossing or slip: a1 any end, b1 the end most opposite a1, b2 the remaining end on
  b1's side (d_b1·d > 0), a2 the last; the routes of :data:`schemas.network.SWITCH_ROUTES`
  ``both``, every other pair ``none``. Which diagonal of a single slip has the slip route
  OSM does not say: A1–B2 is assumed (reported).
* **4 ends with ``railway=switch``** and no slip tag (``railway:switch`` missing or
  ``default``) whose directions form two sides of two ends each (:func:`two_sides`): two
  tracks cross at a node with switch blades — a slip. Which one OSM does not say: imported as
  a *double slip* (every route from one side to the other; which end pairs count as straight
  through then does not matter; a route assumed costs the matcher an extra candidate, a route
  missing loses the train), reported (``osm.switch_inferred``). Without two straight pairs: as *any other*.
* **any other** — no switch row; every pair of ends whose directions are opposite within
  60° (dᵢ·dⱼ < −½) is joined ``both``, the others ``none`` (reported).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dbtools.interchange.osm_read import OsmNode
from schemas.enums import Navigability, Severity, SwitchType
from schemas.findings import Finding
from schemas.network import SWITCH_PORTS, SWITCH_ROUTES

#: A tagged turnout side contradicted by the geometry by more than this is reported [deg].
SIDE_MARGIN_DEG = 1.0
#: Opposite directions: d_i·d_j below this (angle above 120°).
OPPOSITE = -0.5
BOTH, NONE = Navigability.BOTH.value, Navigability.NONE.value
SLIPS = {"single_slip": SwitchType.SINGLE_SLIP, "double_slip": SwitchType.DOUBLE_SLIP}


@dataclass
class Junctions:
    """Rows of connections and switches, buffer-stop ends and findings."""

    connections: list[dict[str, Any]] = field(default_factory=list)
    switches: list[dict[str, Any]] = field(default_factory=list)
    stops: set[tuple[str, str]] = field(default_factory=set)
    findings: list[Finding] = field(default_factory=list)
    guessed_sides: int = 0
    dead_ends: int = 0
    untagged: list[int] = field(default_factory=list)
    runs_on: list[tuple[tuple[str, str], tuple[str, str]]] = field(default_factory=list)
    """Track ends a line runs straight on through: plain joints and the straight routes of
    crossings and slips (A1–B1, A2–B2), for the km chains."""
    points: list[tuple[tuple[str, str], tuple[str, str], tuple[str, str]]] = field(default_factory=list)
    """Point switches' (toe, through branch, diverging branch) ends; the through branch is the
    one not on the diverging side (the left one of a wye). Which branch the line runs on is
    decided with the lines (:func:`dbtools.interchange.osm_km.switch_links`)."""

    def warn(self, rule: str, node: int, message: str, **keys: Any) -> None:
        self.findings.append(
            Finding(rule, Severity.WARNING, "switches", message, keys={"element": f"node/{node}", **keys})
        )


End = tuple[str, str, float, float]  # track, end, dx, dy


def _connect(j: Junctions, a: End, b: End, nav: str, switch: str | None) -> None:
    j.connections.append(
        {"track_a": a[0], "end_a": a[1], "track_b": b[0], "end_b": b[1], "navigability": nav, "switch_id": switch}
    )


def _dot(a: End, b: End) -> float:
    return a[2] * b[2] + a[3] * b[3]


def _number(text: str | None) -> float | None:
    """The leading number of a tag value ("500", "500 m", "100;60" → first), else None."""
    m = re.match(r"\s*(\d+(?:\.\d+)?)", text or "")
    return float(m.group(1)) if m else None


def _point(j: Junctions, node: int, tags: dict[str, str], ends: list[End], lat: float, lon: float) -> None:
    sums = [sum(_dot(ends[i], ends[k]) for k in range(3) if k != i) for i in range(3)]
    toe_i = int(np.argmin(sums))
    toe = ends[toe_i]
    c, b = (ends[k] for k in range(3) if k != toe_i)
    cross = c[2] * b[3] - c[3] * b[2]
    left, right = (b, c) if cross > 0 else (c, b)
    sid = f"n{node}"
    t = (-toe[2], -toe[3])
    turn = [math.degrees(math.acos(max(-1.0, min(1.0, t[0] * e[2] + t[1] * e[3])))) for e in (left, right)]
    if max(turn) > 60.0:
        j.warn("osm.switch_geometry", node, f"a branch leaves the toe at {max(turn):.0f}°: toe/branches uncertain")
    geo_side = "left" if turn[0] > turn[1] else "right"
    side = tags.get("railway:turnout_side")
    if side not in ("left", "right"):
        if tags.get("railway:switch") != "wye":
            side = geo_side
            j.guessed_sides += 1
        else:
            side = None
    elif side != geo_side and abs(turn[0] - turn[1]) > SIDE_MARGIN_DEG:
        j.warn(
            "osm.turnout_side",
            node,
            f"railway:turnout_side={side} but the {geo_side} branch turns more "
            f"({turn[0]:.1f}° left, {turn[1]:.1f}° right): the tag is kept",
        )
    radius = _number(tags.get("railway:radius") or tags.get("railway:switch:radius"))
    speed = _number(tags.get("railway:maxspeed:diverging"))
    number = _number(tags.get("railway:switch:number"))
    j.switches.append(
        {
            "switch_id": sid,
            "type": SwitchType.POINT.value,
            "a1_track": toe[0],
            "a1_end": toe[1],
            "b1_track": left[0],
            "b1_end": left[1],
            "b2_track": right[0],
            "b2_end": right[1],
            "diverging_side": side,
            "switch_number": number if number is not None and 1.0 <= number <= 100.0 else None,
            "diverging_radius_m": radius if radius is not None and radius >= 20.0 else None,
            "diverging_speed_kmh": speed if speed is not None and speed <= 400.0 else None,
            "lat": lat,
            "lon": lon,
            "name": tags.get("ref") or tags.get("name"),
        }
    )
    through, diverging = (right, left) if side == "left" else (left, right)
    j.points.append(((toe[0], toe[1]), (through[0], through[1]), (diverging[0], diverging[1])))
    _connect(j, toe, left, BOTH, sid)
    _connect(j, toe, right, BOTH, sid)
    _connect(j, left, right, NONE, sid)


def _crossing(
    j: Junctions, node: int, kind: SwitchType, tags: dict[str, str], ends: list[End], ll: tuple[float, float]
) -> None:
    a1 = ends[0]
    rest = ends[1:]
    b1 = min(rest, key=lambda e: _dot(a1, e))
    others = [e for e in rest if e is not b1]
    b2 = max(others, key=lambda e: _dot(b1, e))
    a2 = others[0] if others[1] is b2 else others[1]
    if _dot(a1, b1) > OPPOSITE or _dot(a2, b2) > OPPOSITE:
        j.warn("osm.switch_geometry", node, f"{kind.value}: the two routes are not straight through (uncertain ports)")
    if kind == SwitchType.SINGLE_SLIP:
        j.warn("osm.single_slip", node, "single slip: OSM does not say which diagonal has the slip; A1–B2 assumed")
    sid = f"n{node}"
    port = {"a1": a1, "b1": b1, "a2": a2, "b2": b2}
    row: dict[str, Any] = {"switch_id": sid, "type": kind.value, "lat": ll[0], "lon": ll[1]}
    row["name"] = tags.get("ref") or tags.get("name")
    for name in SWITCH_PORTS[kind]:
        row[f"{name}_track"], row[f"{name}_end"] = port[name][0], port[name][1]
    j.switches.append(row)
    j.runs_on += [((a1[0], a1[1]), (b1[0], b1[1])), ((a2[0], a2[1]), (b2[0], b2[1]))]
    routes = {frozenset(r) for r in SWITCH_ROUTES[kind]}
    names = list(SWITCH_PORTS[kind])
    for i, p in enumerate(names):
        for q in names[i + 1 :]:
            _connect(j, port[p], port[q], BOTH if frozenset((p, q)) in routes else NONE, sid)


def _generic(j: Junctions, node: int, ends: list[End], why: str) -> None:
    j.warn("osm.node_degree", node, f"{len(ends)} track ends meet here ({why}): no switch row; opposite ends joined")
    for i, a in enumerate(ends):
        for b in ends[i + 1 :]:
            _connect(j, a, b, BOTH if _dot(a, b) < OPPOSITE else NONE, None)


def _kind_of(node: OsmNode | None, degree: int) -> SwitchType | None:
    if node is None:
        return SwitchType.POINT if degree == 3 else None
    if degree == 3 and node.kind in ("switch", "railway_crossing"):
        return SwitchType.POINT
    if degree == 4 and node.kind == "railway_crossing":
        return SwitchType.CROSSING
    if degree == 4 and node.kind == "switch":
        return SLIPS.get(node.tags.get("railway:switch", ""))
    return SwitchType.POINT if degree == 3 else None


def two_sides(ends: list[End]) -> bool:
    """Whether 4 ends form two sides of two ends each — within a side the directions agree
    (dᵢ·dⱼ > −:data:`OPPOSITE`, under 60° apart), across the sides they are opposite
    (dᵢ·dⱼ < :data:`OPPOSITE`): two tracks crossing at a node at a small angle."""
    same = [[k for k in range(4) if k != i and _dot(ends[i], ends[k]) > -OPPOSITE] for i in range(4)]
    if any(len(s) != 1 or same[s[0]] != [i] for i, s in enumerate(same)):
        return False
    mate = same[0][0]
    return all(_dot(ends[i], ends[k]) < OPPOSITE for i in (0, mate) for k in range(4) if k not in (0, mate))


def _at_node(j: Junctions, node_id: int, node: OsmNode | None, ends: list[End], ll: tuple[float, float]) -> None:
    deg = len(ends)
    tags = node.tags if node is not None else {}
    kind = _kind_of(node, deg)
    if deg == 2:
        if node is not None and node.kind in ("switch", "railway_crossing"):
            j.warn(
                "osm.switch_incomplete",
                node_id,
                f"railway={node.kind} joins only two tracks (the rest is not in the file)",
            )
        _connect(j, ends[0], ends[1], BOTH, None)
        j.runs_on.append(((ends[0][0], ends[0][1]), (ends[1][0], ends[1][1])))
    elif kind == SwitchType.POINT:
        if node is None or node.kind != "switch":
            j.untagged.append(node_id)
        elif tags.get("railway:switch") in SLIPS:
            j.warn(
                "osm.switch_ports",
                node_id,
                f"railway:switch={tags['railway:switch']} with 3 tracks: imported as a point switch",
            )
        _point(j, node_id, tags, ends, *ll)
    elif kind is not None:
        _crossing(j, node_id, kind, tags, ends, ll)
    elif deg == 4 and node is not None and node.kind == "switch" and two_sides(ends):
        j.warn(
            "osm.switch_inferred",
            node_id,
            f"railway=switch where two tracks cross (4 ends, two on each side) without "
            f"railway:switch=single_slip|double_slip ({tags.get('railway:switch', 'no railway:switch')}): "
            "imported as a double slip (both slip routes assumed; tag the slip type)",
        )
        _crossing(j, node_id, SwitchType.DOUBLE_SLIP, tags, ends, ll)
    else:
        what = f"railway={node.kind}" if node is not None else "untagged"
        _generic(
            j, node_id, ends, what + (f", railway:switch={tags['railway:switch']}" if "railway:switch" in tags else "")
        )


def _dead_end(j: Junctions, nid: int, node: OsmNode | None, end: End) -> None:
    j.dead_ends += 1
    if node is not None and node.kind == "buffer_stop":
        j.stops.add((end[0], end[1]))
    elif node is not None and node.kind in ("switch", "railway_crossing"):
        j.warn("osm.switch_incomplete", nid, f"railway={node.kind} at the end of a single track: no switch")


def junctions(
    ends: pd.DataFrame, track_ids: list[str], nodes: dict[int, OsmNode], node_ll: dict[int, tuple[float, float]]
) -> Junctions:
    """Connections, switches and buffer-stop ends at every node (module doc)."""
    j = Junctions()
    order = ends.sort_values(["node", "piece", "end"], kind="stable")
    node_col = order["node"].to_numpy()
    rows = list(
        zip(
            order["piece"].to_numpy(),
            order["end"].to_numpy(),
            order["dx"].to_numpy(),
            order["dy"].to_numpy(),
            strict=True,
        )
    )
    bounds = np.flatnonzero(np.diff(node_col)) + 1
    for lo, hi in zip(np.concatenate(([0], bounds)), np.concatenate((bounds, [len(rows)])), strict=True):
        nid = int(node_col[lo])
        here: list[End] = [(track_ids[int(p)], str(e), float(dx), float(dy)) for p, e, dx, dy in rows[lo:hi]]
        node = nodes.get(nid)
        if len(here) == 1:
            _dead_end(j, nid, node, here[0])
        elif node is not None and node.kind == "buffer_stop" and len(here) == 2:
            j.stops |= {(here[0][0], here[0][1]), (here[1][0], here[1][1])}
            j.warn("osm.buffer_stop", nid, "buffer stop between two tracks: both ends marked, joined 'none'")
            _connect(j, here[0], here[1], NONE, None)
        else:
            if node is not None and node.kind == "buffer_stop":
                j.warn(
                    "osm.buffer_stop", nid, f"buffer stop where {len(here)} track ends meet: not a track end, ignored"
                )
            _at_node(j, nid, node, here, node_ll[nid])
    return j
