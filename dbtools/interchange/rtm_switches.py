"""Switches inferred from RailTopoModel netrelations (a RailTopoModel GeoJSON network has
no switch objects: a switch is only the pattern of relations at a node). Every relation
among a switch's ports gets its id ``switch:<netelement>:<begin|end>`` (of its A1 end).

**Slips** first: four ends P, Q, X, Y where a relation of navigability ``none`` joins P and
Q and another X and Y, and every navigable relation of each runs to the other pair (P and
Q each to X and/or Y, X and Y each to P and/or Q). All four joins: a **double slip**, A1 =
P (the end found first, in sorted order), A2 = Q, B1 the one of X and Y whose direction is
the straighter continuation of P's track (A1–B1 and A2–B2 are the crossing routes of OSRD's
ports), B2 the other. Three joins: a **single slip**, A1 the end with two (routes A1–B1,
A1–B2), A2 the end with one, B2 its partner (route A2–B2).

**Point switches** then, at the ends no slip holds: a netelement end T is the **toe** of a
point switch when exactly two relations that are navigable (both, AB or BA) join it to two
ends X and Y of two other netelements, and a relation of navigability ``none`` joins X and
Y (the two branches, between which no train may pass). Where a relation would belong to two
such patterns the toe whose id sorts first keeps it and the other is reported
(``rtm.switch_ambiguous``), not inferred.

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


@dataclass
class _Graph:
    """The relations at each end: navigable partners and the relation joining two ends."""

    nav: dict[End, set[End]] = field(default_factory=lambda: defaultdict(set))
    by_ends: dict[frozenset[End], NetRelation] = field(default_factory=dict)

    @classmethod
    def of(cls, relations: list[NetRelation]) -> _Graph:
        g = cls()
        for r in relations:
            g.by_ends[r.ends] = r
            if _navigable(r):
                g.nav[(r.a, r.pos_a)].add((r.b, r.pos_b))
                g.nav[(r.b, r.pos_b)].add((r.a, r.pos_a))
        return g

    def partners(self, e: End) -> set[End]:
        return self.nav.get(e, set())

    def barred(self, x: End, y: End) -> bool:
        """A relation of navigability none joins x and y."""
        r = self.by_ends.get(frozenset((x, y)))
        return r is not None and not _navigable(r)

    def keys(self, ends: tuple[End, ...]) -> list[frozenset[End]]:
        """The relations among these ends."""
        pairs = {frozenset((u, v)) for u in ends for v in ends if u != v}
        return sorted((k for k in pairs if k in self.by_ends), key=sorted)


def _slip(g: _Graph, elements: dict[str, NetElement], p: End) -> tuple[str, dict[str, End]] | None:
    """(type, ports) of a slip whose first end is p (module doc), else None."""
    xs = g.partners(p)
    if len(xs) != 2:
        return None
    x, y = sorted(xs)
    others = (g.partners(x) | g.partners(y)) - {p}
    if not g.barred(x, y) or len(others) != 1:
        return None
    (q,) = others
    if q == p or not g.barred(p, q) or not g.partners(q) <= {x, y}:
        return None
    if len(g.partners(q)) == 1:  # single slip: a1 has both routes, a2 only the one to b2
        (b2,) = g.partners(q)
        return SwitchType.SINGLE_SLIP.value, {"a1": p, "b1": y if b2 == x else x, "a2": q, "b2": b2}
    through = (azimuth_away(elements[p[0]].line, p[1] == 1, REACH_M) + 180.0) % 360.0
    turn = {e: abs(_turn(through, azimuth_away(elements[e[0]].line, e[1] == 1, REACH_M))) for e in (x, y)}
    b1 = min((x, y), key=lambda e: turn[e])  # a1–b1: the straighter (crossing) route
    return SwitchType.DOUBLE_SLIP.value, {"a1": p, "b1": b1, "a2": q, "b2": y if b1 == x else x}


def _row(
    sid: str, kind: str, ports: dict[str, End], elements: dict[str, NetElement], side: str | None
) -> dict[str, Any]:
    a1 = ports["a1"]
    line = elements[a1[0]].line
    i = -1 if a1[1] == 1 else 0
    out: dict[str, Any] = {"switch_id": sid, "type": kind}
    for name, end in ports.items():
        out.update(_port(name, end))
    out.update(diverging_side=side, lat=float(line.lat[i]), lon=float(line.lon[i]), name="inferred from netrelations")
    return out


def infer_switches(elements: dict[str, NetElement], relations: list[NetRelation], file: str) -> Inferred:
    """Slips, then point switches, by the rules of the module doc."""
    g = _Graph.of(relations)
    out = Inferred()
    ends = sorted(set(g.nav))
    in_slip: set[End] = set()
    for p in ends:
        slip = _slip(g, elements, p) if p not in in_slip else None
        if slip is not None:
            kind, ports = slip
            sid = switch_id(p)
            out.switches.append(_row(sid, kind, ports, elements, None))
            in_slip |= set(ports.values())
            out.by_relation.update((k, sid) for k in g.keys(tuple(ports.values())))
    for toe in ends:
        if toe not in in_slip:
            _point(g, elements, toe, out, file)
    return out


def _point(g: _Graph, elements: dict[str, NetElement], toe: End, out: Inferred, file: str) -> None:
    """The point switch whose toe is ``toe``, if the relations there make one (module doc)."""
    if len(g.partners(toe)) != 2:
        return
    x, y = sorted(g.partners(toe))
    if x[0] == y[0] or toe[0] in (x[0], y[0]) or not g.barred(x, y):
        return
    keys = [frozenset((toe, x)), frozenset((toe, y)), frozenset((x, y))]
    taken = [out.by_relation[k] for k in keys if k in out.by_relation]
    sid = switch_id(toe)
    if taken:
        msg = f"the relations at {toe[0]} {end_name(toe[1])} also belong to {taken[0]}: no switch inferred here"
        out.findings.append(
            Finding("rtm.switch_ambiguous", Severity.WARNING, "switches", msg, keys={"switch_id": sid}, file=file)
        )
        return
    left, right, side, problem = _sides(elements, toe, x, y)
    if problem:
        out.findings.append(
            Finding("rtm.switch_sides", Severity.WARNING, "switches", problem, keys={"switch_id": sid}, file=file)
        )
    out.switches.append(_row(sid, SwitchType.POINT.value, {"a1": toe, "b1": left, "b2": right}, elements, side))
    out.by_relation.update((k, sid) for k in keys)


def _port(name: str, end: End) -> dict[str, str]:
    return {f"{name}_track": end[0], f"{name}_end": end_name(end[1])}
