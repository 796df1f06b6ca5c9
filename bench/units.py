"""One positioning unit per cab on its own sensors over many seeded network runs (issue 31
item 6; [the position-detection field test §2]: an onboard unit in each cab, working
independently).

    .venv/bin/python bench/units.py [--runs 40] [--workers 2] [--seed 6] [--wheel-error-pct 10]

Builds the bundled network source set, draws ``--runs`` routes with
:func:`fieldlogs.simulate.network_runs.network_runs` (15 % of them turn back: a cab change),
simulates each with the R cab's own IMU, tacho and GPS (scenario ``[cab_r] sensors = true``)
and replays unit F and unit R (:func:`fieldlogs.pipeline.units.unit_run`), compared by
:func:`fieldlogs.pipeline.units.compare_units`. Each disagreement span (a ``units_disagree``
event) is judged with the truth: the unit whose |error| exceeds its margin or that is determined
on the wrong track during the span is the one wrong. A second pass gives the R axle's wheel
``--wheel-error-pct`` more diameter than run.json says, with neither the wheel rescale nor the
balise check's widening (``[margin] wheel_rescale = false``, ``scale_check_pct = 50``): the
share of runs where the units then disagree is the comparison's power to catch a unit that
does not know it is wrong.

Printed: runs (turnbacks), cycles compared, the runs with a disagreement (honest sensors) and
whom the truth blames, max |km_F − km_R| / (m_F + m_R), the runs where unit R never claimed a
position, and with the wheel error the runs with a disagreement.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench._common import over_network_runs, print_rows
from dbtools.database import read_network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.pipeline.units import UNITS, compare_units, unit_run
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

#: The pipeline settings of the wheel-error pass: no wheel rescale, no widening (docstring).
NO_CORRECTION = {"margin": {"wheel_rescale": False, "scale_check_pct": 50.0}}


def _wrong(positions: Any, truth: Any) -> np.ndarray:
    """Per cycle: the unit claims a position outside its margin of the truth or a wrong track."""
    cmp = compare_with_truth(positions, truth)
    claimed = cmp["claimed"].to_numpy(dtype=bool)
    return np.asarray(claimed & (~cmp["within_margin"].to_numpy(dtype=bool) | cmp["wrong_track"].to_numpy(bool)))


def pair(folder: Path, net: Any, cfg: PipelineConfig, truth: Any) -> dict[str, Any]:
    """Both units on one run: the comparison and, per disagreement span, whom the truth blames."""
    pos, wrong, claimed = {}, {}, {}
    for u in UNITS:
        res = run_pipeline(unit_run(read_run(folder), u, folder.parent / f"{folder.name}-{u}"), net, cfg)
        pos[u] = res.positions
        wrong[u] = _wrong(res.positions, truth)
        claimed[u] = int((res.positions["state"] != "undetermined").sum())
    frame, s = compare_units(pos["F"], pos["R"])
    t = frame["t"].to_numpy(dtype=float)
    blame = []
    for a, b in s["disagreements"]:
        span = (t >= a) & (t <= b)
        blame.append("".join(u for u in UNITS if wrong[u][span].any()) or "neither")
    return {"summary": s, "blame": blame, "claimed": claimed}


def one(args: tuple[int, str, str, dict[str, Any], float]) -> dict[str, Any]:
    i, db, tmp, run, wheel_error = args
    net = read_network(Path(db))
    out: dict[str, Any] = {"i": i, "turnback": len(run["network"].get("points", [])) > 2}
    for name, err, cfg in (
        ("honest", 0.0, PipelineConfig()),
        ("wheel", wheel_error, PipelineConfig.from_dict(NO_CORRECTION)),
    ):
        sc = json.loads(json.dumps(run)) | {"cab_r": {"sensors": True, "wheel_error_pct": err}}
        streams, meta = simulate_run(net, scenario_from_dict(sc, source=sc["name"]))
        folder = write_run(Path(tmp) / f"units{i:04d}-{name}", meta, streams, force=True)
        out[name] = pair(folder, net, cfg, streams["truth"])
    return out


def table(results: list[dict[str, Any]], wheel_error: float) -> list[tuple[str, str]]:
    n, tb = len(results), [r for r in results if r["turnback"]]
    honest = [r["honest"] for r in results]
    share = [s["summary"]["max_difference_share_of_bound"] for s in honest]
    share = [x for x in share if x is not None]
    blames = [b for h in honest for b in h["blame"]]

    def runs_with(rs: list[dict[str, Any]], key: str) -> int:
        return sum(1 for r in rs if r[key]["summary"]["disagreements"])

    return [
        ("runs (turnbacks)", f"{n} ({len(tb)})"),
        ("cycles compared", str(sum(h["summary"]["cycles_compared"] for h in honest))),
        ("honest: runs with units_disagree",
         f"{runs_with(results, 'honest')} / {n} (turnbacks {runs_with(tb, 'honest')} / {len(tb)})"),
        ("honest: spans blamed on F / R / both / neither",
         " / ".join(str(blames.count(k)) for k in ("F", "R", "FR", "neither"))),
        ("honest: max |d| / (m_F + m_R) median, max",
         f"{np.median(share):.3f}, {max(share):.3f}" if share else "n/a"),
        ("honest: runs unit R never claimed a position", str(sum(1 for h in honest if h["claimed"]["R"] == 0))),
        (f"R wheel +{wheel_error:g} %, no correction: runs with units_disagree",
         f"{runs_with(results, 'wheel')} / {n} (turnbacks {runs_with(tb, 'wheel')} / {len(tb)})"),
    ]  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--seed", type=int, default=6)
    ap.add_argument("--wheel-error-pct", type=float, default=10.0)
    args = ap.parse_args()
    results, wall = over_network_runs(one, args.runs, args.seed, args.workers, args.wheel_error_pct)
    print(f"units F and R over {args.runs} seeded network runs (seed {args.seed}), each on its own sensors", end="")
    print(f" ({wall:.1f} s wall)")
    print_rows(table(results, args.wheel_error_pct))


if __name__ == "__main__":
    main()
