"""The headline accuracy claims against simulator truth, in the test suite (issue 14).

24 seeded runs on the bundled sample network (both tracks, half of them starting with the
cab reversed, slips and slides on four of every five, GPS noise and multipath), each
replayed through the whole pipeline and compared with the simulator's ground truth:

* |km error| ≤ margin on ≥ 99.9 % of the cycles with a claimed position;
* no cycle on a wrong line or track while the position is *determined*;
* ≥ 95 % of the injected slip/slide episodes that would cost ≥ 1 m are detected, and no
  detection on the slip-free runs.

The figures over 300 runs are in ``bench/accuracy.py``; this is the guard rail that runs
with every ``make test`` (``make test-fast`` skips it).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dbtools.database import read_network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

RUNS = 24
SEED0 = 7300


def _scenario(i: int, gis: Any) -> dict[str, Any]:
    line = sorted(set(gis["line_code"]))[0]
    track = "D" if i % 2 == 0 else "U"
    km = gis.loc[(gis.line_code == line) & (gis.track == track), "km_m"]
    lo, hi = float(km.min()) + 200, float(km.max()) - 200
    slip = {"slips": 0, "slides": 0, "on_grade_curve": False} if i % 5 == 4 else {"slips": 2, "slides": 2}
    return {
        "name": f"truth-{i}",
        "route": {
            "line_code": line,
            "track": track,
            "path_km_m": [lo, hi] if track == "D" else [hi, lo],
            "start_cab": "R" if i % 4 >= 2 else "F",
        },
        "slip": slip,
        "run": {"run_id": f"TRUTH-{i:03d}"},
    }


@pytest.fixture(scope="module")
def outcomes(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> list[dict[str, Any]]:
    net = read_network(sample_db)
    root = tmp_path_factory.mktemp("truth-runs")
    out = []
    for i in range(RUNS):
        streams, meta = simulate_run(net, scenario_from_dict(_scenario(i, net.gis)), seed=SEED0 + i)
        write_run(root / f"run{i:02d}", meta, streams)
        res = run_pipeline(read_run(root / f"run{i:02d}"), net, PipelineConfig())
        truth = streams["truth"]
        cmp = compare_with_truth(res.positions, truth)
        claimed = cmp[cmp["claimed"]]
        injected = meta.extra["sim_truth"]["slip_episodes"]
        t_truth = truth["t"].to_numpy()
        speed = np.abs(truth["speed_mps"].to_numpy())
        costly, found = 0, 0
        for e in injected:
            v = float(speed[min(np.searchsorted(t_truth, e["t0"]), len(t_truth) - 1)])
            if e["depth"] * v * (e["t1"] - e["t0"]) * 0.7 < 1.0:
                continue  # would cost under 1 m undetected
            costly += 1
            found += any(d.t_end >= e["t0"] - 1.0 and d.t_start <= e["t1"] + 3.0 for d in res.odometry.episodes)
        out.append(
            {
                "claimed": len(claimed),
                "within": int(claimed["within_margin"].sum()),
                "wrong_track": int(claimed["wrong_track"].sum()),
                "costly": costly,
                "found": found,
                "slip_free": not injected,
                "detections": len(res.odometry.episodes),
            }
        )
    return out


@pytest.mark.slow
def test_error_within_margin_on_99_9_percent_of_claimed_cycles(outcomes: list[dict[str, Any]]) -> None:
    claimed = sum(o["claimed"] for o in outcomes)
    within = sum(o["within"] for o in outcomes)
    assert claimed > RUNS * 3000  # every run claims a position for most of its ~15 minutes
    assert within / claimed >= 0.999, f"{within}/{claimed}"


@pytest.mark.slow
def test_never_a_determined_wrong_track(outcomes: list[dict[str, Any]]) -> None:
    assert sum(o["wrong_track"] for o in outcomes) == 0


@pytest.mark.slow
def test_slips_and_slides_are_detected(outcomes: list[dict[str, Any]]) -> None:
    costly = sum(o["costly"] for o in outcomes)
    found = sum(o["found"] for o in outcomes)
    assert costly >= 50
    assert found / costly >= 0.95, f"{found}/{costly}"
    assert all(o["detections"] == 0 for o in outcomes if o["slip_free"])
