"""``trainpos simulate --format nmea|ubx|rinex``: a simulated run with its GNSS part as a recorder
writes it (:func:`fieldlogs.recorders.export.write_recorder_files`), in one atomic step.

The simulator composes the recorder writers, not the other way round: the recorders package
(readers and writers of receiver formats) knows nothing of the simulator.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path

from dbtools.atomic import atomic_folder
from fieldlogs.recorders.export import EXPORT_FORMATS, RECORDER_FOLDER, write_recorder_files
from fieldlogs.simulate.scenario import Scenario, load_scenario
from fieldlogs.simulate.simulator import SimulationSummary, simulate_to_folder
from schemas.errors import UsageError


def simulate_with_recorder(
    db_path: Path,
    out: Path,
    fmt: str,
    *,
    scenario: Scenario | None = None,
    seed: int | None = None,
    force: bool = False,
    inputs: Iterable[Path | str] = (),
) -> tuple[SimulationSummary, list[Path]]:
    """``simulate`` into a temporary folder, add the recorder files, then rename into ``out``:
    nothing is left behind when the recorder format cannot be written. ``rinex`` switches the
    scenario's raw GNSS (``[gnss_raw]``) on: RINEX observations are what it writes."""
    if fmt not in EXPORT_FORMATS:
        raise UsageError(f"recorder format '{fmt}' is not one of {', '.join(EXPORT_FORMATS)}")
    if fmt == "rinex":
        scenario = scenario if scenario is not None else load_scenario()
        scenario = replace(scenario, gnss_raw=replace(scenario.gnss_raw, enabled=True))
    with atomic_folder(Path(out), force=force, inputs=[Path(db_path), *inputs]) as tmp:
        summary = simulate_to_folder(db_path, tmp, scenario, seed=seed, fmt="parquet", force=True)
        files = write_recorder_files(tmp, fmt)
    summary.path = Path(out)
    return summary, [Path(out) / RECORDER_FOLDER / f.name for f in files]
