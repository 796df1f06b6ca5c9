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
from hypothesis import given
from hypothesis import strategies as st

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.pipeline import run as run_module
from fieldlogs.pipeline.cycles import IMU_COLUMNS, Cycles, tacho_motion
from fieldlogs.pipeline.rollback import _starts, detect_rollbacks, inferred_rotation
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


def _starts_by_definition(v: np.ndarray, rest: int) -> list[tuple[int, int]]:
    """The starts as the module docstring defines them, cycle by cycle: a first moving cycle i₀
    after ≥ ``rest`` cycles at rest, its stretch ending at the first j ≥ i₀ that begins ``rest``
    cycles at rest (the run's end without one)."""
    moving = v > 0
    n = v.size
    out = []
    for i0 in range(rest, n):
        if moving[i0] and not moving[i0 - 1] and not moving[i0 - rest : i0].any():
            ends = [j for j in range(i0, n - rest + 1) if not moving[j : j + rest].any()]
            out.append((i0, ends[0] if ends else n))
    return out


def test_starts_hand_computed() -> None:
    v = np.array([0, 0, 1, 1, 0, 0, 0, 1, 0, 0, 1], float)
    # rest 2: after cycles 0-1, 5-6 and 8-9 at rest; stretches end where 2 cycles at rest begin
    assert _starts(v, 2) == [(2, 4), (7, 8), (10, 11)]
    # rest 3: cycle 2 has only 2 cycles at rest before it, cycle 10 only 2 (8-9); 7 runs to the end
    assert _starts(v, 3) == [(7, 11)]
    assert _starts(np.array([0.0, 1.0]), 2) == []  # shorter than a standstill plus a cycle


@given(st.lists(st.sampled_from([0.0, 0.0, 0.5]), max_size=60), st.integers(1, 5))
def test_starts_as_defined(v: list[float], rest: int) -> None:
    speed = np.array(v, dtype=float)
    assert _starts(speed, rest) == _starts_by_definition(speed, rest)


def test_every_start_of_a_long_run_is_judged_alike() -> None:
    """Judging a start reads only the cycles around it: the same rollback repeated after a
    stop (braking 10 s at −0.5 m/s² from 5 m/s) is found at each repetition with the same
    figures."""
    block = [*ROLL, (10.0, -0.5)]
    cycles_per_block = round(sum(d for d, _ in block) / DT)
    found = detect_rollbacks(_cycles(block * 4))
    assert [r.first for r in found] == [50 + k * cycles_per_block for k in range(4)]
    assert [r.last - r.first for r in found] == [78] * 4
    assert [r.distance_m for r in found] == pytest.approx([1.6] * 4, abs=0.02)
    assert [r.ratio for r in found] == pytest.approx([-1.0] * 4, abs=0.05)


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
