"""Benchmark: CLI start-up — ``trainpos --help`` and ``trainpos COMMAND --help`` of every command.

Run: ``.venv/bin/python bench/bench_startup.py [--repeat 5] [--only db,gis]``. Target (issue
21): every ``--help`` ≤ 0.3 s wall. Each ``--help`` (the root, every group, every command
and sub-command) is started ``--repeat`` times as a fresh process (the installed
``trainpos`` script, as a user runs it); per command the median wall and CPU (user + sys of
the child, ``resource.getrusage``) are kept, and printed are their median and maximum over
the commands, against the 0.3 s target and against the interpreter's own floor
(``python -c pass``, the naive baseline no CLI can beat), with the 1-minute load average
(the machine may be shared: CPU seconds move less with the load than wall). Then the
cumulative ``-X importtime`` of ``cli.main`` with its heaviest imports, and which heavy
libraries ``import cli.main`` imports at all (the aim: none). Never fails on timing.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
TARGET_S = 0.3
HEAVY = (
    "dask",
    "distributed",
    "numba",
    "llvmlite",
    "matplotlib",
    "scipy",
    "pandera",
    "pyarrow",
    "pyproj",
    "shapely",
    "pandas",
    "numpy",
    "rich",
    "pydantic",
)


def timed(cmd: list[str], repeat: int) -> tuple[float, float]:
    """(median wall s, median CPU s) of ``repeat`` fresh processes."""
    walls, cpus = [], []
    for _ in range(repeat):
        r0 = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=ROOT, capture_output=True, check=False)
        walls.append(time.perf_counter() - t0)
        r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpus.append((r1.ru_utime - r0.ru_utime) + (r1.ru_stime - r0.ru_stime))
    return statistics.median(walls), statistics.median(cpus)


def command_paths() -> list[tuple[str, ...]]:
    """The root, every group and every (sub-)command of ``trainpos``."""
    import typer

    from cli.main import app

    def walk(cmd: object, prefix: tuple[str, ...]) -> list[tuple[str, ...]]:
        out = [prefix]
        for name, sub in sorted(getattr(cmd, "commands", {}).items()):
            out += walk(sub, (*prefix, name))
        return out

    return walk(typer.main.get_command(app), ())


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
    ap.add_argument("--repeat", type=int, default=5, help="fresh processes per command (median kept)")
    ap.add_argument("--only", default="", help="comma-separated top-level commands (default: all)")
    args = ap.parse_args()
    trainpos = str(Path(sys.executable).parent / "trainpos")
    only = {c for c in args.only.split(",") if c}
    paths = [p for p in command_paths() if not only or not p or p[0] in only]
    load0 = os.getloadavg()[0]
    floor_wall, floor_cpu = timed([sys.executable, "-c", "pass"], args.repeat)
    per = {p: timed([trainpos, *p, "--help"], args.repeat) for p in paths}
    load1 = os.getloadavg()[0]
    root_wall, root_cpu = per[()]
    walls = sorted(((w, c, p) for p, (w, c) in per.items() if p), reverse=True)
    med_w, med_c = statistics.median(w for w, _, _ in walls), statistics.median(c for _, c, _ in walls)
    top_w, top_c, top_p = walls[0]
    over = [" ".join(p) for w, _, p in walls if w > TARGET_S]
    load = f"load {load0:.2f} → {load1:.2f} on {os.cpu_count()} cores"
    print(
        f"trainpos --help: {root_wall:.3f} s wall, {root_cpu:.3f} s CPU (target ≤ {TARGET_S} s); "
        f"python -c pass {floor_wall:.3f} s wall, {floor_cpu:.3f} s CPU  [median of {args.repeat}; {load}]"
    )
    print(
        f"COMMAND --help over {len(walls)} commands: median {med_w:.3f} s wall ({med_c:.3f} s CPU), "
        f"max {top_w:.3f} s wall ({top_c:.3f} s CPU, trainpos {' '.join(top_p)}); "
        f"max {top_w / floor_wall:.1f}× the interpreter floor; "
        + (f"{len(over)} over {TARGET_S} s wall (slowest: {', '.join(over[:5])})" if over else "all within it")
    )
    total, top = import_times()
    print(
        f"import cli.main: {total:.3f} s cumulative (-X importtime); heaviest: "
        + ", ".join(f"{m} {s:.3f} s" for s, m in top)
    )
    probe = f"import sys, cli.main; print(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    eager = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True).stdout.split()
    print("heavy libraries imported by import cli.main: " + (", ".join(eager) if eager else "none"))


if __name__ == "__main__":
    main()
