"""``trainpos audit`` and ``trainpos report``: fleet audits and their reports."""

from __future__ import annotations

import json
import time
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from cli.errors import cli_command
from cli.options import DASK_SCHEDULER, NO_VERIFY_HASH, workers_option
from cli.render import (
    console,
    emit_rendered,
    emit_text,
    err_console,
    frame_table,
    key_value_table,
    print_json,
    progress,
    safe,
    write_out,
)
from fieldlogs.pipeline.config import TARGET_PCT
from schemas.errors import EXIT_FINDINGS, UsageError
from schemas.jsonable import jsonable

if TYPE_CHECKING:
    import pandas as pd
    from rich.console import Console
    from rich.progress import Progress, TaskID

    from fieldlogs.reports.report import Report


class ProgressBar:
    """Adapts the library's ``progress(done, total, run)`` callback to a Rich bar with
    runs/s (runs processed by this call, not the ones skipped up front) and ETA."""

    def __init__(self, bar: Progress, description: str) -> None:
        self.bar = bar
        self.task: TaskID = bar.add_task(description, total=None, rate="")
        self.first: int | None = None
        self.started = time.perf_counter()

    def __call__(self, done: int, total: int, _run: str) -> None:
        if self.first is None:  # runs skipped without reading them: not part of the rate/ETA
            self.first = done
            self.started = time.perf_counter()
            self.bar.reset(self.task, total=total, completed=done)
            return
        dt = time.perf_counter() - self.started
        rate = (done - self.first) / dt if dt > 0 else 0.0
        self.bar.update(self.task, completed=done, total=total, rate=f"{rate:.2f} runs/s")


class Unit(StrEnum):
    F = "F"
    R = "R"
    both = "both"


@cli_command
def audit(
    log_roots: list[Path] = typer.Argument(..., help="Run folders or folders to search for runs (run.json)."),
    db: Path = typer.Option(..., "--db", help="Onboard DB (.sqlite)."),
    out: Path = typer.Option(..., "--out", "-o", help="Audit database (created, or resumed if it exists)."),
    workers: int | None = workers_option("running the pipeline"),
    dask_scheduler: str | None = DASK_SCHEDULER,
    config: Path | None = typer.Option(None, "--config", help="Settings (TOML, see trainpos config show)."),
    unit: Unit = typer.Option(
        Unit.F,
        "--unit",
        help="Positioning unit [S003 §2: one per cab]: F (the F cab's), R (the R cab's: the run seen from the "
        "other end), both (unit F's figures stored with the two units' disagreements).",
    ),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Run the positioning pipeline on every run found and store the results as each run finishes.

    Resumes an interrupted audit; skips runs already audited with the same file contents,
    DB content, config and unit; a failing run is recorded with its error and the others go on.
    Exit 0 when every run was audited (or skipped), 1 when some run failed, 2 when the DB,
    a log root or the audit database cannot be read, 3 when --out is inside a release
    registry (nothing is ever written there).

    Example: trainpos audit logs/ --db net.sqlite --out audit.sqlite --workers 2
    """
    from fieldlogs.audit.runner import audit as run_audit
    from fieldlogs.config import load_tree

    cfg = load_tree(config).pipeline
    with progress(err_console()) as bar:
        stats = run_audit(
            log_roots,
            db,
            out,
            config=cfg,
            workers=workers,
            scheduler=dask_scheduler,
            progress=ProgressBar(bar, "auditing"),
            unit=unit.value,
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
    for warning in stats.warnings:
        err_console().print(f"[yellow]warning:[/] {safe(warning)}", highlight=False)
    for path, err in stats.errors[:20]:
        err_console().print(
            f"[red]failed:[/] {safe(path)}: {safe(err.splitlines()[0] if err else '')}", highlight=False
        )
    if len(stats.errors) > 20:
        err_console().print(f"… {len(stats.errors) - 20} more failed runs (see the runs table of {safe(out)})")
    if stats.failed:
        raise typer.Exit(EXIT_FINDINGS)


class By(StrEnum):
    route = "route"
    run = "run"
    vehicle = "vehicle"
    track = "track"


class ReportFmt(StrEnum):
    table = "table"
    csv = "csv"
    json = "json"
    html = "html"


#: Columns of the terminal tables (labelled by schemas.labels, as on the HTML page).
PCT_COLUMNS = [
    "n_runs",
    "distance_km",
    "n_corrections",
    "mean_correction_pct",
    "median_correction_pct",
    "max_correction_pct",
    "share_above_target",
]
OTHER_COLUMNS = [
    "n_feature_corrections",
    "n_feature_refused",
    "n_slips",
    "n_slips_readhered",
    "max_slip_error_m",
    "gps_decisions",
    "gps_trusted_share",
    "n_failsafe",
    "n_anomalies",
]
#: One line per column of the report tables: what the printed term means (issue 33: a summary
#: explains its terms).
LEGEND = {
    "runs": "runs audited without error",
    "distance [km]": "distance travelled (corrected odometry)",
    "balise corrections": "position corrections at balises",
    "mean correction [%], median correction [%], max correction [%]": (
        "correction ÷ distance since the previous correction × 100, over balise corrections"
    ),
    "share above target": "share of balise corrections above the target % (--target-pct)",
    "feature corrections, feature corrections refused": "corrections at curves (feature points) accepted, and refused",
    "failed diagnostics (count)": "the diagnostics that refused feature-point corrections, with their counts",
    "slips, slips re-adhered": "wheel slip/slide episodes corrected inertially, and those that re-adhered in time",
    "max slip error [m]": "largest error budget of a slip correction",
    "GPS decisions": "up/down track decisions made from trusted GPS fixes",
    "GPS trusted share": "mean share of GPS fixes that passed the trust checks",
    "fail-safe events": "fail-safe events (a slip correction lasted too long)",
    "anomalies": "balise anomalies (telegrams that do not fit the DB; the events name them)",
}


def print_legend(c: Console) -> None:
    """The report tables' terms, one line each (a key/value table: records at 80 columns)."""
    c.print(key_value_table(LEGEND.items(), title="What the columns mean"))


def _view(frame: pd.DataFrame, cols: list[str]) -> pd.DataFrame:
    """Rounded, missing values blank (the columns keep their machine names: the table labels them)."""
    f = frame[cols].round(3)
    return f.astype(object).where(f.notna(), None)


def render_tables(rep: Report, c: Console) -> None:
    from fieldlogs.reports.page import units_view
    from fieldlogs.reports.report import ROUTE_COLUMNS, TRACK_COLUMNS

    keys = {
        "route": ROUTE_COLUMNS,
        "run": ["run_id", "vehicle_id", *ROUTE_COLUMNS],
        "vehicle": ["vehicle_id"],
        "track": TRACK_COLUMNS,
    }[rep.by]
    g = rep.groups.assign(distance_km=(rep.groups["distance_m"] / 1000.0).round(1))
    pct = [col for col in PCT_COLUMNS if not (rep.by == "run" and col == "n_runs")]
    title = f"Position correction by {rep.by} (balise corrections, target {rep.target_pct:g} %)"
    c.print(frame_table(_view(g, keys + pct), title=title))
    c.print(frame_table(_view(g, keys + OTHER_COLUMNS), title=f"Slips, feature points, GPS and alarms by {rep.by}"))
    refused = g[g["refusal_reasons"] != ""]
    if len(refused):
        c.print(frame_table(_view(refused, [*keys, "refusal_reasons"]), title="Feature points refused"))
    if len(rep.units):
        c.print(frame_table(_view(units_view(rep), list(rep.units.columns)), title="Units F and R compared"))
    if len(rep.failed_runs):
        c.print(frame_table(rep.failed_runs, title="Runs that failed"))


@cli_command
def report(
    audit_db: Path = typer.Argument(..., help="Audit database written by `trainpos audit`."),
    by: By = typer.Option(
        By.route,
        "--by",
        help="Group by route (the run's track_id and direction), run, vehicle or track (track_id: the runs' "
        "paths of tracks); line and track are shown as names.",
    ),
    fmt: ReportFmt = typer.Option(ReportFmt.table, "--format", help="table, csv, json or html."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write to this file (required for html)."),
    target_pct: float = typer.Option(TARGET_PCT, "--target-pct", min=0.0, help="Position-correction target [%]."),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Position-correction percentages, slips, feature points, GPS and alarms per route/run/vehicle.

    Correction statistics are over balise corrections; feature-point corrections are
    counted separately. JSON has a stable shape (routes, runs, vehicles, failed_runs, tracks,
    paths) whatever --by is; csv and table follow --by; html is one self-contained file.

    Example: trainpos report audit.sqlite --format html --out audit.html
    """

    from fieldlogs.reports.page import render_html
    from fieldlogs.reports.report import build_report, report_json

    rep = build_report(audit_db, by=by.value, target_pct=target_pct)
    onboard = rep.meta.get("db_path")  # read for the html page's plots: an input too
    inputs = [audit_db, *([Path(str(onboard))] if onboard else [])]
    if fmt == ReportFmt.html:
        if out is None:
            raise UsageError("--format html needs --out FILE")
        write_out(out, force=force, inputs=inputs, text=render_html(rep, audit_db))
        console().print(f"HTML report written to {safe(out)}")
    elif fmt == ReportFmt.json:
        data: Any = report_json(rep)
        if out:
            write_out(
                out,
                force=force,
                inputs=inputs,
                text=json.dumps(jsonable(data), indent=2, ensure_ascii=False) + "\n",
            )
        else:
            print_json(data)
    elif fmt == ReportFmt.csv:
        emit_text(out, rep.groups.to_csv(index=False, lineterminator="\n"), force=force, inputs=inputs)
    else:
        emit_rendered(out, lambda c: render_tables(rep, c), force=force, inputs=inputs)
