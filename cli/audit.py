"""``trainpos audit`` and ``trainpos report``: fleet audits and their reports."""

from __future__ import annotations

import time
from enum import StrEnum
from pathlib import Path

import typer

from cli.errors import cli_command
from cli.render import console, err_console, frame_table, key_value_table, print_json, progress
from fieldlogs.audit import audit as run_audit
from fieldlogs.pipeline import PipelineConfig
from fieldlogs.report import build_report, report_json
from schemas.errors import UsageError


@cli_command
def audit(
    log_roots: list[Path] = typer.Argument(..., help="Run folders or folders to search for runs (run.json)."),
    db: Path = typer.Option(..., "--db", help="Onboard DB (.sqlite)."),
    out: Path = typer.Option(..., "--out", "-o", help="Audit database (created, or resumed if it exists)."),
    workers: int | None = typer.Option(None, "--workers", "-j", min=1, help="Processes (default: all cores)."),
    dask_scheduler: str | None = typer.Option(None, "--dask-scheduler", help="Run on this Dask cluster instead."),
    config: Path | None = typer.Option(None, "--config", help="Pipeline parameters (TOML)."),
) -> None:
    """Run the pipeline on every run found and store the results as each run finishes.

    Resumes an interrupted audit; skips runs already audited with the same files, DB
    content and config; a failing run is recorded with its error and the others go on.

    Example: trainpos audit logs/ --db net.sqlite --out audit.sqlite --workers 2
    """
    cfg = PipelineConfig.from_toml(config) if config else PipelineConfig()
    started = time.perf_counter()
    with progress(err_console()) as bar:
        task = bar.add_task("auditing", total=None, rate="")

        def on_progress(done: int, total: int, _run: str) -> None:
            dt = time.perf_counter() - started
            bar.update(task, completed=done, total=total, rate=f"{done / dt:.2f} runs/s" if dt > 0 else "")

        stats = run_audit(
            log_roots, db, out, config=cfg, workers=workers, scheduler=dask_scheduler, progress=on_progress
        )
    rows = [
        ("runs found", stats.total),
        ("audited", stats.audited),
        ("skipped (unchanged)", stats.skipped),
        ("failed", stats.failed),
        ("elapsed", f"{stats.elapsed_s:.1f} s"),
        ("throughput", f"{stats.runs_per_min:.1f} runs/min"),
    ]
    console().print(key_value_table(rows, title=f"Audit → {out}"))
    for path, err in stats.errors[:20]:
        err_console().print(f"[red]failed:[/] {path}: {err.splitlines()[0] if err else ''}", highlight=False)


class By(StrEnum):
    route = "route"
    run = "run"
    vehicle = "vehicle"


class ReportFmt(StrEnum):
    table = "table"
    csv = "csv"
    json = "json"
    html = "html"


@cli_command
def report(
    audit_db: Path = typer.Argument(..., help="Audit database written by `trainpos audit`."),
    by: By = typer.Option(By.route, "--by", help="Group by route (line, track, direction), run or vehicle."),
    fmt: ReportFmt = typer.Option(ReportFmt.table, "--format", help="table, csv, json or html."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write to this file (required for html)."),
    target_pct: float = typer.Option(0.5, "--target-pct", help="Position-correction target [%]."),
) -> None:
    """Position-correction percentages, slips, feature points, GPS and alarms per route/run/vehicle.

    Example: trainpos report audit.sqlite --format html --out audit.html
    """
    from fieldlogs.report_html import render_html

    rep = build_report(audit_db, by=by.value, target_pct=target_pct)
    if fmt == ReportFmt.html:
        if out is None:
            raise UsageError("--format html needs --out FILE")
        _write(out, render_html(rep, audit_db))
        console().print(f"HTML report written to {out}")
        return
    if fmt == ReportFmt.json:
        import json

        text = json.dumps(report_json(rep), indent=2, ensure_ascii=False)
        _write(out, text + "\n") if out else print_json(report_json(rep))
        return
    if fmt == ReportFmt.csv:
        text = rep.groups.to_csv(index=False, lineterminator="\n")
        _write(out, text) if out else typer.echo(text, nl=False)
        return
    c = console()
    cols = [c_ for c_ in rep.groups.columns if c_ not in ("refusal_reasons",)]
    c.print(frame_table(rep.groups[cols].round(3), title=f"Positioning audit by {by.value} (target {target_pct:g} %)"))
    if len(rep.failed_runs):
        c.print(frame_table(rep.failed_runs, title="Runs that failed"))


def _write(path: Path, text: str) -> None:
    from dbtools.atomic import atomic_file

    with atomic_file(path, force=True) as tmp:
        tmp.write_text(text, encoding="utf-8")
