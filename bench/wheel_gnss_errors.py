"""The GNSS wheel scale's along-track errors against the simulated truth (issue 19).

Run on demand over runs kept by ``bench_survey.py --keep DIR --sensors gnss`` (prints a
table, never pass/fail)::

    .venv/bin/python bench/wheel_gnss_errors.py DIR/logs-gnss-1x6 --db DIR/surveyed.sqlite --cache C

Every run is replayed as ``trainpos survey`` replays it (wheel calibration off) and its
GNSS points (:func:`fieldlogs.survey.wheelaids.along_track`) compared with the truth: the
error e = y − σ·c(km_true(t)) of each point (``--cache`` keeps the points and the truth per
run, so a changed fit is measured without replaying). Printed per run: the fit's scale
error z = (λ̂ − λ_true)/se, the error's sample spread, its autocorrelation at 10, 60, 180,
600 s lags and the slope of e against the travel (the part of e that is a scale error);
over all runs the spread of z (≈ 1 for a right interval) and the coverage of λ̂ ± 1.96·se.
"""

from __future__ import annotations

import argparse
import json
import pickle
import sys
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _points(job: tuple[str, str]) -> dict[str, Any]:
    """One run's GNSS points, truth and diameters."""
    from dbtools.database import read_network
    from fieldlogs.pipeline.config import PipelineConfig
    from fieldlogs.pipeline.metric import track_metric
    from fieldlogs.pipeline.run import run_pipeline
    from fieldlogs.runs.handle import read_run
    from fieldlogs.survey.config import SurveyConfig
    from fieldlogs.survey.extract import _Trace, find_segments
    from fieldlogs.survey.wheelaids import GNSS, SegmentSpan, along_track

    folder, db = job
    net = read_network(Path(db))
    pipe = PipelineConfig()
    pipe = replace(pipe, odometry=replace(pipe.odometry, wheel_calibration=False))
    run = read_run(Path(folder))
    result = run_pipeline(run, net, pipe)
    tr = _Trace.of(result)
    segs = find_segments(result.positions, tr.d, tr.cab, SurveyConfig().extrapolate_m)
    spans = [SegmentSpan(float(tr.t[g.ia]), float(tr.t[g.ib - 1]), g.line_code, g.track, g.motion, g.cab) for g in segs]
    a = along_track(result, net, spans, GNSS)
    import pandas as pd

    truth = pd.read_parquet(Path(folder) / "truth.parquet")
    st = json.loads((Path(folder) / "run.json").read_text())
    line, track = st["sim_truth"]["line_code"], st["sim_truth"]["track"]
    out: dict[str, Any] = {
        "folder": folder,
        "vehicle": st["vehicle_id"],
        "d_true": st["sim_truth"]["wheel_diameter_true_m"],
        "d_cfg": st["wheel_diameter_m"],
        "points": a,
    }
    if a is not None:
        km_true = np.interp(a.t, truth["t"].to_numpy(float), truth["km_m"].to_numpy(float))
        c_true = np.asarray(track_metric(net, line, track).c_of_km(km_true), dtype=float)
        motion = np.sign(np.nanmedian(np.diff(a.y))) * np.sign(np.nanmedian(np.diff(c_true))) if a.n > 1 else 1.0
        out["y_true"] = motion * c_true
    return out


def load(folders: list[Path], db: Path, cache: Path | None, workers: int) -> list[dict[str, Any]]:
    todo, got = [], {}
    for f in folders:
        p = cache / f"{f.parent.parent.name}-{f.parent.name}-{f.name}.pkl" if cache else None
        if p is not None and p.is_file():
            got[str(f)] = pickle.loads(p.read_bytes())
        else:
            todo.append(str(f))
    with ProcessPoolExecutor(workers) as pool:
        for r in pool.map(_points, [(f, str(db)) for f in todo]):
            got[r["folder"]] = r
            if cache:
                cache.mkdir(parents=True, exist_ok=True)
                f = Path(r["folder"])
                (cache / f"{f.parent.parent.name}-{f.parent.name}-{f.name}.pkl").write_bytes(pickle.dumps(r))
    return [got[str(f)] for f in folders]


def _acf(e: np.ndarray, t: np.ndarray, lag: float) -> float:
    """Autocorrelation of e at ``lag`` s (pairs within ±0.5 s of it)."""
    e = e - e.mean()
    j = np.searchsorted(t, t + lag)
    ok = (j < t.size) & (np.abs(t[np.minimum(j, t.size - 1)] - t - lag) <= 0.5)
    if ok.sum() < 10:
        return float("nan")
    return float(np.mean(e[ok] * e[j[ok]]) / np.var(e))


def main() -> None:
    from fieldlogs.survey.config import SurveyConfig
    from fieldlogs.survey.wheelaids import GNSS, gnss_scale

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", type=Path, nargs="+", help="folders of runs (bench_survey's logs-gnss-…)")
    ap.add_argument("--db", type=Path, action="append", required=True, help="the DB of each logs folder (or one)")
    ap.add_argument("--cache", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    cfg = SurveyConfig()
    rows = []
    dbs = args.db * len(args.logs) if len(args.db) == 1 else args.db
    for logs, db in zip(args.logs, dbs, strict=True):
        folders = sorted(p for p in logs.iterdir() if (p / "run.json").is_file())
        for r in load(folders, db, args.cache, args.workers):
            a = r["points"]
            fit = gnss_scale(a, GNSS, cfg) if a is not None else None
            if a is None or fit is None:
                continue
            lam_true = r["d_true"] / r["d_cfg"]
            e = a.y - r["y_true"]
            slope = float(np.polyfit(a.d, e - np.mean(e), 1)[0]) if a.n > 2 else float("nan")
            label = f"{logs.parent.name}/{Path(r['folder']).name}"
            acf = [_acf(e, a.t, lag) for lag in (10, 60, 180, 600)]
            err = fit.scale - lam_true
            rows.append((label, err / fit.se, 100 * err, 100 * fit.se, float(np.std(e)), *acf, 100 * slope, a.n))
    head = ("run", "z", "err%", "se%", "sd_e", "r10", "r60", "r180", "r600", "e/d%", "n")
    print(f"{head[0]:28s} " + " ".join(f"{h:>7s}" for h in head[1:]))
    for row in rows:
        print(f"{row[0]:28s} " + " ".join(f"{v:7.4f}" for v in row[1:-1]) + f" {row[-1]:7d}")
    z = np.array([r[1] for r in rows])
    if z.size < 2:
        print(f"\n{z.size} runs with GNSS points: too few for the spread of z")
        return
    half = 1.96 * np.array([r[3] for r in rows])
    err_abs = np.abs([r[2] for r in rows])
    print(
        f"\n{z.size} runs: sd(z) {np.std(z, ddof=1):.2f}, mean z {z.mean():+.2f}, |z| ≤ 1.96: "
        f"{int((np.abs(z) <= 1.96).sum())}/{z.size}; median 95 % half-width {np.median(half):.4f} %, "
        f"median |error| {np.median(err_abs):.4f} %"
    )


if __name__ == "__main__":
    main()
