"""``trainpos radar speed`` as one library call: read, process, write, plot."""

from __future__ import annotations

from pathlib import Path

from dbtools.atomic import check_target
from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.convention import check_convention, convention_finding
from fieldlogs.radar.speed import OutFormat, RadarSpeed, process_frames, run_frames, write_speed
from fieldlogs.runs.handle import Run
from schemas.errors import UsageError


def radar_speed_command(
    run_dir: Path,
    *,
    fmt: str = "table",
    out: Path | None = None,
    plot: Path | None = None,
    plot_t: float | None = None,
    force: bool = False,
    cfg: RadarConfig = RadarConfig(),
) -> RadarSpeed:
    """Ground speed of every frame of ``run_dir``'s radar_if; with ``out`` written as CSV or
    JSON, with ``plot`` a PNG (``plots.plot_run``). Existing outputs are refused before any
    work unless ``force``; both are written atomically. Samples that look recorded in the
    other I/Q convention than declared give a warning in ``result.findings`` (``convention``)."""
    if out is not None and fmt not in ("csv", "json"):
        raise UsageError("--out writes csv or json: add --format csv or --format json")
    inputs = [Path(run_dir)]
    for p in (out, plot):
        if p is not None:
            check_target(p, force=force, kind="file", inputs=inputs)  # before the work
    run = Run(Path(run_dir))
    frames, params = run_frames(run)
    result = process_frames(frames, params, cfg)
    result.run_id = run.run_id
    found = convention_finding(check_convention(frames, params, cfg), str(run.stream_file("radar_if")))
    result.findings += [found] if found is not None else []
    if out is not None:
        fmt_out: OutFormat = "csv" if fmt == "csv" else "json"
        write_speed(result, out, fmt_out, force=force, inputs=inputs)
    if plot is not None:
        from fieldlogs.radar.plots import plot_run

        plot_run(run, frames, result, plot, frame_t=plot_t, force=force, inputs=inputs)
    return result
