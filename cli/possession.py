"""``trainpos possession …``: possession (線路閉鎖) alarms for road-rail vehicles."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from cli.errors import cli_command
from cli.options import DECIMAL, DELIMITER, NO_VERIFY_HASH, csv_locale, workers_option
from cli.render import (
    check_outputs,
    console,
    emit_rendered,
    err_console,
    frame_table,
    inputs_of,
    key_value_table,
    print_findings,
    print_json,
    safe,
    write_out,
)
from schemas.enums import AlarmType, NoticeType
from schemas.errors import EXIT_FINDINGS, EXIT_UNREADABLE, UsageError
from schemas.units import format_km

if TYPE_CHECKING:
    import pandas as pd
    from rich.console import Console

    from fieldlogs.possession.check import PossessionReport

app = typer.Typer(help="Possession (線路閉鎖) alarms for road-rail vehicles.", no_args_is_help=True)


class Fmt(StrEnum):
    table = "table"
    json = "json"
    html = "html"
    geojson = "geojson"


ALARM_COLUMNS = ["type", "t_s", "time", "km", "track", "work_no", "evidence"]
#: Evidence shown in the terminal table per type (JSON and HTML have all of it).
BRIEF: dict[str, tuple[str, ...]] = {
    AlarmType.WRONG_TRACK: ("planned_track", "decided_track", "after_on_rail_s", "llr"),
    AlarmType.WRONG_TRACK_SUSPECTED: ("planned_track", "likeliest_track", "odds", "n_fixes"),
    AlarmType.OVERRUN: ("end", "beyond_m", "uncertainty_m", "until_t"),
    AlarmType.RELEASED_ON_RAIL: ("released_at", "until_t"),
    AlarmType.NOT_STARTED: ("started_at", "reason", "until_t"),
    NoticeType.APPROACHING_END: ("end", "distance_m", "speed_mps"),
    NoticeType.OVERRUN_POSSIBLE: ("end", "uncertainty_m", "until_t"),
    NoticeType.TRACK_UNDECIDED: ("decided_at_t",),
    NoticeType.CROSSOVER: ("from", "to", "rms_m"),
    NoticeType.POSITION_UNCERTAIN: ("uncertainty_m", "until_t"),
    NoticeType.POSITION_UNDETERMINED: ("km_known_from_t",),
}


def _frame(items: list[dict[str, object]]) -> pd.DataFrame:
    import pandas as pd

    rows = []
    for a in items:
        ev = a["evidence"] if isinstance(a["evidence"], dict) else {}
        keys = BRIEF.get(str(a["type"]), tuple(ev))
        km = a["km_m"]
        rows.append(
            {
                "type": a["type"],
                "t_s": f"{a['t']:.1f}",
                "time": str(a["time"])[11:21],
                "km": format_km(float(km)) if isinstance(km, int | float) else "",
                "track": a["track"] or "",
                "work_no": a["work_no"] or "",
                "evidence": ", ".join(f"{k}={ev[k]}" for k in keys if ev.get(k) is not None),
            }
        )
    return pd.DataFrame(rows, columns=ALARM_COLUMNS)


def _decision_text(dec: dict[str, object] | None) -> str:
    if not dec:
        return "undecided"
    return f"{dec['line_code']} / {dec['track']} at t = {dec['t']} s ({dec['after_on_rail_s']} s after PTO on)"


def render_tables(report: PossessionReport, c: Console) -> None:
    for check in report.to_json()["runs"]:
        dec = check["track_decision"]
        rows = [
            ("run", check["run"]),
            ("possessions", ", ".join(check["possessions"]) or "none"),
            (
                "on rail",
                "; ".join(f"{p['time_on']} – {p['time_off']}" for p in check["on_rail"]) or "never",
            ),
            ("track decision", _decision_text(dec)),
            ("tacho", "used" if check["tacho"]["used"] else check["tacho"]["note"]),
            ("alarms", len(check["alarms"])),
            ("notices", len(check["notices"])),
        ]
        c.print(key_value_table(rows, title=f"Possession check: {check['run_id']}"))
        if check["alarms"]:
            c.print(frame_table(_frame(check["alarms"]), title="Alarms"))
        if check["notices"]:
            c.print(frame_table(_frame(check["notices"]), title="Notices"))
    failed = f", {len(report.failed)} run(s) could not be checked" if report.failed else ""
    c.print(f"{report.n_alarms} alarm(s) in {len(report.checks)} run(s){safe(failed)}")


@app.command("check")
@cli_command
def check(
    runs: list[Path] = typer.Argument(
        ...,
        help="Road-rail run folders (run.json with start_time, gps, cab.pto; tacho used when present), or folders "
        "to search for runs.",
    ),
    db: Path = typer.Option(..., "--db", help="Onboard DB (.sqlite): GIS grid for km and up/down."),
    plan: Path = typer.Option(
        ...,
        "--plan",
        help="Possession plan CSV/XLSX: work_no, line_code, track, km_from_m, km_to_m, planned_start, planned_end, "
        "started_at, released_at (ISO 8601 with offset); optional vehicle_id and purpose (work/protection).",
    ),
    fmt: Fmt = typer.Option(
        Fmt.table, "--format", help="table, json, html or geojson (alarms and sections, for QGIS)."
    ),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write to this file (required for html and geojson)."),
    config: Path | None = typer.Option(
        None, "--config", help="Settings (TOML; its [gps] and [possession] sections; see trainpos config show)."
    ),
    work: str | None = typer.Option(
        None,
        "--work",
        help="The work the worker selected on the device (work_no): only its possession allows being on rail. "
        "Without it, the plan rows for the run's vehicle_id (or for any vehicle).",
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file."),
    no_verify_hash: bool = NO_VERIFY_HASH,
    workers: int | None = workers_option("checking runs"),
    delimiter: str | None = DELIMITER,
    decimal: str | None = DECIMAL,
) -> None:
    """Check road-rail runs against a possession plan: wrong track, overrun, released or not started while on rail.

    On rail = PTO on. The up/down decision comes from trusted D-GPS (5/15/30 s RMS filter,
    decided as soon as the evidence suffices, else undecided); km from map-matched fixes with
    an uncertainty band (overrun as soon as km ± u leaves the section, u taken at most 15 m;
    a wider band leaving it is an overrun_possible notice); a tacho stream, when the run has
    a usable one, holds km and band at a standstill and sharpens the speed (else GPS only,
    and the output says why); notices 30 m before a section end. Runs are matched to
    possessions by wall-clock time (run.json start_time + t) and line. Runs are checked by
    the replayer of audit and survey (--workers processes, a progress bar); a run that
    cannot be read or checked is listed with its error and the others go on.

    Exit codes: 0 no alarm; 1 alarms found, or the plan has errors (listed with file, line,
    column); 2 the DB, plan or config cannot be read, a run could not be checked (the other
    runs are still reported), or --format html without --out; 3 --out exists (use --force)
    or would replace an input.

    Example: trainpos possession check runs/rr-0116 --db net.sqlite --plan possessions.csv --format html --out pz.html
    """

    from fieldlogs.possession.check import check_files

    if fmt in (Fmt.html, Fmt.geojson) and out is None:
        raise UsageError(f"--format {fmt.value} needs --out FILE")
    inputs = inputs_of(runs, db, plan, config)
    check_outputs(files=[out], force=force, inputs=inputs)
    from cli.gis import _Bar
    from cli.render import progress

    bar = _Bar(progress(err_console()))
    try:
        report = check_files(
            runs, db, plan, config, work=work, workers=workers, progress=bar, locale=csv_locale(delimiter, decimal)
        )
    finally:
        if bar.task is not None:
            bar.bar.stop()
    if report.plan.findings:
        print_findings(report.plan.findings, console=err_console(), title="Plan warnings")
    _emit(report, fmt, out, plan=plan, db=db, force=force, inputs=inputs)
    for run, err in report.failed:
        err_console().print(f"[red]failed:[/] {safe(run)}: {safe(err.splitlines()[0] if err else '')}", highlight=False)
    if report.failed:
        raise typer.Exit(EXIT_UNREADABLE)
    if report.n_alarms:
        raise typer.Exit(EXIT_FINDINGS)


def _emit(
    report: PossessionReport, fmt: Fmt, out: Path | None, *, plan: Path, db: Path, force: bool, inputs: list[Path]
) -> None:
    """The report in ``fmt``, to ``out`` or the terminal."""
    if fmt == Fmt.html:
        from fieldlogs.possession.page import render_html

        assert out is not None
        write_out(
            out,
            render_html(report.checks, plan=str(plan), db=str(db), failed=report.failed),
            force=force,
            inputs=inputs,
        )
        console().print(f"HTML report written to {safe(out)} ({report.n_alarms} alarm(s))")
    elif fmt == Fmt.geojson:
        from dbtools.database import read_network
        from dbtools.interchange.geojson import possession_geojson, write_geojson

        assert out is not None
        data = possession_geojson(read_network(db), report.to_json(), report.plan.possessions)
        write_geojson(out, data, force=force, inputs=inputs)
        console().print(f"GeoJSON written to {safe(out)} ({report.n_alarms} alarm(s))")
    elif fmt == Fmt.json:
        data = report.to_json()
        if out:
            write_out(out, json.dumps(data, indent=2, ensure_ascii=False) + "\n", force=force, inputs=inputs)
        else:
            print_json(data)
    else:
        emit_rendered(out, lambda c: render_tables(report, c), force=force, inputs=inputs)
