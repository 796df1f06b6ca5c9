"""``trainpos gis …``: the 20 m GIS kilometrage grid."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import typer

from cli.errors import cli_command
from cli.render import console, frame_table, key_value_table, print_findings
from dbtools.gis.io import grid_files
from schemas.units import format_km

app = typer.Typer(help="Build the 20 m GIS kilometrage grid from surveys.", no_args_is_help=True)


@app.command("grid")
@cli_command
def grid(
    centrelines: Path = typer.Argument(
        ...,
        help="Track centrelines: CSV/XLSX (line_code, track, seq, lon, lat[, height_m]) or GeoJSON "
        "LineStrings with properties line_code, track.",
    ),
    posts: Path = typer.Option(
        ..., "--posts", help="Kilometre posts CSV/XLSX: line_code, km_m (or 12k345.6), lon, lat[, km_after_m]."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output grid in the gis source format (e.g. src/gis.csv)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output (and km_breaks.csv beside it)."),
) -> None:
    """Resample surveyed centrelines every 20 m of kilometrage, km from the kilometre posts.

    Posts are projected onto every track; km is piecewise linear through them (slope 1
    beyond the first/last post). A post's km_after_m is a kilometrage break; breaks are
    written to km_breaks.csv beside the output, which db build reads.

    Example: trainpos gis grid survey/centrelines.csv --posts survey/kmposts.csv --out src/gis.csv
    """
    written = grid_files(centrelines, posts, out, force=force)
    out_c = console()
    if written.warnings:
        print_findings(written.warnings, console=out_c, title="Warnings")
    rows: list[tuple[str, object]] = [("file", str(written.path))]
    if written.km_breaks_path is not None:
        rows.append(("km_breaks", f"{written.km_breaks_path} ({len(written.result.km_breaks)} break(s))"))
    if written.removed_stale is not None:
        rows.append(("removed", f"{written.removed_stale} (no breaks any more)"))
    rows.append(("points", len(written.result.gis)))
    out_c.print(key_value_table(rows, title="GIS grid"))
    tracks = pd.DataFrame(
        [
            {
                "line_code": t.line_code,
                "track": t.track,
                "points": t.points,
                "first km": format_km(t.km_first_m),
                "last km": format_km(t.km_last_m),
                "length_m": f"{t.length_m:.1f}",
                "posts": t.posts_used,
                "post_offset_m": f"{t.post_offset_m:+.2f}",
                "breaks": t.breaks,
                "reversed": "yes" if t.reversed else "",
            }
            for t in written.result.tracks
        ]
    )
    out_c.print(frame_table(tracks, title="Tracks"))
