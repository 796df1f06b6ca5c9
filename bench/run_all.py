"""Run every benchmark and write one Markdown table: ``bench/RESULTS.md``.

    .venv/bin/python bench/run_all.py            # quick sizes (make bench), ~15-25 min on 2 cores
    .venv/bin/python bench/run_all.py --full     # the sizes the targets are stated for
    .venv/bin/python bench/run_all.py --only pipeline,db

Each benchmark runs in its own process (``OMP_NUM_THREADS=1``), one after the other, and
prints its throughput, the ratio against its naive baseline and, where one exists, against
the best library alternative measured side by side in the same run. The table has one row
per benchmark: the command that reproduces it, what it printed, its wall time and the
1-minute load average (``os.getloadavg``) before and after it, since the machine may be
shared. A benchmark that fails is a row saying so (exit code and last line): the table is
written all the same. Every ``bench/bench_*.py`` is a row (a test checks it). Never fails on
timing: it reports.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent


@dataclass(frozen=True)
class Bench:
    name: str
    component: str
    quick: tuple[str, ...]
    full: tuple[str, ...]
    script: str = ""

    @property
    def path(self) -> Path:
        return BENCH / (self.script or f"bench_{self.name}.py")


BENCHES = (
    Bench("startup", "CLI start-up (measurement only)", ("--repeat", "3"), ("--repeat", "7")),
    Bench("logs", "log reading (CSV, Parquet) and logs check", ("--hours", "1", "--repeat", "2"), ("--hours", "10")),
    Bench(
        "import",
        "recorder import (NMEA, UBX, RINEX, IMU CSV)",
        (
            "--nmea-hours",
            "1",
            "--imu-hours",
            "1",
            "--rinex-hours",
            "0.25",
            "--georinex-minutes",
            "1",
            "--ubx-hours",
            "0.25",
        ),
        (),
    ),
    Bench("db", "db build / validate, read_network", ("--lines", "100", "--naive-fraction", "0.01"), ()),
    Bench("topology", "db validate: topology and balise-group rules, 50,000 tracks", ("--lines", "100"), ()),
    Bench("matching", "GPS map matching", ("--lines", "20", "--fixes", "100000", "--repeat", "2"), ()),
    Bench("pipeline", "pipeline core (1 h run)", (), ()),
    Bench(
        "scaling",
        "pipeline linearity in run length, memory",
        ("--hours", "0.25", "1", "4"),
        ("--hours", "0.25", "1", "2", "4", "8", "24"),
    ),
    Bench("run", "trainpos run, whole process (CSV, Parquet)", ("--repeat", "2"), ("--repeat", "5")),
    Bench("outputs", "writing outputs (share of trainpos run)", (), ()),
    Bench("odometry", "slip/slide odometry", ("--repeat", "5"), ()),
    Bench("gnss", "S002 GNSS epochs/s", ("--runs", "5", "--throughput-runs", "2"), ()),
    Bench("gnss_fde", "S002 fault detection and exclusion (step, ramp)", ("--runs", "5"), ("--runs", "50")),
    Bench("gnss_pipeline", "S002 GNSS aid in the pipeline (aid off vs on)", ("--runs", "3"), ("--runs", "24")),
    Bench("radar", "S004 radar frames/s", ("throughput", "--hours", "0.25", "--loop-minutes", "1"), ("throughput",)),
    Bench("radar_pipeline", "S004 radar in the pipeline (pulses + IMU vs + radar)", ("--runs", "3"), ("--runs", "30")),
    Bench("possession", "possession alarms", ("--runs", "12"), ()),
    Bench("gis_verify", "GIS verification", (), ()),
    Bench("simulate", "simulator", ("--km", "30"), ()),
    Bench(
        "survey",
        "survey: moved/missed balises, curves, wheels; run-hours/min",
        ("--lines", "1", "--length-km", "12", "--runs", "4"),
        (),
    ),
    Bench("impact", "db impact vs two audits of the same runs", ("--copies", "2", "--pairs", "1"), ()),
    Bench("audit", "fleet audit scaling, 1 → 2 workers, Dask", ("--runs", "100"), ("--runs", "200")),
)


def _run(b: Bench, full: bool, timeout_s: float) -> tuple[str, str, float, float, float]:
    """(command, output, wall s, load before, load after) of one benchmark."""
    args = b.full if full and b.full else b.quick
    cmd = [".venv/bin/python", f"bench/{b.path.name}", *args]
    shown = " ".join(cmd)
    if not b.path.exists():
        return shown, "not run: the script does not exist yet", 0.0, os.getloadavg()[0], os.getloadavg()[0]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    load0, t0 = os.getloadavg()[0], time.perf_counter()
    try:
        proc = subprocess.run(
            [sys.executable, str(b.path), *args],
            cwd=ROOT,
            env=env,
            capture_output=True,
            text=True,
            timeout=timeout_s,
            check=False,
        )
        out = proc.stdout.strip()
        if proc.returncode != 0:
            last = (proc.stderr.strip().splitlines() or ["?"])[-1]
            out = f"{out}\nFAILED (exit {proc.returncode}): {last}".strip()
    except subprocess.TimeoutExpired:
        out = f"FAILED: no result within {timeout_s:.0f} s"
    return shown, out, time.perf_counter() - t0, load0, os.getloadavg()[0]


def _cell(text: str) -> str:
    return "<br>".join(line.replace("|", "\\|") for line in text.splitlines() if line.strip()) or "—"


def write_results(rows: list[tuple[Bench, str, str, float, float, float]], full: bool, out: Path) -> None:
    head = [
        "# Benchmark results",
        "",
        f"Written by `bench/run_all.py{' --full' if full else ''}` on {datetime.now(UTC):%Y-%m-%d %H:%M} UTC, "
        f"{os.cpu_count()} cores, Python {platform.python_version()}. Each row is one benchmark run in its own "
        "process; *load* is the 1-minute load average before → after it (above the core count the figures "
        "are pessimistic: the benchmark waited for a core). Re-run a row with its command.",
        "",
        "| component | command | result | wall | load |",
        "| --- | --- | --- | --- | --- |",
    ]
    body = [
        f"| {b.component} | `{cmd}` | {_cell(text)} | {wall:.0f} s | {l0:.1f} → {l1:.1f} |"
        for b, cmd, text, wall, l0, l1 in rows
    ]
    out.write_text("\n".join(head + body) + "\n", encoding="utf-8")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the full sizes the targets are stated for")
    ap.add_argument("--only", default="", help="comma-separated names (startup, logs, db, pipeline, …)")
    ap.add_argument("--out", type=Path, default=BENCH / "RESULTS.md")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per benchmark")
    args = ap.parse_args()
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    rows = []
    for b in BENCHES:
        if only and b.name not in only:
            continue
        print(f"[{datetime.now():%H:%M:%S}] {b.name} …", flush=True)
        cmd, text, wall, l0, l1 = _run(b, args.full, args.timeout)
        rows.append((b, cmd, text, wall, l0, l1))
        print(text, flush=True)
        write_results(rows, args.full, args.out)  # a partial table survives an interruption
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
