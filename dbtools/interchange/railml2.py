"""railML 2.x (2.0–2.5) reader: tracks, mileage, balises, signals, radius changes, lines,
coordinates.

* Mileage of a track: ``trackBegin/@absPos`` at its ``pos`` (direction ``@absDir`` raising
  or falling, else from ``trackEnd/@absPos``), ``trackEnd/@absPos`` at its end, and every
  ``mileageChanges/mileageChange``: at its ``pos`` the km jumps from ``@absPosIn`` (the
  incoming mileage) to ``@absPos`` (the outgoing one, which the elements after it use).
  An element's km is its own ``@absPos`` when given (a stated km is kept); the km derived
  from its ``pos`` is compared with it and a difference over :data:`ABSPOS_TOLERANCE_M` is
  reported.
* Coordinates: every ``geoCoord`` child (``@coord`` in the order of ``@epsgCode``, default
  WGS 84 lat lon [h]) of an element with a ``pos`` on the track (trackBegin, trackEnd,
  mileageChange, geoMapping, balise …).
* Curves: ``trackElements/radiusChanges/radiusChange``: ``@radius`` [m] valid from its pos to
  the next one (0 straight, negative left in the direction of increasing pos — the railML 3
  convention), ``@geometryElementDescription`` naming transitions (clothoid …).
"""

from __future__ import annotations

from dbtools.interchange import topology2
from dbtools.interchange import xmltree as xt
from dbtools.interchange.model import GeoPoint, Mileage, RailmlDoc, RBalise, RCurve, RGroup, RLine, RSignal, RTrack
from dbtools.interchange.xmltree import Element
from schemas.enums import Severity

#: A stated absPos may differ from the km derived from pos by this much [m].
ABSPOS_TOLERANCE_M = 1.0
#: A position may lie this far beyond a track's end [m] (rounding in the source).
END_TOLERANCE_M = 0.5

DIRECTIONS = {"up": 1, "down": -1, "both": 0, "none": 0, "unknown": 0}


def read(tree: object, file: str, version: str) -> RailmlDoc:
    root = tree.getroot()  # type: ignore[attr-defined]
    doc = RailmlDoc(file=file, version=version)
    doc.use(root)
    for infra in xt.children(root, "infrastructure"):
        doc.use(infra, xt.child(infra, "tracks"), xt.child(infra, "trackGroups"))
        for el in xt.descend(infra, "tracks", "track"):
            _track(doc, el)
        for el in xt.descend(infra, "trackGroups", "line"):
            _line(doc, el)
        topology2.read(doc, infra)
    return doc


def _err(doc: RailmlDoc, el: Element, rule: str, msg: str, column: str | None = None) -> None:
    doc.findings.append(xt.finding(el, rule, msg, file=doc.file, column=column))


def _num(doc: RailmlDoc, el: Element, name: str) -> float | None:
    try:
        return xt.number(el, name)
    except ValueError:
        _err(doc, el, "railml.value", f"@{name} '{xt.attr(el, name)}' is not a number [m]", column=name)
        return None


def _track(doc: RailmlDoc, el: Element) -> None:
    ident = xt.attr(el, "id")
    if ident is None:
        _err(doc, el, "railml.missing_id", "track has no @id", column="id")
        return
    topo = xt.child(el, "trackTopology")
    begin = xt.child(topo, "trackBegin") if topo is not None else None
    end = xt.child(topo, "trackEnd") if topo is not None else None
    doc.use(topo, begin, end, xt.child(el, "trackElements"), xt.child(el, "ocsElements"))
    if begin is None or end is None:
        _err(doc, el, "railml.topology", "track has no trackTopology/trackBegin and trackEnd")
        return
    p0 = _num(doc, begin, "pos") or 0.0
    p1 = _num(doc, end, "pos")
    track = RTrack(ident, el, name=xt.attr(el, "name"), length=None if p1 is None else p1 - p0)
    doc.use(el)
    track.mileage = _mileage(doc, topo, begin, end, p0, p1)
    doc.tracks[ident] = track
    for conn in xt.iter_named(begin, "connection"):
        doc.use(conn)
    for conn in xt.iter_named(end, "connection"):
        doc.use(conn)
    for e in el.iter():
        geo = xt.child(e, "geoCoord") if xt.local(e) else None
        if geo is not None and xt.attr(e, "pos") is not None:
            _geo(doc, track, e, geo)
    for b in xt.descend(el, "ocsElements", "balises", "balise"):
        _balise(doc, track, b)
    for g in xt.descend(el, "ocsElements", "balises", "baliseGroup"):
        _balise_group(doc, track, g)
    doc.use(*xt.descend(el, "ocsElements", "balises"))
    for s in xt.descend(el, "ocsElements", "signals", "signal"):
        _signal(doc, track, s)
    _radius_changes(doc, track, xt.descend(el, "trackElements", "radiusChanges", "radiusChange"))


def _mileage(
    doc: RailmlDoc, topo: Element, begin: Element, end: Element, p0: float, p1: float | None
) -> Mileage | None:
    km0 = _num(doc, begin, "absPos")
    km1 = _num(doc, end, "absPos")
    if km0 is None:
        return None
    sign = -1.0 if (xt.attr(begin, "absDir") == "falling" or (km1 is not None and km1 < km0)) else 1.0
    knots = [(p0, km0)]
    changes = xt.descend(topo, "mileageChanges", "mileageChange")
    doc.use(*xt.descend(topo, "mileageChanges"))
    for mc in sorted(changes, key=lambda e: _num(doc, e, "pos") or 0.0):
        pos, k_in, k_out = _num(doc, mc, "pos"), _num(doc, mc, "absPosIn"), _num(doc, mc, "absPos")
        if pos is None or k_out is None:
            _err(doc, mc, "railml.mileage", "mileageChange needs @pos and @absPos [m]")
            continue
        knots.append((pos, k_in if k_in is not None else Mileage(knots).km(pos)))
        knots.append((pos, k_out))
        if xt.attr(mc, "absDir") in ("raising", "falling"):
            sign = 1.0 if xt.attr(mc, "absDir") == "raising" else -1.0
        doc.use(mc)
    if p1 is not None and km1 is not None:
        knots.append((p1, km1))
    elif len(knots) == 1 or knots[-1][0] == knots[-2][0]:
        knots.append((knots[-1][0] + 1.0, knots[-1][1] + sign))
    return Mileage(knots)


def _position(doc: RailmlDoc, track: RTrack, el: Element) -> tuple[float, float] | None:
    """(pos, km) of a placed element; findings for a missing pos or km, or pos off the track."""
    pos = _num(doc, el, "pos")
    if pos is None:
        _err(doc, el, "railml.position", f"{xt.local(el)} has no @pos on track {track.id}", column="pos")
        return None
    stated = _num(doc, el, "absPos")
    if pos < -END_TOLERANCE_M or (track.length is not None and pos > track.length + END_TOLERANCE_M):
        where = f"@pos {pos:g} m is outside track {track.id} (length {track.length or 0:g} m)"
        if stated is None:
            _err(doc, el, "railml.position", f"{where} and has no @absPos", column="pos")
            return None
        doc.findings.append(  # the stated mileage still places it on the line
            xt.finding(
                el,
                "railml.position",
                f"{where}; placed by its @absPos {stated:g} on the same line and track",
                file=doc.file,
                severity=Severity.WARNING,
                column="pos",
            )
        )
        return pos, stated
    derived = track.mileage.km(pos) if track.mileage is not None else None
    if stated is None and derived is None:
        _err(doc, el, "railml.no_mileage", f"no @absPos and track {track.id} has no mileage (trackBegin/@absPos)")
        return None
    if stated is not None and derived is not None and abs(stated - derived) > ABSPOS_TOLERANCE_M:
        doc.findings.append(
            xt.finding(
                el,
                "railml.mileage",
                f"@absPos {stated:g} differs from the km derived from @pos ({derived:.1f}) by "
                f"{stated - derived:+.1f} m; @absPos used",
                file=doc.file,
                severity=Severity.WARNING,
                column="absPos",
            )
        )
    return pos, stated if stated is not None else float(derived)  # type: ignore[arg-type]


def _geo(doc: RailmlDoc, track: RTrack, el: Element, geo: Element) -> None:
    from dbtools.interchange.geometry import to_lonlat

    where = _position(doc, track, el)
    coord = (xt.attr(geo, "coord") or "").split()
    try:
        values = [float(c) for c in coord]
        lon, lat, h = to_lonlat(values, xt.attr(geo, "epsgCode"))
    except ValueError as exc:
        _err(doc, geo, "railml.geocoord", f"geoCoord/@coord '{' '.join(coord)}': {exc}", column="coord")
        return
    doc.use(geo)
    if where is None:
        return
    if xt.local(el) == "mileageChange":  # a kilometre post with a break: in → out
        k_in = _num(doc, el, "absPosIn")
        track.geo.append(GeoPoint(where[0], k_in if k_in is not None else where[1], lon, lat, h, km_after=where[1]))
    else:
        track.geo.append(GeoPoint(where[0], where[1], lon, lat, h))


def _balise(doc: RailmlDoc, track: RTrack, el: Element) -> None:
    ident = xt.attr(el, "id")
    if ident is None:
        _err(doc, el, "railml.missing_id", "balise has no @id", column="id")
        return
    where = _position(doc, track, el)
    if where is None:
        return
    doc.use(el)  # written, or reported by the balise mapping
    parent = el.getparent()
    in_group = parent is not None and xt.local(parent) == "baliseGroup"
    group = xt.attr(parent, "id") if in_group else xt.attr(el, "baliseGroupRef")
    ext = {k.rsplit("}", 1)[-1]: str(v) for k, v in el.attrib.items() if k.startswith("{" + xt.TPOS_NS)}
    nid_c, nid_bg = _int(doc, el, "countryID"), _int(doc, el, "groupID")
    if group is None and nid_bg is not None:
        group = f"{nid_c}:{nid_bg}"
    doc.balises.append(
        RBalise(
            ident,
            el,
            track.id,
            where[0],
            where[1],
            name=xt.attr(el, "name"),
            direction=DIRECTIONS.get(xt.attr(el, "dir") or "", 0),
            group=group,
            ext=ext,
            nid_c=nid_c,
            nid_bg=nid_bg,
            n_pig=_int(doc, el, "ndx"),
        )
    )


def _int(doc: RailmlDoc, el: Element, name: str) -> int | None:
    """An integer attribute (ETCS NID_C, NID_BG, N_PIG): None when absent, a warning when not
    an integer."""
    text = xt.attr(el, name)
    if text is None:
        return None
    try:
        return int(text)
    except ValueError:
        doc.findings.append(
            xt.finding(
                el,
                "railml.value",
                f"@{name} '{text}' is not an integer: ignored",
                file=doc.file,
                severity=Severity.WARNING,
                column=name,
            )
        )
        return None


def _balise_group(doc: RailmlDoc, track: RTrack, el: Element) -> None:
    """railML 2 ``baliseGroup`` holding its ``balise`` elements: the group of each."""
    ident = xt.attr(el, "id")
    if ident is None:
        _err(doc, el, "railml.missing_id", "baliseGroup has no @id", column="id")
        return
    doc.use(el)
    doc.groups[ident] = RGroup(ident, el, nid_c=_int(doc, el, "countryID"), nid_bg=_int(doc, el, "groupID"))
    for b in xt.children(el, "balise"):
        _balise(doc, track, b)


def _signal(doc: RailmlDoc, track: RTrack, el: Element) -> None:
    ident = xt.attr(el, "id")
    pos = _num(doc, el, "pos")
    km = _num(doc, el, "absPos")
    if km is None and pos is not None and track.mileage is not None:
        km = track.mileage.km(pos)
    if ident is None or km is None:
        return  # reported as not mapped (or for its missing id) by the importer
    function = xt.attr(el, "function") or xt.attr(el, "type")
    doc.signals[ident] = RSignal(ident, el, track.id, km, DIRECTIONS.get(xt.attr(el, "dir") or "", 0), function)


def _radius_changes(doc: RailmlDoc, track: RTrack, changes: list[Element]) -> None:
    """Consecutive radiusChanges → curve pieces (the last one runs to the track end)."""
    placed = []
    for el in changes:
        where = _position(doc, track, el)
        radius = _num(doc, el, "radius")
        if where is None or radius is None:
            continue
        placed.append((where[1], radius, el))
    placed.sort(key=lambda t: t[0])
    end_km = track.mileage.km(track.length or 0.0) if track.mileage is not None and track.length else None
    for i, (km, radius, el) in enumerate(placed):
        km_to = placed[i + 1][0] if i + 1 < len(placed) else end_km
        if km_to is None or km_to <= km:
            continue
        descr = (xt.attr(el, "geometryElementDescription") or "").lower()
        kind = "straight" if radius == 0 else ("clothoide" if "cloth" in descr or "trans" in descr else "arc")
        doc.curves.append(RCurve(xt.attr(el, "id") or "", el, track.id, km, km_to, kind, radius))


def _line(doc: RailmlDoc, el: Element) -> None:
    ident = xt.attr(el, "id")
    if ident is None:
        _err(doc, el, "railml.missing_id", "line has no @id", column="id")
        return
    line = RLine(ident, el, code=xt.attr(el, "code"), name=xt.attr(el, "name"))
    doc.use(el)
    for ref in xt.children(el, "trackRef"):
        target = xt.attr(ref, "ref")
        if target is None and xt.attr(ref, "id") in doc.tracks:  # some generators write @id for @ref
            target = xt.attr(ref, "id")
            doc.quirks.add(id(ref))
            doc.findings.append(
                xt.finding(
                    ref,
                    "railml.quirk",
                    f"trackRef has @id '{target}' instead of @ref: read as the reference",
                    file=doc.file,
                    severity=Severity.WARNING,
                    column="ref",
                )
            )
        if target not in doc.tracks:
            _err(doc, ref, "railml.undefined_track", f"trackRef names track '{target}', which is not defined")
            continue
        doc.use(ref)
        line.track_ids.append(target)
        doc.tracks[target].line_id = ident
    doc.lines[ident] = line
