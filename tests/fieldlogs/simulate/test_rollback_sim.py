"""Rolling back in the simulator (``running.rollback_*``) and the two-phase tacho's ``direction``
column (``tacho.two_phase``) [S003 §2, §5.3(2)]: noise off, checked against the truth stream."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.simulate.samples import sample_scenarios
from fieldlogs.simulate.scenario import ScenarioError, scenario_from_dict
from fieldlogs.simulate.simulator import SimulatedRun, simulate_run

ROLL_M = 3.0
QUIET: dict[str, Any] = {
    "noise": False,
    "imu": {"accel_lsb_mps2": 0.0, "gyro_lsb_deg_s": 0.0},
    "slip": {"slips": 0, "slides": 0},
}


def _merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


@pytest.fixture(scope="module")
def net(sample_network_db: Path) -> Network:
    return read_network(sample_network_db)


def _run(net: Network, extra: dict[str, Any]) -> SimulatedRun:
    over = _merge(_merge(sample_scenarios(net)["sim-d-reversal"], QUIET), extra)
    return simulate_run(net, scenario_from_dict(over, source="test"))


@pytest.fixture(scope="module")
def runs(net: Network) -> tuple[SimulatedRun, SimulatedRun]:
    plain = _run(net, {})
    rolled = _run(net, {"running": {"rollback_m": ROLL_M}, "tacho": {"two_phase": True}})
    return plain, rolled


def _against_cab(streams: dict[str, pd.DataFrame]) -> tuple[np.ndarray, np.ndarray]:
    """Truth rows moving against the driving cab, and the cab sign per truth row."""
    truth, cab = streams["truth"], streams["cab"]
    idx = np.searchsorted(cab["t"].to_numpy(dtype=float), truth["t"].to_numpy(dtype=float), side="right") - 1
    sign = np.where(cab["direction"].astype(str).to_numpy()[idx] == "F", 1.0, -1.0)
    v = truth["speed_mps"].to_numpy(dtype=float)
    return (v * sign < 0), sign


def _spans(mask: np.ndarray) -> list[tuple[int, int]]:
    edges = np.diff(np.concatenate([[0], mask.astype(np.int8), [0]]))
    return list(zip(np.flatnonzero(edges == 1).tolist(), (np.flatnonzero(edges == -1) - 1).tolist(), strict=True))


def test_no_rollback_by_default(runs: tuple[SimulatedRun, SimulatedRun]) -> None:
    plain, _ = runs
    against, _ = _against_cab(plain.streams)
    assert not against.any()
    assert "direction" not in plain.streams["tacho"].columns


def test_rolls_back_slowly_against_the_cab_and_ends_where_planned(runs: tuple[SimulatedRun, SimulatedRun]) -> None:
    plain, rolled = runs
    truth = rolled.streams["truth"]
    against, _ = _against_cab(rolled.streams)
    spans = _spans(against)
    assert len(spans) >= 2  # the start of the run and at least one later start roll back
    v = truth["speed_mps"].to_numpy(dtype=float)
    km = truth["km_m"].to_numpy(dtype=float)
    for a, b in spans:
        assert np.abs(v[a : b + 1]).max() <= 0.5 + 1e-9  # rollback_speed_mps
        # from rest to rest: the km moves back by the rollback distance (truth at 10 Hz: ± 1 cm)
        assert abs(km[b + 1] - km[a - 1]) == pytest.approx(ROLL_M, abs=0.01)
    assert list(rolled.streams["cab"]["direction"]) == list(plain.streams["cab"]["direction"])  # cab unchanged
    assert km[-1] == pytest.approx(plain.streams["truth"]["km_m"].iloc[-1], abs=1e-6)  # same end point
    # the wheels roll the rollback forth and back: 2·r more per rollback
    st0, st1 = plain.meta.extra["sim_truth"], rolled.meta.extra["sim_truth"]
    assert st1["distance_m"] - st0["distance_m"] == pytest.approx(2 * ROLL_M * len(spans), abs=0.05)


def test_two_phase_direction_is_the_sign_of_the_body_speed(runs: tuple[SimulatedRun, SimulatedRun]) -> None:
    _, rolled = runs
    tacho, truth = rolled.streams["tacho"], rolled.streams["truth"]
    pulses = tacho["pulses"].to_numpy()
    assert (np.diff(pulses) >= 0).all()  # still counting up whatever the sense
    came = np.diff(pulses, prepend=pulses[0]) > 0
    direction = tacho["direction"].to_numpy()
    assert set(np.unique(direction)) == {-1, 0, 1}
    assert (direction[~came] == 0).all()
    # the sense over the cycle (k−1, k]: the body speed there (truth speed is toward the F end)
    v = truth["speed_mps"].to_numpy(dtype=float)
    both = came & (np.abs(v) > 0.05) & (np.abs(np.roll(v, 1)) > 0.05)
    assert (direction[both] == np.sign(v[both])).all()
    assert (direction[both] == -1).sum() > 0


def test_the_imu_feels_the_rollback(runs: tuple[SimulatedRun, SimulatedRun]) -> None:
    """Body x acceleration less its value at rest, integrated from rest, is the truth speed
    toward the F end (the gradient's share of gravity is the same over the 3 m)."""
    _, rolled = runs
    truth, imu = rolled.streams["truth"], rolled.streams["imu"]
    against, _ = _against_cab(rolled.streams)
    a, b = _spans(against)[0]
    t0, t1 = float(truth["t"].iloc[a - 1]), float(truth["t"].iloc[b + 1])
    t_imu = imu["t"].to_numpy(dtype=float)
    ax = imu["ax"].to_numpy(dtype=float)
    rest = ax[(t_imu > t0 - 2.0) & (t_imu <= t0)].mean()
    w = (t_imu >= t0) & (t_imu <= t1)
    v_imu = np.cumsum(ax[w] - rest) * 0.01
    v_true = np.interp(t_imu[w], truth["t"].to_numpy(dtype=float), truth["speed_mps"].to_numpy(dtype=float))
    assert np.abs(v_imu - v_true).max() < 0.02
    assert v_true.min() < -0.3


def test_rollback_knobs_checked() -> None:
    with pytest.raises(ScenarioError, match="rollback_speed_mps"):
        scenario_from_dict({"running": {"rollback_speed_mps": 5.0}})
    with pytest.raises(ScenarioError, match="rollback_m"):
        scenario_from_dict({"running": {"rollback_m": -1.0}})
    with pytest.raises(ScenarioError, match="readers_x_m"):
        scenario_from_dict({"balise": {"readers_x_m": [9.5]}})
    with pytest.raises(ScenarioError, match="readers_x_m"):
        scenario_from_dict({"balise": {"readers_x_m": [9.5, float("nan")]}})
