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

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer
from rich.console import Console
from rich.table import Table as RichTable

from cli.errors import NO_VERIFY_HASH, cli_command
from cli.render import console, key_value_table, print_findings, print_json
from dbtools.build import build_db
from dbtools.diff import DbDiff, diff_paths
from dbtools.release import ImpactAttachment, list_releases, release_db, verify_releases
from schemas.errors import UsageError
from schemas.findings import Finding, findings_report, has_errors
from schemas.registry import DB_VERSION_RULE, REGISTRY_FILE

if TYPE_CHECKING:
    from fieldlogs.impact import ImpactReport

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


@app.command("build")
@cli_command
def build(
    source_dir: Path = typer.Argument(..., help="Source set folder: gis, balises, feature_points (.csv/.xlsx)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output onboard DB file (.sqlite)."),
    version: str | None = typer.Option(None, "--version", help=f"DB version: {DB_VERSION_RULE} (default: UTC time)."),
    note: str = typer.Option("", "--note", help="Release note: who and why."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output file."),
) -> None:
    """Build an onboard DB version from a source set.

    Example: trainpos db build network/ --out net-2026.11.sqlite --version 2026.11 --note "new curve table"
    """
    result = build_db(source_dir, out, db_version=version, note=note, force=force)
    out_c = console()
    if result.warnings:
        print_findings(result.warnings, console=out_c, title="Source warnings")
    rows = [(f"rows: {k}", v) for k, v in result.rows.items()]
    out_c.print(
        key_value_table(
            [
                ("file", str(result.path)),
                ("db_version", result.db_version),
                ("content_hash", result.content_hash),
                *rows,
            ],
            title="Built",
        )
    )


@app.command("validate")
@cli_command
def validate(
    target: Path = typer.Argument(..., help="Onboard DB file (.sqlite) or source set folder."),
    fmt: ValidateFmt = typer.Option(
        ValidateFmt.table, "--format", help="table, json, sarif (SARIF 2.1.0) or junit (JUnit XML) for CI."
    ),
    strict: bool = typer.Option(False, "--strict", help="Warnings also fail (exit 1)."),
) -> None:
    """Check every consistency rule; exit 0 clean, 1 errors (or warnings with --strict), 2 unreadable.

    Example: trainpos db validate net-2026.11.sqlite --format json
    """
    from dbtools.validate import validate_path

    findings = validate_path(target)
    if fmt in (ValidateFmt.sarif, ValidateFmt.junit):
        _ci_report(findings, target, fmt, strict)
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
    head = RichTable(title="db diff")
    head.add_column("")
    head.add_column("old", overflow="fold")
    head.add_column("new", overflow="fold")
    head.add_row("origin", _side_cell(d.old, "origin"), _side_cell(d.new, "origin"))
    head.add_row("db_version", _side_cell(d.old, "db_version"), _side_cell(d.new, "db_version"))
    head.add_row("content_hash", _side_cell(d.old, "content_hash")[:16], _side_cell(d.new, "content_hash")[:16])
    head.add_row("content check", _content_check(d.old), _content_check(d.new))
    head.add_row("schema_version", *("—" if v is None else str(v) for v in d.schema_version))
    out.print(head)
    counts = RichTable(title="Rows")
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
    workers: int = typer.Option(1, "--workers", "-j", min=1, help="Processes replaying the --impact runs."),
    config: Path | None = typer.Option(None, "--config", help="Settings (TOML) for the --impact replay."),
) -> None:
    """Validate a DB and add it to a registry as an immutable, read-only version.

    Writes DIR/<db_version>.sqlite (mode 0444), DIR/<db_version>.sha256 (sha256sum format)
    and a row in DIR/registry.sqlite. With --impact RUNS the runs are first replayed
    against the registry's latest release (or --impact-against) and this DB, and the
    `db impact` JSON report is stored read-only as DIR/<db_version>.impact.json and
    recorded in the registry (verify-release checks it). Exit 1 if validation finds an
    error (nothing written), 2 if unreadable, 3 if the version is already released.

    Example: trainpos db release net-2026.11.sqlite --registry releases/ --note "new curve table" --impact logs/
    """
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
    rows = list_releases(registry)
    if fmt == Fmt.json:
        print_json({"registry": str(registry), "releases": [r.to_dict() for r in rows]})
        return
    t = RichTable(title=f"Releases in {registry}")
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
    report = verify_releases(registry, version)
    if fmt == Fmt.json:
        print_json(report.to_dict())
    else:
        out = console()
        t = RichTable(title=f"Verification of {registry}")
        t.add_column("db_version")
        t.add_column("file")
        t.add_column("status")
        for r in report.checked:
            bad = report.failed(r.db_version)
            t.add_row(r.db_version, r.file, "[red]FAILED[/]" if bad else "[green]ok[/]")
        out.print(t)
        if report.findings:
            print_findings(report.findings, console=out, title="Problems")
        n_bad = sum(report.failed(r.db_version) for r in report.checked)
        out.print(f"{len(report.checked) - n_bad} of {len(report.checked)} release(s) intact")
    if not report.ok:
        raise typer.Exit(1)


def _ci_report(findings: list[Finding], target: Path, fmt: ValidateFmt, strict: bool) -> None:
    """SARIF or JUnit on stdout (dbtools.interchange.ci)."""
    import sys

    from dbtools.build import tool_version
    from dbtools.interchange.ci import junit, sarif_text

    if fmt == ValidateFmt.sarif:
        sys.stdout.write(
            sarif_text(findings, target=None if target.is_dir() else str(target), tool_version=tool_version())
        )
    else:
        sys.stdout.write(junit(findings, target=str(target), strict=strict))


@app.command("import")
@cli_command
def import_(
    source: Path = typer.Argument(..., help="railML file (2.0–2.5 or 3.1–3.3)."),
    fmt: ImportFmt = typer.Option(..., "--format", help="railml."),
    out: Path = typer.Option(..., "--out", "-o", help="Output source set folder (then: db build SOURCE_DIR)."),
    line_code: Path | None = typer.Option(
        None,
        "--line-code",
        help="Map (TOML): railML lines/tracks → line_code and track, initial pairs → station codes.",
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing output folder."),
) -> None:
    """Import a railML file as a source set; every element that cannot be mapped is reported.

    Writes the source tables, network.toml (when declared), survey/ (centrelines and km
    posts for gis grid, when the file has coordinates) and import_report.json. Exit 0
    written (unmapped elements are warnings), 1 errors such as duplicate or missing ids,
    positions on undefined tracks, lengths not in metres or an unknown railML version
    (nothing written), 2 unreadable (malformed XML, entity declarations, bad map), 3 output exists.

    Example: trainpos db import line.railml --format railml --out src/ --line-code map.toml
    """
    from dbtools.interchange.importer import import_railml

    result = import_railml(source, out, line_map=line_code, force=force)
    out_c = console()
    if result.findings:
        print_findings(result.findings, console=out_c, title="Not imported / warnings")
    rows = [(f"rows: {k}", v) for k, v in result.rows.items()]
    out_c.print(
        key_value_table(
            [
                ("folder", str(result.out)),
                ("railML version", result.version),
                ("balises in the file", result.balises_seen),
                *rows,
            ],
            title="Imported",
        )
    )


@app.command("export")
@cli_command
def export(
    db: Path = typer.Argument(..., help="Onboard DB file (.sqlite) or source set folder."),
    fmt: str = typer.Option(..., "--format", help="railml (3.2), geojson, gpkg (GeoPackage) or geoparquet."),
    out: Path = typer.Option(..., "--out", "-o", help="Output file."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output file."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Export a DB as railML 3.2 or as GIS layers for QGIS (GeoJSON, GeoPackage, GeoParquet).

    Layers: balises, feature_points, gis_points, gis_lines. Exit 0 written, 1 source set
    errors, 2 unreadable input or unknown format, 3 output exists.

    Example: trainpos db export net.sqlite --format gpkg --out net.gpkg
    """
    from dbtools.interchange.export import ExportFormat, export_network
    from schemas.errors import UsageError

    try:
        kind = ExportFormat(fmt)
    except ValueError:
        raise UsageError(f"--format '{fmt}': use one of {', '.join(f.value for f in ExportFormat)}") from None
    counts = export_network(db, out, kind, force=force)
    console().print(key_value_table([("file", str(out)), ("format", kind.value), *counts.items()], title="Exported"))


@app.command("review")
@cli_command
def review(
    old: Path = typer.Argument(..., help="Old onboard DB file (.sqlite) or source set folder."),
    new: Path = typer.Argument(..., help="New onboard DB file (.sqlite) or source set folder."),
    out: Path = typer.Option(..., "--out", "-o", help="Output page (.html), self-contained."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output file."),
) -> None:
    """One page for the reviewer of a DB change: validation of NEW, the diff, a map of what moved.

    The map is inline SVG drawn in NEW's metric CRS (no tiles, no scripts). Exit 0 written
    and NEW has no error, 1 written but NEW has errors, 2 unreadable, 3 output exists.

    Example: trainpos db review net-2026.10.sqlite net-2026.11.sqlite --out review.html
    """
    from dbtools.interchange.review import write_review

    findings = write_review(old, new, out, force=force)
    console().print(f"review page written to {out}")
    if has_errors(findings):
        raise typer.Exit(1)


# --------------------------------------------------------------------------- db impact


class ImpactFmt(StrEnum):
    table = "table"
    json = "json"
    html = "html"


@app.command("impact")
@cli_command
def impact(
    old: Path = typer.Argument(..., help="Old onboard DB file (.sqlite), e.g. the version in service."),
    new: Path = typer.Argument(..., help="New onboard DB file (.sqlite), the candidate release."),
    runs: list[Path] = typer.Argument(..., help="Run folders, or folders to search for runs (run.json)."),
    fmt: ImpactFmt = typer.Option(ImpactFmt.table, "--format", help="table, json or html (html needs --out)."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write the report to this file instead of stdout."),
    plan: Path | None = typer.Option(
        None, "--plan", help="Possession plan (CSV/XLSX): road-rail runs are checked against it on both versions."
    ),
    workers: int = typer.Option(1, "--workers", "-j", min=1, help="Processes replaying runs."),
    config: Path | None = typer.Option(
        None, "--config", help="Settings (TOML): the pipeline's sections, [possession]."
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Replay runs against two DB versions and show what the new one changes, before `db release`.

    Each run is read once and replayed through the positioning pipeline on OLD and on NEW
    (the same replayer as `audit`). Per route (line, track, direction) and per run, old →
    new: balise and feature-point corrections (count, mean/max position-correction %),
    feature corrections refused and their diagnostics, balise anomalies, fail-safes,
    possession alarms (road-rail runs, with --plan) and the largest margin; and every
    correction whose amount changed (e.g. at a balise whose km moved).

    JSON (--format json): {"old": {path, db_version, content_hash}, "new": {…}, "plan",
    "same_content", "totals": {runs, runs_changed, runs_failed: {old, new},
    corrections_changed}, "routes": [{line_code, track, direction, runs, replayed, old,
    new, delta, refusals: {old, new}}], "runs": [{run, run_id, vehicle_id, vehicle_kind, line_code, track,
    direction, old, new, delta, refusals, alarms, errors, changed_corrections}]}; the
    figures of old/new/delta: n_balise, balise_mean_pct, balise_max_pct, n_feature,
    feature_mean_pct, feature_max_pct, n_refused, n_anomalies, n_failsafe, n_alarms,
    max_margin_m.

    Exit 0 (a report, whatever changes); 2 if a DB, the plan or the runs cannot be read;
    3 if --out exists (use --force) or would replace an input.

    Example: trainpos db impact net-2026.10.sqlite net-2026.11.sqlite logs/ --format html --out impact.html
    """
    from cli.render import check_outputs, inputs_of
    from fieldlogs.config import load_tree

    if fmt == ImpactFmt.html and out is None:
        raise UsageError("--format html needs --out FILE")
    inputs = inputs_of(old, new, runs, plan, config)
    check_outputs(files=[out], force=force, inputs=inputs)
    report = _impact_report(old, new, runs, plan, load_tree(config), workers)
    _emit_impact(report, fmt, out, force, inputs)


def _impact_report(
    old: Path, new: Path, runs: list[Path], plan: Path | None, tree: object, workers: int
) -> ImpactReport:
    """The impact report, with a progress bar on stderr while the runs are replayed."""
    from cli.gis import _Bar
    from cli.render import err_console, progress
    from fieldlogs.impact import impact_runs

    bar = _Bar(progress(err_console()))
    try:
        return impact_runs(old, new, runs, plan=plan, tree=tree, workers=workers, progress=bar)
    finally:
        if bar.task is not None:
            bar.bar.stop()


def _emit_impact(report: ImpactReport, fmt: ImpactFmt, out: Path | None, force: bool, inputs: list[Path]) -> None:
    import io
    import json
    import sys

    from rich.console import Console

    from cli.render import write_out

    if fmt == ImpactFmt.html:
        from fieldlogs.impact.page import render_html

        text = render_html(report)
    elif fmt == ImpactFmt.json:
        text = json.dumps(report.to_dict(), ensure_ascii=False, indent=2, default=str) + "\n"
    else:
        buf = io.StringIO()
        _print_impact(report, Console(file=buf, width=200, color_system=None) if out else console())
        text = buf.getvalue()
    if out is None:
        sys.stdout.write(text)
        return
    write_out(out, text, force=force, inputs=inputs)
    console().print(f"impact report written to {out}")


def _num_text(v: object) -> str:
    if v is None:
        return "—"
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def _route_table(r: dict[str, Any]) -> RichTable:
    """One route: every figure old, new and the change."""
    from fieldlogs.impact import FIGURES

    t = RichTable(title=f"{r['line_code']} {r['track']} {r['direction']}: {r['runs']} run(s)")
    for c in ("figure", "old", "new", "change"):
        t.add_column(c, justify="left" if c == "figure" else "right")
    for k, label in FIGURES.items():
        change = r["delta"].get(k)
        shown = "" if change in (None, 0, 0.0) else ("+" if float(change) > 0 else "") + _num_text(change)
        t.add_row(label, _num_text(r["old"].get(k)), _num_text(r["new"].get(k)), shown)
    refused = r["refusals"]
    for diag in sorted(set(refused["old"]) | set(refused["new"])):
        a, b = refused["old"].get(diag, 0), refused["new"].get(diag, 0)
        t.add_row(f"  refused: {diag}", str(a), str(b), "" if a == b else f"{b - a:+d}")
    return t


def _runs_table(runs: list[dict[str, Any]]) -> RichTable:
    """The runs that change: the change of each figure (new − old)."""
    from fieldlogs.impact import FIGURES

    t = RichTable(title="Runs that change (new − old)")
    t.add_column("run")
    for label in FIGURES.values():
        t.add_column(label, justify="right", overflow="fold")
    t.add_column("corrections changed", justify="right")
    for r in runs:
        cells = [_num_text(r["delta"].get(k)) for k in FIGURES]
        t.add_row(str(r["run_id"] or r["run"]), *cells, str(len(r["changed_corrections"])))
    return t


def _print_impact(report: ImpactReport, out: Console) -> None:
    d = report.to_dict()
    tot = d["totals"]
    out.print(
        key_value_table(
            [
                ("old", f"{d['old']['path']} (version {d['old']['db_version']})"),
                ("new", f"{d['new']['path']} (version {d['new']['db_version']})"),
                ("runs", tot["runs"]),
                ("runs changed", tot["runs_changed"]),
                ("corrections changed", tot["corrections_changed"]),
                ("runs not replayed", f"old {tot['runs_failed']['old']}, new {tot['runs_failed']['new']}"),
            ],
            title="db impact",
        )
    )
    for route in d["routes"]:
        out.print(_route_table(route))
    changed = [r for r in d["runs"] if r["changed_corrections"] or any(v not in (None, 0) for v in r["delta"].values())]
    if changed:
        out.print(_runs_table(changed))
    for r in changed:
        for c in r["changed_corrections"][:10]:
            out.print(
                f"• {r['run_id']}: {c['type']} {c['row']} at t {c['t']:.1f} s: "
                f"{_num_text(c['old_m'])} → {_num_text(c['new_m'])} m (change {_num_text(c['delta_m'])} m)",
                markup=False,
            )
    for r in d["runs"]:
        for side in ("old", "new"):
            if r["errors"][side]:
                out.print(f"• {r['run']}: {side} version cannot replay it: {r['errors'][side]}", markup=False)


def _impact_attachment(
    file: Path,
    registry: Path,
    runs: list[Path] | None,
    against: Path | None,
    plan: Path | None,
    config: Path | None,
    workers: int,
) -> ImpactAttachment | None:
    """``db release --impact``: the impact report of ``file`` against ``against`` or the
    registry's latest release, as the attachment :func:`release_db` stores."""
    import json

    from fieldlogs.config import load_tree

    if not runs:
        if against is not None or plan is not None:
            raise UsageError("--impact-against and --plan need --impact RUNS")
        return None
    if against is None:
        if not (registry / REGISTRY_FILE).exists() or not list_releases(registry):
            raise UsageError("--impact needs a release in the registry to compare with, or --impact-against OLD.sqlite")
        against = registry / list_releases(registry)[-1].file
    report = _impact_report(against, file, runs, plan, load_tree(config), workers)
    data = report.to_dict()
    return ImpactAttachment(
        report_json=(json.dumps(data, ensure_ascii=False, indent=2, default=str) + "\n").encode("utf-8"),
        against_version=data["old"]["db_version"],
        against_content_hash=data["old"]["content_hash"],
        runs=data["totals"]["runs"],
        runs_changed=data["totals"]["runs_changed"],
    )
