"""The floor of the network accuracy bench (bench/accuracy_network.py, issue 31) on fewer runs (and of
its raw-GNSS condition below):
40 seeded runs over the network sample (10 per GNSS condition), simulated and replayed —
no wrong-track claim, ≥ 99 % of the facing switches resolved correctly, |error| ≤ margin
on ≥ 99.9 % of the determined cycles, and the D-GPS selectivity the D-GPS aids along the
track brought (75 % before them, 85 % with them on 100 runs) and the IMU test's looks after the
toe (89.1 % on these 40 runs, 86 % on 100; the median distance after the switch until resolved
27 m with one test at the window's end, 14 m with the looks; the floors leave room)."""

from __future__ import annotations

from pathlib import Path

import pytest

from dbtools.database import read_network
from fieldlogs.pipeline.track_truth import TrackFigures
from fieldlogs.simulate.network_runs import network_runs
from tests.bench.scripts import load_script

RUNS, SEED = 40, 31


@pytest.mark.slow
def test_network_accuracy_floor(sample_network_db: Path, tmp_path: Path) -> None:
    bench = load_script("accuracy_network")
    runs = network_runs(read_network(sample_network_db), RUNS, SEED)
    results = [bench.one((i, str(sample_network_db), str(tmp_path), r)) for i, r in enumerate(runs)]
    assert {r["condition"] for r in results} == set(bench.CONDITIONS)
    s = sum((r["figures"] for r in results), TrackFigures()).summary()
    assert s["facing_switches"] >= 100
    assert s["wrong_track_cycles"] == 0
    assert s["switches_resolved_wrongly"] == 0
    assert s["switches_resolved_correctly"] >= 0.99
    dgps = sum((r["figures"] for r in results if r["condition"] == "D-GPS"), TrackFigures()).summary()
    assert dgps["selectivity"] >= 0.87, dgps
    assert dgps["median_resolution_m"] <= 20.0, dgps
    determined = sum(r["determined"] for r in results)
    assert sum(r["det_within"] for r in results) >= 0.999 * determined > 0


RAW_RUNS = 12


@pytest.mark.slow
def test_network_accuracy_raw_gnss(sample_network_db: Path, tmp_path: Path) -> None:
    """The bench's raw-GNSS condition (runs 40–51 of the same draw, as ``--runs 40 --raw-runs
    12``): simulated pseudoranges along the routes, balise-only otherwise, half of the runs with
    multipath at the neighbouring tracks over the whole route — no wrong-track claim, no facing
    switch resolved wrongly, |error| ≤ margin on every determined cycle."""
    bench = load_script("accuracy_network")
    runs = network_runs(read_network(sample_network_db), RUNS + RAW_RUNS, SEED)[RUNS:]
    results = [bench.one((RUNS + j, str(sample_network_db), str(tmp_path), r, bench.RAW)) for j, r in enumerate(runs)]
    assert {r["condition"] for r in results} == {bench.RAW}
    assert sum(r["multipath"] for r in results) >= RAW_RUNS // 2
    s = sum((r["figures"] for r in results), TrackFigures()).summary()
    assert s["facing_switches"] >= 20
    assert s["wrong_track_cycles"] == 0 and s["switches_resolved_wrongly"] == 0
    determined = sum(r["determined"] for r in results)
    assert sum(r["det_within"] for r in results) == determined > 0
