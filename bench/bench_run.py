"""Benchmark: ``trainpos run`` as a whole process on a one-hour run, CSV and Parquet.

Run: ``.venv/bin/python bench/bench_run.py [--hours 1] [--repeat 3] [--dir DIR]``.

Simulates a run of about ``--hours`` (shuttling on a 110 km double-track line), writes it
as Parquet and as CSV, and times fresh ``trainpos run`` processes (best of ``--repeat``,
wall and CPU, outputs written), start-up included, against a process that only imports
the CLI (``python -c "import cli.main"``: what every command pays before it parses; the
issue's ``trainpos --help`` costs more, rich rendering the help) and so without start-up.
Prints the real-time factor of each (target issue 21: ≥ 2,000× with start-up). The naive
baseline is the per-sample Python of ``bench/bench_pipeline.py`` (≈ 50× real time).
``--breakdown`` adds, per format, where the time of one such process goes (phases and the
imports made in each: ``bench/run_breakdown.py``). Never fails on timing.
"""

from __future__ import annotations

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import load, simulated_run, verdict


def best_wall(cmd: list[str], repeat: int) -> tuple[float, float]:
    """(best wall s, best CPU s) of ``repeat`` fresh processes (CPU: user + system of the child,
    which a busy machine inflates far less than wall)."""
    best, best_cpu = float("inf"), float("inf")
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
        wall = time.perf_counter() - t0
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        if proc.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed: {proc.stderr.strip().splitlines()[-1:]}")
        best = min(best, wall)
        best_cpu = min(best_cpu, r1.ru_utime - r0.ru_utime + r1.ru_stime - r0.ru_stime)
    return best, best_cpu


def _without(total: float, start: float, real_s: float, what: str) -> str:
    """The run's time less the start-up, as a real-time factor ('—' when the noise of a busy
    machine made the start-up alone measure longer)."""
    work = total - start
    return f"{work:.2f} s {what} = {real_s / work:,.0f}×" if work > 0 else f"— {what} (start-up measured longer)"


def breakdown(run_args: list[str]) -> str:
    """The phase table of ``bench/run_breakdown.py`` on ``trainpos run``'s arguments; SystemExit
    with its error when it fails (a stale stage list is a broken benchmark, not a timing)."""
    script = str(Path(__file__).resolve().parent / "run_breakdown.py")
    proc = subprocess.run([sys.executable, script, *run_args], capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise SystemExit(f"bench/run_breakdown.py failed (exit {proc.returncode}):\n{proc.stderr.strip()}")
    return proc.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--dir", type=Path, default=None, help="keep the simulated runs here (reused)")
    ap.add_argument("--breakdown", action="store_true", help="also print where one process's time goes")
    args = ap.parse_args()
    trainpos = str(Path(sys.executable).parent / "trainpos")
    with tempfile.TemporaryDirectory() as tmpd:
        folder = args.dir or Path(tmpd)
        folder.mkdir(parents=True, exist_ok=True)
        runs = {fmt: simulated_run(folder, args.hours, fmt=fmt) for fmt in ("parquet", "csv")}
        hours = 0.0
        # start-up: what every command pays before it runs (importing the CLI); ``--help``
        # costs more (rich renders the help of every command)
        start, start_cpu = best_wall([sys.executable, "-c", "import cli.main"], args.repeat)
        for fmt, (run_dir, db) in runs.items():
            out = Path(tmpd) / f"out-{fmt}"
            cmd = [trainpos, "run", str(run_dir), "--db", str(db), "--out", str(out), "--force"]
            wall, cpu = best_wall(cmd, args.repeat)
            hours = json.loads((out / "summary.json").read_text(encoding="utf-8"))["duration_s"] / 3600.0
            size = sum(p.stat().st_size for p in run_dir.iterdir()) / 1e6
            rt = 3600 * hours
            print(
                f"trainpos run, {hours:.2f} h {fmt} ({size:.0f} MB): with start-up {wall:.2f} s wall = "
                f"{rt / wall:,.0f}× real time {verdict('≥ 2,000×', rt / wall >= 2000)}; {cpu:.2f} s CPU = "
                f"{rt / cpu:,.0f}×; without: "
                f"{_without(wall, start, rt, 'wall')}, {_without(cpu, start_cpu, rt, 'CPU')}; start-up = import "
                f"cli.main {start:.2f} s wall, {start_cpu:.2f} s CPU  [{load()}]",
                flush=True,
            )
            if args.breakdown:
                print(f"  where one {fmt} run's time goes  [{load()}]\n{breakdown(cmd[2:])}", flush=True)
            shutil.rmtree(out, ignore_errors=True)


if __name__ == "__main__":
    main()
