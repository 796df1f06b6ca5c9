"""Benchmark: read and ``logs check`` a 10-hour run (3.6 M IMU rows) from Parquet and CSV.

Run: ``.venv/bin/python bench/bench_logs.py [--hours 10]``. Prints timings, throughput and
the ratio against a naive baseline (csv.reader + per-row Python checks on a 10-minute CSV
slice, scaled linearly to the full run). Targets: read ≤ 1 s, check ≤ 3 s. Never fails on
timing: it reports.

Then the same run written as CSV and as Parquet is read by ``Run.load_all`` and, side by
side, by the library readers of the same files with the declared column types:
``pyarrow.csv.read_csv``, ``pandas.read_csv`` (C engine, typed), polars (when installed)
and ``pyarrow.parquet.read_table``; each line gives our time over the fastest of them
(target ≤ 1.3× for CSV), as the median of the interleaved rounds' ratios and the worst
round's. ``--readers-only`` runs that comparison alone.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
import pandas as pd

from fieldlogs.quality.checks import check_run
from fieldlogs.runs.handle import Run
from fieldlogs.runs.write import write_run
from schemas.logs import LOG_STREAMS, MAX_ABS_ACCEL_MPS2, MAX_ABS_RATE_RADPS
from tests.fieldlogs.make_runs import make_meta, synthetic_streams


def naive_check(folder: Path) -> int:
    """The per-row way: csv.reader, float() per cell, Python comparisons per row."""
    problems = 0
    for name in ("tacho", "imu", "gps"):
        rate = LOG_STREAMS[name].rate_hz or 1.0
        with open(folder / f"{name}.csv", newline="", encoding="utf-8") as fh:
            reader = csv.reader(fh)
            header = next(reader)
            prev_t, prev_p, seen = -math.inf, -math.inf, set()
            for row in reader:
                values = [float(x) if x else math.nan for x in row]
                rec = dict(zip(header, values, strict=True))
                t = rec["t"]
                if t < prev_t or t in seen:
                    problems += 1
                if t - prev_t > 3 / rate and prev_t > -math.inf:
                    problems += 1
                seen.add(t)
                prev_t = t
                if name == "tacho":
                    if rec["pulses"] < prev_p:
                        problems += 1
                    prev_p = rec["pulses"]
                elif name == "imu":
                    for c in ("ax", "ay", "az"):
                        if math.isnan(rec[c]) or abs(rec[c]) > MAX_ABS_ACCEL_MPS2:
                            problems += 1
                    for c in ("wx", "wy", "wz"):
                        if math.isnan(rec[c]) or abs(rec[c]) > MAX_ABS_RATE_RADPS:
                            problems += 1
    return problems


def damage(streams: dict[str, pd.DataFrame], seed: int = 0) -> dict[str, pd.DataFrame]:
    """1 % NaN in imu.ax, 1000 swapped tacho rows, 100 repeated rows and one counter reset."""
    rng = np.random.default_rng(seed)
    out = {k: v.copy() for k, v in streams.items()}
    imu = out["imu"]
    imu.loc[rng.choice(len(imu), len(imu) // 100, replace=False), "ax"] = np.nan
    tacho = out["tacho"]
    order = np.arange(len(tacho))
    sw = rng.choice(np.arange(0, len(tacho) - 1, 2), 1000, replace=False)
    order[sw], order[sw + 1] = order[sw + 1], order[sw]
    tacho = tacho.iloc[order].reset_index(drop=True)
    p = tacho["pulses"].to_numpy().copy()
    p[len(p) // 2 :] -= p[len(p) // 2 - 1]
    tacho["pulses"] = p
    out["tacho"] = pd.concat([tacho, tacho.iloc[:100]], ignore_index=True)
    return out


def library_readers(folder: Path, fmt: str) -> dict[str, Callable[[], object]]:
    """Readers of every stream file of ``folder`` with the declared column types."""
    files = {name: folder / f"{name}.{fmt}" for name in LOG_STREAMS if (folder / f"{name}.{fmt}").exists()}

    def typed(name: str) -> dict[str, str]:
        return {c.name: ("float64" if c.dtype in ("float", "int") else "string") for c in LOG_STREAMS[name].columns}

    if fmt == "parquet":
        import pyarrow.parquet as pq

        return {"pyarrow.parquet.read_table": lambda: [pq.read_table(p) for p in files.values()]}
    import pyarrow as pa
    import pyarrow.csv as pcsv

    def arrow() -> object:
        return [
            pcsv.read_csv(
                p,
                convert_options=pcsv.ConvertOptions(
                    column_types={
                        k: pa.type_for_alias("double" if v == "float64" else "string") for k, v in typed(n).items()
                    }
                ),
            )
            for n, p in files.items()
        ]

    out: dict[str, Callable[[], object]] = {
        "pyarrow.csv.read_csv": arrow,
        "pandas.read_csv (C, typed)": lambda: [pd.read_csv(p, dtype=typed(n)) for n, p in files.items()],  # type: ignore[arg-type]
    }
    try:
        import polars as pl

        out["polars.read_csv"] = lambda: [
            pl.read_csv(
                p, schema_overrides={k: (pl.Float64 if v == "float64" else pl.Utf8) for k, v in typed(n).items()}
            )
            for n, p in files.items()
        ]
    except ImportError:
        pass
    return out


def compare_readers(tmp: Path, streams: dict[str, pd.DataFrame], repeat: int) -> None:
    """``Run.load_all`` against the library readers of the same files, CSV and Parquet,
    interleaved: each round reads the files with ours and then with every library reader,
    so that the ratio of a round compares readers under the same machine load; the median
    over the rounds is printed beside the best times (wall; CPU of all threads)."""
    for fmt in ("csv", "parquet"):
        folder = write_run(tmp / f"run-{fmt}", make_meta("BENCH"), streams, fmt=fmt)  # type: ignore[arg-type]
        size = sum(p.stat().st_size for p in folder.iterdir()) / 1e6
        readers: dict[str, Callable[[], object]] = {
            "Run.load_all": lambda folder=folder: Run(folder).load_all(),
            **library_readers(folder, fmt),
        }
        times: dict[str, list[tuple[float, float]]] = {k: [] for k in readers}
        for fn in readers.values():  # warm-up: imports, page cache
            fn()
        for _ in range(max(repeat, 3)):
            for k, fn in readers.items():
                t0, c0 = time.perf_counter(), time.process_time()
                fn()
                times[k].append((time.perf_counter() - t0, time.process_time() - c0))
        lib = [k for k in readers if k != "Run.load_all"]
        best = {k: min(w for w, _ in v) for k, v in times.items()}
        fastest = min(lib, key=lambda k: best[k])
        rounds = range(len(times["Run.load_all"]))
        per_round_w = [times["Run.load_all"][i][0] / min(times[k][i][0] for k in lib) for i in rounds]
        per_round_c = [times["Run.load_all"][i][1] / min(times[k][i][1] for k in lib) for i in rounds]
        ratio_w, ratio_c = np.median(per_round_w), np.median(per_round_c)
        others = ", ".join(f"{k} {best[k]:.2f} s" for k in lib)
        target = " (target ≤ 1.3×)" if fmt == "csv" else ""
        print(
            f"read {fmt:7s} ({size:.0f} MB): Run.load_all {best['Run.load_all']:.2f} s = "
            f"{size / best['Run.load_all']:.0f} MB/s; {others}; ours / fastest ({fastest}) = "
            f"{best['Run.load_all'] / best[fastest]:.2f}× best of {len(rounds)}, median of the rounds' ratios "
            f"to the round's fastest {ratio_w:.2f}× wall, {ratio_c:.2f}× CPU{target}; the worst round "
            f"{max(per_round_w):.2f}× wall, {max(per_round_c):.2f}× CPU  [load {os.getloadavg()[0]:.2f}]"
        )


def best_of(n: int, fn):  # type: ignore[no-untyped-def]
    best, out = math.inf, None
    for _ in range(n):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument(
        "--readers-only", action="store_true", help="only Run.load_all against the library readers (CSV, Parquet)"
    )
    args = ap.parse_args()
    seconds = args.hours * 3600
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        streams = synthetic_streams(seconds, seed=1)
        if args.readers_only:
            compare_readers(Path(tmp), streams, args.repeat)
            return
        folder = write_run(Path(tmp) / "run", make_meta("BENCH"), streams, fmt="parquet")
        gen = time.perf_counter() - t0
        rows = {k: len(v) for k, v in streams.items()}
        total = sum(rows.values())
        size = sum(p.stat().st_size for p in folder.iterdir())
        print(f"run: {args.hours:g} h, rows {rows}, Parquet {size / 1e6:.1f} MB (generated in {gen:.1f} s)")

        t_read, _ = best_of(args.repeat, lambda: Run(folder).load_all())
        t_check, findings = best_of(args.repeat, lambda: check_run(folder))
        timings = (("read  (Parquet → typed frames)", t_read, 1), ("check (read + every check)   ", t_check, 3))
        for what, secs, target in timings:
            print(f"{what}: {secs:6.2f} s  {total / secs / 1e6:6.1f} M rows/s  (target ≤ {target} s)")
        print(f"findings on the clean run: {len(findings)}")

        bad = write_run(Path(tmp) / "damaged", make_meta("DAMAGED"), damage(streams), fmt="parquet")
        t_bad, found = best_of(args.repeat, lambda: check_run(bad))
        print(
            f"check of a damaged run (36 k NaN, 1000 swaps, 100 repeats, a reset): {t_bad:.2f} s, {len(found)} findings"
        )

        slice_s = 600.0
        small = write_run(Path(tmp) / "slice", make_meta("SLICE"), synthetic_streams(slice_s, seed=1), fmt="csv")
        t_naive, _ = best_of(1, lambda: naive_check(small))
        scaled = t_naive * seconds / slice_s
        t_ours_csv, _ = best_of(1, lambda: check_run(small))
        print(
            f"naive baseline (csv.reader + per-row Python, 10-min CSV slice): {t_naive:.2f} s "
            f"→ scaled to {args.hours:g} h: {scaled:.1f} s"
        )
        print(f"logs check on the same 10-min CSV slice: {t_ours_csv:.2f} s ({t_naive / t_ours_csv:.1f}x faster)")
        print(f"ratio naive (scaled) / logs check on Parquet: {scaled / t_check:.1f}x")
        compare_readers(Path(tmp), streams, args.repeat)


if __name__ == "__main__":
    main()
