"""``trainpos demo``: the main job on the bundled sample network and logs."""

from __future__ import annotations

from pathlib import Path

import typer

from cli.audit import ProgressBar, print_legend, render_tables
from cli.errors import cli_command
from cli.options import workers_option
from cli.render import console, err_console, print_findings, progress, safe
from schemas.errors import InputError


def sample_logs_dir() -> Path:
    """The bundled sample runs (``fieldlogs/sample_logs``, made by ``fieldlogs.simulate.samples``)."""
    return Path(__file__).resolve().parent.parent / "fieldlogs" / "sample_logs"


def sample_source_dir() -> Path:
    """The bundled sample network's source set with its station, crossovers and junction
    (``dbtools/sample_network/network_sources``)."""
    from dbtools.sample_network import sample_network_source_dir as bundled

    return Path(bundled())


@cli_command
def demo(
    out: Path = typer.Option(Path("demo-out"), "--out", "-o", help="Folder for the DB, audit and report."),
    workers: int | None = workers_option("running the pipeline"),
) -> None:
    """Build and validate the sample DB (real Kawagoe line geometry), audit the bundled
    sample logs through the positioning pipeline, print the report and write it as HTML.

    Writes OUT/sample-network.sqlite, OUT/audit.sqlite and OUT/report.html (replaced on
    every run).

    Example: trainpos demo --out demo-out
    """
    from dbtools.atomic import refuse_registry
    from dbtools.build import build_db
    from dbtools.validate import validate_path
    from fieldlogs.audit.runner import audit
    from fieldlogs.reports.page import render_html
    from fieldlogs.reports.report import build_report

    refuse_registry(out)  # every file it writes lies inside OUT
    logs = sample_logs_dir()
    if not logs.is_dir():
        raise InputError("sample logs are missing from this installation", path=logs)
    c = console()
    out.mkdir(parents=True, exist_ok=True)
    db = out / "sample-network.sqlite"
    res = build_db(sample_source_dir(), db, db_version="sample-1", note="bundled sample network", force=True)
    c.print(
        f"[bold]1.[/] built {safe(db)} (version {safe(res.db_version)}, "
        f"{res.rows['gis']} GIS points, {res.rows['balises']} balises, {res.rows['feature_points']} feature rows)"
    )
    findings = validate_path(db)
    c.print("[bold]2.[/] validated:", end=" ")
    print_findings(findings, console=c)
    audit_db = out / "audit.sqlite"
    for stale in (audit_db, audit_db.with_name(audit_db.name + "-wal"), audit_db.with_name(audit_db.name + "-shm")):
        stale.unlink(missing_ok=True)  # a fresh audit: the DB was just rebuilt
    with progress(err_console()) as bar:
        stats = audit([logs], db, audit_db, workers=workers, progress=ProgressBar(bar, "auditing sample runs"))
    c.print(
        f"[bold]3.[/] audited {stats.audited} runs ({stats.failed} failed) in {stats.elapsed_s:.1f} s "
        f"→ {safe(audit_db)}"
    )
    for path, err in stats.errors:
        err_console().print(
            f"[red]failed:[/] {safe(path)}: {safe(err.splitlines()[0] if err else '')}", highlight=False
        )
    rep = build_report(audit_db)
    render_tables(rep, c)
    print_legend(c)
    html = out / "report.html"
    html.write_text(render_html(rep, audit_db), encoding="utf-8")
    c.print(f"[bold]4.[/] HTML report: {safe(html)}")
