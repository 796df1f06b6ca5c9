"""``trainpos simulate``: a seeded, physically consistent field-log run over an onboard DB."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path

import typer

from cli.errors import cli_command
from cli.options import NO_VERIFY_HASH
from cli.render import console, key_value_table


class LogFmt(StrEnum):
    parquet = "parquet"
    csv = "csv"
    nmea = "nmea"
    ubx = "ubx"
    rinex = "rinex"


@cli_command
def simulate(
    db: Path = typer.Option(..., "--db", help="Onboard DB file (.sqlite) whose line/track the vehicle runs on."),
    out: Path = typer.Option(..., "--out", "-o", help="Run folder to write (run.json + one file per stream)."),
    scenario: Path | None = typer.Option(
        None, "--scenario", help="Scenario TOML; overrides the knobs of fieldlogs/simulate/scenarios/default.toml."
    ),
    seed: int | None = typer.Option(None, "--seed", min=0, help="Random seed (default: the scenario's 'seed')."),
    line: str | None = typer.Option(None, "--line", help="Line code (overrides route.line_code)."),
    track: str | None = typer.Option(None, "--track", help="Track U, D or S (overrides route.track)."),
    fmt: LogFmt = typer.Option(
        LogFmt.parquet,
        "--format",
        help="parquet (zstd) or csv streams; nmea, ubx or rinex: Parquet streams plus the GNSS part as a "
        "recorder writes it, in RUN_DIR/recorder/ (rinex switches the scenario's [gnss_raw] on: raw observations "
        "of two receivers; ubx includes them when the scenario has them).",
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing run folder."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Simulate a field-log run: IMU, tacho, GPS, balises, cab (+ truth, radar) from the DB's track.

    Speed profile with curve limits and station stops, 3-D attitude from the GIS geometry,
    slips/slides, wheel wear, GPS outages; everything seeded; raw GNSS observations (gnss_obs,
    gnss_nav) of a GPS/Galileo/QZSS constellation with [gnss_raw] enabled = true. Exit 2 on a bad scenario
    (the message names the file and the key) or a line/track not in the DB, 3 when the
    output exists without --force.

    Example: trainpos simulate --db net-2026.11.sqlite --out runs/sim-001 --seed 7
    """
    from fieldlogs.simulate.scenario import load_scenario
    from fieldlogs.simulate.simulator import simulate_to_folder

    overrides: dict[str, dict[str, str]] = {}
    if line is not None or track is not None:
        overrides["route"] = {k: v for k, v in (("line_code", line), ("track", track)) if v is not None}
    sc = load_scenario(scenario, overrides or None)
    inputs = [p for p in (db, scenario) if p is not None]  # never replaced by --out
    files: list[Path] = []
    if fmt.value in ("nmea", "ubx", "rinex"):
        from fieldlogs.simulate.recorder import simulate_with_recorder

        result, files = simulate_with_recorder(db, out, fmt.value, scenario=sc, seed=seed, force=force, inputs=inputs)
    else:
        result = simulate_to_folder(db, out, sc, seed=seed, fmt=fmt.value, force=force, inputs=inputs)  # type: ignore[arg-type]
    slips = [e for e in result.slip_episodes if e.kind == "slip"]
    rows = [
        ("run folder", str(result.path)),
        ("run_id", result.run_id),
        ("line / track", f"{result.line_code} / {result.track}"),
        ("duration", f"{result.duration_s:.1f} s"),
        ("distance", f"{result.distance_m / 1000:.3f} km"),
        ("slips / slides", f"{len(slips)} / {len(result.slip_episodes) - len(slips)}"),
        ("true wheel diameter", f"{result.wheel_diameter_true_m:.5f} m"),
        *((f"rows: {k}", v) for k, v in result.rows.items()),
        *(("recorder file", str(f)) for f in files),
    ]
    console().print(key_value_table(rows, title="Simulated run"))
