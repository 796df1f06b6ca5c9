"""railML 2.x track topology → connections, switches and crossings (SPEC §8.1).

railML 2 joins tracks by pairs of ``connection`` elements, each naming its partner by
``@ref`` (railML 2 wiki, *Dev:Connection between tracks*; *IS:connection switch*):

* ``trackBegin/connection`` and ``trackEnd/connection``: the two track ends meet; a pair
  becomes one of our connections, navigability ``both``.
* ``connections/switch`` on a track at ``@pos``: its ``connection`` children are the
  **branches** (``@course`` left/right/straight, ``@orientation`` outgoing/incoming seen in
  the track's direction, towards its ``trackEnd``); the through leg is the track itself and
  the track-end connection at the switch. railML 2 places a switch at a track end (pos 0 or
  the length); a switch inside a track (any other pos) cuts the track there into pieces: the
  first keeps the railML id, the others are ``ID@POS`` (POS the cut's ``@pos``, %g), joined
  end to begin through the switch.
* Which leg is the toe: a branch ``outgoing`` at the track's end (or ``incoming`` at its
  begin) diverges from the track, so the track's end is the toe (port a1) and the through
  partner and the branch are b1/b2; otherwise the through partner is the toe. Without
  ``@orientation`` the track is taken as the toe (the wiki's advice: a switch belongs to the
  track from which it is run facing).
* Sides: ``@course`` is seen in the track's direction; seen from the toe it is the same for
  ``outgoing`` and mirrored for ``incoming``. The branch's side is the diverging side (our
  b1 left, b2 right); a ``straight`` branch with ``@trackContinueCourse`` left/right makes the
  through leg the diverging one. No side stated: b1 = through leg, b2 = branch, side empty
  (a warning).
* Geometry: lat/lon from the switch's ``geoCoord``; the switch number n from ``@model``
  (``1:n`` in it, e.g. ``EV-UIC60-300-1:9``), the branch's ``@radius`` and ``@maxSpeed``
  (2.3+) → diverging radius and speed; km = ``@absPos`` (else the track's mileage at
  ``@pos``). ``@normalPosition``, ``@length`` and ``@trackContinueRadius`` have no column.
  ``@passable="false"`` on a branch: its route toe → branch gets navigability ``none``.
* ``crossing``: ``simpleCrossing`` → crossing, ``simpleSwitchCrossing`` → single_slip,
  ``doubleSwitchCrossing`` → double_slip; the track and its through partner are route a1–b1,
  the crossing's two connections a2 and b2 (in document order); slip routes a1–b2 (and
  a2–b1 for a double slip).
* Generator quirk (the Finnish file): a connection whose ``@ref`` names a *track* instead of
  a connection is read as that track's end connection referring back to it, else the only
  end of that track still open (a ``railml.quirk`` warning).
* A ``@ref`` naming nothing in the file (a track outside the extract): ``railml.dangling_ref``
  warning naming the element, line and missing id; that end stays open. A switch inside a
  track none of whose legs is in the file (the Finnish file: legs named by track sections of
  the national topology the extract leaves out) is the track running straight through it and
  a diverging branch outside: the track is cut there (toe and through pieces by the branch's
  ``@orientation``) and the switch imported with its diverging port empty (a
  ``railml.switch_open_port`` warning naming where the branch leads). Any other switch with
  a leg outside the file is not imported (a ``railml.switch_open`` warning).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from itertools import pairwise

from dbtools.interchange import xmltree as xt
from dbtools.interchange.model import Piece, RailmlDoc, RLink, RSwitch, RTrack
from dbtools.interchange.xmltree import Element
from schemas.enums import Navigability, Severity, Side, SwitchType, TrackEnd, TrackKind

#: A switch this close to a track end [m] is at that end.
END_TOLERANCE_M = 1.0
BEGIN, END = TrackEnd.BEGIN.value, TrackEnd.END.value
BOTH, NONE = Navigability.BOTH.value, Navigability.NONE.value
CROSSINGS = {
    "simpleCrossing": SwitchType.CROSSING.value,
    "simpleSwitchCrossing": SwitchType.SINGLE_SLIP.value,
    "doubleSwitchCrossing": SwitchType.DOUBLE_SLIP.value,
}
#: railML 2 track ``@type`` → our kind (``mainTrack`` etc.; railML 2.1+).
TRACK_KINDS = {
    "mainTrack": TrackKind.MAIN.value,
    "secondaryTrack": TrackKind.STATION.value,
    "stationTrack": TrackKind.STATION.value,
    "connectingTrack": TrackKind.CONNECTING.value,
    "sidingTrack": TrackKind.SIDING.value,
    "crossover": TrackKind.CROSSOVER.value,
}
#: A track end with one of these has no connection (our tracks' ends simply have none).
ENDINGS = ("openEnd", "bufferStop", "macroscopicNode")
_RATIO = re.compile(r"1:(\d+(?:[.,]\d+)?)")

End = tuple[str, str]


@dataclass
class _Node:
    """A switch or crossing on a railML track."""

    el: Element
    track: RTrack
    pos: float
    legs: list[tuple[Element, End]] = field(default_factory=list)
    """(its connection, the track end it leads to)."""
    open: list[Element] = field(default_factory=list)
    open_branch: Element | None = None
    """A switch inside a track whose diverging leg leads out of the file: that leg (module doc)."""


@dataclass
class _State:
    doc: RailmlDoc
    ends: dict[str, tuple[Element, End]] = field(default_factory=dict)
    """track-end connection id → (element, (railML track, end))."""
    legs: dict[str, tuple[Element, Element]] = field(default_factory=dict)
    """switch/crossing connection id → (element, switch element)."""
    links: dict[frozenset[End], RLink] = field(default_factory=dict)

    def warn(self, el: Element, rule: str, msg: str, column: str | None = None) -> None:
        self.doc.findings.append(
            xt.finding(el, rule, msg, file=self.doc.file, table="connections", severity=Severity.WARNING, column=column)
        )

    def link(self, a: End, b: End, el: Element) -> RLink:
        key = frozenset((a, b))
        if key not in self.links:
            self.links[key] = RLink(a[0], a[1], b[0], b[1], BOTH, None, el)
        return self.links[key]


def read(doc: RailmlDoc, infra: Element) -> None:
    """Fill ``doc.links``, ``doc.switches`` and ``doc.pieces`` from the tracks of one
    ``infrastructure`` element."""
    st = _State(doc)
    nodes = _collect(st, infra)
    _pair_ends(st)
    by_el = {id(n.el): n for n in nodes}
    for cid, (c, node_el) in st.legs.items():
        _resolve_leg(st, by_el[id(node_el)], c, cid)
    for c, (tid, side) in st.ends.values():  # a track end that names a switch leg
        ref = xt.attr(c, "ref")
        if ref in st.legs:
            node = by_el[id(st.legs[ref][1])]
            if all(e != (tid, side) for _, e in node.legs):
                node.legs.append((st.legs[ref][0], (tid, side)))
    complete = [n for n in nodes if _complete(st, n)]
    _cut(st, complete)
    for n in complete:
        _node(st, n)
    doc.links += list(st.links.values())


def _collect(st: _State, infra: Element) -> list[_Node]:
    """Index the track-end and switch connections; the switches and crossings."""
    nodes: list[_Node] = []
    for el in xt.descend(infra, "tracks", "track"):
        track = st.doc.tracks.get(xt.attr(el, "id") or "")
        if track is None:
            continue
        track.kind = TRACK_KINDS.get(xt.attr(el, "type") or "")
        topo = xt.child(el, "trackTopology")
        for side, name in ((BEGIN, "trackBegin"), (END, "trackEnd")):
            st.doc.use(*[e for n in ENDINGS for e in xt.descend(topo, name, n)])
            for c in xt.descend(topo, name, "connection"):
                if (cid := xt.attr(c, "id")) is not None:
                    st.ends[cid] = (c, (track.id, side))
        for conns in xt.children(topo, "connections"):
            st.doc.use(conns)
            for node_el in [*xt.children(conns, "switch"), *xt.children(conns, "crossing")]:
                nodes.append(_Node(node_el, track, _pos(node_el)))
                for c in xt.children(node_el, "connection"):
                    if (cid := xt.attr(c, "id")) is not None:
                        st.legs[cid] = (c, node_el)
    return nodes


def _pos(el: Element) -> float:
    try:
        return xt.number(el, "pos") or 0.0
    except ValueError:
        return 0.0


def _pair_ends(st: _State) -> None:
    """Track end ↔ track end pairs; quirks and dangling refs (module doc)."""
    quirks = []
    for cid, (c, end) in st.ends.items():
        ref = xt.attr(c, "ref")
        st.doc.use(c)
        if ref in st.ends:
            st.link(end, st.ends[ref][1], c)
        elif ref in st.legs:
            continue  # a switch's branch: read with the switch
        elif ref in st.doc.tracks:
            quirks.append((c, cid, end, ref))
        else:
            st.warn(c, "railml.dangling_ref", f"connection {cid} refers to '{ref}', which is not in the file: open end")
    paired = {e for k in st.links for e in k}
    for c, cid, end, ref in quirks:
        if end in paired:
            continue
        back = [e for el, e in st.ends.values() if e[0] == ref and xt.attr(el, "ref") in (cid, end[0])]
        opened = [e for e in ((ref, BEGIN), (ref, END)) if e not in paired and e[0] != end[0]]
        partner = back[0] if back else (opened[0] if len(opened) == 1 else None)
        if partner is None:
            st.warn(c, "railml.dangling_ref", f"connection {cid} names track '{ref}', not a connection: open end")
            continue
        st.link(end, partner, c)
        paired |= {end, partner}
        st.warn(
            c,
            "railml.quirk",
            f"connection {cid} has @ref '{ref}', a track, not a connection: read as its {partner[1]}",
            column="ref",
        )


def _resolve_leg(st: _State, node: _Node, c: Element, cid: str) -> None:
    ref = xt.attr(c, "ref")
    st.doc.use(c)
    if ref in st.ends:
        node.legs.append((c, st.ends[ref][1]))
    elif ref not in st.legs:  # a leg that names another switch's leg is read from that side
        st.warn(
            c,
            "railml.dangling_ref",
            f"{xt.local(node.el)} {xt.attr(node.el, 'id')}: connection {cid} refers to '{ref}', which is not in "
            "the file",
        )
        node.open.append(c)


def _open_switch(st: _State, n: _Node) -> bool:
    """A switch inside a track none of whose legs is in the file: its straight legs are the
    track itself running through, so it is kept with the diverging port left empty (a
    ``railml.switch_open_port`` warning naming where that branch leads)."""
    if xt.local(n.el) != "switch" or n.legs or _at_end(n) is not None:
        return False
    branches = [c for c in n.open if xt.attr(c, "course") not in (None, "straight")]
    if len(branches) != 1:
        return False
    n.open_branch = branches[0]
    st.doc.findings.append(
        xt.finding(
            n.el,
            "railml.switch_open_port",
            f"switch {xt.attr(n.el, 'id')} on track {n.track.id}: its diverging branch leads to "
            f"'{xt.attr(branches[0], 'ref')}', outside the file; imported with that port empty",
            file=st.doc.file,
            table="switches",
            severity=Severity.WARNING,
        )
    )
    return True


def _complete(st: _State, n: _Node) -> bool:
    kind = xt.local(n.el)
    st.doc.use(n.el)  # imported, or reported here
    if _open_switch(st, n):
        return True
    need = 1 if kind == "switch" else 2
    legs = {e for _, e in n.legs}
    if n.open or len(legs) != need:
        why = (
            f"{len(n.open)} leg(s) lead out of the file"
            if n.open
            else f"{len(legs)} branch leg(s), our {kind} has {need} (a three-way switch has no counterpart)"
        )
        st.doc.findings.append(
            xt.finding(
                n.el,
                "railml.switch_open",
                f"{kind} {xt.attr(n.el, 'id')} on track {n.track.id} not imported: {why}; the switch table needs "
                "every port",
                file=st.doc.file,
                table="switches",
                severity=Severity.WARNING,
            )
        )
        return False
    return True


def _at_end(n: _Node) -> str | None:
    if n.pos <= END_TOLERANCE_M:
        return BEGIN
    if n.track.length is not None and n.pos >= n.track.length - END_TOLERANCE_M:
        return END
    return None


def _cut(st: _State, nodes: list[_Node]) -> None:
    """Cut railML tracks at the switches inside them (module doc); move their end links."""
    inner: dict[str, list[float]] = {}
    for n in nodes:
        if _at_end(n) is None:
            inner.setdefault(n.track.id, []).append(n.pos)
    for tid, cuts in inner.items():
        length = st.doc.tracks[tid].length or max(cuts)
        bounds = [0.0, *sorted(set(cuts)), length]
        pieces = [
            Piece(tid if i == 0 else f"{tid}@{bounds[i]:g}", bounds[i], bounds[i + 1] - bounds[i])
            for i in range(len(bounds) - 1)
        ]
        st.doc.pieces[tid] = pieces
        last = pieces[-1].id
        for key in [k for k in st.links if (tid, END) in k]:
            old = st.links.pop(key)
            other = next(iter(key - {(tid, END)}), (tid, END))
            st.link((last, END), other, old.el)
        for a, b in pairwise(pieces):
            st.link((a.id, END), (b.id, BEGIN), None)
    for n in nodes:  # legs arriving at a cut track's end now arrive at its last piece
        n.legs = [(c, _moved(st, e)) for c, e in n.legs]


def _moved(st: _State, end: End) -> End:
    pieces = st.doc.pieces.get(end[0])
    return (pieces[-1].id, END) if pieces and end[1] == END else end


def _home(st: _State, n: _Node) -> tuple[End, End | None]:
    """(the switch's own track end, the through partner) — for a switch inside a track the
    piece before it and the piece after it."""
    side = _at_end(n)
    if side is None:
        pieces = st.doc.pieces[n.track.id]
        i = next(i for i, p in enumerate(pieces) if abs(p.offset - n.pos) < 1e-9)
        return (pieces[i - 1].id, END), (pieces[i].id, BEGIN)
    own = _moved(st, (n.track.id, side))
    partners = [e for k in st.links for e in k if own in k and e != own and not _is_leg(n, e)]
    return own, partners[0] if len(partners) == 1 else None


def _is_leg(n: _Node, e: End) -> bool:
    return any(e == leg for _, leg in n.legs)


def _node(st: _State, n: _Node) -> None:
    own, through = _home(st, n)
    ident = xt.attr(n.el, "id") or ""
    if through is None:
        st.doc.findings.append(
            xt.finding(
                n.el,
                "railml.switch_open",
                f"{xt.local(n.el)} {ident}: its track {n.track.id} has no (single) connection at the switch's end "
                "for the through leg; not imported",
                file=st.doc.file,
                table="switches",
                severity=Severity.WARNING,
            )
        )
        return
    km = _km(st.doc, n)
    name = xt.attr(n.el, "name")
    if xt.local(n.el) == "crossing":
        _crossing(st, n, ident, own, through, km, name)
    else:
        _switch(st, n, ident, own, through, km, name)


def _km(doc: RailmlDoc, n: _Node) -> float | None:
    try:
        km = xt.number(n.el, "absPos")
    except ValueError:
        km = None
    if km is None and n.track.mileage is not None:
        km = n.track.mileage.km(n.pos)
    return km


def _switch(st: _State, n: _Node, ident: str, own: End, through: End, km: float | None, name: str | None) -> None:
    c, branch = n.legs[0] if n.legs else (n.open_branch, None)
    orientation = xt.attr(c, "orientation")
    toe_is_own = orientation is None or (orientation == "outgoing") == (own[1] == END)
    toe, straight = (own, through) if toe_is_own else (through, own)
    mirror = orientation == "incoming"
    course = _seen_from_toe(xt.attr(c, "course"), mirror)
    cont = _seen_from_toe(xt.attr(n.el, "trackContinueCourse"), mirror)
    if course in (Side.LEFT.value, Side.RIGHT.value):
        side: str | None = course
        left, right = (branch, straight) if course == Side.LEFT.value else (straight, branch)
    elif course == "straight" and cont in (Side.LEFT.value, Side.RIGHT.value):
        side = cont
        left, right = (straight, branch) if cont == Side.LEFT.value else (branch, straight)
    else:
        side, left, right = None, straight, branch
        st.warn(n.el, "railml.switch_side", f"switch {ident}: no side stated (@course): b1 = through, b2 = branch")
    st.link(toe, straight, n.el).switch_id = ident
    if branch is not None:
        st.link(toe, branch, c).switch_id = ident
        if xt.attr(c, "passable") == "false":
            st.links[frozenset((toe, branch))].navigability = NONE
        st.link(straight, branch, n.el)
        st.links[frozenset((straight, branch))].navigability = NONE
        st.links[frozenset((straight, branch))].switch_id = ident
    model = xt.attr(n.el, "model") or ""
    ratio = _RATIO.search(model)
    lat, lon = _lat_lon(n.el)
    st.doc.switches[ident] = RSwitch(
        ident,
        n.el,
        SwitchType.POINT.value,
        {k: v for k, v in (("a1", toe), ("b1", left), ("b2", right)) if v is not None},
        diverging_side=side,
        switch_number=float(ratio.group(1).replace(",", ".")) if ratio else None,
        radius=_abs_num(c, "radius"),
        speed=_abs_num(c, "maxSpeed"),
        km=km,
        name=name,
        track_id=toe[0],
        lat=lat,
        lon=lon,
    )


def _lat_lon(el: Element) -> tuple[float | None, float | None]:
    """The switch's own ``geoCoord`` (its toe), read as the track's coordinates are
    (:mod:`~dbtools.interchange.railml2`, which reports a bad one)."""
    from dbtools.interchange.geometry import to_lonlat

    geo = xt.child(el, "geoCoord")
    if geo is None:
        return None, None
    try:
        lon, lat, _ = to_lonlat([float(c) for c in (xt.attr(geo, "coord") or "").split()], xt.attr(geo, "epsgCode"))
    except ValueError:
        return None, None
    return lat, lon


def _seen_from_toe(course: str | None, mirror: bool) -> str | None:
    if course is None or not mirror or course not in (Side.LEFT.value, Side.RIGHT.value):
        return course
    return Side.RIGHT.value if course == Side.LEFT.value else Side.LEFT.value


def _abs_num(el: Element, name: str) -> float | None:
    try:
        v = xt.number(el, name)
    except ValueError:
        return None
    return None if v is None else abs(v)


def _crossing(st: _State, n: _Node, ident: str, own: End, through: End, km: float | None, name: str | None) -> None:
    kind = CROSSINGS.get(xt.attr(n.el, "type") or "", SwitchType.CROSSING.value)
    (_, a2), (_, b2) = n.legs[0], n.legs[1]
    ports = {"a1": own, "b1": through, "a2": a2, "b2": b2}
    routes = {("a1", "b1"), ("a2", "b2")}
    if kind != SwitchType.CROSSING.value:
        routes.add(("a1", "b2"))
    if kind == SwitchType.DOUBLE_SLIP.value:
        routes.add(("a2", "b1"))
    for p, q in (("a1", "b1"), ("a2", "b2"), ("a1", "b2"), ("a2", "b1"), ("a1", "a2"), ("b1", "b2")):
        link = st.link(ports[p], ports[q], n.el)
        link.switch_id = ident
        link.navigability = BOTH if (p, q) in routes else NONE
    st.doc.switches[ident] = RSwitch(ident, n.el, kind, ports, km=km, name=name, track_id=own[0])
