"""``db export --format railml``: an onboard DB as railML 3.2.

What goes where (checked structurally by the tests; the railML XSDs are not shipped with the
suite, so XML Schema validation runs only against one the user gives, ``db export --xsd``:
:mod:`~dbtools.interchange.xsd`):

* ``common/positioning``: one ``linearPositioningSystem`` per line (``@units="m"``, the
  line's km range; each kilometrage break an ``anchor`` at ``km_from`` with ``tpos:kmTo``),
  one ``geometricPositioningSystem`` in the geodetic CRS of the network's metric CRS (the
  lat/lon datum of the GIS table).
* ``infrastructure/topology``: one ``netElement`` per line and track, its length the geodesic
  length of the GIS points, each GIS point an ``intrinsicCoordinate`` (intrinsic coordinate
  = distance along / length, ``linearCoordinate`` = km, ``geometricCoordinate`` x = lon,
  y = lat, z = height); one micro ``network`` level holding them.
* ``infrastructure/geometry/horizontalCurves``: per feature point the straight – clothoid –
  arc – clothoid – straight pieces its six rows imply (:func:`curves.curves_of_feature`),
  radius negative to the left in increasing km.
* the network (``tracks``, ``connections``, ``switches``, G balises on their tracks) when the
  DB has one: :mod:`~dbtools.interchange.topology_out`; the line-and-track netElements above
  are then the gis grid's carriers (``tpos:implied``), not tracks.
* ``functionalInfrastructure``: ``balises`` (a ``spotLocation`` with the km as
  ``linearCoordinate``; ``applicationDirection`` normal on D/S, reverse on U), one
  ``baliseGroup`` per initial pair and per C balise, ``lines``, ``tracks`` (with a
  ``gml:LineString`` of the GIS points, EPSG axis order lat lon).

Every ``@id`` is an XML NCName made by :func:`~dbtools.interchange.railml_ids.xml_id` (a
kind prefix such as ``bal_``/``ne_``/``hc_`` and the escaped DB key: injective, unique in the
document), and every reference is built by the same function; the DB ids themselves (balise
id, line code, feature id) are standard railML ``designator`` elements of the register
:data:`~dbtools.interchange.railml_ids.REGISTER`, so a plain railML consumer sees them too.

Whatever railML has no attribute for is written in this suite's namespace
(:data:`~dbtools.interchange.xmltree.TPOS_NS`, railML's ``anyAttribute`` extension point):
balise kind, station code, signal type, equipment km, distance from the pair's I1; each
feature's six rows (``tpos:featureRows``, JSON) on its arc; line code and track on each
netElement; the network's declarations on the root. Floats are written in Python's
shortest round-trip form, so export → import → build gives the same content hash.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import pandas as pd

from dbtools.gis.geometry import geodesic_step
from dbtools.gis.index import network_georef
from dbtools.interchange.curves import curves_of_feature
from dbtools.interchange.geometry import WGS84, geodetic_epsg
from dbtools.interchange.railml_ids import xml_id
from dbtools.interchange.railml_xml import DC_NS, NS, XSI_NS, designate, sub, tpos_name
from dbtools.interchange.topology_out import write_group_balises, write_topology
from dbtools.interchange.xmltree import GML_NS, TPOS_NS
from dbtools.network import Network
from schemas.enums import BaliseKind, Track


class _Track:
    """km ↔ intrinsic coordinate of one netElement (through the GIS points)."""

    def __init__(self, gis: pd.DataFrame) -> None:
        g = gis.sort_values("km_m")
        self.km = g["km_m"].to_numpy(dtype=float)
        lon, lat = g["lon"].to_numpy(dtype=float), g["lat"].to_numpy(dtype=float)
        self.s = np.concatenate([[0.0], np.cumsum(geodesic_step(lon, lat))]) if len(g) else np.zeros(0)
        self.length = float(self.s[-1]) if len(self.s) else 0.0
        self.frame = g

    def intrinsic(self, km: float) -> float | None:
        if self.length <= 0 or len(self.km) < 2:
            return None
        return float(np.clip(np.interp(km, self.km, self.s) / self.length, 0.0, 1.0))


def _spot(parent: Any, ident: str, ne: str, lps: str, tr: _Track | None, km: float, direction: str | None) -> None:
    loc = sub(
        parent,
        "spotLocation",
        id=ident,
        netElementRef=ne,
        intrinsicCoord=tr.intrinsic(km) if tr is not None else None,
        applicationDirection=direction,
    )
    sub(loc, "linearCoordinate", positioningSystemRef=lps, measure=km)


def _root(network: Network, geo_epsg: int) -> Any:
    from lxml import etree

    root = etree.Element(
        f"{{{NS}}}railML",
        nsmap={None: NS, "gml": GML_NS, "dc": DC_NS, "tpos": TPOS_NS, "xsi": XSI_NS},
        version="3.2",
    )
    root.set(tpos_name("gisGrid"), "true")
    meta = network.meta
    for src, dst in (
        ("metric_crs", "metricCrs"),
        ("metric_crs_source", "metricCrsSource"),
        ("area", "area"),
        ("area_source", "areaSource"),
        ("height_datum", "heightDatum"),
        ("geoid_model", "geoidModel"),
        ("db_version", "dbVersion"),
        ("content_hash", "contentHash"),
    ):
        if meta.get(src):
            root.set(tpos_name(dst), meta[src])
    md = sub(root, "metadata")
    sub(md, "title", DC_NS).text = f"trainpos onboard DB {meta.get('db_version', '')}".strip()
    sub(md, "source", DC_NS).text = network.origin
    sub(md, "description", DC_NS).text = f"lat/lon in EPSG:{geo_epsg}; km in metres"
    return root


def network_railml(network: Network) -> bytes:
    """The railML 3.2 document of a network (module doc)."""
    from lxml import etree

    georef = network_georef(network)
    geo_epsg = geodetic_epsg(georef.crs_epsg) if georef is not None else WGS84
    root = _root(network, geo_epsg)
    pos = sub(sub(root, "common", id="co"), "positioning")
    lpss, gpss = sub(pos, "linearPositioningSystems"), sub(pos, "geometricPositioningSystems")
    sub(gpss, "geometricPositioningSystem", id="gps_geo", crsDefinition=f"EPSG:{geo_epsg}")
    infra = sub(root, "infrastructure", id="is")
    topo = sub(infra, "topology")
    nes = sub(topo, "netElements")
    rels = sub(topo, "netRelations")
    level = sub(sub(sub(topo, "networks"), "network", id="nw"), "level", id="lv0", descriptionLevel="Micro")
    curves = sub(sub(infra, "geometry"), "horizontalCurves")
    fi = sub(infra, "functionalInfrastructure")
    bal, grp, lines_el, tracks_el = (sub(fi, n) for n in ("balises", "baliseGroups", "lines", "tracks"))
    tracks = _net_elements(network, nes, level, tracks_el, geo_epsg)
    _lines(network, lpss, lines_el, tracks)
    _features(network, curves, tracks)
    _balises(network, bal, grp, tracks)
    nets = write_topology(network, nes, rels, level, fi)
    write_group_balises(network, bal, grp, nets, {k: t.intrinsic for k, t in tracks.items()})
    return bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True))


def _pairs(network: Network) -> list[tuple[str, str]]:
    keys = set()
    for t in ("gis", "balises", "feature_points", "km_breaks"):
        f = network.tables[t].dropna(subset=["line_code", "track"])
        keys |= set(zip(f["line_code"].astype(str), f["track"].astype(str), strict=True))
    return sorted(keys)


def _net_elements(
    network: Network, nes: Any, level: Any, tracks_el: Any, geo_epsg: int
) -> dict[tuple[str, str], _Track]:
    out: dict[tuple[str, str], _Track] = {}
    gis = network.gis
    for line, track in _pairs(network):
        ne_id = xml_id("ne", line, track)
        tr = _Track(gis[(gis["line_code"].astype(str) == line) & (gis["track"].astype(str) == track)])
        out[(line, track)] = tr
        ne = sub(
            nes,
            "netElement",
            id=ne_id,
            length=tr.length if tr.length > 0 else None,
            tpos_lineCode=line,
            tpos_track=track,
            tpos_implied="true",
        )
        aps = sub(ne, "associatedPositioningSystem", id=xml_id("aps", line, track))
        for i, (km, lat, lon, h) in enumerate(
            tr.frame[["km_m", "lat", "lon", "height_m"]].itertuples(index=False, name=None)
        ):
            ic = sub(
                aps,
                "intrinsicCoordinate",
                id=xml_id("ic", line, track, i),
                intrinsicCoord=tr.s[i] / tr.length if tr.length > 0 else 0.0,
            )
            sub(ic, "linearCoordinate", positioningSystemRef=xml_id("lps", line), measure=km)
            sub(
                ic,
                "geometricCoordinate",
                positioningSystemRef="gps_geo",
                x=lon,
                y=lat,
                z=None if pd.isna(h) else float(h),
            )
        sub(level, "networkResource", ref=ne_id)
        t_el = sub(tracks_el, "track", id=xml_id("tr", line, track))
        sub(t_el, "name", name=f"{line} {track}", language="en")
        sub(
            sub(t_el, "linearLocation", id=xml_id("tr", line, track, "loc")),
            "associatedNetElement",
            netElementRef=ne_id,
            intrinsicCoordBegin=0.0,
            intrinsicCoordEnd=1.0,
        )
        if len(tr.frame) >= 2:
            ls = sub(sub(t_el, "gmlLocations"), "LineString", GML_NS, srsName=f"urn:ogc:def:crs:EPSG::{geo_epsg}")
            ls.set(f"{{{GML_NS}}}id", xml_id("gml", line, track))
            sub(ls, "posList", GML_NS).text = " ".join(
                f"{la!r} {lo!r}" for la, lo in zip(tr.frame["lat"], tr.frame["lon"], strict=True)
            )
    return out


def _lines(network: Network, lpss: Any, lines_el: Any, tracks: dict[tuple[str, str], _Track]) -> None:
    breaks = network.km_breaks
    for rec in _records(network.lines):
        line = str(rec["line_code"])
        kms = np.concatenate([t.km for (ln, _), t in tracks.items() if ln == line] or [np.zeros(0)])
        lps = sub(
            lpss,
            "linearPositioningSystem",
            id=xml_id("lps", line),
            units="m",
            linearReferencingMethod="absolute",
            startMeasure=float(kms.min()) if kms.size else None,
            endMeasure=float(kms.max()) if kms.size else None,
            tpos_lineCode=line,
        )
        sub(lps, "name", name=line, language="en")
        for j, b in enumerate(_records(breaks[breaks["line_code"].astype(str) == line])):
            sub(
                lps,
                "anchor",
                id=xml_id("anc", line, j),
                measure=float(b["km_from_m"]),
                tpos_track=str(b["track"]),
                tpos_kmTo=float(b["km_to_m"]),
            )
        el = sub(
            lines_el,
            "line",
            id=xml_id("ln", line),
            tpos_lineCode=line,
            tpos_attributes=_s(rec["attributes_json"]),
        )
        if _s(rec["name"]) is not None:
            sub(el, "name", name=str(rec["name"]), language="en")
        designate(el, line)
        loc = sub(el, "linearLocation", id=xml_id("ln", line, "loc"))
        for ln, track in tracks:
            if ln == line:
                sub(
                    loc,
                    "associatedNetElement",
                    netElementRef=xml_id("ne", line, track),
                    intrinsicCoordBegin=0.0,
                    intrinsicCoordEnd=1.0,
                )


def _features(network: Network, curves_el: Any, tracks: dict[tuple[str, str], _Track]) -> None:
    fp = network.feature_points.sort_values(["line_code", "track", "feature_id", "seq"])
    for (line, track, fid), g in fp.groupby(["line_code", "track", "feature_id"], sort=True):
        rows = _records(g)
        payload = json.dumps(
            [
                [
                    int(r["seq"]),
                    float(r["km_m"]),
                    float(r["radius_m"]),
                    str(r["attribute"]),
                    None if pd.isna(r["role"]) else str(r["role"]),
                ]
                for r in rows
            ]
        )
        pieces = curves_of_feature(rows, str(track)) or [
            ("arc", min(g["km_m"]), max(g["km_m"]), float(g["radius_m"].max()))
        ]
        ne, lps, tr = xml_id("ne", line, track), xml_id("lps", line), tracks.get((str(line), str(track)))
        for n, (kind, k0, k1, radius) in enumerate(pieces):
            is_arc = kind == "arc"
            el = sub(
                curves_el,
                "horizontalCurve",
                id=xml_id("hc", line, track, fid, n + 1),
                curveType=kind,
                radius=radius,
                length=k1 - k0,
                tpos_featureId=str(fid),
                tpos_featureRows=payload if is_arc else None,
            )
            sub(el, "name", name=str(fid), language="en")
            if is_arc:
                designate(el, fid)
            loc = sub(el, "linearLocation", id=xml_id("hc", line, track, fid, n + 1, "loc"))
            a = sub(
                loc,
                "associatedNetElement",
                netElementRef=ne,
                intrinsicCoordBegin=tr.intrinsic(k0) if tr else None,
                intrinsicCoordEnd=tr.intrinsic(k1) if tr else None,
            )
            sub(a, "linearCoordinateBegin", positioningSystemRef=lps, measure=k0)
            sub(a, "linearCoordinateEnd", positioningSystemRef=lps, measure=k1)


def _balises(network: Network, bal: Any, grp: Any, tracks: dict[tuple[str, str], _Track]) -> None:
    made: set[str] = set()
    for rec in _records(network.balises):
        if rec["kind"] == BaliseKind.G:
            continue  # balise groups: topology_out
        line, track, kind = str(rec["line_code"]), str(rec["track"]), str(rec["kind"])
        group = (
            xml_id("bg", line, rec["station_code"], track) if kind != BaliseKind.C else xml_id("bg", rec["balise_id"])
        )
        if group not in made:
            made.add(group)
            g = sub(
                grp,
                "baliseGroup",
                id=group,
                numberOfBalisesInGroup="1" if kind == BaliseKind.C else "2",
                mileageDirection="reverse" if track == Track.UP.value else "nominal",
            )
            sub(g, "applicationType", value="other:trainpos")
            sub(g, "functionalType", value="other:positionCorrection" if kind == BaliseKind.C else "other:initialPair")
        el = sub(
            bal,
            "balise",
            id=xml_id("bal", rec["balise_id"]),
            tpos_kind=kind,
            tpos_stationCode=_s(rec["station_code"]),
            tpos_signalType=_s(rec["signal_type"]),
            tpos_kmEquipment=_n(rec["km_equipment_m"]),
            tpos_distFromInitial=_n(rec["dist_from_initial_m"]),
        )
        designate(el, rec["balise_id"])
        direction = "reverse" if track == Track.UP.value else "normal"
        _spot(
            el,
            xml_id("sl", rec["balise_id"]),
            xml_id("ne", line, track),
            xml_id("lps", line),
            tracks.get((line, track)),
            float(rec["km_actual_m"]),
            direction,
        )
        sub(el, "belongsToParent", ref=group)


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    return [{str(k): v for k, v in r.items()} for r in frame.to_dict("records")]


def _s(v: Any) -> str | None:
    return None if v is None or pd.isna(v) else str(v)


def _n(v: Any) -> str | None:
    return None if v is None or pd.isna(v) else repr(float(v))
