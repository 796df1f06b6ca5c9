"""Benchmark: CLI start-up — ``python -X importtime`` of ``cli.main`` and ``trainpos --help``.

Run: ``.venv/bin/python bench/bench_startup.py [--repeat 5]``. A measurement only (the
start-up work itself is issue 21's CLI item): the wall time of ``trainpos --help`` (best
of ``--repeat`` fresh processes) against the interpreter's own floor (``python -c pass``,
the naive baseline no CLI can beat) and against importing pandas alone (the one heavy
library every command needs); the cumulative import time of ``cli.main`` and its
heaviest top-level imports (``-X importtime``), and which of the libraries the issue
wants imported lazily are imported by ``cli.main`` at start-up. Target (issue 21):
``trainpos --help`` ≤ 0.3 s. Never fails on timing.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HEAVY = ("dask", "distributed", "numba", "matplotlib", "scipy.stats", "pandera", "pyarrow.parquet", "pyproj")


def wall(cmd: list[str], repeat: int) -> float:
    best = float("inf")
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=ROOT, capture_output=True, check=False)
        best = min(best, time.perf_counter() - t0)
    return best


def import_times() -> tuple[float, list[tuple[float, str]]]:
    """(cumulative s of cli.main, [(cumulative s, module)] of the direct imports, heaviest first)."""
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", "import cli.main"], cwd=ROOT, capture_output=True, text=True
    )
    total, top = 0.0, []
    for line in proc.stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        parts = line.split("|")
        try:
            cum = int(parts[1]) / 1e6
        except ValueError:
            continue
        name = parts[2]
        depth = (len(name) - len(name.lstrip())) // 2
        if name.strip() == "cli.main":
            total = cum
        elif depth <= 1:
            top.append((cum, name.strip()))
    return total, sorted(top, reverse=True)[:8]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()
    trainpos = str(Path(sys.executable).parent / "trainpos")
    floor = wall([sys.executable, "-c", "pass"], args.repeat)
    pandas = wall([sys.executable, "-c", "import pandas"], args.repeat)
    helps = wall([trainpos, "--help"], args.repeat)
    total, top = import_times()
    probe = f"import sys, cli.main; print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    eager = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True).stdout.split()
    load = f"load {os.getloadavg()[0]:.2f}/{os.cpu_count()} cores"
    print(
        f"trainpos --help: {helps:.2f} s wall (target ≤ 0.3 s); python -c pass {floor:.3f} s "
        f"(floor: {helps / floor:.0f}× it); import pandas {pandas:.2f} s  [{load}]"
    )
    print(
        f"import cli.main: {total:.2f} s cumulative (-X importtime); heaviest: "
        + ", ".join(f"{m} {s:.2f} s" for s, m in top)
    )
    print("imported at start-up of those to be lazy: " + (", ".join(eager) if eager else "none"))


if __name__ == "__main__":
    main()
