"""``trainpos demo``: the main job on the bundled sample network and logs."""

from __future__ import annotations

from pathlib import Path

import typer

from cli.errors import cli_command
from cli.render import console, err_console, frame_table, print_findings, progress
from dbtools.build import build_db
from dbtools.validate import validate_path
from fieldlogs.audit import audit
from fieldlogs.report import build_report
from schemas.errors import InputError


def sample_logs_dir() -> Path:
    return Path(__file__).resolve().parent.parent / "fieldlogs" / "sample_logs"


@cli_command
def demo(
    out: Path = typer.Option(Path("demo-out"), "--out", "-o", help="Folder for the DB, audit and report."),
    workers: int | None = typer.Option(None, "--workers", "-j", min=1, help="Processes (default: all cores)."),
) -> None:
    """Build and validate the sample DB (real Kawagoe line geometry), audit the bundled
    sample logs through the positioning pipeline, print the report and write it as HTML.

    Example: trainpos demo --out demo-out
    """
    from dbtools.sample_network import sample_source_dir
    from fieldlogs.report_html import render_html

    c = console()
    out.mkdir(parents=True, exist_ok=True)
    db = out / "sample-network.sqlite"
    res = build_db(sample_source_dir(), db, db_version="sample-1", note="bundled sample network", force=True)
    c.print(
        f"[bold]1.[/] built {db} (version {res.db_version}, "
        f"{res.rows['gis']} GIS points, {res.rows['balises']} balises, {res.rows['feature_points']} feature rows)"
    )
    findings = validate_path(db)
    c.print("[bold]2.[/] validated:", end=" ")
    print_findings(findings, console=c)
    logs = sample_logs_dir()
    if not logs.is_dir():
        raise InputError("sample logs are missing from this installation", path=logs)
    audit_db = out / "audit.sqlite"
    if audit_db.exists():
        audit_db.unlink()
    with progress(err_console()) as bar:
        task = bar.add_task("auditing sample runs", total=None, rate="")
        stats = audit(
            [logs], db, audit_db, workers=workers, progress=lambda d, t, _r: bar.update(task, completed=d, total=t)
        )
    c.print(f"[bold]3.[/] audited {stats.audited} runs ({stats.failed} failed) in {stats.elapsed_s:.1f} s")
    rep = build_report(audit_db)
    cols = [
        "line_code",
        "track",
        "direction",
        "n_runs",
        "n_corrections",
        "distance_m",
        "mean_correction_pct",
        "median_correction_pct",
        "max_correction_pct",
        "share_above_target",
        "n_slips",
        "n_failsafe",
    ]
    c.print(frame_table(rep.routes[cols].round(3), title="Position-correction per route (target 0.5 %)"))
    c.print(frame_table(rep.runs.round(3), title="Runs"))
    html = out / "report.html"
    html.write_text(render_html(rep, audit_db), encoding="utf-8")
    c.print(f"[bold]4.[/] HTML report: {html}")
