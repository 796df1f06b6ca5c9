"""Peak resident memory of each stage of ``run_pipeline`` on one run, as a worker runs it.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python bench/stage_memory.py RUN DB`` (a run of
``bench_scaling.py --dir DIR``; its truth stream is left out, as a field log has none).
``TRACE=1`` adds tracemalloc's current/peak of each stage (numpy and Python allocations;
Arrow's pool is not traced) and ``SNAP=stage,stage`` the largest live allocations after
those stages (slow). Each stage's functions, as ``fieldlogs.pipeline.run`` imports them, are
wrapped to print ``VmRSS`` and ``VmHWM`` when they return; ``VmHWM`` is then reset
(``/proc/self/clear_refs``, Linux), so each line's HWM is that stage's own peak. Stream
reads are printed the same way, with Arrow's pool.
"""

from __future__ import annotations

import os
import sys
import tempfile
import tracemalloc
from collections.abc import Callable
from pathlib import Path
from typing import Any

TRACE = os.environ.get("TRACE") == "1"
SNAP = set(os.environ.get("SNAP", "").split(","))
STAGES = (
    "require_usable",
    "clean_stream",
    "clocks_aligned",
    "build_cycles",
    "speed_aids",
    "correct_odometry",
    "imu_gaps",
    "analyse_gps",
    "FeatureUnit",
    "wheel_corrected",  # the balise checks (checked_solution), with the wheel-scale replays
    "episode_events",
    "events_frame",
    "summarise",
)


def status() -> dict[str, float]:
    """VmRSS and VmHWM of this process [MB]; VmHWM reset afterwards."""
    out = {}
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith(("VmRSS:", "VmHWM:")):
            key, value = line.split(":")
            out[key] = int(value.split()[0]) / 1024.0
    Path("/proc/self/clear_refs").write_text("5")
    return out


def wrapped(name: str, f: Callable[..., Any]) -> Callable[..., Any]:
    def g(*args: Any, **kwargs: Any) -> Any:
        out = f(*args, **kwargs)
        s = status()
        line = f"{name:18s} RSS {s['VmRSS']:7.0f} HWM {s['VmHWM']:7.0f} MB"
        if TRACE:
            cur, peak = tracemalloc.get_traced_memory()
            tracemalloc.reset_peak()
            line += f"  traced {cur / 1e6:7.1f} peak {peak / 1e6:7.1f} MB"
        print(line, flush=True)
        if TRACE and name in SNAP:
            for st in tracemalloc.take_snapshot().statistics("lineno")[:25]:
                print(f"    {st.size / 1e6:7.1f} MB {st.count:6d}", st.traceback.format()[-1].strip())
        return out

    return g


def main() -> None:
    import pyarrow as pa

    import fieldlogs.pipeline.run as pipeline
    from dbtools.database import read_network
    from fieldlogs.runs.csv_reader import CsvStream
    from fieldlogs.runs.handle import read_run
    from fieldlogs.runs.parquet_reader import ParquetStream

    run_dir, db = Path(sys.argv[1]), Path(sys.argv[2])
    for name in STAGES:
        setattr(pipeline, name, wrapped(name, getattr(pipeline, name)))

    def reporting(read_stream: Any) -> Any:
        def read(self: Any, window: Any = None) -> Any:
            out = read_stream(self, window)
            s, pool = status(), pa.default_memory_pool()
            print(
                f"  read {self.table.name:10s} RSS {s['VmRSS']:7.0f} HWM {s['VmHWM']:7.0f} MB  "
                f"Arrow pool ({pool.backend_name}) {pool.bytes_allocated() / 1e6:.0f} MB",
                flush=True,
            )
            return out

        return read

    for reader in (CsvStream, ParquetStream):
        reader.read = reporting(reader.read)  # type: ignore[method-assign]
    net = read_network(db)
    if TRACE:
        tracemalloc.start(25)
    with tempfile.TemporaryDirectory() as tmp:
        field = Path(tmp) / "run"
        field.mkdir()
        for f in run_dir.iterdir():
            if f.is_file() and f.name != "truth.parquet":
                os.link(f, field / f.name)
        pipeline.run_pipeline(read_run(field), net)
    print("end", status())


if __name__ == "__main__":
    main()
