"""Benchmark: is the pipeline linear in the length of the run, and is its memory bounded?

Run: ``.venv/bin/python bench/bench_scaling.py [--hours 0.25 1 4 8 24] [--dir DIR]``.

For each length a run of about that many hours is simulated (a train shuttling end to end
on a 110 km double-track line, a cab reversal at each end, 10 slips and 10 slides; kept
in ``--dir`` and reused), then a fresh process loads it and times ``run_pipeline`` (file
reading excluded), best of 3, and reports its CPU and wall time and its peak resident
memory (``ru_maxrss``: streams, pipeline and outputs in memory). The slope of a
least-squares fit of log(CPU time) on log(run hours) is printed: 1 is linear, above 1
superlinear (target ≤ 1.05; the fixed cost of a run makes short runs cost more per hour,
so slopes below 1 are expected over small sizes). The naive baseline is linear
extrapolation of the shortest-but-one run: the ratio per size says how far above it each
run costs. Never fails on timing.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import load, simulated_run


def one(run_dir: Path, db: Path) -> dict[str, float]:
    """Time the pipeline on one simulated run (in this process)."""
    from dbtools.database import read_network
    from fieldlogs.io import read_run
    from fieldlogs.pipeline.run import run_pipeline

    net = read_network(db)
    run = read_run(run_dir)
    run.load_all()
    run._streams.pop("truth", None)  # no truth comparison: what a field log has
    best_w, best_c, duration = float("inf"), float("inf"), 0.0
    res = None
    for _ in range(3):
        res = None  # one result in memory at a time: the peak is one run's
        w0, c0 = time.perf_counter(), time.process_time()
        res = run_pipeline(run, net)
        best_w, best_c = min(best_w, time.perf_counter() - w0), min(best_c, time.process_time() - c0)
        duration = float(res.summary["duration_s"])
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    cycles = float(len(res.positions)) if res is not None else 0.0
    return {"hours": duration / 3600.0, "cpu": best_c, "wall": best_w, "rss_mb": rss, "cycles": cycles}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, nargs="+", default=[0.25, 1.0, 4.0])
    ap.add_argument("--dir", type=Path, default=None, help="keep the simulated runs here (reused)")
    ap.add_argument("--one", nargs=2, type=Path, metavar=("RUN", "DB"), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.one:
        print(json.dumps(one(*args.one)))
        return
    with tempfile.TemporaryDirectory() as tmpd:
        folder = args.dir or Path(tmpd)
        folder.mkdir(parents=True, exist_ok=True)
        rows = []
        for h in args.hours:
            run_dir, db = simulated_run(folder, h)
            proc = subprocess.run(
                [sys.executable, __file__, "--one", str(run_dir), str(db)],
                capture_output=True,
                text=True,
                check=True,
                env={**os.environ, "OMP_NUM_THREADS": "1"},
            )
            r = json.loads(proc.stdout.strip().splitlines()[-1])
            rows.append(r)
            print(
                f"{r['hours']:6.2f} h ({r['cycles']:,.0f} cycles): CPU {r['cpu']:.3f} s = "
                f"{r['cpu'] / r['hours']:.3f} s per hour ({3600 * r['hours'] / r['cpu']:,.0f}× real time), "
                f"wall {r['wall']:.3f} s, "
                f"peak RSS {r['rss_mb']:.0f} MB  [{load()}]",
                flush=True,
            )
    hours = np.array([r["hours"] for r in rows])
    cpu = np.array([r["cpu"] for r in rows])
    wall = np.array([r["wall"] for r in rows])
    if len(rows) >= 2:
        slope = float(np.polyfit(np.log(hours), np.log(cpu), 1)[0])
        slope_w = float(np.polyfit(np.log(hours), np.log(wall), 1)[0])
        ref = 1 if len(rows) > 2 else 0
        per_h = cpu[ref] / hours[ref]
        ratios = ", ".join(f"{h:.2f} h {c / (per_h * h):.2f}×" for h, c in zip(hours, cpu, strict=True))
        print(f"log-log slope of CPU time on run length: {slope:.3f} (wall {slope_w:.3f}); target ≤ 1.05")
        print(f"CPU against linear extrapolation of the {hours[ref]:.2f} h run: {ratios}")
        mem = np.polyfit(hours, [r["rss_mb"] for r in rows], 1)
        print(f"peak RSS ≈ {mem[1]:.0f} MB + {mem[0]:.0f} MB per hour of log (whole run in memory)  [{load()}]")


if __name__ == "__main__":
    main()
