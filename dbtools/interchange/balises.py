"""railML balises → our balise table [S003 §4].

Our model is not ETCS's: an *initial pair* (I1 then I2, 5 m apart) tells the onboard unit
its line, station and track; a *position-correction* balise (C) is the first balise of a
home or block signal, identified from the last pair passed and its signal type, and its row
carries the travel distance from that pair's I1. railML describes balise groups and their
positions, not our telegram roles, so the import maps:

* **groups** — a railML 3 ``baliseGroup`` (``belongsToParent``); in railML 2.x consecutive
  balises of one track read in the same direction within :data:`GROUP_SPAN_M` of each
  other; a balise of no group is a group of one;
* **initial pair** — a group the ``--line-code`` map names in ``[initial_pairs]`` (with the
  station code: railML has none) and that has exactly two balises; I1 is the first in the
  running direction of its track (D, S: km increasing; U: decreasing);
* **C** — every other group: its first balise in running direction, with ``signal_type``
  the function (else type) of the signal of the group (railML 3
  ``connectedWithInfrastructureElement``, else the group's ``functionalType``; railML 2.x:
  the first signal ahead in running direction within :data:`SIGNAL_AHEAD_M` read in the
  same direction), ``blocking``/``intermediate`` → ``block``, ``entry`` → ``home``;
  its governing pair is the last initial pair before it in running direction on the same
  line and track, and ``dist_from_initial_m`` the travel distance from that pair's I1: the
  km difference less the jumps of the mileage changes between them (on one railML track).

Reported and not written (honest findings, never invented codes): a C candidate with no
initial pair before it, the further balises of a group (only a group's first balise is
read for correction), a group named as a pair that does not have two balises. A balise of
our own railML export carries its row in ``tpos:`` attributes and is taken as it is.
``km_equipment_m`` = the railML km (railML has one mileage).

Balises of European balise groups, and every balise when the map names no initial pair, are
G rows instead (:mod:`~dbtools.interchange.balise_groups`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

from dbtools.interchange import xmltree as xt
from dbtools.interchange.balise_groups import is_group_balise, map_group_balises
from dbtools.interchange.mapping import LineMap, Target
from dbtools.interchange.model import RailmlDoc, RBalise, RSignal
from schemas.enums import BaliseKind, Severity, Track
from schemas.findings import Finding

#: railML 2.x balises of one track closer than this are one group [m].
GROUP_SPAN_M = 8.0
#: A railML 2.x signal at most this far ahead of a C balise names its signal type [m].
SIGNAL_AHEAD_M = 100.0
SIGNAL_TYPES = {"blocking": "block", "intermediate": "block", "entry": "home"}


@dataclass
class _Group:
    key: str
    members: list[RBalise]
    target: Target
    sign: int


def _sign(track: str) -> int:
    return -1 if track == Track.UP.value else 1


def _row(
    b: RBalise, t: Target, kind: str, station: str | None, signal: str | None, dist: float | None
) -> dict[str, Any]:
    return {
        "balise_id": b.id,
        "kind": kind,
        "line_code": t.line_code,
        "station_code": station,
        "track": t.track,
        "signal_type": signal,
        "km_actual_m": b.km,
        "km_equipment_m": b.km,
        "dist_from_initial_m": dist,
    }


def _own_row(b: RBalise, t: Target) -> dict[str, Any]:
    e = b.ext
    return _row(b, t, e["kind"], e.get("stationCode"), e.get("signalType"), _float(e.get("distFromInitial"))) | {
        "km_equipment_m": _float(e.get("kmEquipment")) if e.get("kmEquipment") else b.km
    }


def _float(text: str | None) -> float | None:
    return None if text is None or text == "" else float(text)


def _groups(balises: Sequence[RBalise], targets: dict[str, Target]) -> list[_Group]:
    by_key: dict[str, _Group] = {}
    loose: dict[str, list[RBalise]] = {}
    for b in balises:
        t = targets[b.track_id]
        if b.group is not None:
            g = by_key.setdefault(b.group, _Group(b.group, [], t, _sign(t.track)))
            g.members.append(b)
        else:
            loose.setdefault(b.track_id, []).append(b)
    out = list(by_key.values())
    for track_id, bs in loose.items():
        t = targets[track_id]
        current: list[RBalise] = []
        for b in sorted(bs, key=lambda x: (x.km, x.id)):
            if current and (b.km - current[-1].km > GROUP_SPAN_M or b.direction != current[-1].direction):
                out.append(_Group(current[0].id, current, t, _sign(t.track)))
                current = []
            current.append(b)
        if current:
            out.append(_Group(current[0].id, current, t, _sign(t.track)))
    for g in out:
        g.members.sort(key=lambda b: (b.km * g.sign, b.id))
    return sorted(out, key=lambda g: (g.target.line_code, g.target.track, g.members[0].km * g.sign))


def _warn(doc: RailmlDoc, b: RBalise, rule: str, message: str) -> Finding:
    return xt.finding(b.el, rule, message, file=doc.file, table="balises", severity=Severity.WARNING)


def _signal_type(doc: RailmlDoc, g: _Group, first: RBalise) -> str | None:
    func: str | None = None
    group = doc.groups.get(g.key) if first.group is not None else None
    if group is not None:
        sig = doc.signals.get(group.signal_ref or "")
        func = sig.function if sig is not None else group.function
        func = None if func is not None and func.startswith("other:") else func  # not a signal function
    else:
        ahead = [
            s
            for s in doc.signals.values()
            if s.track_id == first.track_id
            and 0 <= (s.km - first.km) * g.sign <= SIGNAL_AHEAD_M
            and (s.direction == first.direction or 0 in (s.direction, first.direction))
        ]
        nearest: RSignal | None = min(ahead, key=lambda s: abs(s.km - first.km), default=None)
        func = nearest.function if nearest is not None else None
    if func is None:
        return None
    return SIGNAL_TYPES.get(func.lower(), func.lower())


def map_balises(
    doc: RailmlDoc, targets: dict[str, Target], lmap: LineMap
) -> tuple[list[dict[str, Any]], list[Finding]]:
    """Rows of the balise table and the findings for every balise not written (module doc)."""
    group = {id(b) for b in doc.balises if is_group_balise(doc, b, lmap)}
    rows, findings = map_group_balises(doc, [b for b in doc.balises if id(b) in group], targets)
    placed = []
    for b in [b for b in doc.balises if id(b) not in group]:
        if b.track_id not in targets:
            findings.append(_warn(doc, b, "railml.unmapped", f"balise {b.id}: its track {b.track_id} has no line code"))
        elif "kind" in b.ext:
            rows.append(_own_row(b, targets[b.track_id]))
        else:
            placed.append(b)
    pairs: dict[tuple[str, str], list[tuple[float, str, RBalise]]] = {}
    candidates: list[tuple[_Group, RBalise]] = []
    for g in _groups(placed, targets):
        station = next(
            (lmap.initial_pairs[k] for k in [g.key, *(b.id for b in g.members)] if k in lmap.initial_pairs), None
        )
        if station is not None and len(g.members) == 2:
            i1, i2 = g.members
            rows += [
                _row(i1, g.target, BaliseKind.I1, station, None, None),
                _row(i2, g.target, BaliseKind.I2, station, None, None),
            ]
            pairs.setdefault((g.target.line_code, g.target.track), []).append((i1.km * g.sign, station, i1))
            continue
        if station is not None:
            findings.append(
                _warn(
                    doc,
                    g.members[0],
                    "railml.pair",
                    f"group {g.key} is named an initial pair but has {len(g.members)} balise(s), not 2",
                )
            )
        candidates.append((g, g.members[0]))
        for b in g.members[1:]:
            findings.append(
                _warn(
                    doc,
                    b,
                    "railml.unmapped",
                    f"balise {b.id} is not the first of group {g.key}: only a group's first balise is "
                    "a position-correction balise [S003 §4.5]",
                )
            )
    for g, first in candidates:
        result = _c_row(doc, g, first, pairs.get((g.target.line_code, g.target.track), []))
        if isinstance(result, Finding):
            findings.append(result)
        else:
            rows.append(result)
    return rows, findings


def _c_row(
    doc: RailmlDoc, g: _Group, first: RBalise, pairs: list[tuple[float, str, RBalise]]
) -> dict[str, Any] | Finding:
    before = [p for p in pairs if p[0] < first.km * g.sign]
    if not before:
        return _warn(
            doc,
            first,
            "railml.no_pair",
            f"balise {first.id} ({g.target.line_code} {g.target.track} km {first.km:.1f}) has no "
            "initial pair before it "
            "in running direction: a C balise needs one (name pairs in the map's [initial_pairs])",
        )
    _, station, i1 = max(before, key=lambda p: p[0])
    # travel distance: the km difference less the mileage changes between them on their track
    mileage = doc.tracks[i1.track_id].mileage if first.track_id == i1.track_id else None
    jumps = mileage.jumps(i1.pos, first.pos) if mileage is not None else 0.0
    dist = abs(first.km - i1.km - jumps)
    return _row(first, g.target, BaliseKind.C, station, _signal_type(doc, g, first), round(dist, 6))
