"""``trainpos gnss …``: track-constrained GNSS positioning from a run's raw pseudoranges [S002]."""

from __future__ import annotations

import io
import json
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from cli.errors import cli_command
from cli.options import NO_VERIFY_HASH
from cli.render import check_outputs, console, frame_table, inputs_of, key_value_table, safe, write_out
from schemas.errors import UsageError
from schemas.jsonable import jsonable
from schemas.units import format_km

if TYPE_CHECKING:
    import pandas as pd
    from rich.console import Console

    from fieldlogs.gnss.report import GnssPositionReport

app = typer.Typer(help="Track-constrained GNSS positioning from raw pseudoranges [S002].", no_args_is_help=True)


class Fmt(StrEnum):
    table = "table"
    json = "json"


class Facing(StrEnum):
    auto = "auto"
    increasing = "increasing"
    decreasing = "decreasing"


def _systems(text: str | None) -> tuple[str, ...] | None:
    if text is None:
        return None
    out = tuple(s.strip().upper() for s in text.split(",") if s.strip())
    bad = [s for s in out if s not in ("G", "E", "J")]
    if bad or not out:
        raise UsageError(f"--systems '{text}': give G, E and/or J separated by commas (GPS, Galileo, QZSS)")
    return out


def _km(v: object) -> str:
    return format_km(float(v)) if isinstance(v, int | float) and v == v else ""


def _table_frame(report: GnssPositionReport) -> pd.DataFrame:
    import pandas as pd

    e = report.epochs
    return pd.DataFrame(
        {
            "t": e["t"].map(lambda v: f"{v:.1f}"),
            "rx": e["receiver"],
            "status": e["status"].where(e["available"], e["status"] + " ✗"),
            "km": e["km_m"].map(_km),
            "±U m": e["uncertainty_m"].map(lambda v: f"{v:.1f}" if v == v else ""),
            "res m": e["residual_rms_m"].map(lambda v: f"{v:.2f}" if v == v else ""),
            "used": e["used"].map(len),
            "excl": e["excluded"].map(lambda x: " ".join(x)),
            "lsq": e["lsq_available"].map(lambda b: "ok" if b else "—"),
            "lsq n": e["lsq_n_used"],
            "PDOP": e["lsq_pdop"].map(lambda v: f"{v:.1f}" if v == v else ""),
            "lsq off m": e["lsq_offset_m"].map(lambda v: f"{v:.1f}" if v == v else ""),
        }
    )


def render_table(report: GnssPositionReport, c: Console) -> None:
    a = report.availability
    facing = {1: "increasing km", -1: "decreasing km", 0: "unknown (km between both facings)"}[report.direction]
    rows = [
        ("run", report.run_id),
        ("track", f"{report.line_code} / {report.track} ({report.track_source})"),
        ("F end faces", f"{facing} ({report.facing_source})"),
        ("systems / sky mask", f"{','.join(report.systems)} / {report.sky_mask}"),
        ("epochs", a["epochs"]),
        ("constrained available", f"{100 * a['constrained']:.1f} %"),
        ("unconstrained available", f"{100 * a['unconstrained']:.1f} %"),
    ]
    c.print(key_value_table(rows, title="GNSS position (track-constrained vs unconstrained)"))
    c.print(frame_table(_table_frame(report), max_rows=len(report.epochs)))


@app.command("position")
@cli_command
def position(
    run_dir: Path = typer.Argument(..., help="Run folder with gnss_obs, gnss_nav and the vehicle block (antennas)."),
    db: Path = typer.Option(..., "--db", help="Onboard DB (.sqlite) whose GIS grid (with heights) is the 3-D track."),
    line: str | None = typer.Option(None, "--line", help="Line code of the track (with --track)."),
    track: str | None = typer.Option(None, "--track", help="Track U, D or S (with --line)."),
    sky_mask: str = typer.Option(
        "none", "--sky-mask", help="none, west-half, east-half, or a CSV table azimuth_deg,elevation_deg [deg]."
    ),
    systems: str | None = typer.Option(None, "--systems", help="Satellite systems, e.g. G,E,J (default: [gnss])."),
    facing: Facing = typer.Option(
        Facing.auto,
        "--facing",
        help="Which way the vehicle's F end faces (auto: from the pipeline, or with --line/--track from the fixes' "
        "motion, else unknown).",
    ),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write to this file instead of the terminal."),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file."),
    config: Path | None = typer.Option(None, "--config", help="Settings (TOML; its [gnss] section)."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Position every epoch of a run on its track from the raw pseudoranges, beside the classical 4-satellite fix.

    Per receiver and epoch: satellites used, excluded (fault detection and exclusion) and
    masked with the reason, status, km of the vehicle's reference point, the stated
    uncertainty, the residual RMS; the unconstrained least-squares solution beside it; the
    availability of both. --sky-mask blocks part of the sky (west-half: the paper's
    experiment, 47 % → 93 %). Without --line/--track the track is the one the positioning
    pipeline decides for the run (with the GNSS aid off): the line/track of most of its
    determined cycles, set by balise pairs or the GPS up/down decision; a run without either
    needs --line and --track. With --line/--track no pipeline runs (a GNSS-only or static
    receiver is positioned): --facing auto takes the facing from the fixes' motion (and the
    cab stream), or states it unknown (the km between both facings, the bound widened).

    Exit codes: 0 done; 1 the track cannot carry it (no or partial GIS heights, orthometric
    heights) or the run's GNSS part is incomplete (no gnss_nav, no ephemeris near the observations,
    a receiver without an antenna);
    2 unreadable input or bad usage (no gnss_obs, no track decided, a bad sky mask); 3 --out
    exists without --force.

    Example: trainpos gnss position runs/sim-rinex --db net.sqlite --sky-mask west-half --systems G
    """
    from rich.console import Console

    from dbtools.database import read_network
    from fieldlogs.config import load_tree
    from fieldlogs.gnss.gis import gis_track
    from fieldlogs.gnss.report import position_report
    from fieldlogs.gnss.runinputs import run_gnss
    from fieldlogs.gnss.skymask import load_mask
    from fieldlogs.pipeline.route import decided_route
    from fieldlogs.quality.usability import Purpose, usability_findings
    from fieldlogs.runs.handle import read_run

    if (line is None) != (track is None):
        raise UsageError("give --line and --track together (or neither: the pipeline decides the track)")
    sky_file = None if sky_mask in ("none", "west-half", "east-half") else Path(sky_mask)  # a table
    inputs = inputs_of(run_dir, db, sky_file, config)
    check_outputs(files=[out], force=force, inputs=inputs)
    tree = load_tree(config)
    network = read_network(db)
    run = read_run(run_dir)
    g = run_gnss(run)
    if g is None:
        raise UsageError("the run has no gnss_obs (raw observations)", path=run_dir)
    mask = load_mask(sky_mask)
    direction = {Facing.increasing: 1, Facing.decreasing: -1, Facing.auto: 0}[facing]  # 0: from the fixes
    facing_source = "given"
    if line is None or track is None:  # only then the pipeline runs (it needs the tacho)
        unusable = usability_findings(run, Purpose.POSITIONING)
        if unusable:
            raise UsageError(
                f"the pipeline cannot decide this run's track ({'; '.join(f.message for f in unusable[:2])}): give "
                "--line and --track (a GNSS-only or static receiver is positioned on the track given)",
                path=run_dir,
            )
        route = decided_route(run, network, tree.pipeline)
        if route is None:
            raise UsageError("the pipeline decides no track for this run (no balise pair, no GPS decision): give "
                             "--line and --track", path=run_dir)  # fmt: skip
        line, track, track_source = route[0], route[1], "pipeline"
        if facing == Facing.auto:
            direction, facing_source = route[2], "pipeline"
    else:
        track_source = "given"
    report = position_report(
        run.run_id, g, gis_track(network, line, track), direction, cfg=tree.gnss, systems=_systems(systems),
        sky_mask=mask, sky_mask_name=sky_mask, track_source=track_source, facing_source=facing_source,
        cab=run.stream("cab"),
    )  # fmt: skip
    if fmt == Fmt.json:
        text = json.dumps(jsonable(report.to_json()), ensure_ascii=False, indent=2) + "\n"
    else:
        buf = io.StringIO()
        render_table(report, Console(file=buf, width=160, highlight=False, soft_wrap=False))
        text = buf.getvalue()
    if out is None:
        console().file.write(text)
    else:
        write_out(out, text, force=force, inputs=inputs)
        console().print(f"{len(report.epochs)} receiver-epochs written to {safe(out)}")
