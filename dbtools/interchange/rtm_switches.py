"""Point switches inferred from RailTopoModel netrelations (a RailTopoModel GeoJSON network
has no switch objects: a switch is only the pattern of relations at a node).

Rule: a netelement end T is the **toe** of a point switch when exactly two relations that
are navigable (both, AB or BA) join it to two ends X and Y of two other netelements, and a
relation of navigability ``none`` joins X and Y (the two branches, between which no train
may pass). The three relations get the switch's id (``switch:<toe netelement>:<begin|end>``).
Where a relation would belong to two such patterns (double switches meeting at one node)
the toe whose id sorts first keeps it and the other is reported, not inferred.

**Left and right** (OSRD ports: A1 toe, B1 left, B2 right, seen from the toe towards the
branches): the direction of each branch leaving the node is the forward azimuth α from the
node to the point :data:`REACH_M` metres along it, as a unit vector d = (sin α, cos α) in
the local east–north plane at the node. With the cross product z = d_X × d_Y = d_X.e d_Y.n −
d_X.n d_Y.e, Y lies counter-clockwise of X — to the left — when z > 0. **Diverging side**:
the branch turning more from the toe track's own direction through the node (the azimuth
into the toe track plus 180°) is the diverging one; none is named when both turn alike
(within :data:`SYMMETRIC_DEG`).
"""

from __future__ import annotations

import math
from collections import defaultdict
from dataclasses import dataclass, field
from typing import Any

from dbtools.interchange.polyline import azimuth_away
from dbtools.interchange.rtm_read import NetElement, NetRelation
from schemas.enums import Navigability, Severity, Side, SwitchType, TrackEnd
from schemas.findings import Finding

#: How far along a branch its direction is taken [m].
REACH_M = 30.0
#: Branches whose turn from the toe direction differs by less than this are symmetric [deg].
SYMMETRIC_DEG = 0.5
End = tuple[str, int]


def end_name(pos: int) -> str:
    return TrackEnd.BEGIN.value if pos == 0 else TrackEnd.END.value


def switch_id(toe: End) -> str:
    return f"switch:{toe[0]}:{end_name(toe[1])}"


@dataclass
class Inferred:
    switches: list[dict[str, Any]] = field(default_factory=list)
    by_relation: dict[frozenset[End], str] = field(default_factory=dict)
    """The ends of a relation → the id of the switch it belongs to."""
    findings: list[Finding] = field(default_factory=list)


def _turn(a: float, b: float) -> float:
    """Signed difference b − a of two azimuths, in (−180°, 180°]."""
    d = (b - a) % 360.0
    return d - 360.0 if d > 180.0 else d


def _sides(elements: dict[str, NetElement], toe: End, x: End, y: End) -> tuple[End, End, str | None, str | None]:
    """(left branch, right branch, diverging side, problem) — module doc."""
    az = {e: azimuth_away(elements[e[0]].line, e[1] == 1, REACH_M) for e in (x, y)}
    dx = (math.sin(math.radians(az[x])), math.cos(math.radians(az[x])))
    dy = (math.sin(math.radians(az[y])), math.cos(math.radians(az[y])))
    z = dx[0] * dy[1] - dx[1] * dy[0]
    if abs(z) < 1e-9:
        return x, y, None, "both branches leave the node in the same direction: left/right not known"
    left, right = (y, x) if z > 0 else (x, y)
    through = (azimuth_away(elements[toe[0]].line, toe[1] == 1, REACH_M) + 180.0) % 360.0
    turn_l, turn_r = abs(_turn(through, az[left])), abs(_turn(through, az[right]))
    if abs(turn_l - turn_r) < SYMMETRIC_DEG:
        return left, right, None, None
    return left, right, (Side.LEFT.value if turn_l > turn_r else Side.RIGHT.value), None


def _navigable(rel: NetRelation) -> bool:
    return rel.navigability != Navigability.NONE.value


def infer_switches(elements: dict[str, NetElement], relations: list[NetRelation], file: str) -> Inferred:
    """Point switches by the rule of the module doc."""
    at: dict[End, list[tuple[End, NetRelation]]] = defaultdict(list)
    by_ends: dict[frozenset[End], NetRelation] = {}
    for r in relations:
        at[(r.a, r.pos_a)].append(((r.b, r.pos_b), r))
        at[(r.b, r.pos_b)].append(((r.a, r.pos_a), r))
        by_ends[r.ends] = r
    out = Inferred()
    for toe in sorted(at):
        nav = [(other, r) for other, r in at[toe] if _navigable(r)]
        if len(nav) != 2:
            continue
        (x, rx), (y, ry) = nav
        between = by_ends.get(frozenset((x, y)))
        if x[0] == y[0] or toe[0] in (x[0], y[0]) or between is None or _navigable(between):
            continue
        keys = [rx.ends, ry.ends, between.ends]
        taken = [out.by_relation[k] for k in keys if k in out.by_relation]
        sid = switch_id(toe)
        if taken:
            msg = f"the relations at {toe[0]} {end_name(toe[1])} also belong to {taken[0]}: no switch inferred here"
            out.findings.append(
                Finding("rtm.switch_ambiguous", Severity.WARNING, "switches", msg, keys={"switch_id": sid}, file=file)
            )
            continue
        left, right, side, problem = _sides(elements, toe, x, y)
        if problem:
            out.findings.append(
                Finding("rtm.switch_sides", Severity.WARNING, "switches", problem, keys={"switch_id": sid}, file=file)
            )
        line = elements[toe[0]].line
        i = -1 if toe[1] == 1 else 0
        out.switches.append(
            {
                "switch_id": sid,
                "type": SwitchType.POINT.value,
                **_port("a1", toe),
                **_port("b1", left),
                **_port("b2", right),
                "diverging_side": side,
                "lat": float(line.lat[i]),
                "lon": float(line.lon[i]),
                "name": "inferred from netrelations",
            }
        )
        for k in keys:
            out.by_relation[k] = sid
    return out


def _port(name: str, end: End) -> dict[str, str]:
    return {f"{name}_track": end[0], f"{name}_end": end_name(end[1])}
