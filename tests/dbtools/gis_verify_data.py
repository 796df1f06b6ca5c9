"""Shared data of the ``gis verify`` tests: a truth DB, a surveyed DB with one GIS error
and simulated runs on the truth geometry (built once per session).

A 6 km double-track line (``demo_line``); 8 full-length runs per track simulated on the
*truth* DB with the default GPS model (σ 0.75 m per axis, τ 180 s, multipath), each
starting a random fraction of a second later (so that the 1 Hz fixes of different runs
do not all fall on the same places); the
*surveyed* DB has the down track's GIS points km 3000–3200 shifted 3 m to the left
(perpendicular to the track) — the simulator drove on the truth, so the runs see the
surveyed grid 3 m off there.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import Projector
from dbtools.gis.verify.proposal import shift_grid_points
from dbtools.sources import write_source_set
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

PROJECTOR = Projector(9)
LINE = "0900"
DEFECT_TRACK = "D"
DEFECT_KM = (3000.0, 3200.0)
DEFECT_SHIFT_M = 3.0
RUNS_PER_TRACK = 8


@dataclass(frozen=True)
class VerifyData:
    truth_db: Path
    surveyed_db: Path
    surveyed_src: Path
    logs: Path

    @property
    def runs(self) -> list[Path]:
        return sorted(p for p in self.logs.iterdir() if p.is_dir())


_CACHE: dict[str, VerifyData] = {}


def verify_data(factory: pytest.TempPathFactory) -> VerifyData:
    if "data" not in _CACHE:
        root = factory.mktemp("gis-verify")
        truth = build_network([demo_line(LINE, length_m=6000.0)], PROJECTOR)
        build_db(write_source_set(truth, root / "src-truth"), root / "truth.sqlite", db_version="truth")
        km = np.arange(DEFECT_KM[0], DEFECT_KM[1] + 1.0, 20.0)
        truth.tables["gis"] = shift_grid_points(truth.gis, LINE, DEFECT_TRACK, km, DEFECT_SHIFT_M, PROJECTOR)
        src = write_source_set(truth, root / "src-surveyed")
        build_db(src, root / "surveyed.sqlite", db_version="surveyed")
        net = read_network(root / "truth.sqlite")
        for ti, track in enumerate(("D", "U")):
            for r in range(RUNS_PER_TRACK):
                seed = 500 + 50 * ti + r
                # a fraction of a second more or less before starting: fixes of different runs
                # fall on different places, as in a real fleet
                wait = 20.0 + float(np.random.default_rng(seed).uniform(0.0, 1.0))
                sc = scenario_from_dict(
                    {
                        "route": {"track": track},
                        "run": {"run_id": f"V-{track}-{r}"},
                        "running": {"standstill_start_s": wait},
                    }
                )
                sim = simulate_run(net, sc, seed=seed)
                write_run(root / "logs" / f"{track}{r}", sim.meta, sim.streams)
        _CACHE["data"] = VerifyData(root / "truth.sqlite", root / "surveyed.sqlite", src, root / "logs")
    return _CACHE["data"]
