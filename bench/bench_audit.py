"""Benchmark: fleet-audit throughput — 1 worker, 2 local worker processes, 2-worker Dask LocalCluster.

All three modes go through the one replayer (``fieldlogs.replay``) via ``audit()``.

Run: ``.venv/bin/python bench/bench_audit.py [--runs 200] [--workers 2] [--rounds 2]``.

Simulates ONE one-hour run per track of a synthetic 62 km double-track line (stations every
3 km, 6 slips + 6 slides each) and hard-links it ``--runs`` times under different folder
names in a temp dir (audits key runs by folder, so every copy is audited). Then audits all
of them into a fresh audit DB per mode and prints runs/min, the speed-up over one worker,
the time to the first finished run (pool start-up), the mean wall and CPU time of a run in
its worker (wall > CPU: the run waited for a core), the CPU of every process of the mode
per run and outside the runs (imports, fork server, warm-up, storing), the cores the mode
obtained (CPU / wall) and the load average (``os.getloadavg``) before and after each mode.

The machine may be shared, and Linux shares CPU between sessions (autogroups) before it
shares it between processes: a second worker gets a core only when the other sessions
leave one. So each round measures, around its 1-worker and pool modes, how much faster 2
processes of a pure CPU loop are than one at that moment (the calibration: no mode can
beat it), and each speed-up is split into the cores obtained (the machine's share) times
the CPU per run of one worker over that of the mode (the code's own cost). ``--rounds``
repeats calibration, 1 worker and pool. The local pool is timed from the ``audit()`` call
(its start-up is part of the cost); the Dask cluster is started before timing. Finally
the time of a 1,000 run-hour audit is extrapolated from the slowest 2-worker rate.
Target: ≥ 1.8× the single-worker throughput with 2 workers on a quiet 2-core machine,
1,000 run-hours ≤ 10 min. Never fails on timing: it reports.
"""

from __future__ import annotations

import argparse
import os
import resource
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from statistics import median

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import verdict

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import Projector
from dbtools.sources import write_source_set
from fieldlogs.audit.runner import audit
from fieldlogs.audit.store import read_table
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

LINE_M = 62_000.0  # about one hour at 95 km/h line speed with a stop every 3 km


def _spin(n: int = 10_000_000) -> int:
    s = 0
    for i in range(n):
        s += i & 7
    return s


def calibrate(workers: int) -> float:
    """Speed-up of ``workers`` processes over one on a pure CPU loop, right now: the most
    any parallel mode can reach on this machine at its current load."""
    from concurrent.futures import ProcessPoolExecutor
    from multiprocessing import get_context

    # spawn, not forkserver: the audit's fork server must start with its own preload list
    with ProcessPoolExecutor(workers, mp_context=get_context("spawn")) as ex:
        list(ex.map(_spin, [10] * workers))  # start the processes
        t0 = time.perf_counter()
        for _ in range(workers):
            _spin()
        one = time.perf_counter() - t0
        t0 = time.perf_counter()
        list(ex.map(_spin, [10_000_000] * workers))
        par = time.perf_counter() - t0
    return one / par


def make_runs(root: Path, n: int) -> tuple[Path, Path, float]:
    """(DB, logs folder, simulated duration of one run [s])."""
    t0 = time.perf_counter()
    src = write_source_set(build_network([demo_line(length_m=LINE_M)], Projector(9)), root / "src")
    db = root / "net.sqlite"
    build_db(src, db, db_version="bench")
    net = read_network(db)
    bases = []
    for i, track in enumerate(("D", "U")):
        scenario = scenario_from_dict(
            {
                "run": {"run_id": f"BENCH-{track}", "vehicle_id": f"EMU-{i + 1:02d}"},
                "route": {"track": track},
                "slip": {"slips": 6, "slides": 6},
            }
        )
        sim = simulate_run(net, scenario, seed=100 + i)
        bases.append(write_run(root / "base" / track, sim.meta, sim.streams))
        duration = float(sim.meta.extra["sim_truth"]["duration_s"])
    logs = root / "logs"
    for k in range(n):
        dst = logs / f"run-{k:04d}"
        dst.mkdir(parents=True)
        for f in bases[k % 2].iterdir():
            try:
                os.link(f, dst / f.name)
            except OSError:
                shutil.copy2(f, dst / f.name)
    print(f"generated 2 runs of {duration / 60:.0f} min, {n} folders, in {time.perf_counter() - t0:.1f} s")
    return db, logs, duration


@dataclass
class Mode:
    """One timed audit: throughput and where its CPU went."""

    label: str
    runs: int
    wall: float
    cpu: float
    """CPU of every process of the mode [s]: this one + the pool's processes (fork server,
    workers: reaped when the pool closes), or + the runs' own CPU on a Dask cluster."""
    in_runs: float
    """CPU inside the runs (``audit_one``, summed from the audit DB) [s]; the rest is the
    mode's fixed cost (imports, fork server, warm-up) and the coordinator's storing."""

    @property
    def rate(self) -> float:
        return 60.0 * self.runs / self.wall

    @property
    def cpu_per_run(self) -> float:
        return self.cpu / max(self.runs, 1)

    @property
    def cores(self) -> float:
        """Cores the mode obtained on average (CPU / wall): the machine's share."""
        return self.cpu / self.wall


def _children_cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def timed(label: str, db: Path, logs: Path, out: Path, **kw: object) -> Mode:
    load0 = os.getloadavg()
    first: list[float] = []
    t0, c0, k0 = time.perf_counter(), time.process_time(), _children_cpu()

    def progress(done: int, _total: int, run: str) -> None:
        if run and not first:
            first.append(time.perf_counter() - t0)

    stats = audit([logs], db, out, progress=progress, **kw)  # type: ignore[arg-type]
    wall = time.perf_counter() - t0
    coordinator_cpu = time.process_time() - c0
    children_cpu = _children_cpu() - k0
    load1 = os.getloadavg()
    runs = read_table(out, "audit_runs")
    run_wall, run_cpu = float(runs["elapsed_s"].mean()), float(runs["cpu_s"].mean())
    if "scheduler" in kw:  # the cluster's processes are not this process's children
        children_cpu = float(runs["cpu_s"].sum())
    mode = Mode(label, stats.audited, wall, coordinator_cpu + children_cpu, float(runs["cpu_s"].sum()))
    print(
        f"{label:<22} {stats.audited:4d} runs  {wall:7.1f} s  {mode.rate:7.1f} runs/min  "
        f"first result {first[0] if first else float('nan'):5.1f} s  "
        f"per run: wall {run_wall:.2f} s, CPU {run_cpu:.2f} s in its worker  "
        f"CPU of all processes {mode.cpu_per_run:.3f} s/run, outside the runs {mode.cpu - mode.in_runs:4.1f} s "
        f"(coordinator {coordinator_cpu:4.1f} s)  "
        f"cores obtained {mode.cores:.2f}  "
        f"load {load0[0]:.2f} → {load1[0]:.2f}" + (f"  FAILED {stats.failed}" if stats.failed else "")
    )
    return mode


def compare(one: Mode, many: Mode, ceiling: float) -> float:
    """Print the speed-up of ``many`` over ``one``, split into the machine's share (cores
    obtained) and the code's CPU cost per run, against the calibration ``ceiling``."""
    speed = many.rate / one.rate
    print(
        f"{'':<22} speed-up {speed:.2f}× = cores {many.cores / one.cores:.2f}× × CPU per run "
        f"{one.cpu_per_run / many.cpu_per_run:.2f}×;  calibration {ceiling:.2f}× → "
        f"{speed / ceiling:.0%} of what the machine gave 2 processes now (target ≥ 1.8× on a quiet machine)"
    )
    return speed


#: Issue 34 states the pool's speed-up (≥ 1.6× one worker) for a fleet of 20 one-hour runs;
#: at any fleet size the pool must never be slower than one worker.
SPEED_UP_RUNS = 20


def issue_34(workers: int, runs: int, speeds: list[float], fixed: list[float]) -> None:
    """The verdicts of issue 34 item 1 over the rounds: the pool's speed-up over one worker
    (median ≥ 1.6× from :data:`SPEED_UP_RUNS` runs on, printed without a target below; the
    slowest round never below 1× at any size) and the pool's own fixed CPU — its CPU outside
    the runs less one worker's (the coordinator's storing, which both pay) — ≤ 0.5 s."""
    med, low, cpu = median(speeds), min(speeds), median(fixed)
    rounds = ", ".join(f"{s:.2f}" for s in speeds)
    target = f" {verdict('≥ 1.6×', med >= 1.6)}" if runs >= SPEED_UP_RUNS else ""
    print(f"{workers} workers / 1 worker, {runs} runs: median {med:.2f}×{target}; rounds {rounds}")
    print(f"{workers} workers / 1 worker, {runs} runs: slowest round {low:.2f}× {verdict('≥ 1×', low >= 1.0)}")
    print(
        f"the pool's fixed CPU (outside the runs, over one worker's): median {cpu:.2f} s "
        f"{verdict('≤ 0.5 s', cpu <= 0.5)}"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=200, help="run folders to audit (default 200)")
    ap.add_argument("--workers", type=int, default=2, help="workers of the parallel modes (default 2)")
    ap.add_argument("--rounds", type=int, default=1, help="rounds of calibration, 1 worker, pool (default 1)")
    ap.add_argument("--no-dask", action="store_true", help="skip the LocalCluster mode")
    ap.add_argument("--keep", action="store_true", help="keep the temp dir")
    args = ap.parse_args()
    root = Path(tempfile.mkdtemp(prefix="bench-audit-"))
    try:
        print(f"cores {os.cpu_count()}, load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}, dir {root}")
        db, logs, duration = make_runs(root, args.runs)
        pools: list[Mode] = []
        speeds: list[float] = []
        fixed: list[float] = []
        for k in range(args.rounds):
            before = calibrate(args.workers)
            one = timed("1 worker", db, logs, root / f"a1-{k}.sqlite", workers=1)
            many = timed(f"{args.workers} workers (pool)", db, logs, root / f"an-{k}.sqlite", workers=args.workers)
            ceiling = 0.5 * (before + calibrate(args.workers))
            print(f"{'':<22} calibration: {args.workers} processes of a pure CPU loop are {ceiling:.2f}× one now")
            speeds.append(compare(one, many, ceiling))
            fixed.append((many.cpu - many.in_runs) - (one.cpu - one.in_runs))
            pools.append(many)
        issue_34(args.workers, args.runs, speeds, fixed)
        if not args.no_dask:
            from distributed import LocalCluster

            with LocalCluster(
                n_workers=args.workers, threads_per_worker=1, processes=True, dashboard_address=":0"
            ) as cluster:
                before = calibrate(args.workers)
                one = timed("1 worker", db, logs, root / "a1-d.sqlite", workers=1)
                dask = timed(
                    f"LocalCluster {args.workers}×1", db, logs, root / "ad.sqlite", scheduler=cluster.scheduler_address
                )
                ceiling = 0.5 * (before + calibrate(args.workers))
            print(f"{'':<22} calibration: {args.workers} processes of a pure CPU loop are {ceiling:.2f}× one now")
            compare(one, dask, ceiling)
        slowest = min(pools, key=lambda m: m.rate)
        n_runs = 1000.0 * 3600.0 / duration
        print(
            f"1,000 run-hours = {n_runs:.0f} runs of {duration / 60:.0f} min: {n_runs / slowest.rate:.1f} min at the "
            f"slowest {args.workers}-worker rate measured here ({slowest.rate:.1f} runs/min, load as above; "
            f"linear: the work per run does not depend on how many there are; target ≤ 10 min)"
        )
    finally:
        if args.keep:
            print(f"kept {root}")
        else:
            shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
