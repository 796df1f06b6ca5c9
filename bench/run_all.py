"""Run every benchmark and write two Markdown tables: ``bench/RESULTS.md``.

    .venv/bin/python bench/run_all.py            # quick sizes (make bench), ~15-25 min on 2 cores
    .venv/bin/python bench/run_all.py --full     # the sizes the issues' targets are stated for (make bench-full)
    .venv/bin/python bench/run_all.py --only pipeline,db
    .venv/bin/python bench/run_all.py --full --only db,db_network

Each benchmark runs in its own process (``OMP_NUM_THREADS=1``), one after the other, and
prints its throughput, the ratio against its naive baseline and, where one exists, against
the best library alternative measured side by side in the same run. The quick table has one
row per benchmark: the command that reproduces it, what it printed, its wall time, the
1-minute load average (``os.getloadavg``) before and after it, since the machine may be
shared, and when it ran. The full table (``--full``) has a row per size an issue states a
target for — the size in words, the target, the benchmark's own verdict lines
(``… (target ≤ 1.3×): met``), then the same columns — keyed by its name, since two rows may
run one script (``db``, ``db_network``). Each table is dated (start and end, with the
1/5/15-minute load average at each) and names the commit; a run rewrites its own table and
copies the other one as it was. ``--only`` redoes those rows and keeps the table's other
rows as they were, each with its own date, so the file is never edited by hand. A benchmark
that fails is a row saying so (exit code and last line): the table is written all the same.
Every ``bench/bench_*.py`` is a row (a test checks it). Never fails on timing: it reports.
"""

from __future__ import annotations

import argparse
import os
import platform
import re
import resource
import subprocess
import sys
import time
from dataclasses import dataclass
from datetime import UTC, datetime
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent


@dataclass(frozen=True)
class Full:
    """A benchmark's row of the full-size table: the arguments of the size an issue states its
    target at, that size in words and the target (the benchmark prints its verdict on it)."""

    args: tuple[str, ...]
    size: str
    target: str


@dataclass(frozen=True)
class Bench:
    """One benchmark: its quick arguments (``None``: no quick row, as a second row of a script
    has), its full size (``None``: none stated) and the script (default ``bench_NAME.py``)."""

    name: str
    component: str
    quick: tuple[str, ...] | None
    full: Full | None = None
    script: str = ""

    @property
    def path(self) -> Path:
        return BENCH / (self.script or f"bench_{self.name}.py")

    def args(self, full: bool) -> tuple[str, ...] | None:
        """The arguments of the quick or the full row, ``None`` when there is no such row."""
        if full:
            return self.full.args if self.full else None
        return self.quick


#: Issue 34's targets for the line-only DB and the audit, issue 30's for the network DB.
DB_TARGET = "issue 34: db validate ≤ 1.5× its bound (CPU and peak RSS); db build ≤ 1.3× the DuckDB build (CPU)"
AUDIT_TARGET = "issue 34: 2 workers ≥ 1.6× one worker; the pool's fixed CPU ≤ 0.5 s"

BENCHES = (
    Bench(
        "startup",
        "CLI start-up (measurement only)",
        ("--repeat", "3"),
        Full(("--repeat", "7"), "7 fresh processes per command", "trainpos --help ≤ 0.3 s"),
    ),
    Bench(
        "logs",
        "log reading (CSV, Parquet) and logs check",
        ("--hours", "1", "--repeat", "2"),
        Full(
            ("--hours", "10"),
            "10-hour run (3.6 M IMU rows)",
            "read ≤ 1 s, check ≤ 3 s; CSV read ≤ 1.3× the fastest reader",
        ),
    ),
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
    ),
    Bench(
        "db",
        "db build / validate, read_network",
        ("--lines", "100", "--naive-fraction", "0.01"),
        Full(
            ("--lines", "1000", "--naive-fraction", "0", "--processes", "3"),
            "1,002,000-point line-only DB (1000 lines × 10 km), 3 interleaved rounds of whole processes",
            DB_TARGET,
        ),
    ),
    Bench(
        "db_network",
        "db build / validate per grid point: lines with station layouts / the lines alone",
        None,
        Full(
            ("--topology", "--lines", "1000", "--rounds", "3"),
            "a stress network at twice a national density: 1000 lines × 10 km with and without station layouts, a "
            "station every 1.1 km (≈ 24 grid points per switch), 3 interleaved rounds",
            "issue 30's ratio at twice the density of its national network (a stress case; the issue's national "
            "network is the db_network_de row): ≤ 1.3× the CPU per grid point of the line-only DB",
        ),
        script="bench_db.py",
    ),
    Bench(
        "db_network_de",
        "db build / validate per grid point at the German network's density of switches",
        None,
        Full(
            ("--topology", "--lines", "1400", "--station-spacing-m", "2400", "--rounds", "3"),
            "the national network at a real density: 1400 lines × 10 km, a station every 2.4 km (≈ 47 grid "
            "points per switch, the German network ≈ 46; ≥ 50,000 tracks), 3 interleaved rounds",
            "issue 30: ≤ 1.3× the CPU per grid point of the line-only DB (build and validate)",
        ),
        script="bench_db.py",
    ),
    Bench(
        "review_map",
        "db review network map: page size, build time",
        ("--lines", "10"),
        Full(
            ("--lines", "50"),
            "1 M-point DB (50 lines × 2 tracks × 200 km)",
            "issue 30: the page stays at a few MB for 1 M points",
        ),
    ),
    Bench("topology", "db validate: topology and balise-group rules, 50,000 tracks", ("--lines", "100")),
    Bench("matching", "GPS map matching", ("--lines", "20", "--fixes", "100000", "--repeat", "2")),
    Bench(
        "track_match",
        "track match: GNSS-only trace → network path, 10,000 tracks",
        ("--lines", "40"),
        Full(
            ("--lines", "200"),
            "10,000 tracks, 50,000 fixes, best of 3",
            "issue 31: ≥ 50,000 fixes/s on one core",
        ),
    ),
    Bench(
        "engine",
        "network engine: line runs on the network DB / on the line-only DB",
        ("--rounds", "3"),
        Full(("--rounds", "5"), "the 6 sample line runs, 5 interleaved rounds", "issue 31: ≤ 1.3× (CPU)"),
    ),
    Bench("pipeline", "pipeline core (1 h run)", ()),
    Bench(
        "scaling",
        "pipeline linearity in run length, memory",
        ("--hours", "0.25", "1", "4"),
        Full(
            ("--hours", "1", "8", "24"),
            "1, 8 and 24 h runs; 2 interleaved pairs of processes, windowed / whole, per windowed run",
            "issue 34: the windowed replay ≤ 1.1× the CPU of the whole replay at 8 h and 24 h",
        ),
    ),
    Bench(
        "run",
        "trainpos run, whole process (CSV, Parquet)",
        ("--repeat", "2"),
        Full(("--repeat", "5"), "1 h run, best of 5 fresh processes", "issue 34: ≥ 2,000× real time"),
    ),
    Bench("outputs", "writing outputs (share of trainpos run)", ()),
    Bench("odometry", "slip/slide odometry", ("--repeat", "5")),
    Bench("gnss", "S002 GNSS epochs/s", ("--runs", "5", "--throughput-runs", "2")),
    Bench(
        "gnss_fde",
        "S002 fault detection and exclusion (step, ramp)",
        ("--runs", "5"),
        Full(("--runs", "50"), "50 simulated runs", "faults kept after detection: 0"),
    ),
    Bench(
        "gnss_pipeline",
        "S002 GNSS aid in the pipeline (aid off vs on)",
        ("--runs", "3"),
        Full(("--runs", "24"), "24 simulated runs", "|km error| ≤ margin ≥ 99.9 %; wrong line/track cycles 0"),
    ),
    Bench(
        "radar",
        "S004 radar frames/s",
        ("throughput", "--hours", "0.25", "--loop-minutes", "1"),
        Full(("throughput",), "the default throughput run", "≥ 100× real time"),
    ),
    Bench(
        "radar_pipeline",
        "S004 radar in the pipeline (pulses + IMU vs + radar)",
        ("--runs", "3"),
        Full(("--runs", "30"), "30 simulated runs", "episode error, fail-safes, margin (no single figure)"),
    ),
    Bench("possession", "possession alarms", ("--runs", "12")),
    Bench("gis_verify", "GIS verification", ()),
    Bench("simulate", "simulator", ("--km", "30")),
    Bench(
        "survey",
        "survey: moved/missed balises, curves, wheels; run-hours/min",
        ("--lines", "1", "--length-km", "12", "--runs", "4"),
    ),
    Bench("impact", "db impact vs two audits of the same runs", ("--copies", "2", "--pairs", "1")),
    Bench(
        "audit",
        "fleet audit scaling, 1 → 2 workers, Dask",
        ("--runs", "100"),
        Full(("--runs", "20", "--rounds", "3", "--no-dask"), "20 one-hour runs, 3 rounds", AUDIT_TARGET),
    ),
    Bench(
        "audit_small",
        "fleet audit, a small fleet: 1 → 2 workers",
        None,
        Full(
            ("--runs", "4", "--rounds", "3", "--no-dask"),
            "4 one-hour runs (the smallest fleet the pool takes), 3 rounds",
            "issue 34: 2 workers never slower than one worker at any fleet size",
        ),
        script="bench_audit.py",
    ),
    Bench(
        "osm",
        "OSM import (Cologne, 3,657 switches) vs osmium's read",
        ("--repeat", "1"),
        Full(("--repeat", "3"), "the Cologne extract, best of 3", "issue 30: ≤ 10 s on one core"),
    ),
)


#: The quick table's header line, and that of the layout before the *when* column.
TABLE_HEAD = "| component | command | result | wall | load | when |"
OLD_TABLE_HEAD = "| component | command | result | wall | load |"
#: The full table's header line; its rows are keyed by their name (two rows may run one script).
FULL_HEAD = "| row | size | target | verdict | command | result | wall | load | when |"
#: A benchmark's verdict on its target, as it prints it: ``… 1.25× (target ≤ 1.3×): met``.
VERDICT = re.compile(r"\(target [^()]*\): (?:met|not met)\b")


@dataclass(frozen=True)
class Table:
    """One table of RESULTS.md: its section title, header line and what its rows are."""

    title: str
    head: str
    about: str

    @property
    def full(self) -> bool:
        return self.head == FULL_HEAD

    @property
    def rule(self) -> str:
        """The line under the header (one ``---`` per column)."""
        return "|" + " --- |" * (self.head.count("|") - 1)


QUICK = Table(
    "## Quick sizes (`make bench`)",
    TABLE_HEAD,
    "Each row is one benchmark at a quick size, run in its own process (`OMP_NUM_THREADS=1`); *load* is the "
    "1-minute load average before → after it (above the core count the figures are pessimistic: the benchmark "
    "waited for a core); *wall* is followed by the CPU of its processes; *when* is when it started (rows an "
    "`--only` run did not redo keep their date).",
)
FULL = Table(
    "## Full sizes: the issues' targets (`make bench-full`)",
    FULL_HEAD,
    "Each row is one benchmark at the size an issue states its target for (`bench/run_all.py --full`), in its "
    "own process (`OMP_NUM_THREADS=1`); *verdict* is what the benchmark itself prints about the target "
    "(`(target …): met` or `not met`); *wall* is followed by the CPU of its processes; *load* is the 1-minute "
    "load average before → after it: the issues' "
    "figures are stated for a quiet machine (load < 1.5), a row measured above that is to be run again with "
    "`bench/run_all.py --full --only NAME`, which redoes that row only.",
)
TABLES = (QUICK, FULL)


@dataclass(frozen=True)
class Row:
    """One benchmark's line of a table: what ran, what it printed, when and under what load
    (a full row: also its name, its size in words and the target it is measured against)."""

    component: str
    command: str
    result: str
    wall_s: float
    load_before: float
    load_after: float
    when: str
    name: str = ""
    size: str = ""
    target: str = ""
    cpu_s: float | None = None
    """CPU (user + system) of the benchmark's process and every process it waited for."""

    @property
    def script(self) -> str:
        """The script the command runs (``bench_db.py``): a quick row's key when rows are merged."""
        return _script_of(self.command)

    @property
    def verdict(self) -> str:
        """The lines of the result that give a verdict on a target (:data:`VERDICT`)."""
        return "\n".join(line for line in self.result.splitlines() if VERDICT.search(line))

    def key(self, table: Table) -> str:
        """What a line of ``table`` is replaced by: the row's name (full), its script (quick)."""
        return self.name if table.full else self.script

    @property
    def _cpu(self) -> str:
        return "" if self.cpu_s is None else f" ({self.cpu_s:.0f} s CPU)"

    def markdown(self, table: Table = QUICK) -> str:
        tail = (
            f"| `{self.command}` | {_cell(self.result)} | {self.wall_s:.0f} s{self._cpu} | "
            f"{self.load_before:.1f} → {self.load_after:.1f} | {self.when} |"
        )
        if table.full:
            return f"| {self.name} | {_cell(self.size)} | {_cell(self.target)} | {_cell(self.verdict)} {tail}"
        return f"| {self.component} {tail}"


def _script_of(text: str) -> str:
    """The first ``bench/NAME.py`` a command or a table line names (its command's), or ''."""
    m = re.search(r"bench/(\w+\.py)", text)
    return m.group(1) if m else ""


def _key_of(line: str, table: Table) -> str:
    """A table line's key: its first cell (the row's name) in the full table, else its script."""
    return line.split("|")[1].strip() if table.full else _script_of(line)


def _now() -> str:
    return f"{datetime.now(UTC):%Y-%m-%d %H:%M} UTC"


def _run(b: Bench, full: bool, timeout_s: float) -> Row:
    """One benchmark in its own process: its row (a failure is a row saying so)."""
    args = b.args(full) or ()
    shown = " ".join([".venv/bin/python", f"bench/{b.path.name}", *args])
    size, target = (b.full.size, b.full.target) if full and b.full else ("", "")

    def row(out: str, wall_s: float, load0: float, load1: float, when: str, cpu_s: float | None = None) -> Row:
        return Row(b.component, shown, out, wall_s, load0, load1, when, b.name, size, target, cpu_s)

    when, load0 = _now(), os.getloadavg()[0]
    if not b.path.exists():
        return row("not run: the script does not exist", 0.0, load0, load0, when)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    t0, c0 = time.perf_counter(), _children_cpu()
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
    return row(out, time.perf_counter() - t0, load0, os.getloadavg()[0], when, _children_cpu() - c0)


def _children_cpu() -> float:
    """CPU (user + system) of the processes this one has waited for, theirs included [s]."""
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


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


@dataclass(frozen=True)
class Section:
    """One table as the file holds it: the lines dating its last run (``* …``) and its rows."""

    meta: list[str]
    rows: list[str]


def _section_lines(lines: list[str], table: Table) -> list[str] | None:
    """The lines under a table's title up to the next title; a file of the layout before the
    titles holds only the quick table (all its lines)."""
    titles = [i for i, line in enumerate(lines) if line.startswith("## ")]
    if table.title in lines:
        start = lines.index(table.title)
        end = next((i for i in titles if i > start), len(lines))
        return lines[start + 1 : end]
    return lines if table is QUICK and not titles else None


def read_section(path: Path, table: Table) -> Section:
    """A table of an existing RESULTS.md (empty when there is none); a quick table of the
    layout before the *when* column gets the file's date in it."""
    if not path.exists():
        return Section([], [])
    text = path.read_text(encoding="utf-8")
    lines = _section_lines(text.splitlines(), table)
    if lines is None:
        return Section([], [])
    meta = [line for line in lines if line.startswith("* ")]
    for head in (table.head,) if table.full else (TABLE_HEAD, OLD_TABLE_HEAD):
        if head in lines:
            rows = [line for line in lines[lines.index(head) + 2 :] if line.startswith("| ")]
            break
    else:
        return Section(meta, [])
    if head != OLD_TABLE_HEAD:
        return Section(meta, rows)
    dated = re.search(r" on (\d{4}-\d\d-\d\d \d\d:\d\d UTC)", text)
    return Section(meta, [f"{line} {dated.group(1) if dated else '?'} (or later) |" for line in rows])


def kept_rows(path: Path, table: Table = QUICK) -> list[str]:
    """The lines of one table of an existing RESULTS.md, to keep the rows a partial run
    (``--only``) does not redo."""
    return read_section(path, table).rows


def merged(rows: list[Row], old: list[str], table: Table = QUICK) -> list[str]:
    """The table body: the rows just run, in place of the old lines of the same key (script
    or name), the other old lines kept as they were (each dated in its *when* column)."""
    done = {r.key(table): r.markdown(table) for r in rows}
    body = []
    for line in old:
        body.append(done.pop(_key_of(line, table), line))
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

    def meta(self, done: bool) -> list[str]:
        """The lines dating a table: this run's start and end (``done`` False: still running,
        the time of this write), with the load average at each, and the commit."""
        return [
            f"* last written by `{self.argv}`: started {self.when}, load average {self.loads}; "
            f"{'finished' if done else 'not finished (table so far)'} {_now()}, load average {_loads()} "
            "(1 / 5 / 15 min)",
            f"* commit {_commit()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        ]


def write_results(
    rows: list[Row], out: Path, started: Started, keep: list[str], *, done: bool = True, table: Table = QUICK
) -> None:
    """RESULTS.md: ``table`` dated with this run (see :meth:`Started.meta`), its rows those just
    run (``keep``: older lines of that table whose benchmarks this run did not redo), and the
    other table as the file held it, lines and dates untouched."""
    text = [
        "# Benchmark results",
        "",
        "Written by `bench/run_all.py` from the benchmarks' own output: do not edit by hand; re-run a row with "
        "its command, or with `bench/run_all.py --only NAME` (quick table) or `bench/run_all.py --full --only "
        "NAME` (full table) to update it here. A run rewrites its own table only.",
    ]
    for t in TABLES:
        kept = Section(started.meta(done), merged(rows, keep, t)) if t is table else read_section(out, t)
        if t is table or kept.rows:
            text += ["", t.title, "", *kept.meta, "", t.about, "", t.head, t.rule, *kept.rows]
    out.write_text("\n".join(text) + "\n", encoding="utf-8")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--full", action="store_true", help="the rows of the sizes the issues' targets are stated for")
    ap.add_argument("--only", default="", help="comma-separated names (startup, logs, db, db_network, …)")
    ap.add_argument("--out", type=Path, default=BENCH / "RESULTS.md")
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per benchmark")
    args = ap.parse_args()
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    unknown = only - {b.name for b in BENCHES}
    if unknown:
        ap.error(f"--only: no benchmark named {', '.join(sorted(unknown))}")
    chosen = [b for b in BENCHES if b.args(args.full) is not None and (not only or b.name in only)]
    sizeless = only - {b.name for b in chosen}
    if sizeless:
        ap.error(f"--only: no {'full' if args.full else 'quick'} size for {', '.join(sorted(sizeless))}")
    table = FULL if args.full else QUICK
    keep = kept_rows(args.out, table) if only else []
    started = Started.now(sys.argv[1:])
    rows: list[Row] = []
    for b in chosen:
        print(f"[{datetime.now():%H:%M:%S}] {b.name} …", flush=True)
        rows.append(_run(b, args.full, args.timeout))
        print(rows[-1].result, flush=True)
        # a partial table survives an interruption
        write_results(rows, args.out, started, keep, done=False, table=table)
    write_results(rows, args.out, started, keep, table=table)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
