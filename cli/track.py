"""``trainpos track …``: a GNSS-only trace matched to a network path (SPEC §8.3)."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from cli.errors import cli_command
from cli.options import NO_VERIFY_HASH
from cli.render import check_outputs, console, emit_rendered, emit_text, frame_table, inputs_of, key_value_table
from schemas.errors import UsageError
from schemas.jsonable import jsonable

if TYPE_CHECKING:
    from rich.console import Console

    from fieldlogs.trackmatch.result import TrackMatch

app = typer.Typer(
    help="Track-level positioning on the network: GNSS-only traces matched to a path of tracks.", no_args_is_help=True
)


class Fmt(StrEnum):
    table = "table"
    json = "json"
    geojson = "geojson"
    csv = "csv"


def render_table(result: TrackMatch, c: Console) -> None:
    s = result.summary
    rows = [(k, s[k]) for k in ("fixes", "matched", "no_candidate", "outlier", "no_position", "chains", "path_tracks")]
    rows.append(("mean |offset| m", "" if s["mean_abs_offset_m"] is None else f"{s['mean_abs_offset_m']:.2f}"))
    c.print(key_value_table(rows, title="Track match"))
    path = result.path.assign(
        probability=result.path["probability"].map(lambda v: f"{v:.3f}"),
        t_from=result.path["t_from"].map(lambda v: f"{v:.1f}"),
        t_to=result.path["t_to"].map(lambda v: f"{v:.1f}"),
    )
    c.print(frame_table(path, title="Path", max_rows=len(path)))


@app.command("match")
@cli_command
def match(
    run_dir: Path = typer.Argument(..., help="Run folder with a gps stream (no odometry needed)."),
    db: Path = typer.Option(..., "--db", help="Onboard DB (.sqlite) whose network (tracks, connections) is matched."),
    fmt: Fmt = typer.Option(
        Fmt.table, "--format", help="table, json, geojson (path + fixes) or csv (one row per fix)."
    ),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write to this file instead of the terminal."),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file."),
    radius: float = typer.Option(50.0, "--radius", min=1.0, help="Search radius around a fix [m]."),
    sigma: float = typer.Option(10.0, "--sigma", min=0.1, help="1-σ of a fix without its own quality figures [m]."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Match a run's GNSS trace to a path through the network (HMM, Viterbi decoding).

    Candidates are the tracks within --radius of each fix; a hidden Markov model with
    emissions from the perpendicular offset (and the heading) and transitions from route
    distance on the topology (navigability respected) vs straight-line distance is decoded
    with Viterbi; forward–backward gives each track's probability. Fixes with no track in
    reach (far off, tunnels) are skipped and the path re-linked across the gap.

    Exit codes: 0 done; 1 no fix could be matched to any track; 2 unreadable input or no gps
    stream; 3 --out exists without --force.

    Example: trainpos track match runs/rr1 --db net.sqlite --format json --out match.json
    """
    from dbtools.database import read_network
    from fieldlogs.runs.handle import read_run
    from fieldlogs.trackmatch.match import MatchSettings, match_trace
    from fieldlogs.trackmatch.trace import gps_fixes

    inputs = inputs_of(run_dir, db)
    check_outputs(files=[out], force=force, inputs=inputs)
    run = read_run(run_dir)
    gps = run.stream("gps")
    if gps is None:
        raise UsageError("the run has no gps stream", path=run_dir)
    network = read_network(db)
    t, lat, lon, sig = gps_fixes(gps)
    result = match_trace(network, t, lat, lon, sig, MatchSettings(radius_m=radius, sigma_m=sigma))
    result.summary["run_id"] = run.run_id
    _no_match(result, run_dir)
    if fmt == Fmt.table:
        emit_rendered(out, lambda c: render_table(result, c), force=force, inputs=inputs)
        return
    if fmt == Fmt.json:
        text = json.dumps(jsonable(result.to_json(), 9), ensure_ascii=False, indent=2) + "\n"
    elif fmt == Fmt.geojson:
        from dbtools.interchange.geojson import geojson_text
        from fieldlogs.trackmatch.output import match_geojson

        text = geojson_text(match_geojson(network, result, run.run_id))
    else:
        from dbtools.csvwrite import csv_bytes

        text = csv_bytes(result.fixes).decode("utf-8")
    emit_text(out, text, force=force, inputs=inputs)
    if out is not None:
        console().print(f"{len(result.path)} path track(s), {len(result.fixes)} fixes written to {out}")


def _no_match(result: TrackMatch, run_dir: Path) -> None:
    from schemas.enums import Severity
    from schemas.errors import FindingsError
    from schemas.findings import Finding

    if result.summary["matched"]:
        return
    f = Finding(
        "trackmatch.no_match",
        Severity.ERROR,
        "gps",
        f"none of the {result.summary['fixes']} fixes lies within the search radius of a track",
        file=str(run_dir),
    )
    raise FindingsError(f.message, [f], path=run_dir)
