"""Benchmark: ``db impact`` against two audits of the same runs (issue 19: ≥ 0.8× their speed).

``db impact OLD NEW RUNS`` replays each run once against both DB versions (one replay task
per run: the run is read once, the pipeline runs twice); the yardstick is what a maintainer
would do without it — ``audit RUNS --db OLD`` and ``audit RUNS --db NEW`` into fresh audit
DBs. Speed ratio = (time of the two audits) / (time of db impact): ≥ 0.8 is the target.

Run::

    .venv/bin/python bench/bench_impact.py                        # prepare, then 3 alternating pairs in process
    .venv/bin/python bench/bench_impact.py --copies 20 --workers 2 --pairs 5
    .venv/bin/python bench/bench_impact.py --work /tmp/imp --mode prepare   # for whole-process timing:
    .venv/bin/python bench/bench_impact.py --work /tmp/imp --mode impact    #   one side each
    .venv/bin/python bench/bench_impact.py --work /tmp/imp --mode audits

Work folder: the bundled sample DB (``old.sqlite``), a copy with C balise 0420-D-C001 30 m
further on (``new.sqlite``), and the bundled sample logs hard-linked ``--copies`` times
(audits and impacts key runs by folder, so every copy is replayed). Prints seconds per
side, runs/min and the ratio per pair, the median, and the load average before and after.
Never fails on timing: it reports.
"""

from __future__ import annotations

import argparse
import csv
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dbtools.build import build_db
from dbtools.sample_network import sample_source_dir
from fieldlogs.audit.runner import audit
from fieldlogs.impact.runner import impact_runs

ROOT = Path(__file__).resolve().parents[1]
SAMPLE_LOGS = ROOT / "fieldlogs" / "sample_logs"
MOVED = "0420-D-C001"


def prepare(work: Path, copies: int) -> None:
    """The two DBs and the hard-linked runs (kept if already there)."""
    if (work / "runs").is_dir():
        return
    work.mkdir(parents=True, exist_ok=True)
    build_db(sample_source_dir(), work / "old.sqlite", db_version="bench-old", force=True)
    src = work / "src-new"
    shutil.copytree(sample_source_dir(), src, dirs_exist_ok=True)
    path = src / "balises.csv"
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        if r["balise_id"] == MOVED:
            r["km_actual_m"] = str(float(r["km_actual_m"]) + 30.0)
            r["km_equipment_m"] = str(float(r["km_equipment_m"]) + 30.0)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    build_db(src, work / "new.sqlite", db_version="bench-new", force=True)
    runs = work / ".runs"
    for i in range(copies):
        for run in sorted(p for p in SAMPLE_LOGS.iterdir() if (p / "run.json").is_file()):
            dst = runs / f"{i:03d}" / run.name
            dst.mkdir(parents=True)
            for f in run.iterdir():
                os.link(f, dst / f.name)
    runs.rename(work / "runs")


def time_impact(work: Path, workers: int) -> tuple[float, int]:
    t0 = time.perf_counter()
    rep = impact_runs(work / "old.sqlite", work / "new.sqlite", [work / "runs"], workers=workers)
    return time.perf_counter() - t0, len(rep.runs)


def time_audits(work: Path, workers: int) -> float:
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(dir=work) as tmp:
        for side in ("old", "new"):
            audit([work / "runs"], work / f"{side}.sqlite", Path(tmp) / f"{side}-audit.sqlite", workers=workers)
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--copies", type=int, default=8, help="copies of the 6 sample runs")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--pairs", type=int, default=3, help="alternating impact / two-audit pairs")
    ap.add_argument("--work", type=Path, default=None, help="work folder (kept; default: a temp folder)")
    ap.add_argument("--mode", choices=("both", "prepare", "impact", "audits"), default="both")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.work or Path(tmp)
        prepare(work, args.copies)
        if args.mode == "prepare":
            return
        if args.mode == "impact":
            print(f"db impact: {time_impact(work, args.workers)[0]:.2f} s")
            return
        if args.mode == "audits":
            print(f"two audits: {time_audits(work, args.workers):.2f} s")
            return
        load0 = os.getloadavg()[0]
        ratios = []
        for i in range(args.pairs):
            t_imp, n = time_impact(work, args.workers)
            t_aud = time_audits(work, args.workers)
            ratios.append(t_aud / t_imp)
            print(
                f"pair {i + 1}: db impact {t_imp:6.2f} s ({60 * n / t_imp:6.1f} runs/min), "
                f"two audits {t_aud:6.2f} s ({60 * n / t_aud:6.1f} runs/min of both versions): ratio {ratios[-1]:.2f}"
            )
        print(
            f"{n} runs, {args.workers} worker(s); speed of db impact / speed of two audits, median "
            f"{statistics.median(ratios):.2f} (min {min(ratios):.2f}, max {max(ratios):.2f}); target ≥ 0.8; "
            f"load {load0:.1f} → {os.getloadavg()[0]:.1f}"
        )


if __name__ == "__main__":
    main()
