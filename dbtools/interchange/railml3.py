"""railML 3.x (3.1–3.3) reader: netElements with their positioning, linear and geometric
positioning systems, balises and balise groups, signals, lines and tracks, horizontal
curves, mileage changes and gml locations.

* A netElement is a track of ours (:class:`~dbtools.interchange.model.RTrack`); ``pos`` is
  ``intrinsicCoord`` × ``@length`` (the intrinsic coordinate itself when the length is not
  given). Its mileage is the piecewise-linear map through the ``intrinsicCoordinate``\\ s of
  its ``associatedPositioningSystem`` that carry a ``linearCoordinate`` (the measure of a
  linear positioning system, which must be in metres: ``@units="m"``), with a jump at every
  ``mileageChange`` (3.2+: a ``spotLocation`` per side, ``@from`` incoming, ``@to`` outgoing).
* A located element's km is the ``measure`` of its ``spotLocation/linearCoordinate`` when
  given, else the mileage at its intrinsic coordinate.
* Coordinates: ``intrinsicCoordinate/geometricCoordinate`` (x = lon, y = lat in a geographic
  CRS, or easting/northing) in the ``@crsDefinition`` of its geometric positioning system;
  failing those, the ``gml:LineString`` of a track's ``gmlLocations``, each vertex placed by
  its geodesic chainage scaled to the netElement's length.
* ``horizontalCurve``: ``@curveType`` (straight, arc, clothoide, …), ``@radius`` (negative
  left as seen from the curve's begin), ``@length``, located by a ``linearLocation``.
* Topology (netRelations, switchesIS, crossings): :mod:`~dbtools.interchange.topology3`; a
  netElement's our-track id is our export's ``tpos:trackId`` (or a designator of our
  register), else ``@id``.
* Balise groups: ``isEurobaliseGroup/@countryID``/``@groupID`` (NID_C, NID_BG),
  ``@numberOfBalisesInGroup`` (N_TOTAL + 1), ``@mileageDirection`` (the group's direction).
* Ids: a balise's id, a line's code and a curve's feature id are the ``entry`` of its
  ``designator`` of our register (:mod:`~dbtools.interchange.railml_ids`, what our export
  writes) when it has one, else its ``@id`` (line: ``@code``; curve: its ``name``).
"""

from __future__ import annotations

from typing import Any

from dbtools.interchange import topology3
from dbtools.interchange import xmltree as xt
from dbtools.interchange.model import GeoPoint, Mileage, RailmlDoc, RBalise, RCurve, RGroup, RLine, RSignal, RTrack
from dbtools.interchange.railml_ids import REGISTER, designator
from dbtools.interchange.xmltree import Element

DIRECTIONS = {"normal": 1, "reverse": -1, "both": 0}
METRES = ("m", "metre", "meter", "metres", "meters")


def _ext(el: Element) -> dict[str, str]:
    return {k.rsplit("}", 1)[-1]: str(v) for k, v in el.attrib.items() if k.startswith("{" + xt.TPOS_NS)}


def _name(el: Element) -> str | None:
    n = xt.child(el, "name")
    return xt.attr(n, "name") if n is not None else xt.attr(el, "name")


class _Reader:
    def __init__(self, tree: Any, file: str, version: str) -> None:
        self.root = tree.getroot()
        self.doc = RailmlDoc(file=file, version=version, meta=_ext(self.root))
        self.lps: dict[str, Element] = {}
        self.crs: dict[str, str | None] = {}
        self.balise_ids: dict[str, Element] = {}

    def err(self, el: Element, rule: str, msg: str, column: str | None = None) -> None:
        self.doc.findings.append(xt.finding(el, rule, msg, file=self.doc.file, column=column))

    def num(self, el: Element, name: str) -> float | None:
        try:
            return xt.number(el, name)
        except ValueError:
            self.err(el, "railml.value", f"@{name} '{xt.attr(el, name)}' is not a number", column=name)
            return None

    # ------------------------------------------------------------------ positioning systems

    def positioning(self) -> None:
        for pos in xt.descend(self.root, "common", "positioning"):
            self.doc.use(pos.getparent(), pos, *xt.children(pos))
            for el in xt.descend(pos, "linearPositioningSystems", "linearPositioningSystem"):
                self._lps(el)
            for el in xt.descend(pos, "geometricPositioningSystems", "geometricPositioningSystem"):
                ident = xt.attr(el, "id")
                if ident:
                    self.crs[ident] = xt.attr(el, "crsDefinition")
                    self.doc.use(el, *xt.children(el))

    def _lps(self, el: Element) -> None:
        ident = xt.attr(el, "id")
        if ident is None:
            self.err(el, "railml.missing_id", "linearPositioningSystem has no @id", column="id")
            return
        units = xt.attr(el, "units") or "m"
        if units.lower() not in METRES:
            self.err(el, "railml.units", f"@units '{units}': only metres are accepted (km in metres)", column="units")
            return
        self.lps[ident] = el
        self.doc.use(el, *xt.children(el, "name"))
        anchors = xt.children(el, "anchor")
        for a in anchors:
            self.doc.use(a)
            ext = _ext(a)
            if "track" in ext and "kmTo" in ext:
                self.doc.km_breaks.append(
                    {
                        "line_code": _ext(el).get("lineCode", ident),
                        "track": ext["track"],
                        "km_from_m": self.num(a, "measure"),
                        "km_to_m": float(ext["kmTo"]),
                    }
                )

    # ------------------------------------------------------------------ topology

    def net_elements(self) -> None:
        topo = xt.descend(self.root, "infrastructure", "topology")
        for t in topo:
            self.doc.use(t.getparent(), t, *xt.children(t, "netElements"))
        for el in [e for t in topo for e in xt.descend(t, "netElements", "netElement")]:
            ident = xt.attr(el, "id")
            if ident is None:
                self.err(el, "railml.missing_id", "netElement has no @id", column="id")
                continue
            ext = _ext(el)
            track = RTrack(ident, el, name=_name(el), length=self.num(el, "length"), ext=ext)
            track.db_id, track.kind = designator(el) or ext.get("trackId"), ext.get("kind")
            # our export's line carriers, and meso/macro netElements (aggregates of others):
            # not tracks
            groups = [*xt.children(el, "elementCollectionUnordered"), *xt.children(el, "elementCollectionOrdered")]
            track.implied = ext.get("implied") == "true" or bool(groups)
            self.doc.use(*groups, *[c for g in groups for c in xt.children(g)])
            self.doc.use(el, *xt.children(el, "name"), *xt.children(el, "designator"))
            self._intrinsic(track)
            self.doc.tracks[ident] = track

    def _scale(self, track: RTrack) -> float:
        return track.length if track.length else 1.0

    def _intrinsic(self, track: RTrack) -> None:
        knots: list[tuple[float, float]] = []
        for aps in xt.children(track.el, "associatedPositioningSystem"):
            self.doc.use(aps)
            for ic in xt.children(aps, "intrinsicCoordinate"):
                self.doc.use(ic)
                t = self.num(ic, "intrinsicCoord")
                if t is None:
                    continue
                pos = t * self._scale(track)
                lin = xt.child(ic, "linearCoordinate")
                km = self._measure(lin) if lin is not None else None
                if km is not None:
                    knots.append((pos, km))
                geo = xt.child(ic, "geometricCoordinate")
                if geo is not None:
                    self._geometric(track, geo, pos, km)
        knots.sort(key=lambda k: k[0])
        if knots:
            track.mileage = Mileage(knots)

    def _measure(self, lin: Element) -> float | None:
        self.doc.use(lin)
        ref = xt.attr(lin, "positioningSystemRef")
        if ref is not None and ref not in self.lps:
            self.err(
                lin,
                "railml.undefined_ref",
                f"positioningSystemRef '{ref}' is not a linear positioning system in metres",
            )
            return None
        return self.num(lin, "measure")

    def _geometric(self, track: RTrack, geo: Element, pos: float, km: float | None) -> None:
        from dbtools.interchange.geometry import to_lonlat

        self.doc.use(geo)
        crs = self.crs.get(xt.attr(geo, "positioningSystemRef") or "")
        try:
            vals = [v for v in (self.num(geo, "x"), self.num(geo, "y"), self.num(geo, "z")) if v is not None]
            lon, lat, h = to_lonlat(vals, crs, xy=True)
        except ValueError as exc:
            self.err(geo, "railml.geocoord", f"geometricCoordinate: {exc}")
            return
        track.geo.append(GeoPoint(pos, km if km is not None else float("nan"), lon, lat, h, vertex_only=km is None))

    # ------------------------------------------------------------------ locations

    def spot(self, el: Element) -> tuple[RTrack, float, float, int] | None:
        """(track, pos, km, direction) of an element's first spotLocation."""
        loc = xt.child(el, "spotLocation")
        if loc is None:
            self.err(el, "railml.position", f"{xt.local(el)} has no spotLocation")
            return None
        self.doc.use(loc)
        ref = xt.attr(loc, "netElementRef")
        track = self.doc.tracks.get(ref or "")
        if track is None:
            self.err(
                loc, "railml.undefined_track", f"netElementRef '{ref}' names no netElement", column="netElementRef"
            )
            return None
        t = self.num(loc, "intrinsicCoord")
        lin = xt.child(loc, "linearCoordinate")
        km = self._measure(lin) if lin is not None else None
        pos = t * self._scale(track) if t is not None else None
        own = xt.tpos(el, "kmActual")  # our export's G balise on a track along no line's km
        if km is None and own is not None:
            km = float(own)
        if km is None and (pos is None or track.mileage is None):
            self.err(loc, "railml.no_mileage", "no linearCoordinate and no mileage on its netElement")
            return None
        if km is None:
            km = track.mileage.km(pos)  # type: ignore[union-attr, arg-type]
        if t is not None and not -1e-9 <= t <= 1 + 1e-9:
            self.err(loc, "railml.position", f"@intrinsicCoord {t:g} is outside [0, 1]", column="intrinsicCoord")
            return None
        return track, pos if pos is not None else 0.0, km, DIRECTIONS.get(xt.attr(loc, "applicationDirection") or "", 0)

    def linear(self, el: Element) -> tuple[RTrack, float, float, bool] | None:
        """(track, km at begin, km at end, km rising along the element) of a linearLocation."""
        ane = xt.descend(el, "linearLocation", "associatedNetElement")
        if not ane:
            self.err(el, "railml.position", f"{xt.local(el)} has no linearLocation/associatedNetElement")
            return None
        a = ane[0]
        self.doc.use(xt.child(el, "linearLocation"), a, *xt.children(a))
        track = self.doc.tracks.get(xt.attr(a, "netElementRef") or "")
        if track is None:
            self.err(a, "railml.undefined_track", f"netElementRef '{xt.attr(a, 'netElementRef')}' names no netElement")
            return None
        kms = []
        for side in ("Begin", "End"):
            lin = xt.child(a, f"linearCoordinate{side}")
            t = self.num(a, f"intrinsicCoord{side}")
            km = self._measure(lin) if lin is not None else None
            if km is None and t is not None and track.mileage is not None:
                km = track.mileage.km(t * self._scale(track))
            if km is None:
                self.err(a, "railml.no_mileage", f"no km for the {side.lower()} of {xt.local(el)}")
                return None
            kms.append(km)
        return track, min(kms), max(kms), kms[1] >= kms[0]


def read(tree: Any, file: str, version: str) -> RailmlDoc:
    r = _Reader(tree, file, version)
    r.doc.use(r.root)
    for md in xt.children(r.root, "metadata"):  # descriptive (Dublin Core): nothing to map
        r.doc.use(*md.iter())
    for net in xt.descend(r.root, "infrastructure", "topology", "networks"):  # levels of the netElements read
        r.doc.use(*net.iter())
    r.doc.use(*xt.descend(r.root, "infrastructure", "topology", "netRelations"))
    r.positioning()
    r.net_elements()
    _mileage_changes(r)
    topology3.read(r.doc, r.root, r.spot)
    fi = xt.descend(r.root, "infrastructure", "functionalInfrastructure")
    for f in fi:
        r.doc.use(f, *xt.children(f, "lines"), *xt.children(f, "tracks"), *xt.children(f, "balises"))
        r.doc.use(*xt.children(f, "baliseGroups"), *xt.children(f, "signalsIS"), *xt.children(f, "mileageChanges"))
    for el in [e for f in fi for e in xt.descend(f, "lines", "line")]:
        _line(r, el)
    for el in [e for f in fi for e in xt.descend(f, "tracks", "track")]:
        _track(r, el)
    for el in [e for f in fi for e in xt.descend(f, "signalsIS", "signalIS")]:
        _signal(r, el)
    for el in [e for f in fi for e in xt.descend(f, "baliseGroups", "baliseGroup")]:
        _group(r, el)
    for el in [e for f in fi for e in xt.descend(f, "balises", "balise")]:
        _balise(r, el)
    geometry = xt.descend(r.root, "infrastructure", "geometry")
    r.doc.use(*geometry, *[c for g in geometry for c in xt.children(g, "horizontalCurves")])
    for el in [e for g in geometry for e in xt.descend(g, "horizontalCurves", "horizontalCurve")]:
        _curve(r, el)
    return r.doc


def _mileage_changes(r: _Reader) -> None:
    """3.2+ ``mileageChange``: a jump from the ``@from`` measure to the ``@to`` measure."""
    for mc in xt.descend(r.root, "infrastructure", "functionalInfrastructure", "mileageChanges", "mileageChange"):
        spots = {xt.attr(s, "id"): s for s in xt.children(mc, "spotLocation")}
        a, b = spots.get(xt.attr(mc, "from")), spots.get(xt.attr(mc, "to"))
        if a is None or b is None:
            r.err(mc, "railml.mileage", "mileageChange needs spotLocations named by @from and @to")
            continue
        track = r.doc.tracks.get(xt.attr(a, "netElementRef") or "")
        la, lb = xt.child(a, "linearCoordinate"), xt.child(b, "linearCoordinate")
        t = r.num(a, "intrinsicCoord")
        if track is None or la is None or lb is None or t is None:
            r.err(mc, "railml.mileage", "mileageChange spotLocations need a netElement, intrinsicCoord and measures")
            continue
        k_in, k_out = r._measure(la), r._measure(lb)
        if k_in is None or k_out is None:
            continue
        pos = t * r._scale(track)
        knots = [k for k in (track.mileage.knots if track.mileage else []) if k[0] != pos]
        knots += [(pos, k_in), (pos, k_out)]
        track.mileage = Mileage(sorted(knots, key=lambda k: k[0]))
        r.doc.use(mc, a, b)


def _associated(r: _Reader, el: Element) -> list[str]:
    refs = []
    for a in xt.descend(el, "linearLocation", "associatedNetElement"):
        ref = xt.attr(a, "netElementRef")
        r.doc.use(a.getparent(), a, *xt.children(a))
        if ref not in r.doc.tracks:
            r.err(a, "railml.undefined_track", f"netElementRef '{ref}' names no netElement", column="netElementRef")
            continue
        refs.append(ref)
    return refs


def _line(r: _Reader, el: Element) -> None:
    ident = xt.attr(el, "id")
    if ident is None:
        r.err(el, "railml.missing_id", "line has no @id", column="id")
        return
    ext = _ext(el)
    code = ext.get("lineCode") or designator(el) or xt.attr(el, "code")
    line = RLine(ident, el, code=code, name=_name(el), ext=ext)
    r.doc.use(el, *xt.children(el, "name"), *xt.children(el, "designator"))
    for ref in _associated(r, el):
        line.track_ids.append(ref)
        r.doc.tracks[ref].line_id = ident
    r.doc.lines[ident] = line


def _track(r: _Reader, el: Element) -> None:
    """A functional track: its netElements get its name, and its gml geometry when they have none."""
    r.doc.use(el, *xt.children(el, "name"))
    refs = _associated(r, el)
    for ref in refs:
        t = r.doc.tracks[ref]
        t.name = t.name or _name(el)
    for gml in xt.children(el, "gmlLocations"):
        r.doc.use(gml, *gml.iter())
        if len(refs) == 1 and not r.doc.tracks[refs[0]].geo:
            _gml_vertices(r, r.doc.tracks[refs[0]], gml)


def _gml_vertices(r: _Reader, track: RTrack, gml: Element) -> None:
    """The vertices of a track's gml LineString; each gets its chainage (geodesic distance
    along the line, scaled to the netElement's length) and, through the netElement's
    mileage, a km — so they are kilometre posts too."""
    import numpy as np

    from dbtools.gis.geometry import geodesic_step
    from dbtools.interchange.geometry import to_lonlat

    for ls in xt.iter_named(gml, "LineString"):
        crs = ls.get("srsName")
        dim = int(ls.get("srsDimension") or 2)
        pos_list = next(xt.iter_named(ls, "posList"), None)
        values = [float(v) for v in (pos_list.text or "").split()] if pos_list is not None else []
        try:
            pts = [to_lonlat(values[i : i + dim], crs) for i in range(0, len(values) - dim + 1, dim)]
        except ValueError as exc:
            r.err(ls, "railml.geocoord", f"gml posList: {exc}")
            return
        if len(pts) < 2:
            continue
        s = np.concatenate([[0.0], np.cumsum(geodesic_step([p[0] for p in pts], [p[1] for p in pts]))])
        scale = track.length / s[-1] if track.length and s[-1] > 0 else 1.0
        for (lon, lat, h), si in zip(pts, s.tolist(), strict=True):
            km = track.mileage.km(si * scale) if track.mileage is not None else float("nan")
            track.geo.append(GeoPoint(si * scale, km, lon, lat, h, vertex_only=track.mileage is None))


def _signal(r: _Reader, el: Element) -> None:
    ident = xt.attr(el, "id")
    where = r.spot(el) if ident else None
    if ident is None or where is None:
        return
    function = xt.attr(el, "function") or xt.attr(el, "signalFunction") or xt.attr(el, "type")
    r.doc.signals[ident] = RSignal(ident, el, where[0].id, where[2], where[3], function)


def _group(r: _Reader, el: Element) -> None:
    ident = xt.attr(el, "id")
    if ident is None:
        r.err(el, "railml.missing_id", "baliseGroup has no @id", column="id")
        return
    conn = xt.child(el, "connectedWithInfrastructureElement")
    func = xt.child(el, "functionalType")
    r.doc.use(
        el, conn, func, *xt.children(el, "name"), *xt.children(el, "applicationType"), *xt.children(el, "spotLocation")
    )
    for s in xt.children(el, "spotLocation"):
        r.doc.use(*xt.children(s))
    function = (xt.attr(func, "value") or (func.text or "").strip() or None) if func is not None else None
    group = RGroup(ident, el, xt.attr(conn, "ref") if conn is not None else None, function)
    euro = xt.child(el, "isEurobaliseGroup")
    if euro is not None:
        r.doc.use(euro)
        group.etcs = True
        group.nid_c, group.nid_bg = _int(r, euro, "countryID"), _int(r, euro, "groupID")
    group.n_total = _int(r, el, "numberOfBalisesInGroup")
    group.direction = {"nominal": 1, "reverse": -1}.get(xt.attr(el, "mileageDirection") or "", 0)
    r.doc.groups[ident] = group


def _int(r: _Reader, el: Element, name: str) -> int | None:
    value = r.num(el, name)
    return None if value is None else int(value)


def _balise_id(r: _Reader, el: Element) -> str | None:
    """The DB id of a balise: the entry of its designator of our register, else its @id; a
    designator entry that another balise already has is a duplicate id (``@id`` duplicates
    are found document-wide by the importer)."""
    entry = designator(el)
    ident = entry or xt.attr(el, "id")
    if ident is None:
        r.err(el, "railml.missing_id", "balise has no @id", column="id")
        return None
    first = r.balise_ids.get(ident)
    if first is not None and (entry is not None or designator(first) is not None):
        r.err(
            el,
            "railml.duplicate_id",
            f"balise id '{ident}' (designator of register {REGISTER}) is used again"
            f" (first at line {xt.line_of(first)})",
            column="designator",
        )
        return None
    r.balise_ids[ident] = el
    return ident


def _balise(r: _Reader, el: Element) -> None:
    ident = _balise_id(r, el)
    if ident is None:
        return
    where = r.spot(el)
    if where is None:
        return
    parent = xt.child(el, "belongsToParent")
    group = xt.attr(parent, "ref") if parent is not None else None
    if group is not None and group not in r.doc.groups:
        r.err(parent, "railml.undefined_ref", f"belongsToParent names balise group '{group}', which is not defined")
        return
    r.doc.use(el, parent, *xt.children(el, "name"), *xt.children(el, "designator"))
    track, pos, km, direction = where
    r.doc.balises.append(RBalise(ident, el, track.id, pos, km, _name(el), direction, group, _ext(el)))


def _curve(r: _Reader, el: Element) -> None:
    where = r.linear(el)
    if where is None:
        return
    track, k0, k1, rising = where
    radius = r.num(el, "radius") or 0.0
    kind = (xt.attr(el, "curveType") or "").strip() or "straight"
    r.doc.use(*xt.children(el, "name"), *xt.children(el, "designator"))  # the curve: used or reported by the mapping
    fid = designator(el) or _name(el)  # the feature id: our register's designator, else the railML name
    r.doc.curves.append(
        RCurve(xt.attr(el, "id") or "", el, track.id, k0, k1, kind, radius if rising else -radius, _ext(el), fid)
    )
