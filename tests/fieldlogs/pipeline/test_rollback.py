"""Rolling back: the sense of motion from a two-phase tachometer (the tacho ``direction``
column) against the driving cab [S003 §2, §5.3(2)] — hand-computed cases."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given
from hypothesis import strategies as st

from fieldlogs.pipeline.cycles import build_cycles, tacho_motion
from fieldlogs.pipeline.estimate import Travel, signed_travel
from fieldlogs.pipeline.types import pulse_only_odometry
from schemas import units

WHEEL_M, TEETH = 0.86, 100
M_PER_PULSE = units.metres_per_pulse(WHEEL_M, TEETH)


def test_the_last_sense_given_holds_and_the_cab_before_the_first() -> None:
    rotation = np.array([0, 0, 1, 1, 0, -1, -1, 0, 1], dtype=np.int8)
    cab = np.array([-1, -1, 1, 1, 1, 1, 1, 1, 1], dtype=np.int8)
    assert tacho_motion(rotation, cab).tolist() == [-1, -1, 1, 1, 1, -1, -1, -1, 1]
    assert tacho_motion(np.zeros(3, np.int8), np.array([1, -1, 1], np.int8)).tolist() == [1, -1, 1]


def _tacho(steps: list[int], direction: list[int] | None) -> pd.DataFrame:
    pulses = np.concatenate([[1000], 1000 + np.cumsum(np.abs(steps))])
    frame = pd.DataFrame({"t": np.arange(len(pulses)) * 0.1, "pulses": pd.array(pulses, dtype="Int64")})
    if direction is not None:
        frame["direction"] = pd.array([0, *direction], dtype="Int64")
    return frame


def test_a_roll_back_on_a_gradient_is_subtracted() -> None:
    # 100 pulses forward, 20 back (rolling back with the cab still forward), 50 forward:
    # the unsigned travel is 170 pulses, the body-forward travel 130
    steps = [10] * 10 + [5] * 4 + [10] * 5
    sense = [1] * 10 + [-1] * 4 + [1] * 5
    cycles = build_cycles(tacho=_tacho(steps, sense), imu=None, cab=None, wheel_diameter_m=WHEEL_M, teeth=TEETH)
    odo = pulse_only_odometry(cycles.d_pulse, cycles.v_pulse)
    s = signed_travel(cycles, odo)
    assert np.isclose(cycles.d_pulse[-1], 170 * M_PER_PULSE)
    assert np.isclose(s[-1], 130 * M_PER_PULSE)
    assert np.isclose(s[:15].max(), s[10]) and np.isclose(s[10], 100 * M_PER_PULSE)
    assert np.isclose(s[14], 80 * M_PER_PULSE)
    travel = Travel.of(cycles, odo)
    assert travel.motion.tolist()[11:15] == [-1] * 4 and travel.cab.tolist()[11:15] == [1] * 4


def test_without_a_direction_column_the_cab_gives_the_sense() -> None:
    steps = [10] * 10
    cab = pd.DataFrame({"t": [0.55], "direction": ["R"]})
    cycles = build_cycles(tacho=_tacho(steps, None), imu=None, cab=cab, wheel_diameter_m=WHEEL_M, teeth=TEETH)
    assert cycles.rotation is None
    odo = pulse_only_odometry(cycles.d_pulse, cycles.v_pulse)
    assert np.isclose(signed_travel(cycles, odo)[-1], (50 - 50) * M_PER_PULSE)
    assert Travel.of(cycles, odo).rotation_motion is None


@given(st.lists(st.tuples(st.integers(0, 30), st.sampled_from([-1, 0, 1])), min_size=2, max_size=60))
def test_signed_travel_is_the_sum_of_signed_steps(rows: list[tuple[int, int]]) -> None:
    steps = [n for n, _ in rows]
    sense = [s for _, s in rows]
    cycles = build_cycles(tacho=_tacho(steps, sense), imu=None, cab=None, wheel_diameter_m=WHEEL_M, teeth=TEETH)
    odo = pulse_only_odometry(cycles.d_pulse, cycles.v_pulse)
    # hand rule: a step moves with the last nonzero sense given up to it (+1 before the first)
    last, want = 1, 0.0
    for n, sg in rows:
        last = sg if sg != 0 else last
        want += last * n
    assert np.isclose(signed_travel(cycles, odo)[-1], want * M_PER_PULSE)
    assert np.isclose(cycles.d_pulse[-1], sum(steps) * M_PER_PULSE)
