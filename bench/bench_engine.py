"""Benchmark: what the network engine costs a run (issue 31: the hypothesis engine ≤ 1.3× today's
``trainpos run`` on the existing sample runs).

Run: ``.venv/bin/python bench/bench_engine.py [--rounds 5]``.

The bundled sample runs along line 0420 (``sim-d-*``, ``sim-u-*``, ``sim-road-rail``: the runs
that existed before the network) are replayed in process through ``run_pipeline`` (the whole
positioning, outputs not written) on two DBs built from the bundled sample sources:

* **network**: the sample as shipped: tracks, connections, switches, track points, the tracks'
  feature points and the ETCS balise groups, so every aid of the hypothesis engine is on;
* **line-only**: the same lines without the network tables and without the G balises, the DB
  the pipeline ran these runs on before the engine (line and track U/D/S, one hypothesis).

Rounds interleave the two (line-only, then network), each DB read once beforehand (the run's
share of reading it is in ``bench_run.py``); the CPU of each round is summed over the runs and the
ratio network / line-only printed per round, with the median. The network runs (``sim-net-*``)
have no line-only counterpart: their CPU per run is printed beside. Never fails on timing.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench._common import load, verdict

if TYPE_CHECKING:
    from dbtools.network import Network
    from fieldlogs.runs.handle import Run

#: The network tables a line-only source set leaves out.
NETWORK_TABLES = ("tracks", "connections", "switches", "track_points", "track_feature_points")
#: Sample runs along line 0420 (they existed before the network was added).
LINE_RUNS = ("sim-d-evening", "sim-d-reversal", "sim-d-slips", "sim-road-rail", "sim-u-evening", "sim-u-tunnel")


def line_only_sources(src: Path, out: Path) -> Path:
    """``src`` without the network tables and the G balises (and their group columns)."""
    from schemas.tables import BALISE_GROUP_COLUMNS

    out.mkdir(parents=True)
    for f in src.iterdir():
        if f.suffix == ".csv" and f.stem not in NETWORK_TABLES and f.stem != "balises":
            shutil.copy(f, out / f.name)
    b = pd.read_csv(src / "balises.csv", dtype=str, keep_default_na=False)
    group = [c.name for c in BALISE_GROUP_COLUMNS if c.name in b.columns]
    b[b["kind"] != "G"].drop(columns=group).to_csv(out / "balises.csv", index=False)
    return out


def cpu_of(runs: Sequence[Run], net: Network) -> float:
    """CPU seconds of replaying ``runs`` through the pipeline on ``net``."""
    from fieldlogs.pipeline.config import PipelineConfig
    from fieldlogs.pipeline.run import run_pipeline

    c0 = time.process_time()
    for run in runs:
        run_pipeline(run, net, PipelineConfig())
    return time.process_time() - c0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds (default 5)")
    ap.add_argument("--runs", type=int, default=len(LINE_RUNS), help="how many of the line runs (default all)")
    args = ap.parse_args()

    from cli.demo import sample_logs_dir
    from dbtools.build import build_db
    from dbtools.database import read_network
    from dbtools.sample_network import sample_network_source_dir
    from fieldlogs.runs.handle import read_run

    work = Path(tempfile.mkdtemp(prefix="trainpos-bench-engine-"))
    try:
        src = sample_network_source_dir()
        build_db(src, work / "network.sqlite")
        build_db(line_only_sources(src, work / "line-src"), work / "line.sqlite")
        nets = {k: read_network(work / f"{k}.sqlite") for k in ("line", "network")}
        logs = sample_logs_dir()
        runs = [read_run(logs / name) for name in LINE_RUNS[: args.runs]]
        net_runs = sorted(p for p in logs.iterdir() if p.name.startswith("sim-net-"))
        print(f"{len(runs)} line runs of the sample, {len(net_runs)} network runs; {load()}")
        for k in nets:  # warm: imports, numba, the networks' caches
            cpu_of(runs[:1], nets[k])
        per: dict[str, list[float]] = {"line": [], "network": []}
        for r in range(args.rounds):
            for k in ("line", "network"):
                per[k].append(cpu_of(runs, nets[k]))
            print(
                f"  round {r + 1}: line-only {per['line'][-1]:.3f} s CPU, network {per['network'][-1]:.3f} s CPU, "
                f"ratio {per['network'][-1] / per['line'][-1]:.2f}×"
            )
        ratios = np.array(per["network"]) / np.array(per["line"])
        med = float(np.median(ratios))
        print(
            f"line runs on the network DB / on the line-only DB: median {med:.2f}× {verdict('≤ 1.3×', med <= 1.3)}; "
            f"rounds {', '.join(f'{x:.2f}' for x in ratios)}  [{load()}]"
        )
        for p in net_runs:
            run = read_run(p)
            cpu = min(cpu_of([run], nets["network"]) for _ in range(max(1, args.rounds // 2)))
            print(f"  {p.name:20} {cpu:.3f} s CPU on the network DB")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
