"""Shared data of the survey tests: the bundled sample network with known errors and eight
seeded simulated runs on it (four per track, one vehicle per track).

Built once per test session (``survey_data(tmp_path_factory)``). The runs are simulated on
the sample network as built (the truth); the DB under survey (``surveyed.sqlite``, from the
source set ``src-surveyed``) has C balise ``0420-D-C002`` 3 m beyond where it is, C balise
``0420-U-C002`` missing (the runs read it: a candidate) and the curve ``F002`` of track D
missing (a new curve); the telegrams of ``0420-03-D-I1`` and ``0420-U-C003`` are taken out
of every run (unpowered balises, still in the DB).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.network import Network
from dbtools.sample_network import sample_source_dir
from dbtools.sources import write_source_set
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

MOVED = {"0420-D-C002": 3.0}
REMOVED_BALISE = "0420-U-C002"
REMOVED_FEATURE = ("0420", "D", "F002")
UNPOWERED = ("0420-03-D-I1", "0420-U-C003")
#: (track, vehicle, wear %) of the runs; four seeds each.
FLEET = (("D", "EMU-A", 0.20), ("U", "EMU-B", 0.35))
SEEDS = (31, 32, 33, 34)


@dataclass(frozen=True)
class SurveyData:
    truth_db: Path
    db: Path
    """The DB under survey (with the errors of the module docstring)."""
    sources: Path
    """Its source set."""
    logs: Path
    truth: Network

    def true_wheel(self, vehicle: str) -> float:
        """Mean true wheel diameter of a vehicle's runs (run.json ``sim_truth``)."""
        values = []
        for run in sorted(self.logs.iterdir()):
            meta = json.loads((run / "run.json").read_text())
            if meta["vehicle_id"] == vehicle:
                values.append(meta["sim_truth"]["wheel_diameter_true_m"])
        return float(np.mean(values))


def surveyed_network(truth: Network) -> Network:
    b = truth.balises.copy()
    for bid, dx in MOVED.items():
        m = b["balise_id"] == bid
        b.loc[m, ["km_actual_m", "km_equipment_m", "dist_from_initial_m"]] += dx
    b = b[b["balise_id"] != REMOVED_BALISE]
    fp = truth.feature_points
    line, track, fid = REMOVED_FEATURE
    fp = fp[~((fp["line_code"] == line) & (fp["track"] == track) & (fp["feature_id"] == fid))]
    tables = dict(truth.tables)
    tables["balises"], tables["feature_points"] = b, fp
    return Network(tables, origin="surveyed", meta=dict(truth.meta))


def _unpowered_mask(streams: dict[str, pd.DataFrame], truth: Network, track: str) -> np.ndarray:
    """Telegrams of the unpowered balises (truth km at the telegram, same kind)."""
    tel, tr = streams["balise"], streams["truth"]
    km = np.interp(tel["t"].to_numpy(dtype=float), tr["t"].to_numpy(dtype=float), tr["km_m"].to_numpy(dtype=float))
    drop = np.zeros(len(tel), dtype=bool)
    b = truth.balises
    for bid in UNPOWERED:
        row = b[b["balise_id"] == bid].iloc[0]
        if row["track"] == track:
            drop |= (np.abs(km - float(row["km_actual_m"])) < 0.5) & (tel["kind"].astype(str) == row["kind"]).to_numpy()
    return drop


_CACHE: dict[str, SurveyData] = {}


def survey_data(factory: pytest.TempPathFactory) -> SurveyData:
    if "data" not in _CACHE:
        root = factory.mktemp("survey-data")
        truth_db = root / "truth.sqlite"
        build_db(sample_source_dir(), truth_db, db_version="survey-truth")
        truth = read_network(truth_db)
        src = write_source_set(surveyed_network(truth), root / "src-surveyed")
        db = root / "surveyed.sqlite"
        build_db(src, db, db_version="survey-test")
        for track, vehicle, wear in FLEET:
            for k, seed in enumerate(SEEDS):
                start = pd.Timestamp("2026-02-01T08:00:00+09:00") + pd.Timedelta(days=k)
                sc = scenario_from_dict(
                    {
                        "route": {"track": track},
                        "run": {"run_id": f"SV-{track}-{seed}", "vehicle_id": vehicle, "start_time": start.isoformat()},
                        "tacho": {"wear_pct": [wear, wear]},
                    }
                )
                sim = simulate_run(truth, sc, seed=seed)
                streams = dict(sim.streams)
                streams["balise"] = streams["balise"][~_unpowered_mask(streams, truth, track)].reset_index(drop=True)
                write_run(root / "logs" / f"{track}-{seed}", sim.meta, streams)
        _CACHE["data"] = SurveyData(truth_db, db, src, root / "logs", truth)
    return _CACHE["data"]
