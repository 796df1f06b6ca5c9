"""Shared pieces of the benchmarks: simulated runs of a given length, timing, load.

Not a test helper: benchmarks only report, they never fail on timing.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, Literal

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

#: The line every simulated run of the benchmarks runs on (110 km, double track).
LINE_LENGTH_M = 110_000.0
#: One end-to-end trip of that line takes about this long (stations every 3 km) [h].
HOURS_PER_TRIP = 1.84


def load() -> str:
    """The 1-minute load average and the core count, for printing beside a figure."""
    return f"load {os.getloadavg()[0]:.2f}/{os.cpu_count()} cores"


def verdict(target: str, met: bool) -> str:
    """A benchmark's verdict on a target, in the one form ``bench/run_all.py`` picks out of its
    output for the full table's *verdict* column: ``(target ≤ 1.3×): met`` or ``… not met``."""
    return f"(target {target}): {'met' if met else 'not met'}"


def best_of(fn: Callable[[], Any], repeat: int = 3) -> tuple[float, float, Any]:
    """(best wall s, CPU s of that run, result) of ``repeat`` calls of ``fn``."""
    best, cpu, out = float("inf"), 0.0, None
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        w, c = time.perf_counter() - w0, time.process_time() - c0
        if w < best:
            best, cpu = w, c
    return best, cpu, out


def network_db(folder: Path) -> Path:
    """The benchmarks' network (``LINE_LENGTH_M`` demo line) built as ``folder/net.sqlite``."""
    from dbtools.build import build_db
    from dbtools.gis.geometry import Projector
    from dbtools.sources import write_source_set
    from fieldlogs.simulate.networks.synthetic import build_network, demo_line

    db = folder / "net.sqlite"
    if not db.exists():
        net = build_network([demo_line(length_m=LINE_LENGTH_M)], Projector(9))
        write_source_set(net, folder / "src")
        build_db(folder / "src", db)
    return db


def shuttle_path(hours: float) -> list[float]:
    """Stop points of a run of about ``hours`` shuttling end to end on the line (a cab
    reversal at each end), the last trip cut short."""
    a, b = 1150.0, LINE_LENGTH_M + 850.0
    dist = hours / HOURS_PER_TRIP * (b - a)
    path, pos, toward = [a], a, b
    while dist > 1.0:
        leg = min(abs(toward - pos), dist)
        pos = pos + leg if toward > pos else pos - leg
        path.append(pos)
        dist -= leg
        toward = a if toward == b else b
    return path


def simulated_run(
    folder: Path, hours: float, *, seed: int = 3, fmt: Literal["csv", "parquet"] = "parquet"
) -> tuple[Path, Path]:
    """(run folder, DB) of a simulated run of about ``hours`` on the benchmark line, 10 slips
    and 10 slides, written once under ``folder`` (reused when it is already there)."""
    from dbtools.database import read_network
    from fieldlogs.runs.write import write_run
    from fieldlogs.simulate.scenario import scenario_from_dict
    from fieldlogs.simulate.simulator import simulate_run

    db = network_db(folder)
    run = folder / f"run-{hours:g}h-{seed}-{fmt}"
    if not (run / "run.json").exists():
        net = read_network(db)
        scenario = {"route": {"track": "D", "path_km_m": shuttle_path(hours)}, "slip": {"slips": 10, "slides": 10}}
        streams, meta = simulate_run(net, scenario_from_dict(scenario), seed=seed)
        write_run(run, meta, streams, fmt=fmt)
    return run, db


def over_network_runs(
    job: Callable[[Any], Any], runs: int, seed: int, workers: int, *extra: Any
) -> tuple[list[Any], float]:
    """``job((i, db, tmp, run, *extra))`` for each of ``runs`` seeded routes over the bundled
    network sample (:func:`fieldlogs.simulate.network_runs.network_runs`), in ``workers``
    processes: (the results in run order, wall s). ``db`` is the sample built in the temporary
    folder ``tmp``, which the jobs may write into."""
    import tempfile
    from concurrent.futures import ProcessPoolExecutor

    from dbtools.build import build_db
    from dbtools.database import read_network
    from dbtools.sample_network import sample_network_source_dir
    from fieldlogs.simulate.network_runs import network_runs

    with tempfile.TemporaryDirectory() as tmpd:
        db = Path(tmpd) / "net.sqlite"
        build_db(sample_network_source_dir(), db)
        drawn = network_runs(read_network(db), runs, seed)
        t0 = time.perf_counter()
        with ProcessPoolExecutor(workers) as pool:
            results = list(pool.map(job, [(i, str(db), tmpd, r, *extra) for i, r in enumerate(drawn)]))
        return results, time.perf_counter() - t0


def print_rows(rows: list[tuple[str, str]]) -> None:
    """A two-column figure table, names padded to the longest."""
    w = max(len(a) for a, _ in rows)
    for a, b in rows:
        print(f"  {a:<{w}}  {b}")
