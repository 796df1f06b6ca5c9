"""``db export --format railml``: the network (tracks, connections, switches) and the balise
groups (kind G) as railML 3.2, read back by :mod:`~dbtools.interchange.railml3` and
:mod:`~dbtools.interchange.topology3` to the same rows.

* a ``netElement`` per track (``@id`` ``net_<track>``; our track id in ``tpos:trackId``, as
  a netElement has no designator in railML 3.2; ``@length`` = length_m, ``tpos:kind``, and
  ``tpos:lineCode``/``tpos:track`` on a line); where it has km at both ends an
  ``associatedPositioningSystem`` with intrinsic coordinates 0 and 1 whose
  ``linearCoordinate`` is the km on its line's positioning system;
* a ``netRelation`` per connection (``positionOnA``/``B`` 0 = begin, 1 = end;
  ``navigability`` Both / AB / BA / None);
* a point switch → ``switchIS`` (``ordinarySwitch``; ``branchCourse`` = the diverging side,
  ``continueCourse`` the other; ``leftBranch`` = the relation toe–b1, ``rightBranch`` =
  toe–b2, the diverging one with ``@radius`` and ``@branchingSpeed``; ``spotLocation`` at the
  toe; switch number and the toe's lat/lon in ``tpos:switchNumber``, ``tpos:lat``,
  ``tpos:lon`` — railML 3.2 has no attribute for them); a
  crossing → ``crossings/crossing``, a slip → ``switchIS`` single/doubleSwitchCrossing; routes
  a1–b1 and a2–b2 as ``straightBranch``, slip routes a1–b2 (a2–b1) as ``turningBranch``;
* G balises: a ``baliseGroup`` per (NID_C, NID_BG), or — without an identity — per run of
  rows on one track less than 10 m apart up to N_TOTAL rows; ``isEurobaliseGroup``
  ``@countryID``/``@groupID`` where known, ``@numberOfBalisesInGroup`` = N_TOTAL; each
  balise on its track's netElement (else its line-and-track netElement) with its row in
  ``tpos:`` attributes (kind, NID_C, NID_BG, N_PIG, N_TOTAL, link, km).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import pandas as pd

from dbtools.interchange.railml_ids import xml_id
from dbtools.interchange.railml_xml import NS, designate, sub
from dbtools.network import Network
from schemas.enums import BaliseKind, SwitchType, TrackEnd

NAV_OUT = {"both": "Both", "AB": "AB", "BA": "BA", "none": "None"}
GROUP_GAP_M = 10.0


@dataclass
class _Net:
    ne: str
    line: str | None
    km0: float | None
    km1: float | None

    def intrinsic(self, km: float) -> float | None:
        if self.km0 is None or self.km1 is None or self.km1 == self.km0:
            return None
        return min(max((km - self.km0) / (self.km1 - self.km0), 0.0), 1.0)


def _v(x: Any) -> Any:
    return None if x is None or (not isinstance(x, str) and pd.isna(x)) else x


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    return [{str(k): _v(v) for k, v in r.items()} for r in frame.to_dict("records")]


def _pos(end: str) -> str:
    return "0" if end == TrackEnd.BEGIN.value else "1"


def write_topology(network: Network, nes: Any, rels: Any, level: Any, fi: Any) -> dict[str, _Net]:
    """netElements, netRelations, switchesIS and crossings (module doc); track id → netElement."""
    nets: dict[str, _Net] = {}
    for rec in _records(network.tracks):
        tid, line = str(rec["track_id"]), rec["line_code"]
        ne_id = xml_id("net", tid)
        ne = sub(
            nes,
            "netElement",
            id=ne_id,
            length=rec["length_m"],
            tpos_kind=rec["kind"],
            tpos_trackId=tid,
            tpos_lineCode=None if line is None else str(line),
            tpos_track=None if line is None or rec["track"] is None else str(rec["track"]),
        )
        if rec["name"] is not None:
            sub(ne, "name", name=str(rec["name"]), language="en")
        k0, k1 = rec["km_begin_m"], rec["km_end_m"]
        if line is not None and k0 is not None and k1 is not None:
            aps = sub(ne, "associatedPositioningSystem", id=xml_id("aps", "t", tid))
            for i, km in ((0, k0), (1, k1)):
                ic = sub(aps, "intrinsicCoordinate", id=xml_id("ic", "t", tid, i), intrinsicCoord=float(i))
                sub(ic, "linearCoordinate", positioningSystemRef=xml_id("lps", line), measure=float(km))
        sub(level, "networkResource", ref=ne_id)
        nets[tid] = _Net(ne_id, None if line is None else str(line), k0, k1)
    rel_ids = _relations(network, rels, nets)
    _switches(network, fi, nets, rel_ids, rels)
    return nets


def _relations(network: Network, rels: Any, nets: dict[str, _Net]) -> dict[frozenset[tuple[str, str]], str]:
    out: dict[frozenset[tuple[str, str]], str] = {}
    for rec in _records(network.connections):
        a, b = (str(rec["track_a"]), str(rec["end_a"])), (str(rec["track_b"]), str(rec["end_b"]))
        if a[0] not in nets or b[0] not in nets:
            continue
        out[frozenset((a, b))] = _relation(rels, nets, a, b, NAV_OUT.get(str(rec["navigability"]), "Both"))
    return out


def _relation(rels: Any, nets: dict[str, _Net], a: tuple[str, str], b: tuple[str, str], nav: str) -> str:
    rid = xml_id("nr", a[0], a[1], b[0], b[1])
    el = sub(rels, "netRelation", id=rid, positionOnA=_pos(a[1]), positionOnB=_pos(b[1]), navigability=nav)
    sub(el, "elementA", ref=nets[a[0]].ne)
    sub(el, "elementB", ref=nets[b[0]].ne)
    return rid


def _container(fi: Any, name: str, before: str) -> Any:
    from lxml import etree

    found = fi.find(f"{{{NS}}}{name}")
    if found is not None:
        return found
    el = etree.Element(f"{{{NS}}}{name}")
    anchor = fi.find(f"{{{NS}}}{before}")
    fi.insert(list(fi).index(anchor) if anchor is not None else len(fi), el)
    return el


def _switches(
    network: Network, fi: Any, nets: dict[str, _Net], rel_ids: dict[frozenset[tuple[str, str]], str], rels: Any
) -> None:
    def rel(p: tuple[str, str], q: tuple[str, str]) -> str:
        key = frozenset((p, q))
        if key not in rel_ids:
            rel_ids[key] = _relation(rels, nets, p, q, "Both")
        return rel_ids[key]

    for rec in _records(network.switches):
        ports = {
            p: (str(rec[f"{p}_track"]), str(rec[f"{p}_end"]))
            for p in ("a1", "b1", "a2", "b2")
            if rec.get(f"{p}_track") is not None
        }
        if any(t not in nets for t, _ in ports.values()):
            continue
        sid, kind = str(rec["switch_id"]), str(rec["type"])
        if kind == SwitchType.POINT.value:
            _point(fi, rec, sid, ports, nets, rel)
        else:
            _crossing(fi, rec, sid, kind, ports, rel)


def _named(el: Any, rec: dict[str, Any], sid: str) -> None:
    if rec.get("name") is not None:
        sub(el, "name", name=str(rec["name"]), language="en")
    designate(el, sid)


def _point(
    fi: Any,
    rec: dict[str, Any],
    sid: str,
    ports: dict[str, tuple[str, str]],
    nets: dict[str, _Net],
    rel: Callable[[tuple[str, str], tuple[str, str]], str],
) -> None:
    side = rec["diverging_side"]
    other = {"left": "right", "right": "left"}.get(str(side)) if side is not None else None
    sw = sub(
        _container(fi, "switchesIS", "tracks"),
        "switchIS",
        id=xml_id("sw", sid),
        type="ordinarySwitch",
        branchCourse=side,
        continueCourse=other,
        tpos_switchNumber=rec["switch_number"],
        tpos_lat=rec["lat"],
        tpos_lon=rec["lon"],
    )
    _named(sw, rec, sid)
    toe, net = ports["a1"], nets[ports["a1"][0]]
    loc = sub(sw, "spotLocation", id=xml_id("sl", "sw", sid), netElementRef=net.ne, intrinsicCoord=float(_pos(toe[1])))
    if rec["km_m"] is not None and net.line is not None:
        sub(loc, "linearCoordinate", positioningSystemRef=xml_id("lps", net.line), measure=float(rec["km_m"]))
    for name, port, s in (("leftBranch", "b1", "left"), ("rightBranch", "b2", "right")):
        div = side == s
        sub(
            sw,
            name,
            netRelationRef=rel(toe, ports[port]),
            radius=rec["diverging_radius_m"] if div else None,
            branchingSpeed=rec["diverging_speed_kmh"] if div else None,
        )


def _crossing(
    fi: Any,
    rec: dict[str, Any],
    sid: str,
    kind: str,
    ports: dict[str, tuple[str, str]],
    rel: Callable[[tuple[str, str], tuple[str, str]], str],
) -> None:
    if kind == SwitchType.CROSSING.value:
        el = sub(_container(fi, "crossings", "lines"), "crossing", id=xml_id("cr", sid))
    else:
        rail = "singleSwitchCrossing" if kind == SwitchType.SINGLE_SLIP.value else "doubleSwitchCrossing"
        el = sub(_container(fi, "switchesIS", "tracks"), "switchIS", id=xml_id("sw", sid), type=rail)
    _named(el, rec, sid)
    for p, q in (("a1", "b1"), ("a2", "b2")):
        sub(el, "straightBranch", netRelationRef=rel(ports[p], ports[q]))
    slips = [] if kind == SwitchType.CROSSING.value else [("a1", "b2")]
    slips += [("a2", "b1")] if kind == SwitchType.DOUBLE_SLIP.value else []
    for p, q in slips:
        sub(el, "turningBranch", netRelationRef=rel(ports[p], ports[q]))


def _group_keys(g: pd.DataFrame) -> list[str]:
    """A group key per G row (module doc)."""
    keys: list[str] = []
    prev: dict[str, Any] | None = None
    count = 0
    current = ""
    for rec in _records(g):
        if rec["nid_bg"] is not None:
            keys.append(xml_id("bg", "G", rec["nid_c"], rec["nid_bg"]))
            continue
        where = (rec["track_id"], rec["line_code"], rec["track"])
        fresh = (
            prev is None
            or where != (prev["track_id"], prev["line_code"], prev["track"])
            or abs(float(rec["km_actual_m"]) - float(prev["km_actual_m"])) >= GROUP_GAP_M
            or count >= int(prev["n_total"] or 1)
        )
        if fresh:
            current, count = xml_id("bg", "G", rec["balise_id"]), 0
        keys.append(current)
        count += 1
        prev = rec
    return keys


def write_group_balises(
    network: Network,
    bal: Any,
    grp: Any,
    nets: dict[str, _Net],
    carriers: dict[tuple[str, str], Callable[[float], float | None]],
) -> None:
    """The G balises and their groups (module doc)."""
    b = network.balises
    g = b[b["kind"] == BaliseKind.G.value]
    if g.empty:
        return
    g = g.assign(_t=g["track_id"].astype(str), _k=g["km_actual_m"].astype(float)).sort_values(["_t", "_k"])
    made: set[str] = set()
    for key, rec in zip(_group_keys(g), _records(g.drop(columns=["_t", "_k"])), strict=True):
        if key not in made:
            made.add(key)
            el = sub(grp, "baliseGroup", id=key, numberOfBalisesInGroup=_int(rec["n_total"]))
            sub(el, "applicationType", value="ETCS" if rec["nid_bg"] is not None else "other:trainpos")
            if rec["nid_bg"] is not None:
                sub(el, "isEurobaliseGroup", countryID=_int(rec["nid_c"]), groupID=_int(rec["nid_bg"]))
        _balise(bal, rec, key, nets, carriers)


def _int(x: Any) -> str | None:
    return None if x is None else str(int(x))


def _balise(
    bal: Any,
    rec: dict[str, Any],
    group: str,
    nets: dict[str, _Net],
    carriers: dict[tuple[str, str], Callable[[float], float | None]],
) -> None:
    bid, km = str(rec["balise_id"]), float(rec["km_actual_m"])
    net = nets.get(str(rec["track_id"])) if rec["track_id"] is not None else None
    line, track = rec["line_code"], rec["track"]
    if net is not None:
        ne, t = net.ne, net.intrinsic(km)
    elif line is not None and track is not None and (str(line), str(track)) in carriers:
        ne, t = xml_id("ne", line, track), carriers[(str(line), str(track))](km)
    else:
        return  # a G row on no track and no line: nothing to place it on
    el = sub(
        bal,
        "balise",
        id=xml_id("bal", bid),
        tpos_kind=BaliseKind.G.value,
        tpos_nidC=_int(rec["nid_c"]),
        tpos_nidBg=_int(rec["nid_bg"]),
        tpos_nPig=_int(rec["n_pig"]),
        tpos_nTotal=_int(rec["n_total"]),
        tpos_linkGroup=rec["link_group"],
        tpos_linkDistance=rec["link_distance_m"],
        tpos_trackId=rec["track_id"],
        tpos_kmActual=km,
        tpos_kmEquipment=rec["km_equipment_m"],
    )
    designate(el, bid)
    loc = sub(el, "spotLocation", id=xml_id("sl", bid), netElementRef=ne, intrinsicCoord=t)
    if line is not None:
        sub(loc, "linearCoordinate", positioningSystemRef=xml_id("lps", line), measure=km)
    sub(el, "belongsToParent", ref=group)
