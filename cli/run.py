"""``trainpos run``: the positioning pipeline on one recorded run."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import typer

from cli.errors import cli_command
from cli.options import NO_VERIFY_HASH
from cli.render import console, key_value_table
from schemas.units import format_km


@cli_command
def run(
    run_dir: Path = typer.Argument(..., help="Run folder (run.json + streams)."),
    db: Path = typer.Option(..., "--db", help="Onboard DB (.sqlite)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output folder for positions, events, summary.json."),
    config: Path | None = typer.Option(None, "--config", help="Settings (TOML, see trainpos config show)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output folder."),
    unit: str = typer.Option(
        "F",
        "--unit",
        help="Positioning unit [S003 §2: one per cab]: F (the F cab's), R (the R cab's: its own imu_r, tacho_r, "
        "gps_r where the run has them, else the F streams seen from the other end), both (OUT/F and OUT/R, "
        "compared in OUT/units.json; disagreements are units_disagree events).",
    ),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Replay a run cycle by cycle (100 ms) through the onboard positioning logic.

    Writes positions (t, state, line, track, km, equipment km, speed, margin, last fix
    source) and events (corrections, refusals, slips, anomalies, fail-safe) as Parquet and
    CSV, and summary.json. A Parquet run longer than 1.5 × [window] length_h (2 h) is replayed
    in windows of that length, so its memory is a window's (see trainpos config show window).

    Example: trainpos run logs/run-001 --db net.sqlite --out out/run-001
    """
    import tempfile

    from dbtools.database import read_network
    from fieldlogs.config import load_tree
    from fieldlogs.pipeline.outputs import streamed_results
    from fieldlogs.pipeline.units import UNITS, r_sources, r_view, replay_units, unit_run
    from fieldlogs.pipeline.windows import replay_bounded
    from fieldlogs.runs.handle import read_run
    from schemas.errors import UsageError

    if unit not in (*UNITS, "both"):
        raise UsageError(f"--unit must be F, R or both, got {unit!r}")
    cfg = load_tree(config).pipeline
    network = read_network(db)
    inputs = [p for p in (run_dir, db, config) if p is not None]  # never replaced by --out
    if unit == "both":
        results, cmp = replay_units(run_dir, network, cfg, out, force=force, inputs=inputs)
        for u in UNITS:
            _print_result(results[u], cfg.window.length_h, out / u)
        console().print(key_value_table(_comparison_rows(cmp), title=f"Units F and R compared → {out / 'units.json'}"))
        return
    with streamed_results(out, force=force, inputs=inputs) as sink, tempfile.TemporaryDirectory() as scratch:
        view = unit_run(read_run(run_dir), unit, Path(scratch))  # a long Parquet run: by windows
        result = replay_bounded(view, network, cfg, lambda part: sink.add_positions(part.positions))
        sink.finish(result.events, result.summary)
    _print_result(result, cfg.window.length_h, out)
    if unit == "R":
        console().print(f"Unit R read {r_view(r_sources(read_run(run_dir)))}.", highlight=False)


def _comparison_rows(cmp: dict[str, Any]) -> list[tuple[str, Any]]:
    worst = cmp["max_abs_difference_m"]
    return [
        ("unit R read", cmp["unit_r"]["view"]),
        ("cycles compared", cmp["cycles_compared"]),
        ("max |km F − km R|", "—" if worst is None else f"{worst:.2f} m"),
        ("beyond the sum of margins", cmp["cycles_beyond_margins"]),
        ("on other tracks", cmp["cycles_on_other_tracks"]),
        ("disagreements", len(cmp["disagreements"])),
    ]


def _print_result(result: Any, window_h: float, out: Path) -> None:
    s = result.summary
    rows = [
        ("run", s["run_id"]),
        ("route", f"{s['line_code']} {s['track']}" if s["line_code"] else "—"),
        ("duration", f"{s['duration_s']:.0f} s"),
        ("distance", f"{s['distance_m'] / 1000:.2f} km"),
        ("first determined", "never" if s["first_determined_t"] is None else f"t = {s['first_determined_t']:.1f} s"),
        (
            "corrections",
            f"{s['n_balise_corrections']} balise, {s['n_feature_corrections']} feature "
            f"({s['n_feature_refused']} refused)",
        ),
        ("mean correction % (balise)", _pct(s["mean_correction_pct"])),
        ("mean correction % (all)", _pct(s["all_corrections"]["mean_correction_pct"])),
        ("slips/slides", s["n_slips"]),
        ("fail-safe", s["n_failsafe"]),
        ("anomalies", s["n_anomalies"]),
        ("max margin", "—" if s["max_margin_m"] is None else f"{s['max_margin_m']:.1f} m"),
        *(("warning", w) for w in s["warnings"]),
    ]
    if "truth" in s and s["truth"].get("claimed_cycles"):
        tr = s["truth"]
        rows += [
            ("truth: max |error|", f"{tr['max_abs_error_m']:.2f} m"),
            ("truth: within margin", f"{100 * tr['within_margin_share']:.2f} %"),
            ("truth: wrong track", tr["wrong_track_cycles"]),
        ]
    if result.last_position is not None:
        km, margin = result.last_position
        rows.append(("last position", f"{format_km(km)} ± {margin:.1f} m"))
    if result.windows:
        rows.append(("replayed", f"in {result.windows} windows of {window_h:g} h"))
    console().print(key_value_table(rows, title=f"Positioning → {out}"))


def _pct(v: float | None) -> str:
    return "—" if v is None else f"{v:.3f} %"
