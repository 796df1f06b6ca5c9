"""Reading an OpenStreetMap file (``.osm.pbf``, ``.osm``, ``.osm.bz2``) for the network import.

Read with pyosmium (the OSM project's own C++ reader, libosmium: PBF and XML, with a node
location index so that every way comes with the coordinates of its nodes), imported lazily.
One pass over the file keeps:

* the ways tagged ``railway=<one of RAILWAYS>`` (default ``rail``): id, the tags the import
  uses, the node ids and their WGS 84 lat/lon. A node the file does not hold (an extract cut
  at its boundary) has no location: the way is cut there into *runs* of located nodes
  (:attr:`RailWay.runs`), reported as ``osm.missing_node``;
* the nodes tagged ``railway=switch|railway_crossing|buffer_stop|milestone|balise_group``
  with their tags and location;
* the line relations (``type=route`` + ``route=railway|tracks`` with a ``ref``) and their
  member ways;
* how many ways carry any other ``railway=*`` value (trams, subways, platforms, disused
  lines …), with their ids, to report what was left out;
* the ids of the *areas* tagged ``railway=rail``: a closed way (first node = last node) that
  also carries one of :data:`AREA_KEYS` (``building=yes`` + ``railway=rail`` is a mapper's
  way of saying "a railway building", e.g. a substation) or ``area=yes`` is an outline, not a
  centreline (OSM wiki "Area": a closed way with an area tag is an area). Imported as a track
  it would be a ring a few metres long whose ends are one point; it is left out and reported
  (``osm.area``).

OSM data: © OpenStreetMap contributors, ODbL 1.0 (https://www.openstreetmap.org/copyright).
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from dbtools.masks import true_runs
from schemas.errors import InputError

if TYPE_CHECKING:
    import osmium

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: ``railway=*`` values of the ways imported by default (module doc of osm_import says why).
RAILWAYS = ("rail",)
#: ``railway=*`` values of the nodes kept.
NODE_KINDS = ("switch", "railway_crossing", "buffer_stop", "milestone", "balise_group")
#: Way tags kept (everything the mapping reads).
WAY_TAGS = ("railway", "service", "ref", "railway:ref", "railway:track_ref", "name", "usage", "area")
#: Tags that make a closed rail way an area (module doc).
AREA_KEYS = ("building", "landuse", "amenity", "power", "man_made")
#: ``route=*`` values of the relations naming a line (the infrastructure; ``route=train``
#: relations are services — a train number, not a line — and are not read).
LINE_ROUTES = ("railway", "tracks")
#: File name endings osmium reads.
SUFFIXES = (".osm.pbf", ".pbf", ".osm", ".osm.bz2", ".osm.gz")


@dataclass
class RailWay:
    """One rail way: its id, kept tags, node ids and locations (NaN where not in the file)."""

    way_id: int
    tags: dict[str, str]
    nodes: I64
    lat: F64
    lon: F64

    runs: list[tuple[int, int]] = field(default_factory=list)
    """``[start, stop)`` index ranges of consecutive located nodes with ≥ 2 nodes."""

    def __post_init__(self) -> None:
        ok = np.isfinite(self.lat)
        if ok.all():
            self.runs = [(0, len(ok))] if len(ok) >= 2 else []
            return
        self.runs = [(int(a), int(b)) for a, b in zip(*true_runs(ok), strict=True) if b - a >= 2]


@dataclass
class OsmNode:
    """A tagged railway node: id, location and tags."""

    node_id: int
    lat: float
    lon: float
    tags: dict[str, str]

    @property
    def kind(self) -> str:
        return self.tags.get("railway", "")


@dataclass
class OsmData:
    """What the import reads from one file (module doc)."""

    file: str
    ways: list[RailWay] = field(default_factory=list)
    nodes: dict[int, OsmNode] = field(default_factory=dict)
    other_ways: dict[str, list[int]] = field(default_factory=lambda: defaultdict(list))
    """``railway=*`` value → ids of the ways of that value not imported."""
    areas: list[int] = field(default_factory=list)
    """Ids of the closed ``railway=rail`` ways that are areas (module doc), not imported."""
    n_nodes: int = 0
    n_ways: int = 0
    routes: dict[int, tuple[str, str | None, int]] = field(default_factory=dict)
    """Way id → (ref, name, relation id) of the line relation it is a member of."""


def is_osm_file(path: Path) -> bool:
    """Whether the file name says OSM (``.osm.pbf``, ``.osm``, ``.osm.bz2`` …)."""
    return str(path).lower().endswith(SUFFIXES)


def read_osm(path: Path, railways: tuple[str, ...] = RAILWAYS) -> OsmData:
    """One pass over the file (module doc); InputError when osmium cannot read it."""
    import osmium

    path = Path(path)
    if not path.is_file():
        raise InputError("no such file", path=path)
    data = OsmData(str(path))
    wanted, kinds = set(railways), set(NODE_KINDS)
    try:
        for obj in osmium.FileProcessor(str(path)).with_locations():
            if isinstance(obj, osmium.osm.Node):
                data.n_nodes += 1
                kind = obj.tags.get("railway")
                if kind in kinds and obj.location.valid():
                    data.nodes[obj.id] = OsmNode(obj.id, obj.location.lat, obj.location.lon, dict(obj.tags))
            elif isinstance(obj, osmium.osm.Way):
                _way(data, obj, wanted)
            elif isinstance(obj, osmium.osm.Relation):
                _route(data, obj)
    except RuntimeError as exc:  # osmium's parse errors (bad PBF blob, malformed XML, unknown format)
        raise InputError(f"not readable as OpenStreetMap data: {exc}", path=path) from exc
    return data


def _way(data: OsmData, way: osmium.osm.Way, wanted: set[str]) -> None:
    """A way: kept (a rail way), counted as left out (another ``railway=*`` or an area), or
    ignored (no ``railway``)."""
    data.n_ways += 1
    kind = way.tags.get("railway")
    if kind is None:
        return
    if kind not in wanted:
        data.other_ways[kind].append(way.id)
    elif is_area(way):
        data.areas.append(int(way.id))
    else:
        data.ways.append(_rail_way(way))


def is_area(way: osmium.osm.Way) -> bool:
    """A closed way with an area tag (module doc): an outline, not a track."""
    nodes = way.nodes
    if len(nodes) < 4 or nodes[0].ref != nodes[len(nodes) - 1].ref:
        return False
    return way.tags.get("area") == "yes" or any(k in way.tags for k in AREA_KEYS)


def _route(data: OsmData, rel: osmium.osm.Relation) -> None:
    """A line relation (``type=route``, ``route=railway|tracks`` with a ``ref``): its member
    ways take its ref and name (the first relation holding a way wins)."""
    if rel.tags.get("type") != "route" or rel.tags.get("route") not in LINE_ROUTES:
        return
    ref = rel.tags.get("ref")
    if not ref:
        return
    name = rel.tags.get("name")
    for m in rel.members:
        if m.type == "w":
            data.routes.setdefault(int(m.ref), (str(ref), None if name is None else str(name), int(rel.id)))


def _rail_way(way: osmium.osm.Way) -> RailWay:
    """A way's ids and locations as arrays (NaN for a node without location)."""
    refs = way.nodes
    n = len(refs)
    ids = np.empty(n, dtype=np.int64)
    lat = np.full(n, np.nan)
    lon = np.full(n, np.nan)
    for i, nr in enumerate(refs):
        ids[i] = nr.ref
        if nr.location.valid():
            lat[i], lon[i] = nr.location.lat, nr.location.lon
    tags = {k: str(way.tags.get(k)) for k in WAY_TAGS if k in way.tags}
    return RailWay(int(way.id), tags, ids, lat, lon)
