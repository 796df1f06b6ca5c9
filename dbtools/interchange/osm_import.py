"""``db import FILE.osm.pbf --format osm --out SOURCE_DIR``: an OpenStreetMap file → a source set
(SPEC §8.1 "OSM"; user guide ``docs/howto/import-osm.md``).

Steps: read the rail ways and railway nodes (:mod:`~dbtools.interchange.osm_read`); cut the
ways into tracks at switches and junctions, lengths and the 20 m grid
(:mod:`~dbtools.interchange.osm_split`); connections and switches at every node where
tracks meet (:mod:`~dbtools.interchange.osm_switches`); kilometrage from milestones
(:mod:`~dbtools.interchange.osm_km`); tracks, lines and balise groups
(:mod:`~dbtools.interchange.osm_tables`).

**What is imported.** Ways tagged ``railway=rail`` (main-line railways with their sidings,
yards and crossovers); ``railway=light_rail``, ``tram``, ``subway``, ``narrow_gauge``
only when asked for (``railways``): they are other networks, run by other vehicles, with
their own junctions with the rail network usually not mapped as switches; what was left
out is reported (``osm.excluded``, with the way ids).

**Written**: ``tracks.csv`` (every track; line and km where the track has a ``ref`` and
≥ 2 milestones), ``track_points.csv`` (every track's centreline every 20 m),
``connections.csv``, ``switches.csv``, ``lines.csv``, ``balises.csv`` (kind G rows),
``gis.csv`` and ``feature_points.csv`` empty (OSM has no km grid per line and track nor
curve tables: every track's centreline is in ``track_points``), ``network.toml``
(``metric_crs`` = the WGS 84 UTM zone of the median node, the area = the nodes' box plus
:data:`AREA_MARGIN_DEG`), and ``import_report.json`` (counts and every finding).

**Errors.** A file osmium cannot read: InputError (exit 2). A file with no rail way, or
whose rail ways all lack located nodes: FindingsError (exit 1), nothing written.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.interchange.osm_km import km_model, switch_links
from dbtools.interchange.osm_read import RAILWAYS, OsmData, read_osm
from dbtools.interchange.osm_split import Pieces, end_frame, split_ways
from dbtools.interchange.osm_switches import Junctions, junctions
from dbtools.interchange.osm_tables import balise_groups, lines_frame, tracks_and_points, way_attributes
from dbtools.network import Network, canonical, empty_frame
from schemas.enums import Severity
from schemas.errors import FindingsError, RefusedError
from schemas.findings import Finding
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES, TRACK_POINTS
from schemas.tables import BALISES, LINES, SOURCE_TABLES

REPORT_FILE = "import_report.json"
#: Margin of the declared area around the nodes [deg] (≈ 1 km).
AREA_MARGIN_DEG = 0.01
#: Most element ids listed in one finding (the count is always given).
MAX_IDS = 50


@dataclass
class OsmImport:
    """Result of an import: folder, row counts, findings and what the file held."""

    out: Path
    rows: dict[str, int]
    findings: list[Finding] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=dict)
    metric_crs: str = ""


def _warn(rule: str, table: str, message: str, ids: list[int], kind: str) -> Finding:
    shown = ids[:MAX_IDS]
    more = f" (first {MAX_IDS} of {len(ids)} listed)" if len(ids) > MAX_IDS else ""
    keys = {"element": ",".join(f"{kind}/{i}" for i in shown)} if ids else {}
    return Finding(rule, Severity.WARNING, table, message + more, keys=keys, value=len(ids) or None)


def _read_findings(data: OsmData) -> list[Finding]:
    out = [
        _warn(
            "osm.excluded",
            "tracks",
            f"{len(ids)} way(s) railway={kind} not imported (not a railway=rail way)",
            ids,
            "way",
        )
        for kind, ids in sorted(data.other_ways.items())
    ]
    if data.areas:
        out.append(
            _warn(
                "osm.area",
                "tracks",
                f"{len(data.areas)} closed way(s) railway=rail with an area tag (building, area=yes …): "
                "outlines, not tracks — not imported",
                data.areas,
                "way",
            )
        )
    for way in data.ways:
        missing = int(np.count_nonzero(~np.isfinite(way.lat)))
        if missing and way.runs:
            out.append(
                _warn(
                    "osm.missing_node",
                    "tracks",
                    f"{missing} of {len(way.nodes)} nodes of the way are not "
                    "in the file (extract edge): the way is cut there",
                    [way.way_id],
                    "way",
                )
            )
        elif not way.runs:
            out.append(
                _warn(
                    "osm.way_nodes",
                    "tracks",
                    f"way with {len(way.nodes)} node(s), fewer than 2 of them in the file: not imported",
                    [way.way_id],
                    "way",
                )
            )
    return out


def _node_findings(data: OsmData, p: Pieces, j: Junctions) -> list[Finding]:
    on_track = set(np.unique(p.node).tolist())
    stop_nodes = {
        int(p.begin_node[i]) if e == "begin" else int(p.end_node[i])
        for i, t in enumerate(p.track_id)
        for e in ("begin", "end")
        if (t, e) in j.stops
    }
    out = []
    for kind, why in (("switch", "lies on no imported track"), ("railway_crossing", "lies on no imported track")):
        ids = [n for n, node in data.nodes.items() if node.kind == kind and n not in on_track]
        if ids:
            out.append(_warn("osm.unplaced", "switches", f"{len(ids)} railway={kind} node(s) {why}", ids, "node"))
    stops = [n for n, node in data.nodes.items() if node.kind == "buffer_stop" and n not in stop_nodes]
    if stops:
        out.append(
            _warn(
                "osm.buffer_stop",
                "tracks",
                f"{len(stops)} buffer stop(s) not at a dead track end (on another way, or mid-track): not imported",
                stops,
                "node",
            )
        )
    if j.untagged:
        out.append(
            _warn(
                "osm.untagged_switch",
                "switches",
                f"{len(j.untagged)} node(s) where 3 tracks meet without railway=switch: imported as point switches",
                j.untagged,
                "node",
            )
        )
    if j.guessed_sides:
        out.append(
            _warn(
                "osm.turnout_side",
                "switches",
                f"{j.guessed_sides} point switch(es) without "
                "railway:turnout_side: diverging_side guessed from the geometry",
                [],
                "node",
            )
        )
    return out


def _meta(p: Pieces) -> dict[str, str]:
    m = AREA_MARGIN_DEG
    area = {
        "lat_min": round(float(np.min(p.lat)) - m, 6),
        "lat_max": round(float(np.max(p.lat)) + m, 6),
        "lon_min": round(float(np.min(p.lon)) - m, 6),
        "lon_max": round(float(np.max(p.lon)) + m, 6),
    }
    return {
        "metric_crs": f"EPSG:{p.epsg}",
        "metric_crs_source": "declared",
        "area": json.dumps(area),
        "area_source": "declared",
    }


def _switch_km(switches: pd.DataFrame, tracks: pd.DataFrame, p: Pieces, km: Any) -> pd.DataFrame:
    """Line and km of each switch: those of its A1 track at the A1 end."""
    if switches.empty:
        return switches
    index = {t: i for i, t in enumerate(p.track_id)}
    k = np.array([index[t] for t in switches["a1_track"]], dtype=np.int64)
    pos = np.where(switches["a1_end"].to_numpy() == "begin", 0.0, p.length[k])
    switches = switches.copy()
    switches["line_code"] = tracks["line_code"].to_numpy()[k]
    switches["km_m"] = km.at(k, pos)
    return switches


def build_tables(data: OsmData) -> tuple[dict[str, pd.DataFrame], dict[str, str], list[Finding], dict[str, int]]:
    """Every table of the source set, the meta (network.toml), the findings and counts."""
    p = split_ways(data)
    attrs, f_attr = way_attributes(data, p)
    node_ll = {int(n): (float(a), float(o)) for n, a, o in zip(p.node, p.lat, p.lon, strict=True)}
    j = junctions(end_frame(p), p.track_id, data.nodes, node_ll)
    index = {t: i for i, t in enumerate(p.track_id)}
    lines = [None if pd.isna(c) else str(c) for c in attrs["line_code"]]
    links: dict[tuple[int, str], tuple[int, str]] = {}
    for (ta, ea), (tb, eb) in j.runs_on + switch_links(j.points, dict(zip(p.track_id, lines, strict=True))):
        links[(index[ta], ea)] = (index[tb], eb)
        links[(index[tb], eb)] = (index[ta], ea)
    joins: dict[tuple[int, str], list[tuple[int, str]]] = {}
    for c in j.connections:
        if c["navigability"] == "both" and c["track_a"] != c["track_b"]:
            a, b = (index[c["track_a"]], c["end_a"]), (index[c["track_b"]], c["end_b"])
            joins.setdefault(a, []).append(b)
            joins.setdefault(b, []).append(a)
    km = km_model(p, lines, data.nodes, links, joins)
    tracks, points = tracks_and_points(p, attrs, km, j.stops)
    balises, f_bal = balise_groups(data, p, tracks, km)
    switches = _switch_km(pd.DataFrame(j.switches, columns=SWITCHES.column_names), tracks, p, km)
    has_line = attrs["line_code"].notna().to_numpy()
    no_km = [p.track_id[i] for i in np.flatnonzero(has_line) if int(i) not in km.posts]
    ways = sorted(
        {int(data.ways[int(p.way_index[i])].way_id) for i in np.flatnonzero(has_line) if int(i) not in km.posts}
    )
    f_km = []
    if no_km:
        message = (
            f"{len(no_km)} track(s) on {len(ways)} way(s) with a line but fewer than 2 usable milestones "
            "on their chain: no km"
        )
        f_km.append(_warn("osm.no_km", "tracks", message, ways, "way"))
    tables = {
        NETWORK_TRACKS.name: tracks,
        TRACK_POINTS.name: points,
        CONNECTIONS.name: pd.DataFrame(j.connections, columns=CONNECTIONS.column_names),
        SWITCHES.name: switches,
        LINES.name: lines_frame(data, attrs),
        BALISES.name: balises,
    }
    tables = {name: canonical(SOURCE_TABLES[name], frame) for name, frame in tables.items()}
    for name, table in SOURCE_TABLES.items():
        if table.required and name not in tables:
            tables[name] = empty_frame(table)
    findings = _read_findings(data) + f_attr + j.findings + _node_findings(data, p, j) + km.findings + f_km + f_bal
    counts = {
        "nodes": data.n_nodes,
        "ways": data.n_ways,
        "rail_ways": len(data.ways),
        "railway_nodes": len(data.nodes),
        "dead_ends": j.dead_ends,
        "buffer_stop_ends": len(j.stops),
        "milestones_used": len(km.used),
    }
    return tables, _meta(p), findings, counts


def import_osm(source: Path, out: Path, *, force: bool = False, railways: tuple[str, ...] = RAILWAYS) -> OsmImport:
    """Read, map and write (module doc)."""
    from dbtools.sources import write_source_set

    source, out = Path(source), Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())) and not force:
        raise RefusedError("output folder exists and is not empty; use --force", path=out)
    data = read_osm(source, railways)
    wanted = "|".join(railways)
    if not data.ways:
        f = Finding("osm.no_rail", Severity.ERROR, "tracks", f"the file holds no railway={wanted} way", keys={})
        raise FindingsError(f"no railway={wanted} way in {source.name}; nothing was written", [f], path=source)
    if not any(w.runs for w in data.ways):
        findings = _read_findings(data)
        raise FindingsError(
            f"none of the {len(data.ways)} railway={wanted} way(s) of {source.name} has 2 nodes in the file; "
            "nothing was written",
            findings,
            path=source,
        )
    tables, meta, findings, counts = build_tables(data)
    rows = {k: len(v) for k, v in tables.items()}
    report = {
        "source": str(source),
        "format": "osm",
        "railways": list(railways),
        "metric_crs": meta["metric_crs"],
        "osm": counts,
        "rows": rows,
        "findings": [f.to_dict() for f in findings],
    }
    net = Network(tables, origin=str(source), meta=meta)
    text = json.dumps(report, ensure_ascii=False, indent=2) + "\n"
    write_source_set(net, out, force=force, inputs=[source], extra_files={REPORT_FILE: text})
    return OsmImport(out, rows, findings, counts, meta["metric_crs"])
