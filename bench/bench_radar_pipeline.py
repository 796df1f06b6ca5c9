"""What the radar [S004] adds to the positioning pipeline over pulses + IMU (issue 18, phase 2).

    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_radar_pipeline.py [--runs 30] [--workers 2]
        [--cache DIR] [--set odometry_key=value ...]

Simulates short runs (about 4 minutes: from a station stop to the next station, a dwell,
and on) on the bundled sample network with the radar's raw IF samples (``sensors.radar_if``)
and two slips and two slides of 2–18 s each (every 5th run slip-free), then replays each run
through ``run_pipeline`` twice — with its ``radar_if`` and with the stream left out — and
prints both on the same runs: slip/slide detection, distance error over corrected episodes
(as ``bench/accuracy.py`` measures it), fail-safe count (and how many of the injected
episodes shorter than 20 s ended in one), margin percentiles, coverage |error| ≤ margin,
the speed error below 10 km/h and the wheel calibration against the simulated wear.

IF simulation costs about 0.2 s per simulated second: ``--cache DIR`` keeps the simulated
run folders (delete it after changing the simulator).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

#: Injected slips/slides shorter than this must not end in a fail-safe with the radar [s].
SHORT_S = 20.0


def _stops(network: Network, track: str) -> list[float]:
    """Station stop points of the simulator on ``track`` (I1 + 250 m in the running direction)."""
    b = network.balises
    i1 = b[(b["kind"] == "I1") & (b["track"] == track)].drop_duplicates("station_code")
    sign = 1.0 if track == "D" else -1.0
    return sorted(float(k) + sign * 250.0 for k in i1["km_actual_m"])


def scenario(i: int, network: Network, short_m: float | None = None) -> dict[str, Any]:
    """Run ``i``: from 15 m past a station stop to 1.2–1.6 km past the next one (a dwell of
    20 s between), 60–95 km/h, tracks alternating, cab R in half the runs, the radar looking
    toward R in every 8th; two slips and two slides of 2–18 s (none every 5th run).
    ``short_m``: the run ends this far past its start instead (a smoke run of the script)."""
    rng = np.random.default_rng(9000 + i)
    track = "D" if i % 2 == 0 else "U"
    sign = 1.0 if track == "D" else -1.0
    stops = _stops(network, track)
    if track == "U":
        stops = stops[::-1]
    k = int(rng.integers(0, len(stops) - 2))
    start = stops[k] + sign * 15.0
    end = stops[k + 1] + sign * float(rng.uniform(1200.0, 1600.0))
    if short_m is not None:
        end = start + sign * short_m
    slips: dict[str, Any] = (
        {"slips": 0, "slides": 0, "on_grade_curve": False}
        if i % 5 == 4
        else {"slips": 2, "slides": 2, "duration_s": [2.0, 18.0], "on_grade_curve": True}
    )
    return {
        "name": f"radar-pipeline-{i}",
        "run": {"run_id": f"RADAR-PIPE-{i:03d}"},
        "route": {"track": track, "path_km_m": [start, end], "start_cab": "R" if i % 4 >= 2 else "F"},
        "running": {
            "line_speed_kmh": float(rng.uniform(60.0, 95.0)),
            "dwell_s": 20.0,
            "standstill_start_s": 10.0,
            "standstill_end_s": 8.0,
        },
        "slip": slips,
        "sensors": {"radar_if": True},
        "radar_if": {"snr_db": float(rng.uniform(25.0, 35.0)), "looks_toward": "R" if i % 8 == 7 else "F"},
    }


def simulate(i: int, db: str, folder: Path, short_m: float | None = None) -> Path:
    """The run folder of run ``i`` (seed 9500 + i), simulated unless it exists."""
    if (folder / "run.json").exists():
        return folder
    net = read_network(Path(db))
    sc = scenario_from_dict(scenario(i, net, short_m), f"radar-pipeline-{i}")
    streams, meta = simulate_run(net, sc, seed=9500 + i)
    return write_run(folder, meta, streams, force=True)


def without_radar(folder: Path, out: Path) -> Path:
    """A copy of the run folder without its radar streams (files linked, not copied)."""
    if out.exists():
        shutil.rmtree(out)
    out.mkdir(parents=True)
    for f in folder.iterdir():
        if not f.name.startswith("radar"):
            (out / f.name).symlink_to(f.resolve())
    return out


def _true_cycle_speed(truth: pd.DataFrame, t_cyc: np.ndarray) -> np.ndarray:
    """True mean speed over each cycle (t_{k−1}, t_k] from the 10 Hz truth (trapezoid)."""
    tt = truth["t"].to_numpy(dtype=float)
    v = np.abs(truth["speed_mps"].to_numpy(dtype=float))
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(tt))])
    out: np.ndarray = np.diff(np.interp(t_cyc, tt, s), prepend=np.nan) / np.diff(t_cyc, prepend=np.nan)
    return out


def evaluate(folder: Path, db: str, cfg: Any) -> dict[str, Any]:
    """One replay of a run folder: the figures of the table."""
    from accuracy import metrics

    from fieldlogs.pipeline.run import run_pipeline

    net = read_network(Path(db))
    run = read_run(folder)
    t0 = time.perf_counter()
    res = run_pipeline(run, net, cfg)
    elapsed = time.perf_counter() - t0
    assert run.meta is not None
    st = run.meta.extra["sim_truth"]
    truth = run.stream("truth")
    assert truth is not None
    m = metrics(res, truth, json.loads(json.dumps(st)))
    detected = res.odometry.episodes
    short_fs = 0
    for e in st["slip_episodes"]:
        hit = [d for d in detected if d.t_end >= e["t0"] - 1.0 and d.t_start <= e["t1"] + 3.0]
        short_fs += int(e["t1"] - e["t0"] < SHORT_S and any(d.failsafe for d in hit))
    pos = res.positions
    claimed = pos["state"] != "undetermined"
    t_cyc = pos["t"].to_numpy(dtype=float)
    v_true = _true_cycle_speed(truth, t_cyc)
    slow = (v_true < 10.0 / 3.6) & np.isfinite(v_true) & ~res.odometry.slipping
    cal = res.summary.get("wheel_calibration")
    return {
        **m,
        "short_failsafe": short_fs,
        "short_injected": sum(1 for e in st["slip_episodes"] if e["t1"] - e["t0"] < SHORT_S),
        "margin": pos.loc[claimed, "margin_m"].to_numpy(dtype=float).tolist(),
        "slow_err": (res.odometry.v[slow] - v_true[slow]).tolist(),
        "cal_ratio": None if cal is None else cal["ratio"],
        "cal_half": None if cal is None else 0.5 * (cal["ratio_ci95"][1] - cal["ratio_ci95"][0]),
        "true_ratio": st["wheel_diameter_true_m"] / run.meta.wheel_diameter_m,
        "criteria": [d.criterion for d in detected],
        "sources": [d.speed_source for d in detected],
        "elapsed": elapsed,
    }


def one(args: tuple[int, str, str, dict[str, Any], float | None]) -> tuple[int, dict[str, Any], dict[str, Any]]:
    from fieldlogs.pipeline.config import PipelineConfig

    i, db, root, over, short_m = args
    cfg = PipelineConfig.from_dict({"odometry": over}) if over else PipelineConfig()
    folder = simulate(i, db, Path(root) / f"run{i:03d}", short_m)
    with tempfile.TemporaryDirectory() as tmp:
        plain = without_radar(folder, Path(tmp) / "plain")
        return i, evaluate(folder, db, cfg), evaluate(plain, db, cfg)


def _pct(x: np.ndarray, q: float) -> float:
    return float(np.percentile(x, q)) if x.size else float("nan")


def table(results: list[dict[str, Any]]) -> list[tuple[str, str]]:
    """The rows of one column (with or without radar)."""
    m = results
    slip_err = np.array([e for x in m for e in x["slip_err_pct"]])
    margin = np.array([v for x in m for v in x["margin"]])
    slow = np.array([v for x in m for v in x["slow_err"]])
    claimed = sum(x["claimed"] for x in m)
    within = sum(x["within"] for x in m)
    free = [x for x in m if x["injected"] == 0]
    crit: dict[str, int] = {}
    for x in m:
        for c in x["criteria"]:
            crit[c] = crit.get(c, 0) + 1
    cal = [(x["cal_ratio"] - x["true_ratio"], x["cal_half"]) for x in m if x["cal_ratio"] is not None]
    cal_err = np.abs(np.array([c for c, _ in cal]))
    cal_in = sum(1 for c, h in cal if abs(c) <= h)
    rows = [
        ("slip/slide episodes detected", f"{sum(x['matched'] for x in m)}/{sum(x['injected'] for x in m)}"),
        ("  by criterion", ", ".join(f"{k} {v}" for k, v in sorted(crit.items()))),
        ("detections on slip-free runs", f"{sum(x['false_det'] for x in free)} in {len(free)} runs"),
        ("false detections, all runs", f"{sum(x['false_det'] for x in m)}"),
        (
            "distance error over corrected episodes",
            f"mean {slip_err.mean():+.3f} %, median |err| {np.median(np.abs(slip_err)):.3f} %, "
            f"|err| p95 {_pct(np.abs(slip_err), 95):.3f} %, max {np.abs(slip_err).max():.3f} %, "
            f"{100 * (np.abs(slip_err) <= 0.5).mean():.1f} % within ±0.5 % (n={slip_err.size})"
            if slip_err.size
            else "n/a",
        ),
        ("fail-safe events", f"{sum(x['failsafe'] for x in m)}"),
        (
            f"episodes < {SHORT_S:.0f} s ending in a fail-safe",
            f"{sum(x['short_failsafe'] for x in m)} of {sum(x['short_injected'] for x in m)}",
        ),
        (
            "margin on claimed cycles",
            f"p50 {_pct(margin, 50):.1f} m, p95 {_pct(margin, 95):.1f} m, max {margin.max():.1f} m"
            if margin.size
            else "n/a",
        ),
        ("|km error| ≤ margin", f"{100 * within / max(claimed, 1):.3f} % of {claimed} cycles"),
        ("max |km error|", f"{max(x['max_abs_err'] for x in m):.2f} m"),
        (
            "speed error below 10 km/h (not slipping)",
            f"RMS {np.sqrt(np.mean(slow**2)):.3f} m/s, p95 |err| {_pct(np.abs(slow), 95):.3f} m/s (n={slow.size})"
            if slow.size
            else "n/a",
        ),
        (
            "wheel calibration − true D/D_nom",
            f"|err| median {1e2 * np.median(cal_err):.4f} %, max {1e2 * cal_err.max():.4f} %, "
            f"inside its 95 % interval {cal_in}/{len(cal)}"
            if cal
            else "n/a",
        ),
        ("pipeline time per run", f"{np.mean([x['elapsed'] for x in m]):.2f} s"),
    ]
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=30)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--cache", type=Path, default=None, help="keep the simulated run folders here")
    ap.add_argument("--set", action="append", default=[], help="odometry override, e.g. --set ground_detect_z=5")
    ap.add_argument(
        "--short-m", type=float, default=None, help="end each run this far past its start [m] (a smoke run)"
    )
    args = ap.parse_args()
    over = {k: json.loads(v) for k, v in (a.split("=", 1) for a in args.set)}
    from dbtools.sample_network import sample_source_dir

    with tempfile.TemporaryDirectory() as tmpd:
        root = args.cache or Path(tmpd)
        root.mkdir(parents=True, exist_ok=True)
        db = root / "sample.sqlite"
        if not db.exists():
            build_db(sample_source_dir(), db, db_version="sample-1")
        t0 = time.perf_counter()
        todo = [(i, str(db), str(root), over, args.short_m) for i in range(args.first, args.first + args.runs)]
        with ProcessPoolExecutor(args.workers) as pool:
            out = sorted(pool.map(one, todo))
        wall = time.perf_counter() - t0
    with_r, without = table([r for _, r, _ in out]), table([p for _, _, p in out])
    print(f"radar in the pipeline: {args.runs} simulated runs with radar_if ({wall:.0f} s wall)")
    w = max(len(a) for a, _ in with_r)
    for (a, b), (_, c) in zip(with_r, without, strict=True):
        print(f"  {a:<{w}}  with radar:    {b}")
        print(f"  {'':<{w}}  pulses + IMU:  {c}")


if __name__ == "__main__":
    main()
