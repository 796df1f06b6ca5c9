"""Noise of the clock-offset estimates on clean simulated runs (issue 15).

    .venv/bin/python bench/clock_noise.py [--runs 300] [--workers 2] [--imu-shift 0.0]

The runs of ``bench/accuracy.py`` (same scenarios and seeds 1000 + i; the simulator has no
clock offsets). For each run :func:`fieldlogs.quality.clocks.clock_offsets` on the simulated
streams, the IMU's t moved by ``--imu-shift`` seconds (late > 0); prints per stream the
offset's mean, σ, largest |offset| (all, and among the determined), the determined count and
the count beyond the tolerance (clean runs: target 0).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from accuracy import scenario

from dbtools.build import build_db
from dbtools.database import read_network
from fieldlogs.pipeline.config import ClockConfig
from fieldlogs.quality.clocks import clock_offsets
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run


def one(args: tuple[int, str, float]) -> list[dict[str, Any]]:
    i, db, shift = args
    net = read_network(Path(db))
    streams, meta = simulate_run(net, scenario_from_dict(scenario(i, net)), seed=1000 + i)
    imu = streams.get("imu")
    if imu is not None and shift:
        streams = {**streams, "imu": imu.assign(t=imu["t"] + shift)}
    offsets = clock_offsets(streams, meta.wheel_diameter_m, meta.teeth, ClockConfig())
    return [
        {
            "i": i,
            "stream": o.stream,
            "offset": o.offset_s,
            "sigma": o.sigma_s,
            "det": o.determined,
            "beyond": o.beyond_tolerance,
        }
        for o in offsets
    ]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=300)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--imu-shift", type=float, default=0.0)
    args = ap.parse_args()
    from dbtools.sample_network import sample_source_dir

    with tempfile.TemporaryDirectory() as tmpd:
        db = Path(tmpd) / "sample.sqlite"
        build_db(sample_source_dir(), db, db_version="clock-noise")
        with ProcessPoolExecutor(args.workers) as pool:
            rows = [r for res in pool.map(one, [(i, str(db), args.imu_shift) for i in range(args.runs)]) for r in res]
    print(f"clock offsets on {args.runs} simulated runs (IMU moved {args.imu_shift:+.2f} s)")
    for stream in ("imu", "gps"):
        rs = [r for r in rows if r["stream"] == stream]
        if not rs:
            print(f"  {stream}: no estimate")
            continue
        off = np.array([r["offset"] for r in rs]) - (args.imu_shift if stream == "imu" else 0.0)
        det = np.array([r["det"] for r in rs])
        big = float(np.abs(off[det]).max()) if det.any() else float("nan")
        print(
            f"  {stream}: n {off.size}, error mean {off.mean():+.3f} s, σ {off.std():.3f} s, "
            f"max |error| {np.abs(off).max():.3f} s (determined: {int(det.sum())}, max |error| {big:.3f} s, "
            f"σ {off[det].std():.3f} s), beyond tolerance {sum(r['beyond'] for r in rs)}"
        )


if __name__ == "__main__":
    main()
