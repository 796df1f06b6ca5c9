"""Per-episode study of the slip/slide odometry against simulator truth (issue 4).

    .venv/bin/python bench/slip_study.py [--runs 50] [--first 0] [--workers 2]
        [--show all|bad|missed|false|none] [--set odometry_key=value ...]

Simulates the runs of ``bench/accuracy.py`` (same scenarios and seeds; the cycle arrays,
the truth stream and the true travel-frame pitch are cached in ``$TMPDIR/slip_study_cache``
— delete it after changing the simulator), runs only ``correct_odometry`` on them (with
``--set`` overrides of ``[odometry]``) and prints one line per injected episode:

* ``[n ep]`` detections matched (as ``bench/accuracy.py`` matches them), the criterion of
  the first (``ta``, ``residual``, ``residual-end``) and its delay after the slip's onset;
* ``start`` / ``end``: the correction's start relative to the onset t0 and its end relative
  to the slip's end t1 (``!`` no jerk-quiet start point found); ``FS`` fail-safe, ``RE``
  re-opened;
* ``θ0 err``: θ0 minus the true pitch (it legitimately contains the accelerometer bias/G);
* ``ev0`` / ``ev1``: corrected speed minus the true cycle-mean speed at the first and last
  cycle of the correction, ``T`` its length;
* ``δ`` / ``upd``: inertial minus pulse speed (1 s means) at re-adhesion, and the distance the
  re-adhesion speed update moved (``--set readhesion_speed_update=false`` turns it off);
* ``err``: the distance error over the correction exactly as ``bench/accuracy.py`` computes
  it (only episodes corrected and re-adhered in one piece).

then the odometry-only summary lines of ``bench/accuracy.py`` (recall, false detections,
distance error) and the fail-safe count. ``--show bad`` lists episodes beyond ±2 %, false
detections and misses.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from accuracy import _truth_dist, scenario  # type: ignore[import-not-found]

from dbtools.build import build_db
from dbtools.database import read_network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import build_cycles
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from fieldlogs.simulate.track import TrackGeometry

CACHE = Path(tempfile.gettempdir()) / "slip_study_cache"


def _simulate(args: tuple[int, str]) -> Path:
    i, db = args
    out = CACHE / f"run{i:03d}.pkl"
    if out.exists():
        return out
    net = read_network(Path(db))
    sc = scenario_from_dict(scenario(i, net))
    streams, meta = simulate_run(net, sc, seed=1000 + i)
    with tempfile.TemporaryDirectory() as tmp:
        write_run(Path(tmp) / "run", meta, streams, force=True)
        run = read_run(Path(tmp) / "run")
        s = {n: run.stream(n) for n in ("tacho", "imu", "cab", "truth")}
    tacho, truth = s["tacho"], s["truth"]
    assert run.meta is not None and tacho is not None and truth is not None
    cycles = build_cycles(
        tacho=tacho,
        imu=s["imu"],
        cab=s["cab"],
        wheel_diameter_m=run.meta.wheel_diameter_m,
        teeth=run.meta.teeth,
        t_end=float(tacho["t"].iloc[-1]),
    )
    st = meta.extra["sim_truth"]
    # true travel-frame pitch (the grade climbed in the direction of travel)
    path = sc.route.path_km_m
    geom = TrackGeometry.from_network(net, st["line_code"], st["track"], (min(path), max(path)))
    km = truth["km_m"].to_numpy(dtype=float)
    ok = np.isfinite(km)
    th = np.full(km.size, np.nan)
    th[ok] = geom.state(km[ok]).theta
    dkm = np.gradient(np.where(ok, km, np.nan))
    th_travel = th * np.sign(np.where(np.abs(dkm) > 1e-6, dkm, np.nan))
    with out.open("wb") as f:
        pickle.dump({"cycles": cycles, "truth": truth, "st": st, "pitch": th_travel}, f)
    return out


def load(runs: range, workers: int) -> list[dict[str, Any]]:
    CACHE.mkdir(exist_ok=True)
    todo = [i for i in runs if not (CACHE / f"run{i:03d}.pkl").exists()]
    if todo:
        from dbtools.sample_network import sample_source_dir

        db = CACHE / "sample.sqlite"
        if not db.exists():
            build_db(sample_source_dir(), db)
        with ProcessPoolExecutor(workers) as pool:
            list(pool.map(_simulate, [(i, str(db)) for i in todo]))
    out = []
    for i in runs:
        with (CACHE / f"run{i:03d}.pkl").open("rb") as f:
            out.append({"i": i, **pickle.load(f)})
    return out


def study(r: dict[str, Any], cfg: PipelineConfig, show: str) -> dict[str, Any]:
    cycles, truth, st, pitch = r["cycles"], r["truth"], r["st"], r["pitch"]
    odo = correct_odometry(cycles, cfg.odometry)
    t_truth = truth["t"].to_numpy()
    v_truth = np.abs(truth["speed_mps"].to_numpy())
    t_cyc = cycles.t
    injected = st["slip_episodes"]
    detected = odo.episodes
    diag = odo.diagnostics.episodes if odo.diagnostics is not None else ()
    internals = {id(d): x for d, x in zip(detected, diag, strict=True)}
    lines, errs, missed, matched = [], [], [], 0
    for e in injected:
        hit = [d for d in detected if d.t_end >= e["t0"] - 1.0 and d.t_start <= e["t1"] + 3.0]
        v = float(v_truth[min(np.searchsorted(t_truth, e["t0"]), len(t_truth) - 1)])
        head = (
            f"run {r['i']:3d} {e['kind']:5s} t {e['t0']:7.1f}–{e['t1']:7.1f} ({e['t1'] - e['t0']:4.1f} s) "
            f"depth {e['depth']:.2f} v {v:4.1f}"
        )
        if not hit:
            missed.append(e)
            if show in ("all", "missed", "bad"):
                lines.append(f"{head}  MISSED")
            continue
        matched += 1
        d = hit[0]
        after_failsafe = any(f.failsafe and 0.0 <= d.t_start - f.t_end <= 10.0 for f in detected)
        k0 = min(np.searchsorted(t_truth, d.t_start), len(t_truth) - 1)
        th_true = float(pitch[k0])
        dg = internals[id(d)]
        info = (
            f"  [{len(hit)} ep] det {d.criterion:5s} {d.t_detect - e['t0']:+5.1f} s "
            f"start {d.t_start - e['t0']:+5.1f}{'' if d.start_found else '!'} "
            f"end {d.t_end - e['t1']:+5.1f} s  θ0 err {1000 * (d.theta0_rad - th_true):+5.1f} mrad "
            f"(θ {1000 * th_true:+5.1f}) {'FS' if d.failsafe else ''}{'RE' if dg.redetect_t else ''}"
        )
        # speed error of the correction at its start and end vs the true cycle-mean speed
        s_true = np.concatenate([[0.0], np.cumsum(0.5 * (v_truth[1:] + v_truth[:-1]) * np.diff(t_truth))])
        vt = np.diff(np.interp(t_cyc, t_truth, s_true), prepend=0.0) / 0.1
        ev0, ev1 = odo.v[d.i_start + 1] - vt[d.i_start + 1], odo.v[d.i_end] - vt[d.i_end]
        info += f" ev0 {ev0:+.2f} ev1 {ev1:+.2f} m/s T {d.t_end - d.t_start:4.1f}"
        if dg.end_speed_error_mps is not None:
            info += f" δ {dg.end_speed_error_mps:+.2f} m/s upd {d.speed_update_m:+.2f} m"
        err = None
        if not (d.failsafe or not d.readhered or len(hit) > 1 or after_failsafe):
            true_m = _truth_dist(truth, d.t_start, d.t_end)
            corr_m = float(np.interp(d.t_end, t_cyc, odo.d) - np.interp(d.t_start, t_cyc, odo.d))
            if true_m > 5.0:
                err = 100.0 * (corr_m - true_m) / true_m
                errs.append(err)
                info += f"  err {err:+6.2f} % of {true_m:6.1f} m ({corr_m - true_m:+.2f} m)"
        bad = err is not None and abs(err) > 2.0
        if show == "all" or (show == "bad" and bad):
            lines.append(head + info)
    false = [d for d in detected if not any(d.t_end >= e["t0"] - 1.0 and d.t_start <= e["t1"] + 3.0 for e in injected)]
    for d in false:
        if show in ("all", "false", "bad"):
            lines.append(
                f"run {r['i']:3d} FALSE {d.kind} t {d.t_start:.1f}–{d.t_end:.1f} det {d.t_detect:.1f} "
                f"crit {d.criterion} v {internals[id(d)].v_pulse_at_detect_mps:.1f}"
            )
    return {
        "lines": lines,
        "errs": errs,
        "missed": missed,
        "matched": matched,
        "injected": len(injected),
        "false": len(false),
        "free": not injected,
        "failsafe": sum(1 for d in detected if d.failsafe),
    }


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--show", default="bad", choices=["all", "bad", "missed", "false", "none"])
    ap.add_argument("--set", action="append", default=[], help="odometry override, e.g. --set pulse_delay_cycles=0")
    args = ap.parse_args()
    data = load(range(args.first, args.first + args.runs), args.workers)
    over = {k: json.loads(v) for k, v in (a.split("=", 1) for a in args.set)}
    cfg = PipelineConfig.from_dict({"odometry": over}) if over else PipelineConfig()
    t0 = time.perf_counter()
    res = [study(r, cfg, args.show) for r in data]
    el = time.perf_counter() - t0
    for x in res:
        for line in x["lines"]:
            print(line)
    errs = np.array([e for x in res for e in x["errs"]])
    inj = sum(x["injected"] for x in res)
    mat = sum(x["matched"] for x in res)
    print(f"detected {mat}/{inj} = {100 * mat / max(inj, 1):.1f} %")
    free = sum(x["false"] for x in res if x["free"])
    print(f"false detections: slip-free runs {free}, all {sum(x['false'] for x in res)}")
    if errs.size:
        print(
            f"distance error mean {errs.mean():+.2f} %, median |err| {np.median(np.abs(errs)):.2f} %, "
            f"{100 * (np.abs(errs) <= 2).mean():.0f} % within ±2 %, p95 {np.percentile(np.abs(errs), 95):.2f} %, "
            f"max {np.abs(errs).max():.2f} % (n={errs.size})"
        )
    print(f"fail-safe episodes {sum(x['failsafe'] for x in res)}; odometry time {el:.2f} s")


if __name__ == "__main__":
    main()
