"""Benchmark: is the pipeline linear in the length of the run, and is its memory bounded?

Run: ``.venv/bin/python bench/bench_scaling.py [--hours 0.25 1 4 8 24] [--dir DIR]``.

For each length a run of about that many hours is simulated (a train shuttling end to end
on a 110 km double-track line, a cab reversal at each end, 10 slips and 10 slides; kept
in ``--dir`` and reused), then

* a fresh process loads it and times ``run_pipeline`` (file reading excluded), best of 3,
  and reports its CPU and wall time. The slope of a least-squares fit of log(CPU time) on
  log(run hours) is printed: 1 is linear, above 1 superlinear (target ≤ 1.05; the fixed
  cost of a run makes short runs cost more per hour, so slopes below 1 are expected over
  small sizes). The naive baseline is linear extrapolation of the shortest-but-one run:
  the ratio per size says how far above it each run costs;
* another fresh process does what ``trainpos run`` does with it — ``read_run``, then
  ``replay_bounded`` (a run longer than 1.5 × ``[window] length_h`` replayed in windows,
  :mod:`fieldlogs.pipeline.windows`) writing the positions as they come, reading included,
  the ``truth`` stream removed (a field log has none) — and reports its peak resident memory (``VmHWM`` of
  ``/proc/self/status``; not ``ru_maxrss``, which a child started by fork + exec inherits
  from a parent larger than itself). A fit of peak RSS = a + b · hours gives the memory
  bound per worker, printed for 24 h.

Never fails on timing.
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
from dataclasses import replace
from pathlib import Path

import numpy as np
from _common import load, simulated_run, verdict


def peak_rss_mb() -> float:
    """Peak resident memory of this process image [MB] (``VmHWM``)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024.0
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # not Linux


def one(run_dir: Path, db: Path) -> dict[str, float]:
    """Time the pipeline on one simulated run (in this process)."""
    from dbtools.database import read_network
    from fieldlogs.pipeline.run import run_pipeline
    from fieldlogs.runs.handle import read_run

    net = read_network(db)
    run = read_run(run_dir)
    run.load_all()
    run._streams.pop("truth", None)  # no truth comparison: what a field log has
    best_w, best_c, duration = float("inf"), float("inf"), 0.0
    res = None
    for _ in range(3):
        res = None  # one result in memory at a time
        w0, c0 = time.perf_counter(), time.process_time()
        res = run_pipeline(run, net)
        best_w, best_c = min(best_w, time.perf_counter() - w0), min(best_c, time.process_time() - c0)
        duration = float(res.summary["duration_s"])
    cycles = float(len(res.positions)) if res is not None else 0.0
    return {"hours": duration / 3600.0, "cpu": best_c, "wall": best_w, "cycles": cycles}


def worker(run_dir: Path, db: Path, *, whole: bool = False) -> dict[str, float]:
    """Peak memory of one run processed as ``trainpos run`` does it: reading included, a long
    run replayed in windows (``whole``: never, ``[window] length_h = 0``), the positions
    written to the output files as they come."""
    from dbtools.database import read_network
    from fieldlogs.pipeline.config import PipelineConfig
    from fieldlogs.pipeline.outputs import streamed_results
    from fieldlogs.pipeline.windows import replay_bounded
    from fieldlogs.runs.handle import read_run

    base = peak_rss_mb()
    net = read_network(db)
    c0 = time.process_time()
    with tempfile.TemporaryDirectory() as tmp:  # the run without its truth stream
        field = Path(tmp) / "run"
        field.mkdir()
        for f in run_dir.iterdir():
            if f.is_file() and f.name != "truth.parquet":
                os.link(f, field / f.name)
        with streamed_results(Path(tmp) / "out") as sink:
            cfg = PipelineConfig()
            if whole:
                cfg = replace(cfg, window=replace(cfg.window, length_h=0.0))
            res = replay_bounded(read_run(field), net, cfg, lambda p: sink.add_positions(p.positions))
            sink.finish(res.events, res.summary)
    cpu = time.process_time() - c0
    return {
        "rss_mb": peak_rss_mb(),
        "start_mb": base,
        "rows": float(res.cycles),
        "windows": float(res.windows),
        "worker_cpu": cpu,
    }


def _child(flag: str, run_dir: Path, db: Path) -> dict[str, float]:
    proc = subprocess.run(
        [sys.executable, __file__, flag, str(run_dir), str(db)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "OMP_NUM_THREADS": "1"},
    )
    out: dict[str, float] = json.loads(proc.stdout.strip().splitlines()[-1])
    return out


def _windowed_against_whole(run_dir: Path, db: Path, hours: float, rounds: int) -> None:
    """CPU and peak memory of the windowed worker over the whole replay's, in ``rounds``
    interleaved pairs of fresh processes (target: CPU ≤ 1.1×, the memory a window's)."""
    ratios, peaks = [], []
    for _ in range(rounds):
        a, b = _child("--worker", run_dir, db), _child("--worker-whole", run_dir, db)
        ratios.append(a["worker_cpu"] / b["worker_cpu"])
        peaks.append((a["rss_mb"], b["rss_mb"]))
        print(
            f"        windowed {a['worker_cpu']:.2f} s CPU, peak {a['rss_mb']:.0f} MB; whole {b['worker_cpu']:.2f} s, "
            f"{b['rss_mb']:.0f} MB  [{load()}]",
            flush=True,
        )
    med = float(np.median(ratios))
    print(
        f"{hours:6.2f} h windowed / whole worker CPU: median {med:.2f}× {verdict('≤ 1.1×', med <= 1.1)}; rounds "
        f"{', '.join(f'{x:.2f}' for x in ratios)}; peak RSS {', '.join(f'{a:.0f}/{b:.0f}' for a, b in peaks)} MB",
        flush=True,
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, nargs="+", default=[0.25, 1.0, 4.0])
    ap.add_argument("--dir", type=Path, default=None, help="keep the simulated runs here (reused)")
    ap.add_argument("--one", nargs=2, type=Path, metavar=("RUN", "DB"), help=argparse.SUPPRESS)
    ap.add_argument("--worker", nargs=2, type=Path, metavar=("RUN", "DB"), help=argparse.SUPPRESS)
    ap.add_argument("--worker-whole", nargs=2, type=Path, metavar=("RUN", "DB"), help=argparse.SUPPRESS)
    ap.add_argument(
        "--rounds", type=int, default=2, help="windowed / whole worker pairs per run replayed in windows (default 2)"
    )
    args = ap.parse_args()
    if args.one or args.worker or args.worker_whole:
        if args.one:
            out = one(*args.one)
        else:
            out = worker(*args.worker) if args.worker else worker(*args.worker_whole, whole=True)
        print(json.dumps(out))
        return
    with tempfile.TemporaryDirectory() as tmpd:
        folder = args.dir or Path(tmpd)
        folder.mkdir(parents=True, exist_ok=True)
        rows = []
        for h in args.hours:
            run_dir, db = simulated_run(folder, h)
            r = {**_child("--one", run_dir, db), **_child("--worker", run_dir, db)}
            rows.append(r)
            print(
                f"{r['hours']:6.2f} h ({r['cycles']:,.0f} cycles): CPU {r['cpu']:.3f} s = "
                f"{r['cpu'] / r['hours']:.3f} s per hour ({3600 * r['hours'] / r['cpu']:,.0f}× real time), "
                f"wall {r['wall']:.3f} s; worker peak RSS {r['rss_mb']:.0f} MB (imports {r['start_mb']:.0f} MB, "
                f"{r['windows']:.0f} windows; its CPU {r['worker_cpu']:.2f} s = "
                f"{r['worker_cpu'] / r['hours']:.2f} s per hour, reading and writing included)  "
                f"[{load()}]",
                flush=True,
            )
            if r["windows"]:
                _windowed_against_whole(run_dir, db, r["hours"], args.rounds)
    hours = np.array([r["hours"] for r in rows])
    cpu = np.array([r["cpu"] for r in rows])
    wall = np.array([r["wall"] for r in rows])
    if len(rows) >= 2:
        slope = float(np.polyfit(np.log(hours), np.log(cpu), 1)[0])
        slope_w = float(np.polyfit(np.log(hours), np.log(wall), 1)[0])
        ref = 1 if len(rows) > 2 else 0
        per_h = cpu[ref] / hours[ref]
        ratios = ", ".join(f"{h:.2f} h {c / (per_h * h):.2f}×" for h, c in zip(hours, cpu, strict=True))
        print(
            f"log-log slope of CPU time on run length: {slope:.3f} {verdict('≤ 1.05', slope <= 1.05)}; "
            f"wall {slope_w:.3f}"
        )
        print(f"CPU against linear extrapolation of the {hours[ref]:.2f} h run: {ratios}")
        wcpu = np.array([r["worker_cpu"] for r in rows])
        slope_worker = float(np.polyfit(np.log(hours), np.log(wcpu), 1)[0])
        print(f"log-log slope of the worker's CPU (windows over 3 h, reading and writing): {slope_worker:.3f}")
        peaks = ", ".join(f"{r['hours']:.2f} h {r['rss_mb']:.0f} MB" for r in rows)
        print(f"worker peak RSS: {peaks} (reading included, no truth stream)  [{load()}]")
        long = [r for r in rows if r["hours"] > 3.0]  # replayed in windows ([window] length_h 2 h)
        if len(long) >= 2:
            b, a = np.polyfit([r["hours"] for r in long], [r["rss_mb"] for r in long], 1)
            print(
                f"runs over 3 h (replayed in 2 h windows): peak RSS ≈ {a:.0f} MB + {b:.1f} MB per hour "
                f"(the kept result: positions, odometry) → {a + 24 * b:.0f} MB at 24 h  [{load()}]"
            )


if __name__ == "__main__":
    main()
