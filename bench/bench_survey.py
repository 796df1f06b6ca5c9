"""Accuracy and throughput of ``trainpos survey`` against simulated truth (issue 19).

Run on demand (prints a table, never pass/fail)::

    .venv/bin/python bench/bench_survey.py                         # 2 lines × 25 km, 8 runs per track
    .venv/bin/python bench/bench_survey.py --lines 1 --length-km 12 --runs 4
    .venv/bin/python bench/bench_survey.py --sensors radar --wheels-only --keep DIR   # runs with a radar
    .venv/bin/python bench/bench_survey.py --sensors gnss --lines 1 --runs 6 --wheels-only --keep DIR
    .venv/bin/python bench/bench_survey.py --wheels-only --keep DIR --replicate 8    # + throughput of 8 copies

How the errors are made. A synthetic network (``--lines`` double-track lines of
``--length-km``, stations every 3 km with initial pairs and home/block C balises,
:mod:`fieldlogs.simulate.networks`) is the *truth*; ``--runs`` runs per track are simulated on it
(:mod:`fieldlogs.simulate`, default scenario: slips and slides, D-GPS, wheel wear) by four
vehicles whose true wheel diameter wears a little from run to run (run.json ``sim_truth``).
The *surveyed* DB — the one the survey checks — then has, per track: two C balises moved
by 2–5 m (random sign), one C balise removed (the runs still read it: a candidate), one
curve's six rows removed (a new curve to propose) and one curve moved by 30 m; and per
line ``--unpowered`` balises (I1, I2 and C) are kept in the DB but their telegrams taken
out of every run (unpowered balises). Every other balise and curve is clean.

``--sensors`` adds a ready ``radar`` stream or raw GNSS (``gnss_obs``/``gnss_nav``) to every
run (the D-GPS stays); ``--keep DIR`` keeps the simulated runs and reuses them.

Reported against the issue's targets: moved balises flagged and their residual within
±0.5 m; missed balises found, and false "missed"; removed curves proposed within ±10 m
(exit lower-limit crossing) and ±10 % radius; wheel diameters per vehicle within ±0.1 %
of the runs' mean true diameter (and per run), per source (balise, radar, GNSS) and
combined, from all of a vehicle's runs and from its first three, with how often each
run's 95 % interval holds the truth, the runs' median 95 % half-width, how often each
vehicle's pooled interval holds its runs' mean truth, and how many runs and vehicles the
consistency check flags; false "moved" balises and features on the clean items of the surveyed DB, and
everywhere when the truth DB itself is surveyed (per 100 track-km). Throughput: the survey
(replay + aggregation) in run-hours per minute with ``--workers`` processes, extrapolated
to 1,000 run-hours, beside ``gis verify`` alone on the same runs (the replay they share);
``--replicate K`` times a survey of the runs hard-linked K times (with the machine's
2-process ceiling of ``bench_audit.py``), where the fixed costs (start-up, fork server,
aggregation imports) weigh less.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import Projector
from dbtools.network import Network
from dbtools.sources import write_source_set
from fieldlogs.gisverify.evidence import verify_runs
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.networks.synthetic import LineSpec, Station, build_network, random_alignment
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from fieldlogs.survey.features import db_features
from fieldlogs.survey.result import SurveyReport
from fieldlogs.survey.runner import survey
from fieldlogs.survey.wheels import SOURCES, vehicle_wheels

PROJECTOR = Projector(9)
KM0 = 1000.0
VEHICLES = 4
WEAR0_PCT = (0.05, 0.15, 0.30, 0.45)
WEAR_STEP_PCT = 0.005


def make_network(n_lines: int, length_m: float, seed: int) -> Network:
    rng = np.random.default_rng(seed)
    specs = []
    for i in range(n_lines):
        a = random_alignment(rng, length_m, km0=KM0, x0=i * 30_000.0, y0=0.0)
        n_st = int((length_m - 1000) // 3000) + 1
        stations = [Station(f"{j + 1:02d}", f"S{j + 1}", KM0 + 500.0 + j * 3000.0) for j in range(n_st)]
        specs.append(LineSpec(f"{i + 1:04d}", f"Bench line {i + 1}", a, stations))
    return build_network(specs, PROJECTOR)


def build(net: Network, root: Path, name: str) -> Path:
    src = write_source_set(net, root / f"src-{name}", force=True)
    db = root / f"{name}.sqlite"
    build_db(src, db, db_version=name, force=True)
    return db


def _telegram_balise(streams: dict[str, pd.DataFrame], balises: pd.DataFrame, line: str, track: str) -> np.ndarray:
    """The DB balise id of every telegram (truth km at its time, same kind, within 0.5 m)."""
    tel, truth = streams["balise"], streams["truth"]
    km = np.interp(
        tel["t"].to_numpy(dtype=float), truth["t"].to_numpy(dtype=float), truth["km_m"].to_numpy(dtype=float)
    )
    on = balises[(balises["line_code"] == line) & (balises["track"] == track)]
    out = np.full(len(tel), "", dtype=object)
    for j, (k, kind) in enumerate(zip(km, tel["kind"].astype(str), strict=True)):
        d = np.abs(on["km_actual_m"].to_numpy(dtype=float) - k)
        d[on["kind"].to_numpy() != kind] = np.inf
        if d.size and d.min() < 0.5:
            out[j] = on["balise_id"].iloc[int(np.argmin(d))]
    return out


#: Scenario overrides per ``--sensors`` case (the default scenario has D-GPS).
SENSORS: dict[str, dict[str, Any]] = {
    "dgps": {},
    "radar": {"sensors": {"radar": True}},
    "gnss": {"gnss_raw": {"enabled": True}},
}


def _simulate(job: tuple[str, str, str, int, int, str, list[str], str]) -> str:
    db, line, track, seed, k, folder, unpowered, sensors = job
    net = read_network(Path(db))
    vid = k % VEHICLES
    nth = k // VEHICLES
    wear = WEAR0_PCT[vid] + WEAR_STEP_PCT * nth
    day = pd.Timestamp("2026-01-15T09:00:00+09:00") + pd.Timedelta(days=nth, minutes=7 * k)
    sc = scenario_from_dict(
        {
            "route": {"line_code": line, "track": track},
            "run": {"run_id": f"S{line}{track}{seed}", "vehicle_id": f"EMU-{vid + 1}", "start_time": day.isoformat()},
            "running": {"standstill_start_s": 20.0 + float(np.random.default_rng(seed).uniform(0.0, 1.0))},
            "tacho": {"wear_pct": [wear, wear]},
            **SENSORS[sensors],
        }
    )
    sim = simulate_run(net, sc, seed=seed)
    streams = dict(sim.streams)
    ids = _telegram_balise(streams, net.balises, line, track)
    streams["balise"] = streams["balise"][~np.isin(ids, unpowered)].reset_index(drop=True)
    write_run(Path(folder), sim.meta, streams, force=True)
    return folder


def inject(truth: Network, rng: np.random.Generator, unpowered_per_line: int) -> tuple[Network, dict[str, Any]]:
    """The surveyed DB and what was done to it (module docstring)."""
    b = truth.balises.copy()
    fp = truth.feature_points.copy()
    moved: dict[str, float] = {}
    removed_b: list[str] = []
    removed_f: list[tuple[str, str, str]] = []
    moved_f: list[tuple[str, str, str]] = []
    unpowered: list[str] = []
    for (line, track), g in b.groupby(["line_code", "track"]):
        cs = g[g["kind"] == "C"]["balise_id"].to_numpy()
        pick = rng.choice(cs, size=3, replace=False)
        for bid in pick[:2]:
            moved[str(bid)] = float(rng.uniform(2.0, 5.0) * rng.choice([-1.0, 1.0]))
        removed_b.append(str(pick[2]))
        feats = fp[(fp["line_code"] == line) & (fp["track"] == track)]["feature_id"].unique()
        fsel = rng.choice(feats, size=2, replace=False)
        removed_f.append((str(line), str(track), str(fsel[0])))
        moved_f.append((str(line), str(track), str(fsel[1])))
    for _line, g in b.groupby("line_code"):
        free = g[~g["balise_id"].isin([*moved, *removed_b])]["balise_id"].to_numpy()
        unpowered += [str(x) for x in rng.choice(free, size=min(unpowered_per_line, free.size), replace=False)]
    for bid, dx in moved.items():
        m = b["balise_id"] == bid
        sign = np.where(b.loc[m, "track"] == "U", -1.0, 1.0)
        b.loc[m, "km_actual_m"] += dx
        b.loc[m, "km_equipment_m"] += dx
        b.loc[m, "dist_from_initial_m"] += sign * dx
    b = b[~b["balise_id"].isin(removed_b)]
    for line, track, fid in removed_f:
        fp = fp[~((fp["line_code"] == line) & (fp["track"] == track) & (fp["feature_id"] == fid))]
    for line, track, fid in moved_f:
        m = (fp["line_code"] == line) & (fp["track"] == track) & (fp["feature_id"] == fid)
        fp.loc[m, "km_m"] += 30.0
    tables = dict(truth.tables)
    tables["balises"], tables["feature_points"] = b, fp
    net = Network(tables, origin="surveyed", meta=dict(truth.meta))
    what = {"moved": moved, "removed_b": removed_b, "removed_f": removed_f, "moved_f": moved_f, "unpowered": unpowered}
    return net, what


def simulate_runs(
    db: Path, net: Network, runs: int, logs: Path, workers: int, seed: int, unpowered: list[str], sensors: str
) -> list[Path]:
    """The runs of the module docstring in ``logs`` (kept when ``logs`` already holds them all)."""
    jobs = []
    k = 0
    for li, line in enumerate(sorted(set(net.gis["line_code"]))):
        for ti, track in enumerate(("D", "U")):
            for r in range(runs):
                s = seed * 100_000 + li * 1000 + ti * 500 + r
                folder = str(logs / f"{line}-{track}-{r:03d}")
                jobs.append((str(db), str(line), track, s, k, folder, unpowered, sensors))
                k += 1
    if all((Path(j[5]) / "run.json").is_file() for j in jobs) and len(list(logs.iterdir())) == len(jobs):
        return [Path(j[5]) for j in jobs]
    with ProcessPoolExecutor(workers) as pool:
        return [Path(p) for p in pool.map(_simulate, jobs)]


def _wheel_truth(rep: SurveyReport) -> pd.DataFrame:
    import json

    rows = []
    for r in rep.runs.itertuples():
        st = json.loads((Path(r.folder) / "run.json").read_text())["sim_truth"]
        rows.append({"run_id": r.run_id, "vehicle_id": r.vehicle_id, "true_m": st["wheel_diameter_true_m"]})
    return pd.DataFrame(rows)


def _errors(d: pd.Series, true: pd.Series) -> float:
    """Largest |d / true − 1| [%] (NaN without an estimate)."""
    e = (d / true - 1).abs()
    return 100 * float(e.max()) if e.notna().any() else float("nan")


def _vehicle_coverage(wheels: pd.DataFrame, wr: pd.DataFrame, col: str, ci: str) -> str:
    """Vehicles whose pooled interval holds the mean true diameter of the runs used."""
    true = wr[wr[col].notna()].groupby("vehicle_id")["true_m"].mean().rename("true_m")
    v = wheels.merge(true, on="vehicle_id")
    v = v[v[col].notna()]
    return f"{int(((v[col] - v['true_m']).abs() <= v[ci]).sum())}/{len(v)}"


def wheel_sources(rep: SurveyReport, first_runs: int = 3) -> pd.DataFrame:
    """Per source (and combined): runs with an estimate, the largest per-run error, the share
    of runs whose 95 % interval holds the truth, and the largest per-vehicle error from all
    of a vehicle's runs and from its first ``first_runs`` runs (each against the mean true
    diameter of the runs used)."""
    wt = _wheel_truth(rep)
    wr = rep.wheel_runs.merge(wt, on=["run_id", "vehicle_id"])
    first = wr.sort_values("start_time", kind="stable").groupby("vehicle_id").head(first_runs)
    few = vehicle_wheels(first.drop(columns="true_m"), rep.config)
    rows = []
    for name, col, ci in [("combined", "diameter_m", "ci95_m")] + [
        (s, f"diameter_{s}_m", f"ci95_{s}_m") for s in SOURCES
    ]:
        has = wr[col].notna()
        covered = ((wr[col] - wr["true_m"]).abs() <= wr[ci])[has]
        per_veh = []
        for frame, runs_used in ((rep.wheels, wr), (few, first)):
            ok = runs_used[runs_used[col].notna()]
            true = ok.groupby("vehicle_id")["true_m"].mean().rename("true_m")
            v = frame.merge(true, on="vehicle_id")
            per_veh.append((_errors(v[col], v["true_m"]), int(v[col].notna().sum())))
        vcov = _vehicle_coverage(rep.wheels, wr, col, ci)
        rows.append(
            {
                "source": name,
                "runs": int(has.sum()),
                "run_max_pct": _errors(wr[col], wr["true_m"]),
                "covered": f"{int(covered.sum())}/{int(has.sum())}",
                "half_med_pct": 100 * float((wr[ci] / wr[col])[has].median()) if has.any() else float("nan"),
                "veh_covered": vcov,
                "vehicle_max_pct": per_veh[0][0],
                "vehicles": per_veh[0][1],
                f"vehicle_{first_runs}_runs_max_pct": per_veh[1][0],
                f"vehicles_{first_runs}_runs": per_veh[1][1],
            }
        )
    out = pd.DataFrame(rows)
    src = sorted({str(x) for x in wr["gnss_source"].dropna()} | {str(x) for x in wr["radar_source"].dropna()})
    out.attrs["note"] = (
        f"sources in the runs: {', '.join(src) or 'balises only'}; runs whose sources disagree: "
        f"{int((wr['consistent'] == False).sum())} of {int(wr['consistent'].notna().sum())}; "  # noqa: E712
        f"vehicles: {int((rep.wheels['consistent'] == False).sum())} of {len(rep.wheels)}; with {first_runs} "  # noqa: E712
        f"runs: {int((few['consistent'] == False).sum())}"  # noqa: E712
    )
    return out


def evaluate(rep: SurveyReport, truth: Network, what: dict[str, Any]) -> dict[str, Any]:
    """Every figure of the table (module docstring)."""
    b = rep.balises.set_index("balise_id")
    mv = pd.Series(what["moved"])
    flagged = b.loc[mv.index, "status"] == "moved"
    err = (b.loc[mv.index, "residual_m"] - mv).abs()
    up = what["unpowered"]
    missed = b.loc[up, "status"] == "missed"
    touched = set(mv.index) | set(up)
    clean = b[~b.index.isin(touched)]
    cands = rep.candidates
    tf = db_features(truth.feature_points).set_index(["line_code", "track", "feature_id"])
    f = rep.features
    new = f[f["status"] == "new"]
    prop_err = []
    for key in what["removed_f"]:
        t = tf.loc[key]
        on = new[(new["line_code"] == key[0]) & (new["track"] == key[1])]
        if not len(on):
            prop_err.append((np.inf, np.inf))
            continue
        j = int(np.argmin(np.abs(on["exit_km_m"].to_numpy(dtype=float) - t["exit_km_m"])))
        prop_err.append(
            (
                abs(float(on["exit_km_m"].iloc[j]) - t["exit_km_m"]),
                abs(float(on["radius_m"].iloc[j]) / t["radius_m"] - 1),
            )
        )
    pe = np.array(prop_err).reshape(-1, 2)
    mf = {tuple(k) for k in what["moved_f"]}
    f_db = f[f["feature_id"].notna()]
    fkeys = list(zip(f_db["line_code"], f_db["track"], f_db["feature_id"], strict=True))
    moved_f_found = sum(1 for k, s in zip(fkeys, f_db["status"], strict=True) if k in mf and s == "moved")
    false_f = sum(1 for k, s in zip(fkeys, f_db["status"], strict=True) if k not in mf and s == "moved")
    wt = _wheel_truth(rep)
    wr = rep.wheel_runs.merge(wt, on=["run_id", "vehicle_id"])
    run_err = (wr["diameter_m"] / wr["true_m"] - 1).abs()
    veh = rep.wheels.merge(wt.groupby("vehicle_id")["true_m"].mean().rename("true_m"), on="vehicle_id")
    veh_err = (veh["diameter_m"] / veh["true_m"] - 1).abs()
    return {
        "moved_total": len(mv),
        "moved_flagged": int(flagged.sum()),
        "moved_within": int((flagged & (err <= 0.5)).sum()),
        "moved_err_max": float(err.max()),
        "missed_total": len(up),
        "missed_found": int(missed.sum()),
        "false_missed": int((clean["status"] == "missed").sum()),
        "false_moved": int((clean["status"] == "moved").sum()),
        "clean_balises": len(clean),
        "clean_ok": int((clean["status"] == "ok").sum()),
        "cand_total": len(what["removed_b"]),
        "cand_found": int(cands["confirmed"].sum()) if len(cands) else 0,
        "new_total": len(what["removed_f"]),
        "new_within": int(((pe[:, 0] <= 10.0) & (pe[:, 1] <= 0.10)).sum()),
        "new_err_max": float(pe[:, 0].max()) if pe.size else float("nan"),
        "new_r_err_max": float(pe[:, 1].max()) if pe.size else float("nan"),
        "moved_f_total": len(mf),
        "moved_f_found": moved_f_found,
        "false_moved_f": false_f,
        "wheel_run_max_pct": 100 * float(run_err.max()),
        "wheel_veh_max_pct": 100 * float(veh_err.max()),
        "vehicles": len(veh),
        "veh_runs_min": int(veh["runs_estimated"].min()),
    }


def track_km(net: Network) -> float:
    g = net.gis.groupby(["line_code", "track"])["km_m"].agg(["min", "max"])
    return float((g["max"] - g["min"]).sum() / 1000.0)


def _row(label: str, value: str, target: str = "") -> None:
    print(f"{label:62s} {value:>18s}  {target}")


def report(e: dict[str, Any], clean: dict[str, Any], km: float) -> None:
    _row("moved balises flagged, residual within ±0.5 m", f"{e['moved_within']}/{e['moved_total']}", "all (≥ 2 m off)")
    _row("   … largest residual error [m]", f"{e['moved_err_max']:.3f}", "≤ 0.5")
    _row("unpowered balises reported missed", f"{e['missed_found']}/{e['missed_total']}", "≥ 95 %")
    _row("false 'missed' (surveyed DB / truth DB)", f"{e['false_missed']} / {clean['false_missed']}", "0")
    _row("balises removed from the DB found as confirmed candidates", f"{e['cand_found']}/{e['cand_total']}")
    _row("removed curves proposed within ±10 m and ±10 % radius", f"{e['new_within']}/{e['new_total']}", "all")
    _row(
        "   … largest exit-crossing error [m] / radius error",
        f"{e['new_err_max']:.1f} / {100 * e['new_r_err_max']:.1f} %",
        "≤ 10 m / 10 %",
    )
    _row("curves moved 30 m in the DB found moved", f"{e['moved_f_found']}/{e['moved_f_total']}")
    _row("wheel diameter per vehicle, largest error", f"{e['wheel_veh_max_pct']:.4f} %", "≤ 0.1 %")
    _row("   … per run, largest error", f"{e['wheel_run_max_pct']:.4f} %")
    _row("   … vehicles / fewest runs with an estimate", f"{e['vehicles']} / {e['veh_runs_min']}", "≥ 3 runs")
    _row(
        "false 'moved' balises / features, clean items of the surveyed DB",
        f"{e['false_moved']} / {e['false_moved_f']}",
        "0",
    )
    _row(
        f"false 'moved' balises / features, truth DB ({km:.0f} track-km)",
        f"{clean['false_moved']} / {clean['false_moved_f']}",
        "0 in 100 track-km",
    )
    _row("clean balises ok (truth DB)", f"{clean['clean_ok']}/{clean['clean_balises']}")


def _args() -> argparse.Namespace:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=2)
    ap.add_argument("--length-km", type=float, default=25.0)
    ap.add_argument("--runs", type=int, default=8, help="runs per track")
    ap.add_argument("--unpowered", type=int, default=8, help="unpowered balises per line")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--sensors", choices=sorted(SENSORS), default="dgps", help="what the runs carry beside balises")
    ap.add_argument("--wheels-only", action="store_true", help="survey the surveyed DB only: the wheel table, timing")
    ap.add_argument(
        "--replicate",
        type=int,
        default=0,
        help="then time a survey of the runs hard-linked this many times (throughput only)",
    )
    ap.add_argument(
        "--keep", type=Path, default=None, help="work folder to keep, its simulated runs reused (default: temporary)"
    )
    return ap.parse_args()


def print_wheels(ws: pd.DataFrame) -> None:
    print("\nwheel diameter per source (errors against the simulated truth, %; target ±0.1 % from ≥ 3 runs):")
    print(ws.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    print(f"   {ws.attrs['note']}")


def replicate(logs: Path, k: int) -> Path:
    """The runs of ``logs`` hard-linked ``k`` times (``logs-xK/cI/RUN``; kept if complete)."""
    runs = sorted(p for p in logs.iterdir() if (p / "run.json").is_file())
    out = logs.parent / f"{logs.name}-x{k}"
    if out.is_dir() and len(list(out.glob("c*/*/run.json"))) == k * len(runs):
        return out
    tmp = logs.parent / f".{out.name}"
    for i in range(k):
        for run in runs:
            dst = tmp / f"c{i:03d}" / run.name
            dst.mkdir(parents=True, exist_ok=True)
            for f in run.iterdir():
                if not (dst / f.name).exists():
                    os.link(f, dst / f.name)
    tmp.rename(out)
    return out


def time_replicas(logs: Path, db: Path, k: int, workers: int) -> None:
    """Throughput of a survey of ``k`` copies of the runs: wall and CPU with ``workers``
    processes, the machine's 2-process ceiling now (bench_audit's calibration) and the load."""
    from bench_audit import calibrate

    root = replicate(logs, k)
    ceiling = calibrate(workers) if workers > 1 else 1.0
    load0 = os.getloadavg()[0]
    rep, wall, cpu = timed(lambda: survey([root], db, workers=workers))
    load1 = os.getloadavg()[0]
    hours = rep.summary()["run_hours"]
    print(
        f"\nreplicated ×{k}: {len(rep.runs)} runs, {hours:.1f} run-hours; {workers} workers, load {load0:.1f} → "
        f"{load1:.1f}, {workers}-process ceiling {ceiling:.2f}×"
    )
    print(
        f"   wall {wall:.1f} s = {hours / wall * 60:.1f} run-hours/min → 1,000 run-hours in "
        f"{1000 / hours * wall / 60:.1f} min; CPU {cpu:.1f} s = {cpu / hours * 1000 / 60:.1f} CPU-min per 1,000 "
        f"run-hours → {cpu / hours * 1000 / 60 / workers:.1f} min on {workers} idle cores"
    )


def print_throughput(hours: float, t: dict[str, float], workers: int, load: tuple[float, float]) -> None:
    rate = hours / (t["survey"] / 60.0)
    cpu_rate = hours / (t["survey_cpu"] / workers / 60.0)
    print(
        f"\nthroughput ({workers} workers, load {load[0]:.1f} → {load[1]:.1f}): {hours:.1f} run-hours surveyed in "
        f"{t['survey']:.1f} s wall = {rate:.1f} run-hours/min → 1,000 run-hours in {1000.0 / rate:.1f} min "
        "(target ≤ 10 min)"
    )
    print(
        f"   CPU time {t['survey_cpu']:.1f} s (this process and its workers) = {cpu_rate:.1f} run-hours/min on "
        f"{workers} idle cores → 1,000 run-hours in {1000.0 / cpu_rate:.1f} min"
    )
    if "gis" in t:
        print(
            f"survey of the truth DB {t['truth']:.1f} s wall; gis verify alone on the same runs: {t['gis']:.1f} s "
            f"wall, {t['gis_cpu']:.1f} s CPU (survey / gis verify: wall {t['survey'] / t['gis']:.2f}, CPU "
            f"{t['survey_cpu'] / t['gis_cpu']:.2f})"
        )


def main() -> None:
    args = _args()
    with tempfile.TemporaryDirectory() as tmp:
        root = args.keep or Path(tmp)
        root.mkdir(parents=True, exist_ok=True)
        truth = make_network(args.lines, args.length_km * 1000.0, args.seed)
        truth_db = build(truth, root, "truth")
        truth = read_network(truth_db)
        surveyed, what = inject(truth, np.random.default_rng(args.seed + 7), args.unpowered)
        sv_db = build(surveyed, root, "surveyed")
        t0 = time.perf_counter()
        logs = root / f"logs-{args.sensors}-{args.lines}x{args.runs}"
        runs = simulate_runs(truth_db, truth, args.runs, logs, args.workers, args.seed, what["unpowered"], args.sensors)
        print(
            f"simulated {len(runs)} runs ({args.lines} lines × 2 tracks × {args.runs}, {args.sensors}) "
            f"in {time.perf_counter() - t0:.0f} s"
        )
        load0 = os.getloadavg()[0]
        t: dict[str, float] = {}
        rep, t["survey"], t["survey_cpu"] = timed(lambda: survey([logs], sv_db, workers=args.workers))
        if not args.wheels_only:
            rep_truth, t["truth"], _ = timed(lambda: survey([logs], truth_db, workers=args.workers))
            _, t["gis"], t["gis_cpu"] = timed(lambda: verify_runs(sv_db, [logs], workers=args.workers))
        load1 = os.getloadavg()[0]
        if not args.wheels_only:
            e = evaluate(rep, truth, what)
            clean_what = {"moved": {}, "unpowered": what["unpowered"], "removed_b": [], "removed_f": [], "moved_f": []}
            print(f"\n{'metric':62s} {'value':>18s}  target")
            report(e, evaluate(rep_truth, truth, clean_what), track_km(truth))
        print_wheels(wheel_sources(rep))
        print_throughput(rep.summary()["run_hours"], t, args.workers, (load0, load1))
        if args.replicate:
            time_replicas(logs, sv_db, args.replicate, args.workers)


def _cpu() -> float:
    me, kids = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime + kids.ru_utime + kids.ru_stime


def timed(fn: Any) -> tuple[Any, float, float]:
    """(result, wall s, CPU s of this process and the children it waited for)."""
    c0, t0 = _cpu(), time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t0, _cpu() - c0


if __name__ == "__main__":
    main()
