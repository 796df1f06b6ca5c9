"""The radar in the whole pipeline, from its IF samples (issue 18, phase 2): seeded
simulated runs, each replayed with its ``radar_if`` and without it (statistics only; the
benchmark over 30+ runs is ``bench/bench_radar_pipeline.py``).

Two short runs (≈ 70 s: from standstill to 60 km/h and back to a stop) with a 6 s slip
while accelerating and a 14 s slide while braking — longer than ``max_correction_s``, so
without the radar it ends in a fail-safe.
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from fieldlogs.pipeline.aids.radar_if import RadarIfSpeedAid
from fieldlogs.pipeline.aids.registry import speed_aids
from fieldlogs.pipeline.run import PipelineResult, run_pipeline
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run


def scenario(track: str, cab: str, look: str) -> dict[str, Any]:
    start = 18800.0 if track == "D" else 21000.0
    sign = 1.0 if track == "D" else -1.0
    return {
        "name": f"radar-pipeline-{track}{cab}{look}",
        "route": {"track": track, "path_km_m": [start, start + sign * 560.0], "start_cab": cab},
        "running": {
            "line_speed_kmh": 60.0,
            "stop_at_stations": False,
            "standstill_start_s": 5.0,
            "standstill_end_s": 5.0,
        },
        "slip": {
            "slips": 0,
            "slides": 0,
            "on_grade_curve": False,
            "episodes": [
                {"t0_s": 9.0, "duration_s": 6.0, "kind": "slip", "depth": 0.3},
                {"t0_s": 42.0, "duration_s": 14.0, "kind": "slide", "depth": 0.25},
            ],
        },
        "sensors": {"radar_if": True},
        "radar_if": {"looks_toward": look},
    }


@pytest.fixture(scope="module")
def replays(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> list[tuple[Any, ...]]:
    """(truth stream, sim_truth, with radar, without radar) of the two runs."""
    net = read_network(sample_db)
    root = tmp_path_factory.mktemp("radar-pipeline")
    out = []
    for i, (track, cab, look) in enumerate((("D", "F", "F"), ("U", "R", "R"))):
        streams, meta = simulate_run(net, scenario_from_dict(scenario(track, cab, look)), seed=77 + i)
        folder = write_run(root / f"run{i}", meta, streams)
        plain = root / f"plain{i}"
        shutil.copytree(folder, plain, ignore=shutil.ignore_patterns("radar*"))
        with_r, without = (run_pipeline(read_run(f), net) for f in (folder, plain))
        out.append((streams["truth"], meta.extra["sim_truth"], with_r, without))
    return out


def episode_errors(res: PipelineResult, truth: pd.DataFrame) -> list[float]:
    """Relative distance error of each re-adhered correction against the truth [%]."""
    t = truth["t"].to_numpy(dtype=float)
    v = np.abs(truth["speed_mps"].to_numpy(dtype=float))
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * np.diff(t))])
    t_cyc = res.positions["t"].to_numpy(dtype=float)
    out = []
    for ep in res.odometry.episodes:
        true = float(np.interp(ep.t_end, t, s) - np.interp(ep.t_start, t, s))
        corr = float(np.interp(ep.t_end, t_cyc, res.odometry.d) - np.interp(ep.t_start, t_cyc, res.odometry.d))
        out.append(100.0 * (corr - true) / true)
    return out


@pytest.mark.slow
def test_radar_removes_the_failsafe_and_keeps_the_episodes_within_half_a_per_cent(
    replays: list[tuple[Any, ...]],
) -> None:
    for truth, st, with_r, without in replays:
        injected = st["slip_episodes"]
        # without the radar the 14 s slide fails safe (what the test shows the radar removes)
        assert without.summary["n_failsafe"] >= 1
        eps = with_r.odometry.episodes
        assert with_r.summary["n_failsafe"] == 0 and len(eps) == len(injected) == 2
        for ep, e in zip(eps, injected, strict=True):
            assert ep.kind == e["kind"] and ep.criterion == "radar" and ep.speed_source == "radar"
            assert ep.readhered and ep.t_start <= e["t0"] and ep.t_end >= e["t1"] - 0.5
        errs = episode_errors(with_r, truth)
        assert max(abs(x) for x in errs) <= 0.5, errs
        # margins from the radar's σ: covered, and below the pulses + IMU ones
        for res in (with_r, without):
            cmp = compare_with_truth(res.positions, truth)
            assert cmp.loc[cmp.claimed, "within_margin"].all()
        m_with, m_without = (r.positions["margin_m"].max() for r in (with_r, without))
        assert m_with < m_without
        assert sum(ep.max_error_m for ep in eps) < 0.1 * sum(ep.max_error_m for ep in without.odometry.episodes)


@pytest.mark.slow
def test_summary_reports_the_radar_and_the_wheel_calibration(replays: list[tuple[Any, ...]]) -> None:
    for _truth, st, with_r, without in replays:
        radar = with_r.summary["radar"]
        assert radar["source"] == "radar_if" and radar["covered_share"] > 0.95 and radar["against_cab_s"] == 0.0
        cal = with_r.summary["wheel_calibration"]
        true = st["wheel_diameter_true_m"]
        lo, hi = cal["diameter_ci95_m"]
        assert lo <= true <= hi and hi - lo < 0.003 * true
        assert cal["applied"] is False  # off by default
        assert "radar" not in without.summary and "wheel_calibration" not in without.summary


def test_if_aid_is_registered_before_the_ready_stream(sample_db: Path, tmp_path: Path) -> None:
    """A run with both ``radar_if`` and a ready ``radar`` stream is aided by the IF samples;
    without run.json's radar block the IF aid has nothing to work with."""
    net = read_network(sample_db)
    sc = scenario("D", "F", "F")
    sc["running"] = {**sc["running"], "line_speed_kmh": 20.0}
    sc["route"]["path_km_m"] = [18800.0, 18850.0]
    sc["slip"] = {"slips": 0, "slides": 0, "on_grade_curve": False}
    sc["sensors"] = {"radar_if": True, "radar": True}
    streams, meta = simulate_run(net, scenario_from_dict(sc), seed=5)
    run = read_run(write_run(tmp_path / "run", meta, streams))
    aids = speed_aids({"radar_if": streams["radar_if"], "radar": streams["radar"]}, run.radar)
    assert [a.name for a in aids] == ["radar_if", "radar"]
    assert isinstance(aids[0], RadarIfSpeedAid)
    assert [a.name for a in speed_aids({"radar_if": streams["radar_if"], "radar": streams["radar"]}, None)] == ["radar"]
    res = run_pipeline(run, net)
    assert res.summary["radar"]["source"] == "radar_if"
    ground = aids[0].on_cycles(res.cycles) if res.cycles is not None else None
    assert ground is not None and ground.signed_mps is not None
    moving = np.abs(ground.signed_mps) > 1.0
    assert moving.sum() > 50 and (ground.signed_mps[moving] > 0).all()  # + toward F, cab F
