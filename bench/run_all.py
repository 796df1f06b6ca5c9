"""Run every benchmark and write one Markdown table: ``bench/RESULTS.md``.

    .venv/bin/python bench/run_all.py            # quick sizes (make bench), ~15-25 min on 2 cores
    .venv/bin/python bench/run_all.py --full     # the sizes the targets are stated for
    .venv/bin/python bench/run_all.py --only pipeline,db

Each benchmark runs in its own process (``OMP_NUM_THREADS=1``), one after the other, and
prints its throughput, the ratio against its naive baseline and, where one exists, against
the best library alternative measured side by side in the same run. The table has one row
per benchmark: the command that reproduces it, what it printed, its wall time, the 1-minute
load average (``os.getloadavg``) before and after it, since the machine may be shared, and
when it ran. The header is dated (start and end, with the 1/5/15-minute load average at
each) and names the commit. ``--only`` redoes those rows and keeps the file's other rows as
they were, each with its own date, so the file is never edited by hand. A benchmark that
fails is a row saying so (exit code and last line): the table is written all the same.
Every ``bench/bench_*.py`` is a row (a test checks it). Never fails on timing: it reports.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
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
    Bench("review_map", "db review network map: page size, build time", ("--lines", "10"), ("--lines", "50")),
    Bench("topology", "db validate: topology and balise-group rules, 50,000 tracks", ("--lines", "100"), ()),
    Bench("matching", "GPS map matching", ("--lines", "20", "--fixes", "100000", "--repeat", "2"), ()),
    Bench("track_match", "track match: GNSS-only trace → network path, 10,000 tracks", ("--lines", "40"), ()),
    Bench("engine", "network engine: line runs on the network DB / on the line-only DB", ("--rounds", "3"), ()),
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
    Bench("osm", "OSM import (Cologne, 3,657 switches) vs osmium's read", ("--repeat", "1"), ("--repeat", "3")),
)


#: The table's header line, and that of the layout before the *when* column.
TABLE_HEAD = "| component | command | result | wall | load | when |"
OLD_TABLE_HEAD = "| component | command | result | wall | load |"


@dataclass(frozen=True)
class Row:
    """One benchmark's line of the table: what ran, what it printed, when and under what load."""

    component: str
    command: str
    result: str
    wall_s: float
    load_before: float
    load_after: float
    when: str

    @property
    def script(self) -> str:
        """The script the command runs (``bench_db.py``): a row's key when rows are merged."""
        return _script_of(self.command)

    def markdown(self) -> str:
        return (
            f"| {self.component} | `{self.command}` | {_cell(self.result)} | {self.wall_s:.0f} s | "
            f"{self.load_before:.1f} → {self.load_after:.1f} | {self.when} |"
        )


def _script_of(text: str) -> str:
    """The first ``bench/NAME.py`` a command or a table line names (its command's), or ''."""
    m = re.search(r"bench/(\w+\.py)", text)
    return m.group(1) if m else ""


def _now() -> str:
    return f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC"


def _run(b: Bench, full: bool, timeout_s: float) -> Row:
    """One benchmark in its own process: its row (a failure is a row saying so)."""
    args = b.full if full and b.full else b.quick
    shown = " ".join([".venv/bin/python", f"bench/{b.path.name}", *args])
    when, load0 = _now(), os.getloadavg()[0]
    if not b.path.exists():
        return Row(b.component, shown, "not run: the script does not exist", 0.0, load0, load0, when)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    t0 = time.perf_counter()
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
    return Row(b.component, shown, out, time.perf_counter() - t0, load0, os.getloadavg()[0], when)


def _cell(text: str) -> str:
    return "<br>".join(line.replace("|", "\\|") for line in text.splitlines() if line.strip()) or "—"


def _loads() -> str:
    one, five, fifteen = os.getloadavg()
    return f"{one:.2f} / {five:.2f} / {fifteen:.2f}"


def _commit() -> str:
    """The checked-out commit (``+`` when the tree has changes besides RESULTS.md), or ``?``."""
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--", ".", ":(exclude)bench/RESULTS.md"],
            cwd=ROOT,
            capture_output=True,
            text=True,
        )
    except OSError:
        return "?"
    return (head.stdout.strip() or "?") + ("+" if dirty.stdout.strip() else "")


def kept_rows(path: Path) -> list[str]:
    """The table lines of an existing RESULTS.md, to keep the rows a partial run (``--only``)
    does not redo; a table of the layout before the *when* column gets the file's date in it."""
    if not path.exists():
        return []
    text = path.read_text(encoding="utf-8")
    lines = text.splitlines()
    for head in (TABLE_HEAD, OLD_TABLE_HEAD):
        if head in lines:
            rows = [line for line in lines[lines.index(head) + 2 :] if line.startswith("| ")]
            break
    else:
        return []
    if head == TABLE_HEAD:
        return rows
    dated = re.search(r" on (\d{4}-\d\d-\d\d \d\d:\d\d UTC)", text)
    return [f"{line} {dated.group(1) if dated else '?'} (or later) |" for line in rows]


def merged(rows: list[Row], old: list[str]) -> list[str]:
    """The table body: the rows just run, in place of the old lines of the same scripts, the
    other old lines kept as they were (each dated in its *when* column)."""
    done = {r.script: r.markdown() for r in rows}
    body = []
    for line in old:
        body.append(done.pop(_script_of(line), line))
    return body + list(done.values())


@dataclass(frozen=True)
class Started:
    """This invocation of run_all: its arguments, start time and load average then."""

    argv: str
    when: str
    loads: str

    @classmethod
    def now(cls, argv: list[str]) -> Started:
        return cls(" ".join(["bench/run_all.py", *argv]), _now(), _loads())


def write_results(rows: list[Row], out: Path, started: Started, keep: list[str], *, done: bool = True) -> None:
    """RESULTS.md: a header dated with the start and end of this run (``done`` False: still
    running, the time of this write) and the load average at each, then one row per benchmark
    (``keep``: older table lines whose scripts this run did not redo)."""
    head = [
        "# Benchmark results",
        "",
        "Written by `bench/run_all.py` (`make bench`) from the benchmarks' own output: do not edit by hand; "
        "re-run a row with its command, or with `bench/run_all.py --only NAME` to update it here.",
        "",
        f"* last written by `{started.argv}`: started {started.when}, load average {started.loads}; "
        f"{'finished' if done else 'not finished (table so far)'} {_now()}, load average {_loads()} "
        "(1 / 5 / 15 min)",
        f"* commit {_commit()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "",
        "Each row is one benchmark run in its own process (`OMP_NUM_THREADS=1`); *load* is the 1-minute "
        "load average before → after it (above the core count the figures are pessimistic: the benchmark "
        "waited for a core); *when* is when it started (rows an `--only` run did not redo keep their date).",
        "",
        TABLE_HEAD,
        "| --- | --- | --- | --- | --- | --- |",
    ]
    out.write_text("\n".join(head + merged(rows, keep)) + "\n", encoding="utf-8")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the full sizes the targets are stated for")
    ap.add_argument("--only", default="", help="comma-separated names (startup, logs, db, pipeline, …)")
    ap.add_argument("--out", type=Path, default=BENCH / "RESULTS.md")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per benchmark")
    args = ap.parse_args()
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    unknown = only - {b.name for b in BENCHES}
    if unknown:
        ap.error(f"--only: no benchmark named {', '.join(sorted(unknown))}")
    keep = kept_rows(args.out) if only else []
    started = Started.now(sys.argv[1:])
    rows: list[Row] = []
    for b in BENCHES:
        if only and b.name not in only:
            continue
        print(f"[{datetime.now():%H:%M:%S}] {b.name} …", flush=True)
        rows.append(_run(b, args.full, args.timeout))
        print(rows[-1].result, flush=True)
        write_results(rows, args.out, started, keep, done=False)  # a partial table survives an interruption
    write_results(rows, args.out, started, keep)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
