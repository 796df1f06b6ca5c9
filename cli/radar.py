"""``trainpos radar …``: the 2-frequency CW radar speed meter [S004] on a run's raw IF samples."""

from __future__ import annotations

import sys
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from cli.errors import cli_command
from cli.render import console, err_console, frame_table, key_value_table, print_findings, print_json

if TYPE_CHECKING:
    import pandas as pd

#: Frames printed as a table; csv and json always have all of them.
MAX_ROWS = 400

app = typer.Typer(help="2-frequency CW radar [S004]: ground speed from raw IF samples.", no_args_is_help=True)


class Fmt(StrEnum):
    table = "table"
    csv = "csv"
    json = "json"


def _table(frame: pd.DataFrame) -> pd.DataFrame:
    import pandas as pd

    return pd.DataFrame(
        {
            "t [s]": frame["t"].map("{:.3f}".format),
            "V_G [km/h]": (frame["speed_mps"] * 3.6).map(lambda x: "" if pd.isna(x) else f"{x:.2f}"),
            "1σ [km/h]": (frame["sigma_mps"] * 3.6).map(lambda x: "" if pd.isna(x) else f"{x:.3f}"),
            "status": frame["status"],
            "lines": frame["n_lines"],
            "used": frame["n_used"],
            "aliased": frame["n_alias"],
            "SNR [dB]": frame["snr_db"].map(lambda x: "" if pd.isna(x) else f"{x:.1f}"),
            "naive [km/h]": (frame["v_naive_mps"] * 3.6).map(lambda x: "" if pd.isna(x) else f"{x:.2f}"),
        }
    )


@app.command("speed")
@cli_command
def speed(
    run_dir: Path = typer.Argument(..., help="Run folder with a radar_if stream and the run.json 'radar' block."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table, csv or json (one row per T_epi frame)."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write the csv or json to this file instead of stdout."),
    force: bool = typer.Option(False, "--force", help="Replace existing --out / --plot files."),
    plot: Path | None = typer.Option(
        None, "--plot", help="Also write a PNG: radar vs wheel vs truth speed, and one frame's Doppler–range scatter."
    ),
    plot_t: float | None = typer.Option(
        None, "--plot-t", help="Frame of the scatter: the one centred nearest this t [s] (default: most lines used)."
    ),
) -> None:
    """Ground speed V_G [m/s] per T_epi frame from raw IF samples (S004 eq. 2), with its 1σ,
    status (ok, standstill, aliased, no_reflections, low_quality) and quality figures.

    Exit 0 done, 2 no radar_if stream or no usable run.json 'radar' block, 3 an output
    exists without --force.

    Example: trainpos radar speed runs/radar-fig2 --format csv --out radar-fig2.csv --plot radar-fig2.png
    """
    from fieldlogs.radar.command import radar_speed_command
    from fieldlogs.radar.speed import speed_json

    result = radar_speed_command(run_dir, fmt=fmt.value, out=out, plot=plot, plot_t=plot_t, force=force)
    c = console()
    if result.findings:  # on stderr: stdout may be the csv
        print_findings(result.findings, console=err_console(), title="Warnings")
    if out is None and fmt == Fmt.csv:
        result.to_frame().to_csv(sys.stdout, index=False, float_format="%.6g", lineterminator="\n")
    elif out is None and fmt == Fmt.json:
        print_json(speed_json(result))
    elif out is None:
        c.print(frame_table(_table(result.to_frame()), title=f"Radar frames of {result.run_id}", max_rows=MAX_ROWS))
        if len(result) > MAX_ROWS:
            c.print(f"… {len(result) - MAX_ROWS} more frames (use --format csv or json for all)")
    if fmt == Fmt.table or out is not None:
        s = result.summary()
        rows = [
            ("run", result.run_id),
            ("frames", s["frames"]),
            *((f"status {k}", v) for k, v in s["status"].items() if v),
            ("frames with a speed", f"{s['with_speed_share']:.1%}"),
            ("median 1σ (ok)", "—" if s["median_sigma_mps"] is None else f"{s['median_sigma_mps'] * 3.6:.3f} km/h"),
            (
                "T_epi / ΔV / Vmax / Rmax",
                f"{s['t_epi_s']:g} s / {s['speed_resolution_kmh']:.3f} km/h / "
                f"{s['v_max_kmh']:.2f} km/h / {s['r_max_m']:.2f} m",
            ),
        ]
        if out is not None:
            rows.append(("written", str(out)))
        if plot is not None:
            rows.append(("plot", str(plot)))
        c.print(key_value_table(rows, title="Radar speed"))
