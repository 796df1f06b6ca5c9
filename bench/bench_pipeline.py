"""Pipeline throughput: a one-hour run through ``run_pipeline`` (file reading excluded).

    .venv/bin/python bench/bench_pipeline.py [--hours 1]

Simulates a run of the requested length on a synthetic double-track line, loads its
streams, then times the pipeline (best of 3) and prints the real-time factor (target
≥ 5,000×: one hour in ≤ 0.72 s) and the ratio against a straightforward per-sample Python
implementation of the same front end (IMU cycle means, pulse speed, 3 s moving averages,
slip detection and dead reckoning), timed on a ten-minute slice and scaled.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections import deque
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import Projector
from dbtools.sources import write_source_set
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.units import kmh_s_to_mps2, metres_per_pulse


def naive(
    imu: list[tuple[float, ...]],
    tacho: list[tuple[float, int]],
    gps: list[tuple[float, float, float]],
    grid: np.ndarray,
    d_wheel: float,
    teeth: int,
) -> list[dict[str, float]]:
    """Per-sample Python: a first, straightforward implementation of the same work —
    IMU cycle means of six channels, pulse speed and acceleration, 300 ms delay, 3 s moving
    averages, jerks, slip detection, κ = ωz/v smoothed over 1 s, dead reckoning with a
    2 % margin, one output row per cycle, and each GPS fix projected onto the grid
    segment by segment near its nearest point."""
    ta = kmh_s_to_mps2(1.23)
    k_pulse = metres_per_pulse(d_wheel, teeth)
    win_ax: deque[float] = deque()
    win_ap: deque[float] = deque()
    win_k: deque[float] = deque()
    delay: deque[float] = deque([0.0, 0.0, 0.0])
    j = g = 0
    km = margin = 0.0
    prev_d = prev_v = prev_ax = prev_ap = 0.0
    rows = []
    for t, pulses in tacho:
        sums = [0.0] * 6
        n = 0
        while j < len(imu) and imu[j][0] <= t:
            for c in range(6):
                sums[c] += imu[j][c + 1]
            n += 1
            j += 1
        means = [x / n if n else 0.0 for x in sums]
        d = pulses * k_pulse
        v = (d - prev_d) / 0.1
        ap = (v - prev_v) / 0.1
        prev_d, prev_v = d, v
        delay.append(ap)
        ap = delay.popleft()
        win_ax.append(means[0])
        win_ap.append(ap)
        if len(win_ax) > 30:
            win_ax.popleft()
            win_ap.popleft()
        ax_avg = sum(win_ax) / len(win_ax)
        ap_avg = sum(win_ap) / len(win_ap)
        ji, jp = ax_avg - prev_ax, ap_avg - prev_ap
        prev_ax, prev_ap = ax_avg, ap_avg
        slipping = abs(ax_avg - ap_avg) > ta
        win_k.append(means[5] / v if v > 0.5 else 0.0)
        if len(win_k) > 10:
            win_k.popleft()
        kappa = sum(win_k) / len(win_k)
        km += v * 0.1
        margin += 0.02 * v * 0.1
        while g < len(gps) and gps[g][0] <= t:  # map-match the fixes of this cycle
            _, x, y = gps[g]
            i = int(np.argmin((grid[:, 0] - x) ** 2 + (grid[:, 1] - y) ** 2))
            best = np.inf
            for a in range(max(i - 1, 0), min(i + 1, len(grid) - 1)):
                dx, dy = grid[a + 1, 0] - grid[a, 0], grid[a + 1, 1] - grid[a, 1]
                u = min(max(((x - grid[a, 0]) * dx + (y - grid[a, 1]) * dy) / (dx * dx + dy * dy), 0.0), 1.0)
                best = min(best, float(np.hypot(grid[a, 0] + u * dx - x, grid[a, 1] + u * dy - y)))
            g += 1
        rows.append(
            {
                "t": t,
                "km_m": km,
                "speed_mps": v,
                "margin_m": margin,
                "kappa": kappa,
                "slipping": slipping,
                "ji": ji,
                "jp": jp,
            }
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmpd:
        tmp = Path(tmpd)
        length = 110_000.0 * args.hours
        net = build_network([demo_line(length_m=length)], Projector(9))
        write_source_set(net, tmp / "src")
        build_db(tmp / "src", tmp / "net.sqlite")
        net = read_network(tmp / "net.sqlite")
        streams, meta = simulate_run(
            net, scenario_from_dict({"route": {"track": "D"}, "slip": {"slips": 10, "slides": 10}}), seed=3
        )
        write_run(tmp / "run", meta, streams)
        run = read_run(tmp / "run")
        for name in ("tacho", "imu", "balise", "gps", "cab"):
            run.stream(name)  # file reading excluded from the timing
        run._streams.pop("truth", None)
        run.folder = tmp / "run"
        (tmp / "run" / "truth.parquet").unlink()
        best = float("inf")
        for _ in range(3):
            t0 = time.perf_counter()
            res = run_pipeline(run, net)
            best = min(best, time.perf_counter() - t0)
        duration = res.summary["duration_s"]
        imu = run.stream("imu")
        tacho = run.stream("tacho")
        ten = tacho["t"] <= 600.0
        cols = ["t", "ax", "ay", "az", "wx", "wy", "wz"]
        imu_rows = list(imu.loc[imu["t"] <= 600.0, cols].itertuples(index=False, name=None))
        tacho_rows = list(tacho.loc[ten, ["t", "pulses"]].itertuples(index=False, name=None))
        gis = net.gis[(net.gis["track"] == "D")]
        proj = Projector(9)
        gx, gy = proj.to_xy(gis["lon"].to_numpy(), gis["lat"].to_numpy())
        fixes = run.stream("gps")
        fixes = fixes[(fixes["t"] <= 600.0) & fixes["lat"].notna()]
        fx, fy = proj.to_xy(fixes["lon"].to_numpy(), fixes["lat"].to_numpy())
        gps_rows = list(zip(fixes["t"].to_numpy(), fx, fy, strict=True))
        t0 = time.perf_counter()
        naive(imu_rows, tacho_rows, gps_rows, np.column_stack([gx, gy]), meta.wheel_diameter_m, meta.teeth)
        naive_s = (time.perf_counter() - t0) * duration / 600.0
        per_hour = best * 3600.0 / duration
        print(
            f"run: {duration / 3600:.2f} h, {len(imu):,} IMU rows, {len(tacho):,} cycles, "
            f"{res.summary['n_corrections']} corrections, {res.summary['n_slips']} slips"
        )
        print(
            f"pipeline: {best:.3f} s → {per_hour:.3f} s per hour of log = {duration / best:,.0f}× real time "
            f"(target ≥ 5,000×, i.e. ≤ 0.72 s per hour)"
        )
        print(
            f"naive per-sample Python (cycle means, averages, detection, κ, dead reckoning, GPS matching): "
            f"{naive_s:.2f} s → ours is {naive_s / best:.1f}× faster"
        )
        print(f"load average: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
