"""Rolling back with a tachometer that gives no sense: the IMU finds it
(:mod:`fieldlogs.pipeline.rollback`, :mod:`fieldlogs.pipeline.aids.rollback`) [S003 §2, §5.3(2)].

Hand-computed cycles, then seeded simulated runs over the sample network (a turnback with a
10 m rollback at each uphill start): with the two-phase tacho's ``direction`` column the
positions stay within their margins on the right track; without it, the IMU's detection keeps
them so (position *uncertain* after each rollback), and without the detection the error is
≈ 2 × the rollback and leaves the margin."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.pipeline import run as run_module
from fieldlogs.pipeline.cycles import IMU_COLUMNS, Cycles, tacho_motion
from fieldlogs.pipeline.rollback import detect_rollbacks, inferred_rotation
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.samples import sample_scenarios
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import EventType, PositionState

DT = 0.1
A_REST = 0.049  # gravity's share along the body on a 5 ‰ gradient + bias [m/s²]


def _cycles(accel: list[tuple[float, float]], cab: int = 1, rotation: np.ndarray | None = None) -> Cycles:
    """Cycles of a vehicle with body acceleration (duration s, a toward F m/s²) pieces; the IMU
    reads a + A_REST, the tacho |v| (unsigned)."""
    a = np.concatenate([np.full(round(d / DT), x) for d, x in accel])
    v = np.cumsum(a) * DT  # body speed toward F at the end of each cycle
    v[np.abs(v) < 1e-9] = 0.0
    speed = np.abs(v)
    d = np.cumsum(speed) * DT
    n = a.size
    imu = {c: np.full(n, np.nan) for c in IMU_COLUMNS}
    imu["ax"] = a + A_REST
    return Cycles(
        np.arange(n) * DT, d / 0.03, d, speed, imu, np.full(n, cab, np.int8), np.ones(n, np.int8), True, True, rotation
    )


# rest 5 s; roll back: −0.1 m/s² for 4 s, +0.1 for 4 s (0.4 m/s, 1.6 m); rest 3 s; move off 0.5 m/s² for 10 s
ROLL = [(5.0, 0.0), (4.0, -0.1), (4.0, 0.1), (3.0, 0.0), (10.0, 0.5)]


def test_a_rollback_against_the_cab_is_found() -> None:
    cycles = _cycles(ROLL)
    (rb,) = detect_rollbacks(cycles)
    assert rb.first == 50  # the first cycle with pulses
    assert rb.last == 128  # v is back to 0 at the end of cycle 129: cycle 128 is the last that moved
    assert rb.distance_m == pytest.approx(1.6, abs=0.02)  # ½·0.4 m/s·8 s
    assert rb.ratio == pytest.approx(-1.0, abs=0.05)
    rot = inferred_rotation(cycles, [rb])
    assert (rot[50:129] == -1).all() and (rot[:50] == 0).all() and (rot[160:] == 1).all()
    assert tacho_motion(rot, cycles.cab)[140] == -1  # at rest the last sense holds


def test_reversed_cab_rolling_back_toward_f() -> None:
    flipped = [(d, -x) for d, x in ROLL]  # cab R: moving off toward R, rolling back toward F
    (rb,) = detect_rollbacks(_cycles(flipped, cab=-1))
    assert rb.distance_m == pytest.approx(1.6, abs=0.02)
    assert (inferred_rotation(_cycles(flipped, cab=-1), [rb])[50:129] == 1).all()


def test_ordinary_starts_are_not_rollbacks() -> None:
    assert detect_rollbacks(_cycles([(5.0, 0.0), (10.0, 0.5), (4.0, -1.25), (3.0, 0.0), (6.0, 0.5)])) == []
    slow_creep = [(5.0, 0.0), (4.0, 0.1), (4.0, -0.1), (3.0, 0.0)]  # creeping 1.6 m forward and stopping
    assert detect_rollbacks(_cycles(slow_creep)) == []
    # a two-phase tacho gives the sense itself: nothing to infer
    assert detect_rollbacks(_cycles(ROLL, rotation=np.zeros(210, np.int8))) == []


# -- seeded simulated runs ------------------------------------------------------------------
ROLLBACK_M = 10.0


@pytest.fixture(scope="module")
def net(sample_network_db: Path) -> Network:
    return read_network(sample_network_db)


@pytest.fixture(scope="module")
def rolled_run(net: Network, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """sim-d-reversal (seed 103) rolling back 10 m at its uphill starts: with and without the
    tacho's direction column."""
    over: dict[str, Any] = dict(sample_scenarios(net)["sim-d-reversal"])
    over["running"] = {"rollback_m": ROLLBACK_M}
    over["tacho"] = {"two_phase": True}
    streams, meta = simulate_run(net, scenario_from_dict(over, source="test"))
    root = tmp_path_factory.mktemp("rollback")
    signed = write_run(root / "two-phase", meta, streams)
    unsigned = write_run(root / "unsigned", meta, {**streams, "tacho": streams["tacho"].drop(columns="direction")})
    return signed, unsigned


def _figures(folder: Path, net: Network) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    res = run_pipeline(read_run(folder), net)
    cmp = compare_with_truth(res.positions, res.truth)
    judged = cmp[cmp["claimed"] & np.isfinite(cmp["error_m"])]
    return judged, res.positions, res.events


def test_two_phase_tacho_keeps_the_margin(rolled_run: tuple[Path, Path], net: Network) -> None:
    judged, _, events = _figures(rolled_run[0], net)
    assert len(judged) > 4000
    assert (judged["error_m"].abs() <= judged["margin_m"]).all()
    assert not judged["wrong_track"].any()
    assert EventType.ROLLBACK_SUSPECTED.value not in set(events["type"])


def test_unsigned_tacho_rollbacks_found_by_the_imu(rolled_run: tuple[Path, Path], net: Network) -> None:
    judged, positions, events = _figures(rolled_run[1], net)
    found = events[events["type"] == EventType.ROLLBACK_SUSPECTED.value]
    assert len(found) == 2
    assert [json.loads(e)["distance_m"] for e in found["detail"]] == pytest.approx([ROLLBACK_M] * 2, abs=0.1)
    assert (judged["error_m"].abs() <= judged["margin_m"]).all()
    assert not judged["wrong_track"].any()
    # after the later rollback (a position existed) the position is uncertain, not determined,
    # until five agreeing D-GPS fixes along the track confirm it (aids/track_gps_along.py)
    t1 = float(found["t"].iloc[1])
    confirmed = events[(events["type"] == EventType.GPS_CORRECTION.value) & (events["t"] > t1)]
    confirmed = confirmed[[("confirmed_by_fixes" in json.loads(d)) for d in confirmed["detail"]]]
    t2 = float(confirmed["t"].iloc[0]) if len(confirmed) else t1 + 5.0
    assert t2 - t1 >= 4.0  # five fixes at 1 Hz at the least
    after = positions[(positions["t"] > t1) & (positions["t"] < t2)]
    assert len(after) and (after["state"] == PositionState.UNCERTAIN.value).all()


def test_without_the_detection_the_error_leaves_the_margin(
    rolled_run: tuple[Path, Path], net: Network, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Why the detection exists: the counted-forward rollback puts the position ≈ 2 × 10 m
    ahead, beyond its margin."""
    monkeypatch.setattr(run_module, "detect_rollbacks", lambda cycles: [])
    judged, _, events = _figures(rolled_run[1], net)
    assert EventType.ROLLBACK_SUSPECTED.value not in set(events["type"])
    worst = judged["error_m"].abs().max()
    assert 1.5 * ROLLBACK_M < worst < 2.5 * ROLLBACK_M
    assert (judged["error_m"].abs() > judged["margin_m"]).any()
