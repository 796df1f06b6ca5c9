"""``trainpos db …``: build, validate, diff and release onboard DB versions.

JSON shapes (``--format json``), stable:

* ``db diff``: ``{"old": {origin, kind, **meta, content_hash, actual_content_hash,
  content_verified}, "new": {…},
  "schema_version": {"old", "new"}, "meta": {key: [old, new]},
  "tables": {name: {"added", "removed", "changed", "rows": [{"change", "keys",
  "changes": {col: [old, new]}}]}}, "summary": [str]}``
* ``db releases``: ``{"registry": str, "releases": [{db_version, file, sha256,
  content_hash, schema_version, released_at, released_by, note, source_file}]}``
* ``db verify-release``: ``{"ok": bool, "registry": str, "checked": [{"db_version",
  "file", "ok"}], "findings": [finding]}``
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from cli.commands import PathCommand, small_pages
from cli.db_impact import _impact_attachment, impact
from cli.db_inspect import info, show
from cli.errors import cli_command
from cli.options import DECIMAL, DELIMITER, NO_VERIFY_HASH, csv_locale, workers_option
from cli.render import console, key_value_table, print_findings, print_json, rich_table, safe
from schemas.errors import UsageError
from schemas.findings import Finding, count_by_severity, findings_report, has_errors
from schemas.registry import DB_VERSION_RULE

if TYPE_CHECKING:
    from rich.console import Console

    from dbtools.diff import DbDiff

app = typer.Typer(help="Build, validate, diff and release onboard DB versions.", no_args_is_help=True)


class Fmt(StrEnum):
    table = "table"
    json = "json"


class ValidateFmt(StrEnum):
    table = "table"
    json = "json"
    sarif = "sarif"
    junit = "junit"


class ImportFmt(StrEnum):
    railml = "railml"
    osm = "osm"
    rtm_geojson = "rtm-geojson"


@app.command("build")
@cli_command
def build(
    source_dir: Path = typer.Argument(..., help="Source set folder: gis, balises, feature_points (.csv/.xlsx)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output onboard DB file (.sqlite)."),
    version: str | None = typer.Option(None, "--version", help=f"DB version: {DB_VERSION_RULE} (default: UTC time)."),
    note: str = typer.Option("", "--note", help="Release note: who and why."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output file."),
    strict: bool = typer.Option(
        False, "--strict", help="Refuse to write a DB that fails the validation rules (exit 1, nothing written)."
    ),
    no_validate: bool = typer.Option(
        False, "--no-validate", help="Skip the validation rules (only the sources' own checks run)."
    ),
    config: Path | None = typer.Option(
        None, "--config", help="Settings (TOML): its [input] section (limits of .xlsx source files)."
    ),
    delimiter: str | None = DELIMITER,
    decimal: str | None = DECIMAL,
) -> None:
    """Build an onboard DB version from a source set, and validate it.

    Errors in the source files stop the build (exit 1). Then the rules of `db validate` run on the
    content: their summary is printed; the DB is written anyway (exit 0) unless --strict.

    Example: trainpos db build network/ --out net-2026.11.sqlite --version 2026.11 --note "new curve table"
    """
    from dbtools.build import build_db

    if strict and no_validate:
        raise UsageError("--strict needs the validation rules: drop --no-validate")
    result = build_db(
        source_dir,
        out,
        db_version=version,
        note=note,
        force=force,
        validate=not no_validate,
        strict=strict,
        locale=csv_locale(delimiter, decimal),
    )
    head = [("file", str(result.path)), ("db_version", result.db_version), ("content_hash", result.content_hash)]
    out_c = _written(result.warnings, "Source warnings", head, result.rows, "Built")
    if result.validation is not None:
        counts = count_by_severity(result.validation)
        verdict = "valid" if not result.validation else f"{counts['error']} error(s), {counts['warning']} warning(s)"
        hint = f" — see them with: trainpos db validate {safe(result.path)}" if result.validation else ""
        out_c.print(f"validation: {verdict}{hint}")


@app.command("validate", cls=PathCommand)
@cli_command
def validate(
    target: Path = typer.Argument(..., help="Onboard DB file (.sqlite) or source set folder."),
    fmt: ValidateFmt = typer.Option(
        ValidateFmt.table, "--format", help="table, json, sarif (SARIF 2.1.0) or junit (JUnit XML) for CI."
    ),
    strict: bool = typer.Option(False, "--strict", help="Warnings also fail (exit 1)."),
    help_uri_base: str = typer.Option(
        "",
        "--help-uri-base",
        envvar="TRAINPOS_HELP_URI_BASE",
        help="SARIF: base of each rule's helpUri (BASE + docs/reference/rules.md#RULE), e.g. "
        "https://github.com/ORG/trainpos/blob/main/; empty: the repository-relative path.",
    ),
    delimiter: str | None = DELIMITER,
    decimal: str | None = DECIMAL,
) -> None:
    """Check every consistency rule; exit 0 clean, 1 errors (or warnings with --strict), 2 unreadable.

    Example: trainpos db validate net-2026.11.sqlite --format json
    """
    small_pages()  # before numpy's import
    from dbtools.validate import validate_path

    findings = validate_path(target, locale=csv_locale(delimiter, decimal))
    if fmt in (ValidateFmt.sarif, ValidateFmt.junit):
        _ci_report(findings, target, fmt, strict, help_uri_base)
    elif fmt == ValidateFmt.json:
        report = findings_report(findings)
        report["ok"] = not has_errors(findings, strict)
        print_json(report)
    else:
        print_findings(findings, console=console(), title=f"Validation of {target}")
    if has_errors(findings, strict):
        raise typer.Exit(1)


@app.command("diff")
@cli_command
def diff(
    old: Path = typer.Argument(..., help="Old onboard DB file (.sqlite) or source set folder."),
    new: Path = typer.Argument(..., help="New onboard DB file (.sqlite) or source set folder."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json (every changed row)."),
) -> None:
    """Show what changed between two DB versions: rows per table and a plain-language summary.

    Exit 0 whether or not anything differs (it is a report); 1 if a source set has errors;
    2 if an input cannot be read.

    Example: trainpos db diff net-2026.10.sqlite net-2026.11.sqlite
    """
    from dbtools.diff import diff_paths

    result = diff_paths(old, new)
    if fmt == Fmt.json:
        print_json(result.to_dict())
        return
    _print_diff(result)


def _side_cell(side: dict[str, object], key: str) -> str:
    v = side.get(key)
    return "—" if v is None else str(v)


def _content_check(side: dict[str, object]) -> str:
    """Whether a side's content is the one its stored content_hash was made of."""
    ok, actual = side.get("content_verified"), str(side.get("actual_content_hash"))[:16]
    return "— (source set)" if ok is None else "[green]matches[/]" if ok else f"[red]MODIFIED[/] (actual {actual})"


def _print_diff(d: DbDiff) -> None:
    out = console()
    head = rich_table(title="db diff")
    head.add_column("")
    head.add_column("old", overflow="fold")
    head.add_column("new", overflow="fold")
    head.add_row("origin", _side_cell(d.old, "origin"), _side_cell(d.new, "origin"))
    head.add_row("db_version", _side_cell(d.old, "db_version"), _side_cell(d.new, "db_version"))
    head.add_row("content_hash", _side_cell(d.old, "content_hash")[:16], _side_cell(d.new, "content_hash")[:16])
    head.add_row("content check", _content_check(d.old), _content_check(d.new))
    head.add_row("schema_version", *("—" if v is None else str(v) for v in d.schema_version))
    out.print(head)
    counts = rich_table(title="Rows")
    for col in ("table", "added", "removed", "changed"):
        counts.add_column(col, justify="left" if col == "table" else "right")
    for name, t in d.tables.items():
        n = t.counts
        counts.add_row(name, str(n["added"]), str(n["removed"]), str(n["changed"]))
    out.print(counts)
    for line in d.summary:
        out.print(f"• {line}", markup=False)
    if d.has_changes:
        out.print("(--format json lists every changed row with old and new values)")


@app.command("release")
@cli_command
def release(
    file: Path = typer.Argument(..., help="Onboard DB file (.sqlite) to release; never modified."),
    registry: Path = typer.Option(..., "--registry", help="Registry folder (created on first release)."),
    note: str = typer.Option("", "--note", help="Release note: who and why."),
    impact_runs: list[Path] | None = typer.Option(
        None, "--impact", help="Runs (folders) to replay: store the `db impact` report with the release (repeatable)."
    ),
    impact_against: Path | None = typer.Option(
        None, "--impact-against", help="DB to compare with for --impact (default: the registry's latest release)."
    ),
    plan: Path | None = typer.Option(None, "--plan", help="Possession plan for --impact (road-rail runs)."),
    workers: int | None = workers_option("replaying the --impact runs"),
    config: Path | None = typer.Option(None, "--config", help="Settings (TOML) for the --impact replay."),
) -> None:
    """Validate a DB and add it to a registry as an immutable, read-only version.

    Snapshots the DB as SQLite reads it (a WAL-mode DB with its -wal; the DB is only read),
    validates and hashes the snapshot and publishes that same file as DIR/<db_version>.sqlite
    (mode 0444, rollback journal), with DIR/<db_version>.sha256 (sha256sum format) and a row
    in DIR/registry.sqlite; files a killed release left are removed by the next one. With
    --impact RUNS the runs are first replayed against the registry's latest release (or
    --impact-against) and this DB, and the `db impact` JSON report is stored read-only as
    DIR/<db_version>.impact.json and recorded in the registry (verify-release checks it). Exit 1 if validation finds an
    error (nothing written), 2 if unreadable, 3 if the version is already released or being
    released, or an unregistered file is in its way.

    Example: trainpos db release net-2026.11.sqlite --registry releases/ --note "new curve table" --impact logs/
    """
    from dbtools.release import release_db

    attachment = _impact_attachment(file, registry, impact_runs, impact_against, plan, config, workers)
    result = release_db(file, registry, note=note, impact=attachment)
    r = result.release
    out = console()
    if result.warnings:
        print_findings(result.warnings, console=out, title="Validation warnings")
    rows: list[tuple[str, object]] = [
        ("db_version", r.db_version),
        ("file", str(result.path)),
        ("sha256", r.sha256),
        ("content_hash", r.content_hash),
        ("schema_version", r.schema_version),
        ("released_at", r.released_at),
        ("released_by", r.released_by),
        ("note", r.note or ""),
    ]
    if result.impact_path is not None and attachment is not None:
        rows.append(("impact", f"{result.impact_path} ({attachment.runs_changed} of {attachment.runs} run(s) change)"))
    out.print(key_value_table(rows, title="Released"))


@app.command("releases")
@cli_command
def releases(
    registry: Path = typer.Option(..., "--registry", help="Registry folder."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json."),
) -> None:
    """List the released DB versions of a registry, oldest first.

    Example: trainpos db releases --registry releases/ --format json
    """
    from dbtools.release import list_releases

    rows = list_releases(registry)
    if fmt == Fmt.json:
        print_json({"registry": str(registry), "releases": [r.to_dict() for r in rows]})
        return
    t = rich_table(title=f"Releases in {registry}")
    for c in ("db_version", "released_at", "by", "sha256", "schema", "note"):
        t.add_column(c, overflow="fold", no_wrap=c in ("db_version", "released_at", "sha256"))
    for r in rows:
        t.add_row(r.db_version, r.released_at, r.released_by, r.sha256[:12], str(r.schema_version), r.note or "")
    out = console()
    out.print(t)
    out.print(f"{len(rows)} release(s)")


@app.command("verify-release")
@cli_command
def verify_release(
    version: str | None = typer.Argument(None, help="One db_version (default: every release)."),
    registry: Path = typer.Option(..., "--registry", help="Registry folder."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json."),
) -> None:
    """Re-hash released files against registry and manifests; check each DB's content hash.

    Exit 0 all intact, 1 on any mismatch (tampered, missing or corrupt file), 2 if the
    registry cannot be read or the version is unknown.

    Example: trainpos db verify-release --registry releases/ 2026.11
    """
    from dbtools.release import verify_releases

    report = verify_releases(registry, version)
    if fmt == Fmt.json:
        print_json(report.to_dict())
    else:
        from rich.text import Text

        out = console()
        t = rich_table(title=f"Verification of {registry}")
        t.add_column("db_version")
        t.add_column("file")
        t.add_column("status")
        for r in report.checked:
            bad = report.failed(r.db_version)
            t.add_row(r.db_version, r.file, Text("FAILED", style="red") if bad else Text("ok", style="green"))
        out.print(t)
        if report.findings:
            print_findings(report.findings, console=out, title="Problems")
        n_bad = sum(report.failed(r.db_version) for r in report.checked)
        out.print(f"{len(report.checked) - n_bad} of {len(report.checked)} release(s) intact")
    if not report.ok:
        raise typer.Exit(1)


def _ci_report(findings: list[Finding], target: Path, fmt: ValidateFmt, strict: bool, help_uri_base: str) -> None:
    """SARIF or JUnit on stdout (dbtools.interchange.ci)."""
    import sys

    from dbtools.build import tool_version
    from dbtools.interchange.ci import db_source_files, junit, sarif_text

    if fmt == ValidateFmt.sarif:
        sources = {} if target.is_dir() else db_source_files(target)
        text = sarif_text(
            findings, target=target, tool_version=tool_version(), help_uri_base=help_uri_base, source_files=sources
        )
        sys.stdout.write(text)
    else:
        sys.stdout.write(junit(findings, target=str(target), strict=strict))


@app.command("import")
@cli_command
def import_(
    source: Path = typer.Argument(
        ..., help="railML file (2.0–2.5 or 3.1–3.3), OpenStreetMap file (.osm.pbf, .osm) or RailTopoModel GeoJSON."
    ),
    fmt: ImportFmt | None = typer.Option(
        None,
        "--format",
        help="railml, osm or rtm-geojson (RailTopoModel netelements/netrelations as tp-lib reads them); default: "
        "osm for .osm.pbf/.osm/.osm.bz2 files, rtm-geojson for .geojson, else railml.",
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output source set folder (then: db build SOURCE_DIR)."),
    line_code: Path | None = typer.Option(
        None,
        "--line-code",
        help="railML: map (TOML) of railML lines/tracks → line_code and track, initial pairs → station codes.",
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing output folder."),
    xsd: Path | None = typer.Option(
        None, "--xsd", help="railML: validate the file against this XML Schema first (e.g. railML's railml3.xsd)."
    ),
    osm_railway: str = typer.Option(
        "rail",
        "--osm-railway",
        help="osm: railway=* values of the ways imported, comma-separated (e.g. rail,light_rail).",
    ),
    config: Path | None = typer.Option(
        None, "--config", help="Settings (TOML): its [input] section (size limits of XML and compressed inputs)."
    ),
) -> None:
    """Import a railML, OpenStreetMap or RailTopoModel GeoJSON file as a source set; every
    element that cannot be mapped is reported.

    railML: writes the source tables (the network too: tracks, connections, switches; balise groups
    as G balises), network.toml (when declared), survey/ (centrelines and km posts for gis
    grid, when the file has coordinates) and import_report.json. Exit 0 written (unmapped
    elements are warnings), 1 errors such as duplicate or missing ids, positions on
    undefined tracks, lengths not in metres, an unknown railML version, balises or tracks
    of which none could be imported, or (with --xsd) a schema error (nothing written),
    2 unreadable (malformed XML, entity declarations, bad map, unreadable XSD), 3 output
    exists.

    osm: tracks split at switches and junctions, connections, switches, track_points,
    lines, km from milestones, balise groups with an ETCS identity, network.toml (UTM
    zone) and import_report.json. Exit 0 written, 1 no rail way could be imported, 2
    unreadable file, 3 output exists.

    rtm-geojson (docs/howto/import-geojson.md): tracks, connections, inferred point
    switches and 20 m track_points; exit 0 written (skipped features are warnings), 1 no
    netelement could be imported, an unknown CRS or no FeatureCollection (nothing written),
    2 invalid JSON, 3 output exists.

    Example: trainpos db import line.railml --format railml --out src/ --line-code map.toml
    """
    from dbtools.interchange.osm_read import is_osm_file

    if fmt is None:
        fmt = (
            ImportFmt.osm
            if is_osm_file(source)
            else ImportFmt.rtm_geojson
            if source.suffix.lower() == ".geojson"
            else ImportFmt.railml
        )
    if fmt != ImportFmt.railml and (line_code is not None or xsd is not None):
        raise UsageError(f"--line-code and --xsd apply to railML only, not --format {fmt.value}")
    if fmt == ImportFmt.osm:
        _import_osm(source, out, force, osm_railway)
        return
    if fmt == ImportFmt.rtm_geojson:
        _import_rtm(source, out, force)
        return
    from dbtools.interchange.importer import import_railml

    result = import_railml(source, out, line_map=line_code, force=force, xsd=xsd)
    head = [
        ("folder", str(result.out)),
        ("railML version", result.version),
        ("balises in the file", result.balises_seen),
    ]
    _written(result.findings, "Not imported / warnings", head, result.rows, "Imported")


def _import_osm(source: Path, out: Path, force: bool, railways: str) -> None:
    from dbtools.interchange.osm_import import import_osm

    kinds = tuple(k.strip() for k in railways.split(",") if k.strip())
    if not kinds:
        raise UsageError("--osm-railway: give at least one railway=* value, e.g. rail")
    result = import_osm(source, out, force=force, railways=kinds)
    head: list[tuple[str, object]] = [("folder", str(result.out)), ("metric CRS", result.metric_crs)]
    head += [(f"osm: {k}", v) for k, v in result.counts.items()]
    _written(result.findings, "Not imported / guessed", head, result.rows, "Imported (OSM)")


def _import_rtm(source: Path, out: Path, force: bool) -> None:
    from dbtools.interchange.rtm_import import import_rtm_geojson

    result = import_rtm_geojson(source, out, force=force)
    head = [
        ("folder", str(result.out)),
        ("CRS of the file", result.crs),
        ("netelements in the file", result.netelements_seen),
        ("netrelations in the file", result.netrelations_seen),
        ("switches inferred", result.switches_inferred),
    ]
    _written(result.findings, "Not imported / warnings", head, result.rows, "Imported")


@app.command("export")
@cli_command
def export(
    db: Path = typer.Argument(..., help="Onboard DB file (.sqlite) or source set folder."),
    fmt: str = typer.Option(
        ...,
        "--format",
        help="railml (3.2), geojson, gpkg (GeoPackage), geoparquet or rtm-geojson (RailTopoModel, as tp-lib reads it).",
    ),
    out: Path = typer.Option(
        ..., "--out", "-o", help="Output file; geojson: a folder of one file per layer unless .geojson/.json/.zip."
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing output file."),
    xsd: Path | None = typer.Option(
        None, "--xsd", help="railML: validate the export against this XML Schema before writing it (railml3.xsd)."
    ),
    layers: str | None = typer.Option(
        None, "--layers", help="GIS formats: only these layers, comma-separated (e.g. tracks,switches,balises)."
    ),
    crs: str | None = typer.Option(
        None,
        "--crs",
        help="GIS formats: reproject every layer to EPSG:XXXX (GeoJSON other than EPSG:4326: with a 'crs' member).",
    ),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Export a DB as railML 3.2, as GIS layers for QGIS (GeoJSON, GeoPackage, GeoParquet) or
    as RailTopoModel GeoJSON (rtm-geojson: netelements and netrelations, as tp-lib reads them).

    Layers: balises, feature_points, gis_points, gis_lines and the network's tracks,
    switches, connections, balise_groups, km_posts (GeoParquet: the first four). GeoJSON:
    one file (--out *.geojson or *.json), a folder of LAYER.geojson files, or their zip
    (--out *.zip). --layers picks layers, --crs EPSG:XXXX reprojects them (GeoJSON, which
    RFC 7946 keeps in WGS 84, then names the CRS in the GeoJSON 2008 'crs' member that GDAL
    and QGIS read). Exit 0 written, 1 source set
    errors or (with --xsd) the export is not valid against the schema (nothing written),
    2 unreadable input or XSD, unknown format, 3 output exists.

    Example: trainpos db export net.sqlite --format gpkg --out net.gpkg
    """
    from dbtools.interchange.export import ExportFormat, GisOptions, export_network
    from dbtools.interchange.reproject import parse_crs

    try:
        kind = ExportFormat(fmt)
    except ValueError:
        raise UsageError(f"--format '{fmt}': use one of {', '.join(f.value for f in ExportFormat)}") from None
    chosen = None if layers is None else tuple(name.strip() for name in layers.split(",") if name.strip())
    gis = GisOptions(layers=chosen, crs=None if crs is None else parse_crs(crs))
    counts = export_network(db, out, kind, force=force, xsd=xsd, gis=gis)
    console().print(key_value_table([("file", str(out)), ("format", kind.value), *counts.items()], title="Exported"))


@app.command("review")
@cli_command
def review(
    old: Path = typer.Argument(..., help="Old onboard DB file (.sqlite) or source set folder."),
    new: Path = typer.Argument(..., help="New onboard DB file (.sqlite) or source set folder."),
    out: Path = typer.Option(..., "--out", "-o", help="Output page (.html), self-contained."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output file."),
    tiles: str | None = typer.Option(
        None,
        "--tiles",
        help="XYZ tile URL template for the map background, e.g. https://tile.openstreetmap.org/{z}/{x}/{y}.png "
        "(default: no tiles, the page loads nothing from the network).",
    ),
    tiles_attribution: str = typer.Option(
        "© OpenStreetMap contributors", "--tiles-attribution", help="Attribution shown with --tiles."
    ),
) -> None:
    """One page for the reviewer of a DB change: validation of NEW, the diff, a network map.

    The map is interactive (Leaflet, inlined: the single file works offline): NEW's tracks,
    switches, connections, balise groups and km ticks, and what changed; hover for ids and km.
    Exit 0 written and NEW has no error, 1 written but NEW has errors, 2 unreadable,
    3 output exists.

    Example: trainpos db review net-2026.10.sqlite net-2026.11.sqlite --out review.html
    """
    from dbtools.interchange.review import write_review

    findings = write_review(old, new, out, force=force, tiles=tiles, tiles_attribution=tiles_attribution)
    console().print(f"review page written to {safe(out)}")
    if has_errors(findings):
        raise typer.Exit(1)


app.command("info")(info)
app.command("show")(show)
app.command("impact")(impact)  # last in the group's help, as before


def _written(
    findings: list[Finding], findings_title: str, head: Sequence[tuple[str, object]], rows: dict[str, int], title: str
) -> Console:
    """What a command that writes a DB or a source set prints: its findings (if any), then
    what was written — ``head`` and the rows per table. Returns the console for more."""
    out_c = console()
    if findings:
        print_findings(findings, console=out_c, title=findings_title)
    out_c.print(key_value_table([*head, *((f"rows: {k}", v) for k, v in rows.items())], title=title))
    return out_c
