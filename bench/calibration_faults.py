"""Wheel scale and clock faults on the sample run (issue 15): how much of the run stays inside
its margin.

    .venv/bin/python bench/calibration_faults.py [CASE ...]

Each case copies ``fieldlogs/sample_logs/sim-d-slips``, damages it as ``tests/test_damage.py``
does (``("scale", "tacho", 0.05)``: pulses 5 % over the declared wheel; ``("late", "balise",
0.1)``: telegrams stamped 1 s late; ``("delete", "radar", …)``: no radar), replays it and
prints the determined cycles, the share of them with |km error| ≤ margin against the
undamaged truth, their mean margin and the ``wheel_scale`` / ``balise_clock`` events. Never
fails: it reports.
"""

from __future__ import annotations

import json
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.sample_network import sample_source_dir
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.runs.handle import read_run
from tests.test_damage import SAMPLE, _damage

W5, B1 = ("scale", "tacho", 0.05), ("late", "balise", 0.1)
NO_RADAR = ("delete", "radar", 0.5)
CASES: dict[str, list[tuple[str, str, float]]] = {
    "clean": [],
    "wheel+5%": [W5],
    "wheel-5%": [("scale", "tacho", -0.05)],
    "wheel+2%": [("scale", "tacho", 0.02)],
    "wheel+10%": [("scale", "tacho", 0.1)],
    "wheel-10%": [("scale", "tacho", -0.1)],
    "balise-1s-late": [B1],
    "balise-5s-early": [("late", "balise", -0.5)],
    "wheel+5%-balise-1s-late": [W5, B1],
    "wheel-5%-balise-1s-early": [("scale", "tacho", -0.05), ("late", "balise", -0.1)],
    "wheel+5%-balise-1s-early": [W5, ("late", "balise", -0.1)],
    "wheel-5%-balise-1s-late": [("scale", "tacho", -0.05), B1],
    "wheel+2%-balise-0.5s-late": [("scale", "tacho", 0.02), ("late", "balise", 0.05)],
    "wheel+5%-balise-2s-late": [W5, ("late", "balise", 0.2)],
    "wheel+10%-balise-1s-late": [("scale", "tacho", 0.1), B1],
    "no-radar-wheel+5%-balise-1s-late": [W5, B1, NO_RADAR],
    "wheel+5%-imu-2s-late": [W5, ("late", "imu", 0.2)],
}


def main(names: list[str]) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "sample.sqlite"
        build_db(sample_source_dir(), db, db_version="sample-bench")
        network = read_network(db)
        truth = pd.read_parquet(SAMPLE / "truth.parquet")
        for name in names or list(CASES):
            run = Path(tmp) / name
            shutil.copytree(SAMPLE, run)
            rng = np.random.default_rng(0)
            for op, stream, frac in CASES[name]:
                _damage(run, op, stream, frac, rng)
            res = run_pipeline(read_run(run), network)
            pos = res.positions
            det = (pos["state"] == "determined").to_numpy()
            cmp = compare_with_truth(pos, truth)
            within = cmp["within_margin"][cmp["claimed"].to_numpy() & det]
            share = 100.0 * float(within.mean()) if len(within) else float("nan")
            margin = float(pos["margin_m"][det].mean()) if det.any() else float("nan")
            print(
                f"{name:34s} determined {int(det.sum()):5d}  within margin {share:7.2f} %  mean margin {margin:6.1f} m"
            )
            ev = res.events[res.events["type"].isin(["wheel_scale", "balise_clock"])]
            for kind, detail in zip(ev["type"], ev["detail"], strict=True):
                d = json.loads(detail)
                keys = ("scale_pct", "pass_fits_pct", "distance_pct", "offset_s", "action")
                print(f"    {kind}: " + ", ".join(f"{k} {d[k]}" for k in keys if k in d))


if __name__ == "__main__":
    main(sys.argv[1:])
