"""Benchmark: writing the pipeline's outputs, and their share of ``trainpos run``.

Run: ``.venv/bin/python bench/bench_outputs.py [--hours 1] [--dir DIR]``.

Simulates a run of about ``--hours`` (shuttling on a 110 km line), runs the pipeline and
times, best of 3: reading the run, the pipeline, and ``write_results`` (positions and
events as Parquet + CSV, summary.json). The CSV writer (``dbtools.csvwrite``) is timed
side by side with the naive baseline — pandas ``to_csv``, byte for byte the same file
(checked here) — and with ``pyarrow.csv.write_csv`` of the frame as it is (the fastest
library writer measured; not the same bytes: ``1150`` for ``1150.0``, quoted strings),
a lower bound. Target: writing ≤ 25 % of read + pipeline + write. Never fails on timing.
"""

from __future__ import annotations

import argparse
import io
import tempfile
from pathlib import Path

from _common import best_of, load, simulated_run

from dbtools.csvwrite import csv_bytes
from dbtools.database import read_network
from fieldlogs.pipeline.outputs import write_results
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.runs.handle import read_run


def _read(run_dir: Path):  # type: ignore[no-untyped-def]
    run = read_run(run_dir)
    run.load_all()
    return run


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--dir", type=Path, default=None, help="keep the simulated run here (reused)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmpd:
        folder = args.dir or Path(tmpd)
        folder.mkdir(parents=True, exist_ok=True)
        run_dir, db = simulated_run(folder, args.hours)
        net = read_network(db)
        read_s, _, run = best_of(lambda: _read(run_dir))
        pipe_s, _, res = best_of(lambda: run_pipeline(run, net))
        out = Path(tmpd) / "out"
        write_s, _, _ = best_of(lambda: write_results(out, res.positions, res.events, res.summary, force=True))
        pos = res.positions
        ours_s, _, ours = best_of(lambda: csv_bytes(pos))
        pandas_s, _, theirs = best_of(lambda: pos.to_csv(index=False, lineterminator="\n").encode("utf-8"))

        def arrow() -> int:
            import pyarrow as pa
            import pyarrow.csv as pcsv

            buf = io.BytesIO()
            pcsv.write_csv(pa.Table.from_pandas(pos, preserve_index=False), buf)
            return buf.tell()

        arrow_s, _, _ = best_of(arrow)
        hours = res.summary["duration_s"] / 3600.0
        total = read_s + pipe_s + write_s
        mb = len(ours) / 1e6
        print(f"run: {hours:.2f} h, {len(pos):,} position rows, {len(res.events)} events  [{load()}]")
        print(
            f"read {read_s:.3f} s + pipeline {pipe_s:.3f} s + write {write_s:.3f} s = {total:.3f} s: "
            f"writing {100 * write_s / total:.1f} % (target ≤ 25 %)  [{load()}]"
        )
        print(
            f"positions.csv ({mb:.1f} MB): columnar {ours_s:.3f} s = {mb / ours_s:.0f} MB/s; "
            f"naive pandas to_csv {pandas_s:.3f} s → {pandas_s / ours_s:.1f}× faster; "
            f"pyarrow.csv.write_csv (other bytes) {arrow_s:.3f} s → ours at {ours_s / arrow_s:.2f}× of it; "
            f"identical bytes: {ours == theirs}  [{load()}]"
        )


if __name__ == "__main__":
    main()
