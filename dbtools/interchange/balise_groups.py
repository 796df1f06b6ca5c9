"""railML balises → kind ``G`` rows: balises of European (ETCS) balise groups [SPEC §8.2;
SUBSET-026 §3.4.1, §7.5: NID_C, NID_BG, N_PIG, N_TOTAL].

Which balises: every balise of a group with an ETCS identity (railML 3
``baliseGroup/isEurobaliseGroup/@countryID``/``@groupID``; railML 2 ``balise/@countryID``/
``@groupID``), and every balise of a file whose ``--line-code`` map names no initial pair
(nothing can then be an S003 initial pair or correction balise,
:mod:`~dbtools.interchange.balises`). Our own export's G rows (``tpos:kind="G"``) are taken
as they are.

* **group** — the railML 3 ``baliseGroup`` (``belongsToParent``), the railML 2
  ``baliseGroup`` holding the balise or the balises sharing (NID_C, NID_BG); otherwise the
  balises of one railML track read in the same direction, consecutive along the track less
  than :data:`GROUP_SPAN_M` apart and, where both are named by numbers, numbered together
  (less than :data:`NUMBER_SPAN` apart — the Finnish pairs are n and n + 2, 55025/55027).
* **identity** — NID_C/NID_BG verbatim where stated (range-checked: 0–1023, 0–16383); else
  empty, with one ``railml.balise_identity`` warning per group (the file gives the group no
  ETCS identity: a name is not one — the Finnish names 18065 … 55742 are balise numbers, most
  beyond NID_BG's 14-bit range, different within a pair).
* **N_PIG** — railML 2 ``@ndx`` where stated; else the balise's rank along the track in the
  group's direction (railML 3 ``@mileageDirection`` nominal = km rising; railML 2 / 3
  balise ``dir``/``applicationDirection``; neither: increasing position), ties in position
  by name, then id (the file gives no order). **N_TOTAL** — the railML 3
  ``@numberOfBalisesInGroup`` where stated (a warning when the file holds another count),
  else the group's size.
* **track** — ``track_id`` our track (railML track or netElement; the piece where a railML 2
  track is cut at a switch); a balise whose ``pos`` lies beyond its track's end is moved
  along the topology onto the track that continues there (a ``railml.position`` warning —
  the Finnish file places balises up to 1 km past their track's end); ``line_code`` and
  local ``track`` where its track lies along a line, else empty. km = its km (railML 2
  ``@absPos`` / mileage, railML 3 ``linearCoordinate``), equipment km the same.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from dbtools.interchange import xmltree as xt
from dbtools.interchange.mapping import LineMap, Target
from dbtools.interchange.model import RailmlDoc, RBalise
from schemas.enums import BaliseKind, Severity, TrackEnd
from schemas.findings import Finding

#: Consecutive balises of one group are less than this apart [m] (ETCS: a group spans a few m).
GROUP_SPAN_M = 10.0
#: Balises named by numbers belong to one group only when their numbers differ by less than this.
NUMBER_SPAN = 8
NID_C_MAX, NID_BG_MAX = 1023, 16383
#: A position this far past a track end still lies on the track [m].
END_TOLERANCE_M = 0.5


@dataclass
class _Placed:
    b: RBalise
    track: str
    """our track id"""
    rail_track: str
    """the railML track it ends up on (for the line mapping)"""
    pos: float


def is_group_balise(doc: RailmlDoc, b: RBalise, lmap: LineMap) -> bool:
    """A balise mapped to a G row (module doc)."""
    if "kind" in b.ext:
        return b.ext["kind"] == BaliseKind.G.value
    group = doc.groups.get(b.group or "")
    etcs = b.nid_bg is not None or (group is not None and (group.etcs or group.nid_bg is not None))
    return etcs or not lmap.initial_pairs


def _warn(doc: RailmlDoc, el: Any, rule: str, msg: str) -> Finding:
    return xt.finding(el, rule, msg, file=doc.file, table="balises", severity=Severity.WARNING)


End = tuple[str, str]


def _plain_exits(doc: RailmlDoc) -> dict[End, list[End]]:
    """Track end → the track ends joined to it by a connection through no switch."""
    out: dict[End, list[End]] = {}
    for lk in doc.links:
        if lk.switch_id is None:
            a, b = (lk.track_a, lk.end_a), (lk.track_b, lk.end_b)
            out.setdefault(a, []).append(b)
            out.setdefault(b, []).append(a)
    return out


def _follow(doc: RailmlDoc, exits: dict[End, list[End]], tid: str, pos: float) -> tuple[str, float] | None:
    """(railML track, pos) after moving past a track end along plain connections (each
    step: the distance past the end, from the joined end of the next track)."""
    for _ in range(len(doc.tracks)):
        length = doc.tracks[tid].length or 0.0
        if -END_TOLERANCE_M <= pos <= length + END_TOLERANCE_M:
            return tid, pos
        end = TrackEnd.END.value if pos > length else TrackEnd.BEGIN.value
        nxt = exits.get((tid, end), [])
        if len(nxt) != 1 or nxt[0][0] not in doc.tracks:
            return None
        t2, e2 = nxt[0]
        past = pos - length if end == TrackEnd.END.value else -pos
        pos = past if e2 == TrackEnd.BEGIN.value else (doc.tracks[t2].length or 0.0) - past
        tid = t2
    return None


def _place(doc: RailmlDoc, exits: dict[End, list[End]], b: RBalise, findings: list[Finding]) -> _Placed:
    where = _follow(doc, exits, b.track_id, b.pos)
    if where is None:
        piece, local = doc.piece_at(b.track_id, b.pos)
        return _Placed(b, piece, b.track_id, local)
    tid, pos = where
    if tid != b.track_id:
        findings.append(
            _warn(
                doc,
                b.el,
                "railml.position",
                f"balise {b.id}: @pos {b.pos:g} lies past the end of track {b.track_id}: placed on the track that "
                f"continues there, {tid}, at pos {pos:g}",
            )
        )
    piece, local = doc.piece_at(tid, pos)
    return _Placed(b, piece, tid, local)


def _numbered_together(a: str | None, b: str | None) -> bool:
    """Names that are both numbers lie less than :data:`NUMBER_SPAN` apart (any other names:
    no constraint)."""
    if a is None or b is None or not (a.isdigit() and b.isdigit()):
        return True
    return abs(int(a) - int(b)) < NUMBER_SPAN


def _same_group(a: _Placed, b: _Placed) -> bool:
    close = abs(b.b.km - a.b.km) < GROUP_SPAN_M and a.b.direction == b.b.direction and a.track == b.track
    return close and _numbered_together(a.b.name, b.b.name)


def _groups(doc: RailmlDoc, placed: list[_Placed]) -> list[tuple[str | None, list[_Placed]]]:
    by_key: dict[str, list[_Placed]] = {}
    loose: list[_Placed] = []
    for p in placed:
        if p.b.group is not None:
            by_key.setdefault(p.b.group, []).append(p)
        else:
            loose.append(p)
    out: list[tuple[str | None, list[_Placed]]] = list(by_key.items())
    current: list[_Placed] = []
    for p in sorted(loose, key=lambda x: (x.track, x.b.km, x.b.name or "", x.b.id)):
        if current and not _same_group(current[-1], p):
            out.append((None, current))
            current = []
        current.append(p)
    if current:
        out.append((None, current))
    return out


def _order(doc: RailmlDoc, key: str | None, members: list[_Placed]) -> list[_Placed]:
    group = doc.groups.get(key or "")
    if group is not None and group.direction:
        sign, along = group.direction, "km"
    else:
        dirs = {p.b.direction for p in members}
        sign, along = (dirs.pop() or 1) if len(dirs) == 1 else 1, "pos"
    return sorted(
        members,
        key=lambda p: ((p.b.km if along == "km" else p.pos) * sign, p.b.name or "", p.b.id),
    )


def _identity(doc: RailmlDoc, key: str | None, members: list[_Placed]) -> tuple[int | None, int | None]:
    group = doc.groups.get(key or "")
    nid_c = group.nid_c if group is not None and group.nid_c is not None else members[0].b.nid_c
    nid_bg = group.nid_bg if group is not None and group.nid_bg is not None else members[0].b.nid_bg
    return nid_c, nid_bg


def map_group_balises(
    doc: RailmlDoc, balises: list[RBalise], targets: dict[str, Target]
) -> tuple[list[dict[str, Any]], list[Finding]]:
    """G rows of ``balises`` and the findings (module doc)."""
    findings: list[Finding] = []
    rows: list[dict[str, Any]] = []
    exits = _plain_exits(doc)
    placed = [_place(doc, exits, b, findings) for b in balises if "kind" not in b.ext]
    rows += [_own_g(doc, b, targets) for b in balises if "kind" in b.ext]
    for key, members in _groups(doc, placed):
        ordered = _order(doc, key, members)
        nid_c, nid_bg = _identity(doc, key, ordered)
        first = ordered[0].b
        if (nid_c is not None and not 0 <= nid_c <= NID_C_MAX) or (
            nid_bg is not None and not 0 <= nid_bg <= NID_BG_MAX
        ):
            findings.append(
                _warn(
                    doc,
                    first.el,
                    "railml.value",
                    f"group of {first.id}: NID_C {nid_c} / NID_BG {nid_bg} out of range (0–1023 / 0–16383): left empty",
                )
            )
            nid_c = nid_bg = None
        if nid_bg is None:
            names = "/".join(p.b.name or p.b.id for p in ordered)
            findings.append(
                _warn(
                    doc,
                    first.el,
                    "railml.balise_identity",
                    f"balise group {names} ({len(ordered)} balise(s) from {first.id}) has no ETCS identity "
                    "(NID_C/NID_BG) in the file: imported as G rows with nid_bg empty",
                )
            )
        total = _total(doc, key, ordered, findings)
        for i, p in enumerate(ordered):
            rows.append(
                _row(p, targets.get(p.rail_track), nid_c, nid_bg, p.b.n_pig if p.b.n_pig is not None else i, total)
            )
    return rows, findings


def _total(doc: RailmlDoc, key: str | None, members: list[_Placed], findings: list[Finding]) -> int:
    group = doc.groups.get(key or "")
    stated = group.n_total if group is not None else None
    if stated is not None and stated != len(members):
        findings.append(
            _warn(
                doc,
                group.el,  # type: ignore[union-attr]
                "railml.balise_count",
                f"balise group {key}: numberOfBalisesInGroup {stated}, but {len(members)} balise(s) in the file",
            )
        )
    return stated if stated is not None else len(members)


def _row(
    p: _Placed, t: Target | None, nid_c: int | None, nid_bg: int | None, n_pig: int, n_total: int
) -> dict[str, Any]:
    return {
        "balise_id": p.b.id,
        "kind": BaliseKind.G.value,
        "line_code": t.line_code if t is not None else None,
        "station_code": None,
        "track": t.track if t is not None else None,
        "signal_type": None,
        "km_actual_m": p.b.km,
        "km_equipment_m": p.b.km,
        "dist_from_initial_m": None,
        "track_id": p.track,
        "nid_c": nid_c,
        "nid_bg": nid_bg,
        "n_pig": n_pig,
        "n_total": n_total,
        "link_group": None,
        "link_distance_m": None,
    }


def _opt_int(text: str | None) -> int | None:
    return None if text in (None, "") else int(text)  # type: ignore[arg-type]


def _opt_float(text: str | None) -> float | None:
    return None if text in (None, "") else float(text)  # type: ignore[arg-type]


def _own_g(doc: RailmlDoc, b: RBalise, targets: dict[str, Target]) -> dict[str, Any]:
    """A G row of our own export: its ``tpos:`` attributes verbatim."""
    e = b.ext
    t = targets.get(b.track_id)
    track = doc.tracks.get(b.track_id)
    return {
        "balise_id": b.id,
        "kind": BaliseKind.G.value,
        "line_code": e.get("lineCode") or (t.line_code if t is not None else None),
        "station_code": None,
        "track": e.get("track") or (t.track if t is not None else None),
        "signal_type": None,
        "km_actual_m": b.km,
        "km_equipment_m": _opt_float(e.get("kmEquipment")) if e.get("kmEquipment") else b.km,
        "dist_from_initial_m": None,
        "track_id": e.get("trackId") or (track.db_id or track.id if track is not None and not track.implied else None),
        "nid_c": _opt_int(e.get("nidC")),
        "nid_bg": _opt_int(e.get("nidBg")),
        "n_pig": _opt_int(e.get("nPig")),
        "n_total": _opt_int(e.get("nTotal")),
        "link_group": e.get("linkGroup") or None,
        "link_distance_m": _opt_float(e.get("linkDistance")),
    }
