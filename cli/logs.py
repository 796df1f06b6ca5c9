"""``trainpos logs …``: check, summarise, convert and safely repair field-log runs."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import Any

import typer

from cli.errors import cli_command
from cli.options import DECIMAL, DELIMITER, NO_VERIFY_HASH, csv_locale
from cli.render import console, err_console, frame_table, key_value_table, print_findings, print_json, safe
from schemas.errors import EXIT_FINDINGS, EXIT_OK, EXIT_UNREADABLE, InputError
from schemas.findings import has_errors

app = typer.Typer(help="Check, summarise, convert and repair field-log runs.", no_args_is_help=True)


class Fmt(StrEnum):
    table = "table"
    json = "json"


class LogFmt(StrEnum):
    parquet = "parquet"
    csv = "csv"


@app.command("check")
@cli_command
def check(
    runs: list[Path] = typer.Argument(..., help="Run folder(s): run.json plus one CSV/Parquet file per stream."),
    db: Path | None = typer.Option(None, "--db", help="Onboard DB: check GPS area and balise codes against it."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json."),
    strict: bool = typer.Option(False, "--strict", help="Warnings also fail (exit 1)."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Report every problem of each run: file, row (CSV line; Parquet row index + 2), column.

    Exit 0 clean, 1 errors found, 2 a run (or the DB) cannot be read.

    Example: trainpos logs check runs/2026-01-15-V01 --db net-2026.11.sqlite --format json
    """
    from fieldlogs.quality.checks import check_run, load_db_refs

    refs = load_db_refs(db) if db is not None else None
    reports: list[dict[str, Any]] = []
    code = EXIT_OK
    out = console()
    for run in runs:
        try:
            findings = check_run(run, refs)
        except InputError as exc:
            code = max(code, EXIT_UNREADABLE)
            reports.append({"run": str(run), "ok": False, "error": str(exc), "findings": []})
            if fmt == Fmt.table:
                err_console().print(f"[bold red]error:[/] {safe(exc)}", highlight=False)
            continue
        failed = has_errors(findings, strict)
        if failed:
            code = max(code, EXIT_FINDINGS)
        reports.append({"run": str(run), "ok": not failed, "findings": [f.to_dict() for f in findings]})
        if fmt == Fmt.table:
            print_findings(findings, console=out, title=f"Check of {run}")
    if fmt == Fmt.json:
        print_json({"ok": code == EXIT_OK, "runs": reports})
    if code:
        raise typer.Exit(code)


@app.command("info")
@cli_command
def info(
    runs: list[Path] = typer.Argument(..., help="Run folder(s)."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json."),
) -> None:
    """Run id, vehicle, duration, pulse distance, streams with rows and measured rates, GPS availability.

    Example: trainpos logs info runs/2026-01-15-V01
    """
    import pandas as pd

    from fieldlogs.quality.info import run_info

    infos = [run_info(r) for r in runs]
    if fmt == Fmt.json:
        print_json({"runs": [i.to_dict() for i in infos]})
        return
    out = console()
    for i in infos:
        rows: list[tuple[str, Any]] = [
            ("run", i.run),
            ("run_id", i.run_id),
            ("vehicle", f"{i.vehicle_id or '?'} ({i.vehicle_kind or '?'})"),
            ("start_time", i.start_time),
            ("db_version", i.db_version),
            ("duration", None if i.duration_s is None else f"{i.duration_s:.1f} s"),
            ("distance (pulses)", None if i.distance_m is None else f"{i.distance_m:.1f} m"),
        ]
        if i.gps is not None:
            rows.append(("GPS fixes (fix ≥ 1)", f"{i.gps.fix_share:.1%} of {i.gps.rows}"))
            rows.append(("D-GPS (fix = 2)", f"{i.gps.dgps_share:.1%}"))
        if i.errors_reading:
            rows.append(("errors while reading", f"{i.errors_reading} (see trainpos logs check)"))
        out.print(key_value_table(rows, title=f"Run {i.run_id}"))
        frame = pd.DataFrame(
            [
                {
                    "stream": s.name,
                    "format": s.format,
                    "rows": "unreadable" if s.rows is None else s.rows,
                    "t from [s]": _num(s.t_start_s),
                    "t to [s]": _num(s.t_end_s),
                    "declared [Hz]": _num(s.declared_rate_hz),
                    "measured [Hz]": _num(s.measured_rate_hz),
                }
                for s in i.streams
            ]
        )
        out.print(frame_table(frame, title="Streams"))


def _num(x: float | None) -> str:
    return "" if x is None else f"{x:.6g}"


@app.command("convert")
@cli_command
def convert(
    run: Path = typer.Argument(..., help="Run folder to convert."),
    to: LogFmt = typer.Option(..., "--to", help="parquet or csv."),
    out: Path = typer.Option(..., "--out", "-o", help="New run folder to write."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output folder."),
) -> None:
    """Write a run again as Parquet or CSV (same columns) into a new folder; exit 3 if it exists.

    Example: trainpos logs convert runs/2026-01-15-V01 --to parquet --out runs/2026-01-15-V01-pq
    """
    from fieldlogs.runs.write import convert_run

    res = convert_run(run, out, to.value, force=force)
    c = console()
    if res.warnings:
        print_findings(res.warnings, console=c, title="Warnings (not copied)")
    c.print(
        key_value_table(
            [("from", res.source), ("to", res.out), ("format", res.format)]
            + [(f"rows: {k}", v) for k, v in res.rows.items()],
            title="Converted",
        )
    )


@app.command("repair")
@cli_command
def repair(
    run: Path = typer.Argument(..., help="Run folder to repair (only read, never modified)."),
    out: Path = typer.Option(..., "--out", "-o", help="New run folder for the repaired run."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output folder."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json."),
    strict: bool = typer.Option(False, "--strict", help="Warnings left after the repair also fail (exit 1)."),
) -> None:
    """Safe repairs into a new folder: sort by t, drop exact duplicate rows, drop rows with a
    repeated t (keeping the first), bridge pulse-counter resets. Writes repair_log.json.

    The repaired run is checked as `logs check` checks it before it is written. Exit 0
    written (warnings that remain are listed), 1 problems that need a person — found before
    the repair, or still found by logs check after it (listed with file, row, column; with
    --strict warnings too) — and nothing is written, 2 unreadable, 3 refused.

    Example: trainpos logs repair runs/2026-01-15-V01 --out runs/2026-01-15-V01-repaired
    """
    import pandas as pd

    from fieldlogs.quality.repair import REPAIR_LOG, repair_run

    res = repair_run(run, out, force=force, strict=strict)
    if fmt == Fmt.json:
        print_json(res.to_dict())
        return
    c = console()
    frame = pd.DataFrame(
        [
            {
                "stream": s.stream,
                "rows in": s.rows_in,
                "rows out": s.rows_out,
                "action": a.action,
                "count": a.count,
                "what": a.message,
            }
            for s in res.streams
            for a in s.actions
        ],
        columns=["stream", "rows in", "rows out", "action", "count", "what"],
    )
    if len(frame):
        c.print(frame_table(frame, title=f"Repairs written to {res.out}"))
    else:
        c.print(f"Nothing to repair; copy written to {safe(res.out)}")
    rem = res.to_dict()["remaining"]
    if res.remaining:
        print_findings(res.remaining, console=c, title="Still found by logs check")
    c.print(f"log: {safe(Path(res.out) / REPAIR_LOG)}")
    c.print(f"still found by logs check: {rem['errors']} error(s), {rem['warnings']} warning(s)")


class ImportFmt(StrEnum):
    auto = "auto"
    nmea = "nmea"
    ubx = "ubx"
    rinex = "rinex"
    csv = "csv"
    geojson = "geojson"


@app.command("import")
@cli_command
def import_(
    sources: list[Path] = typer.Argument(
        ..., help="Recorder files: NMEA, UBX, RINEX obs/nav (.gz, .crx), CSV/Parquet, GeoJSON point traces."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="New run folder to write."),
    fmt: ImportFmt = typer.Option(
        ImportFmt.auto, "--format", help="auto (from the content), nmea, ubx, rinex, csv, geojson."
    ),
    mapping: list[Path] | None = typer.Option(
        None,
        "--mapping",
        help="Mapping TOML of a CSV/Parquet source (see the field-logs guide); one per table source, in order.",
    ),
    vehicle: Path | None = typer.Option(
        None,
        "--vehicle",
        help="VEHICLE.toml (needed: run.json's vehicle_id, kind, wheel, teeth come from it; see the field-logs guide).",
    ),
    run_id: str | None = typer.Option(None, "--run-id", help="run_id (default: the first source's name)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output folder."),
    config: Path | None = typer.Option(
        None, "--config", help="Settings (TOML): its [input] section (limits of compressed sources)."
    ),
    time_zone: str | None = typer.Option(
        None,
        "--time-zone",
        help="Time zone of time stamps without a UTC offset (GeoJSON traces; CSV: a mapping's [time] timezone "
        "comes first): UTC, +02:00 or an IANA name such as Europe/Oslo.",
    ),
    delimiter: str | None = DELIMITER,
    decimal: str | None = DECIMAL,
) -> None:
    """Import recorder files into a new run folder on one time base (GNSS time).

    Exit 0 written, 1 data or vehicle errors (units that cannot be right, a receiver
    without an antenna), 2 unreadable or corrupt input (truncated, out of order, unknown
    system, a mapping naming a missing column) or bad usage, 3 the output exists.
    Nothing is written unless the exit code is 0.

    Example: trainpos logs import rx1.ubx imu.csv --mapping imu.toml --vehicle car.toml --out runs/r1
    """
    from fieldlogs.quality.checks import check_run as _check
    from fieldlogs.recorders.importer import import_run

    res = import_run(
        sources, out, fmt=fmt.value, mapping=mapping or [], vehicle=vehicle, run_id=run_id, force=force,
        time_zone=time_zone, locale=csv_locale(delimiter, decimal),
    )  # fmt: skip
    c = console()
    if res.warnings:
        print_findings(res.warnings, console=c, title="Warnings")
    rows: list[tuple[str, Any]] = [("run folder", res.out), ("run_id", res.run_id), ("start_time", res.start_time)]
    rows += [(f"rows: {k}", v) for k, v in res.rows.items()]
    for s in res.sources:
        skipped = sum(x["count"] for x in s["skipped"])
        rows.append((f"source {Path(s['file']).name}", f"{s['format']}, {s['records']} records, {skipped} skipped"))
        rows += [("  note", note) for note in s.get("notes", [])]
        if "clock" in s:
            ck = s["clock"]
            rows.append(
                (
                    "  recorder clock",
                    f"drift {ck['drift_ppm']:.1f} ppm, residual RMS "
                    f"{ck['residual_rms_s'] * 1e3:.2f} ms (max {ck['residual_max_s'] * 1e3:.2f} ms)",
                )
            )
    found = _check(Path(res.out))
    n_err = sum(f.severity == "error" for f in found)
    rows.append(("logs check", f"{n_err} error(s), {len(found) - n_err} warning(s)"))
    c.print(key_value_table(rows, title="Imported"))
