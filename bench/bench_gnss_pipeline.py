"""The GNSS aid in the pipeline [S002] (issue 17 phase 2): simulated train runs with raw GNSS.

    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_gnss_pipeline.py --runs 20 [--png margin.png]

Runs of ``bench/accuracy.py``'s scenarios (the sample network, both tracks, cab F/R, slips and
slides) with ``[gnss_raw]`` on — two receivers at ±8 m, GPS + Galileo + QZSS, standalone (no
D-GPS corrections); every third run through the seeded mixed corridor (buildings, cuttings,
overpasses, a short tunnel). Each run goes through the pipeline with the GNSS aid off and on.
Printed: cycles with a claimed position, |km error| ≤ margin, wrong-track cycles, the largest
|km error|, the margin's percentiles over the claimed cycles with and without the aid, the
aid's events, the pipeline time per run (wall and cpu: the machine is shared); ``--png``
writes the margin against the distance travelled of the first run, with and without the aid.
Figures: bench/NOTES.md ("GNSS in the pipeline").
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from accuracy import scenario

from dbtools.build import build_db
from dbtools.database import read_network
from fieldlogs.gnss.config import GnssConfig
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

PCTS = (50, 90, 99, 100)


def one(i: int, net: Any, tmp: Path) -> dict[str, Any]:
    sc = scenario(i, net)
    sc["gnss_raw"] = {"enabled": True, "corridor": "mixed" if i % 3 == 2 else "open"}
    streams, meta = simulate_run(net, scenario_from_dict(sc), seed=1000 + i)
    folder = write_run(tmp / f"run{i:03d}", meta, streams, force=True)
    out: dict[str, Any] = {"i": i, "track": meta.extra["sim_truth"]["track"], "corridor": sc["gnss_raw"]["corridor"]}
    for key, on in (("off", False), ("on", True)):
        t0, c0 = time.perf_counter(), time.process_time()
        res = run_pipeline(read_run(folder), net, PipelineConfig(gnss=GnssConfig(enabled=on)))
        out[f"time_{key}"] = time.perf_counter() - t0
        out[f"cpu_{key}"] = time.process_time() - c0
        assert res.truth is not None
        cmp = compare_with_truth(res.positions, res.truth)
        c = cmp[cmp["claimed"]]
        out[key] = {
            "claimed": len(c),
            "within": int(c["within_margin"].sum()),
            "wrong": int(c["wrong_track"].sum()),
            "max_err": float(c["error_m"].abs().max()),
            "margin": c["margin_m"].to_numpy(dtype=float),
            "events": res.events["type"].astype(str).value_counts().to_dict(),
            "trace": (res.odometry.d[cmp["claimed"].to_numpy(bool)], c["margin_m"].to_numpy(dtype=float)),
        }
    return out


def report(results: list[dict[str, Any]]) -> None:
    for key, label in (("off", "GNSS aid off"), ("on", "GNSS aid on")):
        claimed = sum(r[key]["claimed"] for r in results)
        within = sum(r[key]["within"] for r in results)
        wrong = sum(r[key]["wrong"] for r in results)
        margins = np.concatenate([r[key]["margin"] for r in results])
        pct = np.percentile(margins, PCTS)
        print(f"{label}")
        print(f"  cycles with a claimed position        {claimed}")
        print(f"  |km error| ≤ margin                   {100 * within / claimed:.3f} %  (target ≥ 99.9 %)")
        print(f"  wrong line/track cycles               {wrong}  (target 0)")
        print(f"  max |km error|                        {max(r[key]['max_err'] for r in results):.2f} m")
        print("  margin p50 / p90 / p99 / max          " + " / ".join(f"{v:.1f}" for v in pct) + " m")
        wall, cpu = (np.mean([r[f"{k}_{key}"] for r in results]) for k in ("time", "cpu"))
        print(f"  pipeline time per run                 {wall:.2f} s wall, {cpu:.2f} s cpu")
    ev = pd.DataFrame([r["on"]["events"] for r in results]).fillna(0).sum()
    names = ("gnss_correction", "initial_position_gnss", "gnss_refused", "gnss_track_disagrees")
    print("GNSS events over all runs: " + ", ".join(f"{n} {int(ev.get(n, 0))}" for n in names))
    mixed = [r for r in results if r["corridor"] == "mixed"]
    if mixed:
        m = np.concatenate([r["on"]["margin"] for r in mixed])
        print(f"  mixed-corridor runs ({len(mixed)}): margin p50 / p90 / max with the aid "
              + " / ".join(f"{v:.1f}" for v in np.percentile(m, (50, 90, 100))) + " m")  # fmt: skip


def plot(res: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(11, 4.5))
    for key, label, style in (("off", "without the GNSS aid", "-"), ("on", "with the GNSS aid", "-")):
        d, m = res[key]["trace"]
        ax.plot(np.asarray(d) / 1000.0, m, style, lw=1.2, label=label)
    ax.set_xlabel("distance travelled [km]")
    ax.set_ylabel("margin [m]")
    ax.set_title(f"Safety margin, simulated run {res['i']} (track {res['track']}, two receivers, GPS+Galileo+QZSS)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--png", type=Path, default=None, help="margin trace of the first run (PNG)")
    args = ap.parse_args()
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        from dbtools.sample_network import sample_source_dir

        db = Path(tmp) / "sample.sqlite"
        build_db(sample_source_dir(), db, db_version="bench")
        net = read_network(db)
        results = [one(i, net, Path(tmp)) for i in range(args.runs)]
    print(f"GNSS aid over {args.runs} simulated runs on the sample network ({time.perf_counter() - t0:.0f} s wall)")
    report(results)
    if args.png is not None:
        plot(results[0], args.png)
        print(f"margin trace written to {args.png}")


if __name__ == "__main__":
    main()
