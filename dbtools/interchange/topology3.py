"""railML 3.x (RailTopoModel) topology → connections, switches and crossings (SPEC §8.1).

* ``netRelation``: ``elementA/@ref`` and ``elementB/@ref`` (netElements), ``@positionOnA`` /
  ``@positionOnB`` 0 = the element's begin (intrinsic coordinate 0), 1 = its end;
  ``@navigability`` Both / AB / BA / None → both / AB / BA / none. A relation naming a
  netElement not in the file: ``railml.dangling_ref`` (dropped).
* ``switchIS`` (``ordinarySwitch``, ``insideCurvedSwitch``, ``outsideCurvedSwitch``, no
  type): ``leftBranch`` and ``rightBranch`` name a netRelation each (``@netRelationRef``);
  the track end both relations share is the toe (a1), the left relation's other end b1, the
  right one's b2. The diverging side is ``@branchCourse``, else the side opposite
  ``@continueCourse``; its branch's ``@radius`` and ``@branchingSpeed`` are the diverging
  radius and speed. km: the ``spotLocation``'s ``linearCoordinate``, else the mileage at its
  ``intrinsicCoord``. The two relations and the branch ↔ branch relation (made with
  navigability none when the file has none) carry the switch id. Our export's
  ``tpos:switchNumber``, ``tpos:lat``, ``tpos:lon`` are read back.
* ``crossing`` (simple) and ``switchIS`` ``singleSwitchCrossing`` / ``doubleSwitchCrossing``:
  ``straightBranch`` relations are the routes a1–b1 and a2–b2 (in document order, each
  relation's element A end first), ``turningBranch`` relations the slip routes; type
  crossing / single_slip / double_slip.
* A switch whose branches name no relation of the file, or whose relations share no track
  end, is not imported (``railml.switch_open``); a three-way switch has no counterpart.
"""

from __future__ import annotations

from dbtools.interchange import xmltree as xt
from dbtools.interchange.model import RailmlDoc, RLink, RSwitch
from dbtools.interchange.railml_ids import designator
from dbtools.interchange.xmltree import Element
from schemas.enums import Navigability, Severity, Side, SwitchType, TrackEnd

NAVIGABILITY = {
    "both": Navigability.BOTH.value,
    "ab": Navigability.A_TO_B.value,
    "ba": Navigability.B_TO_A.value,
    "none": Navigability.NONE.value,
}
POINT_TYPES = (None, "ordinarySwitch", "insideCurvedSwitch", "outsideCurvedSwitch")
CROSSING_TYPES = {
    "simpleCrossing": SwitchType.CROSSING.value,
    "singleSwitchCrossing": SwitchType.SINGLE_SLIP.value,
    "doubleSwitchCrossing": SwitchType.DOUBLE_SLIP.value,
}
End = tuple[str, str]


def _end(pos: str | None) -> str | None:
    return {"0": TrackEnd.BEGIN.value, "1": TrackEnd.END.value}.get((pos or "").split(".")[0])


class _Topo:
    def __init__(self, doc: RailmlDoc) -> None:
        self.doc = doc
        self.rels: dict[str, RLink] = {}

    def warn(self, el: Element, rule: str, msg: str, table: str = "connections") -> None:
        self.doc.findings.append(xt.finding(el, rule, msg, file=self.doc.file, table=table, severity=Severity.WARNING))

    def relation(self, el: Element) -> None:
        ident = xt.attr(el, "id") or ""
        a, b = xt.child(el, "elementA"), xt.child(el, "elementB")
        self.doc.use(el, a, b)
        refs = [xt.attr(x, "ref") if x is not None else None for x in (a, b)]
        missing = [r for r in refs if r not in self.doc.tracks]
        ends = (_end(xt.attr(el, "positionOnA")), _end(xt.attr(el, "positionOnB")))
        if missing:
            self.warn(
                el,
                "railml.dangling_ref",
                f"netRelation {ident} names netElement '{missing[0]}', which is not in the file: dropped",
            )
            return
        if None in ends:
            self.warn(el, "railml.topology", f"netRelation {ident}: @positionOnA/@positionOnB must be 0 or 1: dropped")
            return
        nav = NAVIGABILITY.get((xt.attr(el, "navigability") or "both").lower(), Navigability.BOTH.value)
        self.rels[ident] = RLink(refs[0], ends[0], refs[1], ends[1], nav, None, el)  # type: ignore[arg-type]

    def branch_rel(self, sw: Element, name: str) -> tuple[Element | None, RLink | None]:
        br = xt.child(sw, name)
        if br is None:
            return None, None
        self.doc.use(br)
        return br, self.rels.get(xt.attr(br, "netRelationRef") or "")

    def open(self, sw: Element, why: str) -> None:
        self.warn(sw, "railml.switch_open", f"{xt.local(sw)} {xt.attr(sw, 'id')} not imported: {why}", "switches")


def read(doc: RailmlDoc, root: Element, spot: object) -> None:
    """Fill ``doc.links`` and ``doc.switches`` (module doc); ``spot(el)`` locates a
    switch's spotLocation as (track, pos, km, direction) or None."""
    t = _Topo(doc)
    for el in xt.descend(root, "infrastructure", "topology", "netRelations", "netRelation"):
        t.relation(el)
    for ne in doc.tracks.values():
        doc.use(*xt.children(ne.el, "relation"))
    fi = xt.descend(root, "infrastructure", "functionalInfrastructure")
    for f in fi:
        doc.use(*xt.children(f, "switchesIS"), *xt.children(f, "crossings"))
    for sw in [e for f in fi for e in xt.descend(f, "switchesIS", "switchIS")]:
        doc.use(sw, *xt.children(sw, "name"), *xt.children(sw, "designator"))
        kind = xt.attr(sw, "type")
        if kind in CROSSING_TYPES:
            _crossing(t, sw, CROSSING_TYPES[kind], spot)
        elif kind in POINT_TYPES:
            _point(t, sw, spot)
        else:
            t.open(sw, f"type {kind} has no counterpart (a point switch has two branches)")
    for cr in [e for f in fi for e in xt.descend(f, "crossings", "crossing")]:
        doc.use(cr, *xt.children(cr, "name"), *xt.children(cr, "designator"))
        _crossing(t, cr, SwitchType.CROSSING.value, spot)
    doc.links += list(t.rels.values())


def _km(t: _Topo, sw: Element, spot: object) -> float | None:
    if xt.child(sw, "spotLocation") is None:
        return None
    where = spot(sw)  # type: ignore[operator]
    t.doc.use(*[c for s in xt.children(sw, "spotLocation") for c in xt.children(s)])
    return None if where is None else float(where[2])


def _num(el: Element | None, name: str) -> float | None:
    try:
        v = xt.number(el, name) if el is not None else None
    except ValueError:
        return None
    return None if v is None else abs(v)


def _point(t: _Topo, sw: Element, spot: object) -> None:
    ident = xt.attr(sw, "id") or ""
    lb, left = t.branch_rel(sw, "leftBranch")
    rb, right = t.branch_rel(sw, "rightBranch")
    if left is None or right is None:
        t.open(sw, "leftBranch/rightBranch name no netRelation of the file")
        return
    ends_l = {(left.track_a, left.end_a), (left.track_b, left.end_b)}
    ends_r = {(right.track_a, right.end_a), (right.track_b, right.end_b)}
    toe = ends_l & ends_r
    if len(toe) != 1:
        t.open(sw, "its two branch relations share no track end (the toe)")
        return
    a1 = toe.pop()
    b1, b2 = (ends_l - {a1}).pop(), (ends_r - {a1}).pop()
    branch = xt.attr(sw, "branchCourse")
    cont = xt.attr(sw, "continueCourse")
    side = branch if branch in ("left", "right") else {"left": "right", "right": "left"}.get(cont or "")
    div = lb if side == Side.LEFT.value else rb if side == Side.RIGHT.value else None
    sid = designator(sw) or ident
    left.switch_id = right.switch_id = sid
    between = next(
        (r for r in t.rels.values() if {(r.track_a, r.end_a), (r.track_b, r.end_b)} == {b1, b2}),
        None,
    )
    if between is None:
        between = t.rels[f"{ident}#branches"] = RLink(b1[0], b1[1], b2[0], b2[1], Navigability.NONE.value, None, sw)
    between.switch_id = sid
    number = xt.tpos(sw, "switchNumber")  # our export (railML 3.2 has no attribute for it)
    lat, lon = xt.tpos(sw, "lat"), xt.tpos(sw, "lon")
    t.doc.switches[ident] = RSwitch(
        designator(sw) or ident,
        sw,
        SwitchType.POINT.value,
        {"a1": a1, "b1": b1, "b2": b2},
        switch_number=None if number is None else float(number),
        diverging_side=side,
        radius=_num(div, "radius"),
        speed=_num(div, "branchingSpeed"),
        km=_km(t, sw, spot),
        name=_name(sw),
        track_id=a1[0],
        lat=None if lat is None else float(lat),
        lon=None if lon is None else float(lon),
    )


def _name(el: Element) -> str | None:
    n = xt.child(el, "name")
    return xt.attr(n, "name") if n is not None else None


def _crossing(t: _Topo, el: Element, kind: str, spot: object) -> None:
    ident = xt.attr(el, "id") or ""
    found = [t.rels.get(xt.attr(b, "netRelationRef") or "") for b in xt.children(el, "straightBranch")]
    slips = [t.rels.get(xt.attr(b, "netRelationRef") or "") for b in xt.children(el, "turningBranch")]
    t.doc.use(*xt.children(el, "straightBranch"), *xt.children(el, "turningBranch"))
    straight = [r for r in found if r is not None]
    turning = [r for r in slips if r is not None]
    if len(straight) != 2 or len(found) != 2 or len(turning) != len(slips):
        t.open(el, "needs two straightBranch netRelations of the file")
        return
    s1, s2 = straight
    ports = {"a1": (s1.track_a, s1.end_a), "b1": (s1.track_b, s1.end_b)}
    ports |= {"a2": (s2.track_a, s2.end_a), "b2": (s2.track_b, s2.end_b)}
    for r in [s1, s2, *turning]:
        r.switch_id = designator(el) or ident
    t.doc.switches[ident] = RSwitch(
        designator(el) or ident, el, kind, ports, km=_km(t, el, spot), name=_name(el), track_id=s1.track_a
    )
