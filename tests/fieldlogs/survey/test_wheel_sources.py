"""Wheel diameters of simulated runs with a radar and with raw GNSS on the bundled sample
network: each source within 0.1 % of the truth, the sources agreeing, and a radar whose
mounting reads 0.3 % high found inconsistent."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.sample_network import sample_source_dir
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from fieldlogs.survey.result import SurveyReport
from fieldlogs.survey.runner import survey
from tests.fieldlogs.gnss.runs import simulate_gnss_run

SAMPLE = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs" / "sim-d-slips"

WEAR = 0.4
SEEDS = (51, 52, 53)


def _true(folder: str) -> float:
    return float(json.loads((Path(folder) / "run.json").read_text())["sim_truth"]["wheel_diameter_true_m"])


@pytest.fixture(scope="module")
def fleet(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(DB, logs): three runs of vehicle EMU-R with a radar (the third with a mounting that
    reads 0.3 % high, in logs/bad only) and one run of vehicle EMU-G with raw GNSS."""
    root = tmp_path_factory.mktemp("wheel-sources")
    db = root / "net.sqlite"
    build_db(sample_source_dir(), db)
    net = read_network(db)
    for k, seed in enumerate(SEEDS):
        start = pd.Timestamp("2026-03-01T08:00:00+09:00") + pd.Timedelta(days=k)
        sc = scenario_from_dict(
            {
                "route": {"track": "D"},
                "run": {"run_id": f"R-{seed}", "vehicle_id": "EMU-R", "start_time": start.isoformat()},
                "tacho": {"wear_pct": [WEAR, WEAR]},
                "sensors": {"radar": True},
            }
        )
        sim = simulate_run(net, sc, seed=seed)
        write_run(root / "logs" / "radar" / f"r{seed}", sim.meta, sim.streams)
        streams = dict(sim.streams)
        streams["radar"] = streams["radar"].assign(speed_mps=streams["radar"]["speed_mps"] * 1.003)
        write_run(root / "logs" / "bad" / f"r{seed}", sim.meta, streams)
    simulate_gnss_run(net, root / "logs" / "gnss" / "g1", seed=11, length_m=6000.0)
    return db, root / "logs"


@pytest.fixture(scope="module")
def radar_report(fleet: tuple[Path, Path]) -> SurveyReport:
    return survey([fleet[1] / "radar"], fleet[0], workers=1)


def test_radar_runs_have_three_sources_within_a_tenth_of_a_percent(radar_report: SurveyReport) -> None:
    wr = radar_report.wheel_runs
    assert len(wr) == 3 and (wr["radar_source"] == "radar").all() and (wr["gnss_source"] == "dgps").all()
    true = wr["run_id"].map({r.run_id: _true(r.folder) for r in radar_report.runs.itertuples()})
    for col in ("diameter_m", "diameter_balise_m", "diameter_radar_m", "diameter_gnss_m"):
        assert ((wr[col] / true - 1).abs() < 0.001).all(), (col, wr[col] / true - 1)
    assert (wr["sources"] == 3).all() and wr["consistent"].map(bool).all()
    v = radar_report.wheels.iloc[0]
    assert v["runs_radar"] == 3 and v["runs_balise"] == 3 and v["runs_gnss"] == 3
    assert abs(v["diameter_m"] / true.mean() - 1) < 0.001 and bool(v["consistent"])
    assert v["status"] == "alert"  # 0.4 % worn, beyond the 0.3 % alert share
    assert radar_report.summary()["wheels_inconsistent"] == 0


def test_the_wheel_calibration_setting_does_not_change_the_survey(
    fleet: tuple[Path, Path], radar_report: SurveyReport
) -> None:
    cfg = PipelineConfig()
    scaled = replace(cfg, odometry=replace(cfg.odometry, wheel_calibration=True))
    rep = survey([fleet[1] / "radar"], fleet[0], pipeline=scaled, workers=1)
    pd.testing.assert_frame_equal(rep.wheel_runs, radar_report.wheel_runs)


def test_a_radar_reading_high_disagrees_with_balises_and_gnss(fleet: tuple[Path, Path]) -> None:
    rep = survey([fleet[1] / "bad"], fleet[0], workers=1)
    wr = rep.wheel_runs
    assert ((wr["diameter_radar_m"] / wr["diameter_balise_m"] - 1) > 0.002).all()
    assert not wr["consistent"].map(bool).any()
    v = rep.wheels.iloc[0]
    assert v["consistent"] is not None and not bool(v["consistent"])
    assert rep.summary()["wheels_inconsistent"] == 1 and rep.flagged
    assert rep.to_dict()["summary"]["wheels_inconsistent"] == 1


def test_a_raw_gnss_run_uses_the_track_constrained_solutions(fleet: tuple[Path, Path]) -> None:
    rep = survey([fleet[1] / "gnss"], fleet[0], workers=1)
    r = rep.wheel_runs.iloc[0]
    assert r["gnss_source"] == "gnss" and r["radar_source"] is None
    true = _true(rep.runs["folder"].iloc[0])
    assert abs(r["diameter_gnss_m"] / true - 1) < 0.001
    assert abs(r["diameter_m"] / true - 1) < 0.001
    run = rep.to_dict()["wheels"]["runs"][0]
    assert run["gnss_source"] == "gnss" and run["consistent"] is True


def test_the_survey_measures_a_turned_wheel_against_run_json(sample_db: Path, tmp_path: Path) -> None:
    """Pulses 5 % over run.json's 0.86 m wheel: the pipeline divides the balise intervals' scale
    out of the pulses (``margin.wheel_rescale``), which the survey turns off, so the wheel is
    measured against run.json's diameter — 0.86 / 1.05 = 0.819 m (true 0.8591 m, 0.1 % worn:
    0.8182 m). With the rescaling on the survey read 0.8563 m (−0.4 %), hiding the 5 %."""
    run = tmp_path / "logs" / "r1"
    shutil.copytree(SAMPLE, run)
    tacho = pd.read_parquet(run / "tacho.parquet")
    tacho.assign(pulses=(tacho["pulses"] * 1.05).round().astype("int64")).to_parquet(run / "tacho.parquet")
    rep = survey([tmp_path / "logs"], sample_db, workers=1)
    r = rep.wheel_runs.iloc[0]
    assert r["diameter_m"] == pytest.approx(0.859118 / 1.05, rel=0.002)
    assert r["diff_share"] < -0.04
