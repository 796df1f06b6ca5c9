"""Reading a RailTopoModel network in GeoJSON, the format of tp-lib (Matdata-eu/tp-lib,
``tp-core/src/io/geojson.rs``): netelements and netrelations in one ``FeatureCollection``.

* **netelement**: a feature with a ``LineString`` (or ``MultiLineString``: its first part,
  as tp-lib) geometry and an ``id`` property (string or integer; the feature's own ``id``
  member where the property is absent). Position 0 is its first vertex, 1 its last.
* **netrelation**: a feature whose ``type`` property is ``netrelation`` (or that carries
  ``netelementA``/``netelementB``), geometry optional (a ``Point`` at the node): ``id``,
  ``netelementA`` and ``netelementB`` (tp-lib also reads ``from``/``to``), ``positionOnA``
  and ``positionOnB`` ∈ {0, 1} (integers or 0.0/1.0), ``navigability`` ∈ {both, AB, BA,
  none}, case-insensitive as tp-lib reads it (AB: a train may pass from A to B only).
* **CRS**: the collection's ``crs`` member (GeoJSON 2008 §3: ``{"type": "name",
  "properties": {"name": "EPSG:25832"}}``, also ``urn:ogc:def:crs:EPSG::4326`` and
  ``urn:ogc:def:crs:OGC:1.3:CRS84``); without it WGS 84 lon/lat (RFC 7946 §4). A feature's
  own ``crs`` property (RINF exports carry one) overrides it for that feature. Coordinates
  are read in (x, y) = (lon, lat) or (easting, northing) order, as GeoJSON writes them,
  and transformed to WGS 84 lon/lat with PROJ (``always_xy``).

Problems are :class:`~schemas.findings.Finding` s (rule ids ``rtm.*``) naming the feature's
index in ``features`` and its id; a feature with a problem is skipped (warning), the rest
imported. A relation whose two ends lie more than :data:`GAP_WARN_M` apart is reported
(``rtm.gap``: a positionOn the wrong way round?) and kept. A relation listed twice (RINF
exports list every relation from both sides) is kept once; the copies are counted in the
report.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from dbtools.interchange.polyline import GEOD, Polyline, polyline
from schemas.enums import Navigability, Severity
from schemas.errors import FindingsError, InputError
from schemas.findings import Finding

WGS84_NAME = "EPSG:4326"
NAVIGABILITY = {n.value.lower(): n.value for n in Navigability}
#: Ends joined by a relation farther apart than this are reported (``rtm.gap``) [m]; RINF's
#: lie up to about 2 m apart.
GAP_WARN_M = 5.0


@dataclass(frozen=True)
class NetElement:
    id: str
    index: int
    line: Polyline
    """WGS 84 lon/lat vertices with their geodesic distances."""
    name: str | None = None


@dataclass(frozen=True)
class NetRelation:
    id: str
    index: int
    a: str
    pos_a: int
    b: str
    pos_b: int
    navigability: str

    @property
    def ends(self) -> frozenset[tuple[str, int]]:
        return frozenset(((self.a, self.pos_a), (self.b, self.pos_b)))


@dataclass
class RtmDoc:
    file: str
    crs: str
    elements: dict[str, NetElement] = field(default_factory=dict)
    relations: list[NetRelation] = field(default_factory=list)
    findings: list[Finding] = field(default_factory=list)
    netelements_seen: int = 0
    netrelations_seen: int = 0
    relations_merged: int = 0
    by_ends: dict[frozenset[tuple[str, int]], NetRelation] = field(default_factory=dict, repr=False)

    def finding(
        self,
        rule: str,
        message: str,
        index: int | None,
        ident: Any = None,
        *,
        column: str | None = None,
        table: str = "",
    ) -> None:
        keys: dict[str, Any] = {} if index is None else {"feature": index}
        if ident is not None:
            keys["id"] = ident
        where = "" if index is None else f"feature {index}" + (f" (id '{ident}')" if ident is not None else "") + ": "
        self.findings.append(
            Finding(
                rule, Severity.WARNING, table or "tracks", where + message, keys=keys, file=self.file, column=column
            )
        )


class _Crs:
    """Transformers to WGS 84 lon/lat, one per CRS name."""

    def __init__(self) -> None:
        self._cache: dict[str, Any] = {}

    def transformer(self, name: str) -> Any:
        """A PROJ transformer (always_xy); ValueError naming what is wrong."""
        if name not in self._cache:
            from pyproj import CRS, Transformer
            from pyproj.exceptions import CRSError

            text = "OGC:CRS84" if name.strip().upper() == "CRS84" else name
            try:
                crs = CRS.from_user_input(text)
            except CRSError as exc:
                raise ValueError(f"unknown CRS '{name}' (PROJ: {exc})") from None
            if not (crs.is_geographic or crs.is_projected):
                raise ValueError(f"CRS '{name}' is neither geographic nor projected")
            self._cache[name] = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        return self._cache[name]


def crs_name(data: dict[str, Any]) -> str:
    """The name in the collection's ``crs`` member (WGS 84 without one); ValueError when the
    member is there but names no CRS (a ``link`` CRS, a missing name)."""
    crs = data.get("crs")
    if crs is None:
        return WGS84_NAME
    name = crs.get("properties", {}).get("name") if isinstance(crs, dict) and crs.get("type") == "name" else None
    if not isinstance(name, str) or not name.strip():
        raise ValueError(f"the crs member {json.dumps(crs)[:120]} is not a named CRS ({{'type': 'name', …}})")
    return name.strip()


def load(source: Path) -> dict[str, Any]:
    """The FeatureCollection of a file: InputError when it is not JSON, FindingsError when it
    is JSON but no FeatureCollection."""
    try:
        data = json.loads(Path(source).read_text(encoding="utf-8-sig"))
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", path=source) from exc
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", path=source) from exc
    except json.JSONDecodeError as exc:
        raise InputError(f"invalid JSON: {exc.msg}", path=source, row=exc.lineno, column=f"char {exc.colno}") from exc
    if (
        not isinstance(data, dict)
        or data.get("type") != "FeatureCollection"
        or not isinstance(data.get("features"), list)
    ):
        what = data.get("type") if isinstance(data, dict) else type(data).__name__
        msg = f"not a GeoJSON FeatureCollection (type: {what})"
        raise FindingsError(msg, [Finding("rtm.not_collection", Severity.ERROR, "tracks", msg, file=str(source))])
    return data


def _ident(feature: dict[str, Any], props: dict[str, Any]) -> str | None:
    v = props.get("id", feature.get("id"))
    if isinstance(v, bool) or v is None:
        return None
    if isinstance(v, int | str):
        return str(v).strip() or None
    return None


def _is_relation(props: dict[str, Any]) -> bool:
    return str(props.get("type", "")).lower() == "netrelation" or "netelementA" in props or "netelementB" in props


def read(source: Path) -> RtmDoc:
    """Netelements and netrelations of a file (module doc); FindingsError when the CRS is
    unknown (nothing can be placed)."""
    data = load(source)
    doc = RtmDoc(str(source), WGS84_NAME)
    try:
        doc.crs = crs_name(data)
        crs = _Crs()
        crs.transformer(doc.crs)
    except ValueError as exc:
        f = Finding("rtm.crs", Severity.ERROR, "tracks", str(exc), file=doc.file, column="crs", value=doc.crs)
        raise FindingsError(f"{exc}; nothing was written", [f], path=source) from None
    raw_relations: list[tuple[int, dict[str, Any], str | None]] = []
    for index, feature in enumerate(data["features"]):
        props = feature.get("properties") if isinstance(feature, dict) else None
        if not isinstance(props, dict):
            doc.finding("rtm.feature", "not a Feature with a properties object: skipped", index)
            continue
        ident = _ident(feature, props)
        if _is_relation(props):
            doc.netrelations_seen += 1
            raw_relations.append((index, props, ident))
        else:
            _element(doc, crs, index, feature, props, ident)
    for index, props, ident in raw_relations:
        _relation(doc, index, props, ident)
    return doc


def _coords(doc: RtmDoc, index: int, ident: Any, geom: Any) -> list[Any] | None:
    kind = geom.get("type") if isinstance(geom, dict) else None
    coords = geom.get("coordinates") if isinstance(geom, dict) else None
    if kind == "MultiLineString" and isinstance(coords, list) and coords:
        if len(coords) > 1:
            doc.finding("rtm.geometry", f"MultiLineString of {len(coords)} parts: the first part is used", index, ident)
        return coords[0] if isinstance(coords[0], list) else None
    if kind == "LineString" and isinstance(coords, list):
        return coords
    doc.finding("rtm.geometry", f"geometry {kind or 'null'} is not a LineString: skipped", index, ident)
    return None


def _element(doc: RtmDoc, crs: _Crs, index: int, feature: dict[str, Any], props: dict[str, Any], ident: Any) -> None:
    doc.netelements_seen += 1
    if ident is None:
        doc.finding("rtm.missing_id", "netelement without an 'id' (string or integer): skipped", index, column="id")
        return
    if ident in doc.elements:
        first = doc.elements[ident].index
        doc.finding("rtm.duplicate_id", f"id used again (first: feature {first}): skipped", index, ident, column="id")
        return
    coords = _coords(doc, index, ident, feature.get("geometry"))
    if coords is None:
        return
    try:
        xy = [(float(c[0]), float(c[1])) for c in coords]
    except (TypeError, ValueError, IndexError):
        doc.finding("rtm.geometry", "coordinates are not [x, y] number pairs: skipped", index, ident)
        return
    own = props.get("crs")
    name = own if isinstance(own, str) and own.strip() else doc.crs
    try:
        lon, lat = crs.transformer(name).transform([p[0] for p in xy], [p[1] for p in xy])
    except ValueError as exc:
        doc.finding("rtm.crs", f"{exc}: skipped", index, ident, column="crs")
        return
    bad = [i for i, (x, y) in enumerate(zip(lon, lat, strict=True)) if not (abs(x) <= 180 and abs(y) <= 90)]
    if bad:
        msg = f"vertex {bad[0]} {list(xy[bad[0]])} does not lie on the earth in {name}: skipped"
        doc.finding("rtm.geometry", msg, index, ident)
        return
    line = polyline(lon, lat)
    if len(xy) < 2 or line.length <= 0.0:
        doc.finding("rtm.geometry", "fewer than two distinct vertices (length 0): skipped", index, ident)
        return
    name_prop = props.get("name", props.get("track_name"))
    doc.elements[ident] = NetElement(ident, index, line, None if name_prop is None else str(name_prop))


def _position(v: Any) -> int | None:
    if isinstance(v, bool):
        return None
    if isinstance(v, int | float) and v in (0, 1):
        return int(v)
    if isinstance(v, str) and v.strip() in ("0", "1"):
        return int(v.strip())
    return None


def _netelements(doc: RtmDoc, index: int, props: dict[str, Any], ident: Any) -> tuple[str, str] | None:
    """The two netelement ids of a relation (None, with a finding, when it cannot be used)."""

    def skip(rule: str, message: str, column: str) -> None:
        doc.finding(rule, message + ": skipped", index, ident, column=column, table="connections")

    a, b = props.get("netelementA", props.get("from")), props.get("netelementB", props.get("to"))
    for col, v in (("netelementA", a), ("netelementB", b)):
        if v is None or isinstance(v, bool) or not isinstance(v, int | str):
            skip("rtm.relation", f"{col} is missing or not an id", col)
            return None
    a, b = str(a), str(b)
    for col, v in (("netelementA", a), ("netelementB", b)):
        if v not in doc.elements:
            skip("rtm.unknown_netelement", f"{col} '{v}' is no imported netelement", col)
            return None
    if a == b:
        skip("rtm.relation", f"joins netelement '{a}' to itself", "netelementB")
        return None
    return a, b


def _relation(doc: RtmDoc, index: int, props: dict[str, Any], ident: Any) -> None:
    def skip(rule: str, message: str, column: str | None = None) -> None:
        doc.finding(rule, message + ": skipped", index, ident, column=column, table="connections")

    ab = _netelements(doc, index, props, ident)
    if ab is None:
        return
    a, b = ab
    pos = {}
    for col in ("positionOnA", "positionOnB"):
        pos[col] = _position(props.get(col))
        if pos[col] is None:
            return skip("rtm.position", f"{col} is {json.dumps(props.get(col))}, not 0 or 1", col)
    nav = NAVIGABILITY.get(str(props.get("navigability", "")).strip().lower())
    if nav is None:
        got = json.dumps(props.get("navigability"))
        return skip("rtm.navigability", f"navigability {got} is not both, AB, BA or none", "navigability")
    pa, pb = int(pos["positionOnA"] or 0), int(pos["positionOnB"] or 0)
    rel = NetRelation(str(ident or f"feature{index}"), index, a, pa, b, pb, nav)
    _check_gap(doc, rel, ident)
    _add_relation(doc, rel)


def _check_gap(doc: RtmDoc, rel: NetRelation, ident: Any) -> None:
    """``rtm.gap`` when the geodesic distance between the two ends joined exceeds :data:`GAP_WARN_M`."""
    ea, eb = doc.elements[rel.a].line, doc.elements[rel.b].line
    ia, ib = (-1 if rel.pos_a else 0), (-1 if rel.pos_b else 0)
    gap = float(GEOD.inv(ea.lon[ia], ea.lat[ia], eb.lon[ib], eb.lat[ib])[2])
    if gap > GAP_WARN_M:
        msg = (
            f"the ends it joins ({rel.a} at {rel.pos_a}, {rel.b} at {rel.pos_b}) lie {gap:.1f} m apart "
            "(a positionOn the wrong way round?): kept as given"
        )
        doc.finding("rtm.gap", msg, rel.index, ident, column="positionOnA", table="connections")


def _oriented(rel: NetRelation, a: str, pos_a: int) -> str:
    """The relation's navigability seen from end (a, pos_a) as its A."""
    if (rel.a, rel.pos_a) == (a, pos_a):
        return rel.navigability
    return {"AB": "BA", "BA": "AB"}.get(rel.navigability, rel.navigability)


def _add_relation(doc: RtmDoc, rel: NetRelation) -> None:
    other = doc.by_ends.get(rel.ends)
    if other is not None:
        if _oriented(other, rel.a, rel.pos_a) == rel.navigability:
            doc.relations_merged += 1
        else:
            msg = (
                f"joins the same ends as feature {other.index} ('{other.id}') with another navigability "
                f"({rel.navigability} vs {other.navigability}): the first is kept"
            )
            doc.finding("rtm.conflicting_relation", msg, rel.index, rel.id, column="navigability", table="connections")
        return
    doc.by_ends[rel.ends] = rel
    doc.relations.append(rel)
