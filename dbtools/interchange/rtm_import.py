"""``db import network.geojson --format rtm-geojson --out SOURCE_DIR``: a RailTopoModel
network in tp-lib's GeoJSON (:mod:`~dbtools.interchange.rtm_read`) → a source set.

What is written (:func:`dbtools.sources.write_source_set`, one atomic step):

* ``tracks.csv``: one track per netelement, ``track_id`` its id verbatim, no line and no
  km (the format has none), ``kind`` ``main`` (the format does not say), ``length_m`` the
  geodesic length of its LineString on the WGS 84 ellipsoid
  (:mod:`~dbtools.interchange.polyline`), ``name`` its ``name`` or ``track_name`` property;
* ``track_points.csv``: each LineString resampled every 20 m from its first vertex
  (position 0, ``begin``), plus its last vertex (``end``), as WGS 84 lat/lon;
* ``connections.csv``: one row per netrelation (relations listed twice kept once), ends
  ``begin``/``end`` for positionOn 0/1, navigability as given; ``switches.csv``: the point
  switches and slips inferred from the relations (:mod:`~dbtools.interchange.rtm_switches`), whose id
  the relations through them carry;
* ``gis.csv``, ``balises.csv``, ``feature_points.csv``: header only (the format has no
  line grid, no balises, no curves);
* ``network.toml``: the operating area (the box of the points, widened by
  :data:`AREA_MARGIN_DEG`) and the metric CRS (the file's own when it is projected in
  metres with an EPSG code, else the UTM zone of the median point), so that ``db build``
  need not derive them from a grid;
* ``import_report.json``: counts, what was inferred and every finding.

Exit codes as the railML import: findings on single features are warnings (the feature is
skipped); no netelement imported, an unknown CRS or a file that is no FeatureCollection
are errors (nothing written); invalid JSON is unreadable input.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.gis.georef import DECLARED, Area, utm_epsg
from dbtools.interchange.polyline import resample
from dbtools.interchange.rtm_read import RtmDoc, read
from dbtools.interchange.rtm_switches import REACH_M, Inferred, end_name, infer_switches
from dbtools.network import Network, canonical, empty_frame
from dbtools.sources import write_source_set
from schemas.enums import Severity, TrackKind
from schemas.errors import FindingsError, RefusedError
from schemas.findings import Finding
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES, TRACK_POINTS
from schemas.tables import SOURCE_TABLES

FORMAT = "rtm-geojson"
#: The report beside the tables, named as the railML import names it.
REPORT_FILE = "import_report.json"
#: Margin of the declared operating area around the network's points [deg].
AREA_MARGIN_DEG = 0.02
SWITCH_RULE = (
    "four ends in two pairs, each pair joined by a relation of navigability none and each end navigable "
    "only to the other pair, are a double slip (four such joins) or single slip (three); elsewhere a "
    "netelement end with exactly two navigable relations to ends of two other netelements, those two "
    "joined by a relation of navigability none, is the toe of a point switch, left/right from the cross "
    f"product of the branch directions {REACH_M:g} m into them"
)


@dataclass
class RtmImportResult:
    out: Path
    crs: str
    rows: dict[str, int]
    findings: list[Finding] = field(default_factory=list)
    netelements_seen: int = 0
    netrelations_seen: int = 0
    switches_inferred: int = 0


def _tracks(doc: RtmDoc) -> pd.DataFrame:
    rows = [
        {
            "track_id": e.id,
            "line_code": None,
            "track": None,
            "kind": TrackKind.MAIN.value,
            "km_begin_m": None,
            "km_end_m": None,
            "length_m": round(e.line.length, 3),
            "name": e.name,
        }
        for e in doc.elements.values()
    ]
    return canonical(NETWORK_TRACKS, pd.DataFrame(rows, columns=NETWORK_TRACKS.column_names))


def _track_points(doc: RtmDoc) -> pd.DataFrame:
    parts = []
    for e in doc.elements.values():
        pos, lon, lat = resample(e.line)
        pos[-1] = round(e.line.length, 3)
        parts.append(
            pd.DataFrame(
                {
                    "track_id": e.id,
                    "pos_m": np.round(pos, 3),
                    "km_m": np.nan,
                    "lat": np.round(lat, 9),
                    "lon": np.round(lon, 9),
                }
            )
        )
    frame = pd.concat(parts, ignore_index=True) if parts else empty_frame(TRACK_POINTS)
    frame["height_m"] = np.nan
    return canonical(TRACK_POINTS, frame[TRACK_POINTS.column_names])


def _connections(doc: RtmDoc, inferred: Inferred) -> pd.DataFrame:
    rows = [
        {
            "track_a": r.a,
            "end_a": end_name(r.pos_a),
            "track_b": r.b,
            "end_b": end_name(r.pos_b),
            "navigability": r.navigability,
            "switch_id": inferred.by_relation.get(r.ends),
        }
        for r in doc.relations
    ]
    return canonical(CONNECTIONS, pd.DataFrame(rows, columns=CONNECTIONS.column_names))


def declaration(doc: RtmDoc) -> dict[str, str]:
    """network.toml entries: area and metric CRS (module doc)."""
    from pyproj import CRS

    lat = np.concatenate([e.line.lat for e in doc.elements.values()])
    lon = np.concatenate([e.line.lon for e in doc.elements.values()])
    m = AREA_MARGIN_DEG
    area = Area.box(lat.min() - m, lat.max() + m, lon.min() - m, lon.max() + m)
    crs = CRS.from_user_input("OGC:CRS84" if doc.crs.upper() == "CRS84" else doc.crs)
    metres = crs.is_projected and all(a.unit_name in ("metre", "meter") for a in crs.axis_info)
    code = crs.to_epsg() if metres else None
    epsg = code if code is not None else utm_epsg(float(np.median(lat)), float(np.median(lon)))
    return {
        "area": area.to_json(),
        "area_source": DECLARED,
        "metric_crs": f"EPSG:{epsg}",
        "metric_crs_source": DECLARED,
    }


def frames(doc: RtmDoc, inferred: Inferred) -> dict[str, pd.DataFrame]:
    """Every source table of the import (the empty ones with their columns)."""
    tables = {name: empty_frame(table) for name, table in SOURCE_TABLES.items()}
    tables[NETWORK_TRACKS.name] = _tracks(doc)
    tables[TRACK_POINTS.name] = _track_points(doc)
    tables[CONNECTIONS.name] = _connections(doc, inferred)
    sw = pd.DataFrame(inferred.switches, columns=SWITCHES.column_names)
    tables[SWITCHES.name] = canonical(SWITCHES, sw) if len(sw) else empty_frame(SWITCHES)
    return tables


def _report(doc: RtmDoc, tables: dict[str, pd.DataFrame], inferred: Inferred, findings: list[Finding]) -> str:
    report: dict[str, Any] = {
        "source": doc.file,
        "format": FORMAT,
        "crs": doc.crs,
        "features": {"netelements": doc.netelements_seen, "netrelations": doc.netrelations_seen},
        "relations_listed_twice": doc.relations_merged,
        "rows": {k: len(v) for k, v in tables.items() if len(v) or k in ("gis", "balises", "feature_points")},
        "inferred": {
            "switches": len(inferred.switches),
            "switch_rule": SWITCH_RULE,
            "track_kind": "every track is kind main: RailTopoModel GeoJSON does not say what a netelement is used for",
            "lengths": "geodesic length of each LineString on the WGS 84 ellipsoid (the file carries none)",
        },
        "findings": [f.to_dict() for f in findings],
    }
    return json.dumps(report, ensure_ascii=False, indent=2) + "\n"


def import_rtm_geojson(source: Path, out: Path, *, force: bool = False) -> RtmImportResult:
    """Read, infer and write (module doc). FindingsError (nothing written) when no
    netelement can be imported."""
    source, out = Path(source), Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())) and not force:
        raise RefusedError("output folder exists and is not empty; use --force", path=out)
    doc = read(source)
    if not doc.elements:
        msg = f"none of the {doc.netelements_seen} netelement(s) could be imported; nothing was written"
        stop = Finding("rtm.no_netelement", Severity.ERROR, "tracks", msg, file=doc.file)
        raise FindingsError(msg, [*doc.findings, stop], path=source)
    inferred = infer_switches(doc.elements, doc.relations, doc.file)
    findings = doc.findings + inferred.findings
    tables = frames(doc, inferred)
    net = Network(tables, origin=str(source), meta=declaration(doc))
    report = _report(doc, tables, inferred, findings)
    write_source_set(net, out, force=force, inputs=[source], extra_files={REPORT_FILE: report})
    rows = {k: len(v) for k, v in tables.items() if len(v)}
    return RtmImportResult(
        out, doc.crs, rows, findings, doc.netelements_seen, doc.netrelations_seen, len(inferred.switches)
    )
