"""``db import SOURCE --format railml --out SOURCE_DIR``: a railML file → a source set.

Steps: safe parse (:mod:`~dbtools.interchange.xmltree`); with ``--xsd`` validation against
that XML Schema (:mod:`~dbtools.interchange.xsd`); version from ``@version`` (else the
namespace): railML 2.0–2.5 (:mod:`~dbtools.interchange.railml2`) or 3.1–3.3
(:mod:`~dbtools.interchange.railml3`); the ``--line-code`` map
(:mod:`~dbtools.interchange.mapping`); the network — tracks, connections, switches — from
the topology (:mod:`~dbtools.interchange.topology2`, :mod:`~dbtools.interchange.topology3`,
rows: :mod:`~dbtools.interchange.topology_rows`); balises (:mod:`~dbtools.interchange.balises`;
balise groups as G rows: :mod:`~dbtools.interchange.balise_groups`), feature points
(:mod:`~dbtools.interchange.curves`) and geometry (:mod:`~dbtools.interchange.geometry`)
mapped; every element neither consumed nor covered by another finding is reported as
``railml.unmapped`` with its path, id, line and why.

Errors (unknown version, missing or duplicate ids, positions on undefined tracks or off
their track, lengths not in metres, values that are not numbers, and ``railml.nothing_imported``:
a file holding balises or tracks none of which became a row) stop the import: nothing
is written. Otherwise the folder gets the source tables (``gis.csv`` empty when the file
has no coordinates), ``network.toml`` when something is declared, ``survey/`` (centrelines
and kilometre posts for ``gis grid``) when the file has coordinates, and
``import_report.json``: every finding, and the railML name of every imported balise and
feature (our tables have no name column).

Findings (errors stop the import; warnings are in ``import_report.json``):

* ``railml.version`` (error) — the root element is no railML 2.x or 3.x (``@version``). Fix:
  import a railML 2.x/3.x file, or convert it first.
* ``railml.duplicate_id`` (error) — an ``@id`` is used twice in the file. Fix: make the ids
  unique in the exporting tool.
* ``railml.missing_id`` (error) — a track, netElement, line, balise, baliseGroup or
  positioning system without ``@id``. Fix: give it an id.
* ``railml.value`` (error / warning) — an attribute that must be a number is not, or an ETCS
  value (NID_C, NID_BG) is out of range and left empty. Fix: correct the attribute.
* ``railml.units`` (error) — a linear positioning system in other units than metres. Fix:
  export the positioning system in metres.
* ``railml.topology`` (error / warning) — a railML 2 track without trackBegin/trackEnd, or a
  railML 3 netRelation whose ``@positionOnA``/``@positionOnB`` is not 0 or 1 (dropped). Fix:
  complete the element's topology.
* ``railml.mileage`` (error / warning) — a mileageChange without its positions, or an
  ``@absPos`` that differs from the km derived from ``@pos`` (the ``@absPos`` is used). Fix:
  correct the mileage change or the element's ``@absPos``/``@pos``.
* ``railml.position`` (error / warning) — an element without a position on its track, or a
  position outside the track (placed by its ``@absPos`` or on the continuing track where
  possible). Fix: correct ``@pos``/``intrinsicCoord`` or the element's track.
* ``railml.no_mileage`` (error) — an element whose km cannot be derived: no ``@absPos`` and no
  mileage on its track. Fix: add the ``@absPos`` (linearCoordinate), or the track's mileage.
* ``railml.geocoord`` (error) — a coordinate that cannot be read or transformed. Fix: correct
  the coordinate or its CRS (``@epsgCode``).
* ``railml.undefined_track`` (error) — a reference to a track or netElement that is not in the
  file. Fix: correct the reference, or export the referenced element too.
* ``railml.undefined_ref`` (error) — a reference to a positioning system or balise group that
  is not defined (or not linear in metres). Fix: correct the reference, or define it.
* ``railml.dangling_ref`` (warning) — a connection or netRelation naming something not in the
  file (an extract's edge): imported as an open end, or dropped. Fix: none needed at an
  extract's edge; otherwise export the neighbouring element too.
* ``railml.quirk`` (warning) — a known deviation from railML read the way its writer meant it
  (e.g. a connection ``@ref`` naming a track). Fix: check the result; correct the exporter.
* ``railml.switch_open`` (warning) — a switch or crossing not imported (a port without a
  connection, a type we cannot map). Fix: complete the switch's connections in the file, or
  add the switch to ``switches.csv`` by hand.
* ``railml.switch_open_port`` (warning) — a switch whose diverging branch leads out of the
  file: imported with that port empty. Fix: none needed at an extract's edge; otherwise export
  the neighbouring track.
* ``railml.switch_side`` (warning) — a switch without ``@course``: b1 is taken as the through
  leg, b2 as the branch. Fix: state ``@course`` in the file, or check b1/b2 of the switch.
* ``railml.unmapped`` (warning) — an element not imported: no line code for its track, a
  balise that is not the first of its group, a kind we do not map. Fix: map the track's line
  (the map's ``[lines]``), or accept that the element is not used onboard.
* ``railml.pair`` (warning) — a group named as an initial pair has not two balises. Fix: the
  map's ``[initial_pairs]`` or the group in the file.
* ``railml.no_pair`` (warning) — a C balise with no initial pair before it in running
  direction. Fix: name the pair in the map's ``[initial_pairs]``.
* ``railml.balise_identity`` (warning) — a balise group without ETCS identity (NID_C/NID_BG):
  imported with nid_bg empty. Fix: add the identity in the file or fill it in ``balises.csv``.
* ``railml.balise_count`` (warning) — ``numberOfBalisesInGroup`` differs from the balises in
  the file. Fix: the group's balises or its stated number.
* ``railml.curve`` (warning) — a horizontal curve that cannot become a feature (no six-row
  pattern: a missing transition, a radius we cannot read). Fix: check the curve in the file;
  add the feature rows by hand if it matters.
* ``railml.geometry`` (warning) — no usable coordinates: ``gis.csv`` stays empty or no grid is
  built. Fix: build the GIS grid from a survey (``gis grid``), or export coordinates.
* ``railml.nothing_imported`` (error) — the file holds balises or tracks and none could be
  imported. Fix: see the warnings before it (mostly ``railml.unmapped``: map the lines).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pandas as pd

from dbtools.atomic import atomic_folder
from dbtools.gis.georef import NETWORK_FILE, write_declaration
from dbtools.inputs import regular_file
from dbtools.interchange import railml2, railml3
from dbtools.interchange import xmltree as xt
from dbtools.interchange.balises import map_balises
from dbtools.interchange.curves import map_curves
from dbtools.interchange.geometry import grid_from_survey, survey_frames
from dbtools.interchange.mapping import LineMap, Target, line_names, read_map, resolve
from dbtools.interchange.model import RailmlDoc
from dbtools.interchange.topology_rows import connection_frame, switch_frame, track_frame
from dbtools.network import canonical, empty_frame
from schemas.enums import Severity
from schemas.errors import FindingsError, RefusedError
from schemas.findings import Finding
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES
from schemas.tables import BALISES, FEATURE_POINTS, GIS, KM_BREAKS, LINES, SOURCE_TABLES

VERSIONS = ("2.0", "2.1", "2.2", "2.3", "2.4", "2.5", "3.1", "3.2", "3.3")
NAMESPACE_VERSIONS = {"2009": "2.0", "2011": "2.1", "2013": "2.2", "2016": "2.3", "2018": "2.4", "2021": "2.5"}
REPORT_FILE = "import_report.json"
SURVEY_DIR = "survey"

WHY = {
    "signal": "signals are not rows of the onboard DB (a C balise takes its signal_type from its signal)",
    "signalIS": "signals are not rows of the onboard DB (a C balise takes its signal_type from its signal)",
    "switch": "switch not imported (reported above: a leg outside the file or no through leg)",
    "switchIS": "switch not imported (reported above: its branches name no netRelation of the file)",
    "crossing": "crossing not imported (reported above: a leg outside the file)",
    "speedChange": "speed data are not part of the onboard positioning DB",
    "infraAttributes": "infrastructure attributes (speed profiles, …) are not part of the onboard positioning DB",
    "visualization": "schematic screen coordinates, not geographic ones: not used for the GIS",
    "ocp": "operational points have no counterpart (station codes of initial pairs come from the --line-code map)",
    "operationalPoint": "operational points have no counterpart (station codes of initial pairs come "
    "from the --line-code map)",
}


@dataclass
class ImportResult:
    out: Path
    version: str
    rows: dict[str, int]
    findings: list[Finding] = field(default_factory=list)
    balises_seen: int = 0


def detect_version(tree: Any, file: str) -> str:
    """``2.2`` … from ``@version``, else from the namespace; FindingsError when unknown."""
    root = tree.getroot()
    name = xt.local(root)
    version = xt.attr(root, "version")
    ns = root.tag[1:].split("}")[0] if root.tag.startswith("{") else ""
    if version is None and ns:
        tail = ns.rstrip("/").rsplit("/", 1)[-1]
        version = NAMESPACE_VERSIONS.get(tail, tail)
    if name.lower() != "railml":
        problem = f"the root element is <{name}>, not <railml> (railML 2.x) or <railML> (3.x)"
    elif version not in VERSIONS:
        problem = f"railML version '{version}' is not supported (supported: {', '.join(VERSIONS)})"
    else:
        return str(version)
    raise FindingsError(problem, [xt.finding(root, "railml.version", problem, file=file, column="version")], path=file)


def _duplicates(doc: RailmlDoc, root: Any) -> None:
    seen: dict[str, Any] = {}
    for el in root.iter():
        ident = xt.attr(el, "id") if xt.local(el) else None
        if ident is None or id(el) in doc.quirks:
            continue
        if ident in seen:
            first = xt.line_of(seen[ident])
            doc.findings.append(
                xt.finding(
                    el,
                    "railml.duplicate_id",
                    f"id '{ident}' is used again (first at line {first})",
                    file=doc.file,
                    column="id",
                )
            )
        else:
            seen[ident] = el


def _has_id_below(el: Any) -> bool:
    return any(xt.attr(d, "id") for d in el.iter() if d is not el and xt.local(d))


def _unmapped(doc: RailmlDoc, root: Any) -> list[Finding]:
    """Every element neither consumed nor inside a reported one (module doc)."""
    out: list[Finding] = []
    reported: set[int] = set()
    alive = []
    for el in root.iter():
        if not xt.local(el) or doc.is_used(el):
            continue
        parent = el.getparent()
        if parent is not None and id(parent) in reported:
            reported.add(id(el))
            alive.append(el)
            continue
        ident = xt.attr(el, "id")
        empty = not len(el) and not el.attrib and not (el.text or "").strip()
        if ident is None and (empty or _has_id_below(el)):
            continue
        name = xt.local(el)
        why = WHY.get(name, WHY.get(name.rstrip("s"), "no counterpart in the onboard DB"))
        n = sum(1 for _ in el.iter()) - 1
        more = f" (with {n} element(s) inside)" if n else ""
        out.append(
            xt.finding(
                el, "railml.unmapped", f"{name} not imported{more}: {why}", file=doc.file, severity=Severity.WARNING
            )
        )
        reported.add(id(el))
        alive.append(el)
    return out


def _gis(
    doc: RailmlDoc, targets: dict[str, Target]
) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame, pd.DataFrame, list[Finding]]:
    """(gis, km_breaks, centrelines, km posts, findings)."""
    mapped = [
        (t, targets[tid].line_code, targets[tid].track) for tid, t in doc.tracks.items() if tid in targets and t.geo
    ]
    cl, kp = survey_frames(mapped)
    findings: list[Finding] = []
    breaks = pd.DataFrame(doc.km_breaks, columns=KM_BREAKS.column_names)
    if doc.meta.get("gisGrid") == "true":  # our own export: the points are the grid itself
        rows = [
            {"line_code": line, "track": track, "km_m": p.km, "lat": p.lat, "lon": p.lon, "height_m": p.height}
            for t, line, track in mapped
            for p in t.geo
        ]
        return pd.DataFrame(rows, columns=GIS.column_names), breaks, cl, kp, findings
    root = doc.root
    if cl.empty:
        findings.append(
            xt.finding(
                root,
                "railml.geometry",
                "no coordinates on any mapped track: gis.csv is empty (build a grid with gis grid)",
                file=doc.file,
                table="gis",
                severity=Severity.WARNING,
            )
        )
        return empty_frame(GIS), breaks, cl, kp, findings
    if (kp.groupby("line_code").size() < 2).any() or kp.empty:
        findings.append(
            xt.finding(
                root,
                "railml.geometry",
                "fewer than two points with a km on a line: survey/ written, no grid",
                file=doc.file,
                table="gis",
                severity=Severity.WARNING,
            )
        )
        return empty_frame(GIS), breaks, cl, kp, findings
    grid = grid_from_survey(cl, kp)
    for f in grid.findings:
        f.severity = Severity.WARNING if f.severity == Severity.ERROR else f.severity
        f.message = f"grid from the railML coordinates: {f.message}"
    return grid.gis, grid.km_breaks, cl, kp, grid.findings


def _frames(
    doc: RailmlDoc, lmap: LineMap, targets: dict[str, Target]
) -> tuple[dict[str, pd.DataFrame], dict[str, Any], list[Finding]]:
    balise_rows, f_bal = map_balises(doc, targets, lmap)
    feature_rows, f_cur = map_curves(doc, targets)
    gis, breaks, cl, kp, f_geo = _gis(doc, targets)
    names = line_names(doc, lmap, targets)
    lines = pd.DataFrame(
        [{"line_code": k, "name": v["name"], "attributes_json": v["attributes"]} for k, v in sorted(names.items())],
        columns=LINES.column_names,
    )
    tables = {
        NETWORK_TRACKS.name: track_frame(doc, targets),
        CONNECTIONS.name: connection_frame(doc),
        SWITCHES.name: switch_frame(doc, targets),
        LINES.name: lines,
        GIS.name: gis,
        BALISES.name: pd.DataFrame(balise_rows, columns=BALISES.column_names),
        FEATURE_POINTS.name: pd.DataFrame(feature_rows, columns=FEATURE_POINTS.column_names),
        KM_BREAKS.name: breaks,
    }
    extra = {"centrelines": cl, "kmposts": kp, "names": {b.id: b.name for b in doc.balises if b.name}}
    return tables, extra, f_bal + f_cur + f_geo


def _nothing(doc: RailmlDoc, tables: dict[str, pd.DataFrame]) -> list[Finding]:
    """An error when the file holds balises or tracks and none of them became a row: the
    import has failed even though every step only warned (exit 1, nothing written)."""
    out = []
    for what, seen, table in (
        ("balises", len(doc.balises), BALISES.name),
        ("tracks", sum(not t.implied for t in doc.tracks.values()), NETWORK_TRACKS.name),
    ):
        if seen and tables[table].empty:
            out.append(
                xt.finding(
                    doc.root,
                    "railml.nothing_imported",
                    f"the file holds {seen} {what} and none could be imported (see the warnings)",
                    file=doc.file,
                    table=table,
                )
            )
    return out


def _dedupe(findings: list[Finding]) -> list[Finding]:
    seen: set[tuple[Any, ...]] = set()
    out = []
    for f in findings:
        key = (f.rule, f.row, f.message, f.keys.get("element"))
        if key not in seen:
            seen.add(key)
            out.append(f)
    return out


def read_railml(
    source: Path, lmap: LineMap, *, schema: Any = None, xsd: Path | None = None
) -> tuple[RailmlDoc, dict[str, Target]]:
    """Parse and read a railML file (errors raise): the document and its track targets.
    With ``schema`` (the XML Schema loaded from ``xsd``) the file is validated first."""
    file = str(regular_file(Path(source), "railML file"))
    tree = xt.parse(source)
    if schema is not None and xsd is not None:
        from dbtools.interchange.xsd import check_valid

        check_valid(schema, tree, file=file, xsd=xsd, what=Path(source).name)
    version = detect_version(tree, file)
    reader = railml2.read if version.startswith("2") else railml3.read
    doc = reader(tree, file, version)
    _duplicates(doc, tree.getroot())
    return doc, resolve(doc, lmap)


def import_railml(
    source: Path, out: Path, *, line_map: Path | None = None, force: bool = False, xsd: Path | None = None
) -> ImportResult:
    """Read, map and write (module doc). FindingsError (nothing written) on errors. With
    ``xsd`` the file is first validated against that XML Schema (:mod:`~dbtools.interchange.xsd`)."""
    source, out = Path(source), Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())) and not force:
        raise RefusedError("output folder exists and is not empty; use --force", path=out)
    lmap = read_map(line_map)
    schema = None
    if xsd is not None:
        from dbtools.interchange.xsd import load_schema

        schema = load_schema(xsd)
    doc, targets = read_railml(source, lmap, schema=schema, xsd=xsd)
    tables, extra, findings = _frames(doc, lmap, targets)
    findings = _dedupe(_nothing(doc, tables) + doc.findings + findings + _unmapped(doc, doc.root))
    errors = [f for f in findings if f.severity == Severity.ERROR]
    if errors:
        raise FindingsError(f"{len(errors)} error(s) in {source.name}; nothing was written", findings, path=source)
    meta = dict(doc.meta)
    if lmap.metric_crs:
        meta.update(metric_crs=lmap.metric_crs, metric_crs_source="declared")
    _write(out, tables, extra, meta, findings, doc, force, [p for p in (Path(source), line_map) if p is not None])
    rows = {k: len(v) for k, v in tables.items()}
    return ImportResult(out, doc.version, rows, findings, len(doc.balises))


def _write(
    out: Path,
    tables: dict[str, pd.DataFrame],
    extra: dict[str, Any],
    meta: dict[str, str],
    findings: list[Finding],
    doc: RailmlDoc,
    force: bool,
    inputs: list[Path],
) -> None:
    empty = out.is_dir() and not any(out.iterdir())
    with atomic_folder(out, force=force or empty, inputs=inputs) as tmp:  # an empty folder may be replaced
        for name, table in SOURCE_TABLES.items():
            frame = canonical(table, tables.get(name, empty_frame(table)))
            if not table.required and frame.empty:
                continue
            cols = [c for c in table.column_names if c != "attributes_json"]
            frame[cols].to_csv(tmp / f"{name}.csv", index=False, lineterminator="\n")
        write_declaration(_declared(meta), tmp / NETWORK_FILE)
        if not extra["centrelines"].empty:
            (tmp / SURVEY_DIR).mkdir()
            extra["centrelines"].to_csv(tmp / SURVEY_DIR / "centrelines.csv", index=False, lineterminator="\n")
            extra["kmposts"].to_csv(tmp / SURVEY_DIR / "kmposts.csv", index=False, lineterminator="\n")
        report = {
            "source": doc.file,
            "railml_version": doc.version,
            "rows": {k: len(v) for k, v in tables.items()},
            "balise_names": extra["names"],
            "findings": [f.to_dict() for f in findings],
        }
        (tmp / REPORT_FILE).write_text(json.dumps(report, ensure_ascii=False, indent=2) + "\n", encoding="utf-8")


def _declared(meta: dict[str, str]) -> dict[str, str]:
    """Our export's tpos root attributes (metricCrs …) or the map → network.toml entries."""
    out = {k: v for k, v in meta.items() if k in ("metric_crs", "metric_crs_source")}
    for src, dst in (
        ("metricCrs", "metric_crs"),
        ("area", "area"),
        ("heightDatum", "height_datum"),
        ("geoidModel", "geoid_model"),
    ):
        if src in meta:
            out[dst] = meta[src]
    for src, dst in (("metricCrsSource", "metric_crs_source"), ("areaSource", "area_source")):
        if src in meta:
            out[dst] = meta[src]
    return out
