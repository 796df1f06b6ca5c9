"""The one tacho validator (``fieldlogs.quality.tacho``): hand-made streams, each problem
found at the right file line, in the documented order, and the possession filter's reason."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.quality.tacho import (
    TachoIssue,
    TachoLimits,
    cumulative_again,
    pulse_resets,
    review_tacho,
    unusable_reason,
)
from schemas.units import metres_per_pulse

D, TEETH = 0.86, 90
K = math.pi * D / TEETH  # hand-computed metres per pulse
POSSESSION = TachoLimits(max_median_step_s=0.35, max_speed_mps=14.0, max_speed_label="twice max_speed_mps")


def stream(speed_mps: float = 2.0, n: int = 50) -> pd.DataFrame:
    t = np.arange(n) / 10.0
    return pd.DataFrame({"t": t, "pulses": np.floor(speed_mps * t / K).astype(np.int64)})


def issues(frame: pd.DataFrame, **kw: object) -> list[TachoIssue]:
    return [f.issue for f in review_tacho(frame, kw.get("d", D), kw.get("teeth", TEETH), POSSESSION)]  # type: ignore[arg-type]


def test_metres_per_pulse_is_pi_d_over_teeth() -> None:
    assert metres_per_pulse(D, TEETH) == K
    assert metres_per_pulse(1.0, 1) == pytest.approx(3.14159265, abs=1e-8)


def test_pulse_helpers() -> None:
    p = np.array([10, 20, 2, 5, 1, 3, 2])
    resets, decs = pulse_resets(p)
    assert resets.tolist() == [2, 4] and decs.tolist() == [6]
    fixed, _ = cumulative_again(p)
    assert fixed.tolist() == [10, 20, 22, 25, 26, 28, 27]
    glitch = np.array([10, 20, 2, 30, 40])  # one low sample that recovers: not a reset
    assert [x.tolist() for x in pulse_resets(glitch)] == [[], [2]]
    assert cumulative_again(glitch)[0].tolist() == glitch.tolist()


def test_clean_stream_has_no_problem() -> None:
    assert review_tacho(stream(), D, TEETH, POSSESSION) == []
    assert unusable_reason([]) is None


@pytest.mark.parametrize(
    ("edit", "issue", "reason"),
    [
        (lambda f: f.assign(pulses=f["pulses"].astype("Float64").where(f.index != 7)), "pulses_missing", "row 9"),
        (lambda f: f.assign(t=f["t"].where(f.index != 3)), "t_missing", "row 5"),
        (lambda f: f.assign(pulses=f["pulses"].where(f.index != 4, -1)), "pulses_negative", "row 6"),
        (lambda f: f.assign(t=f["t"].where(f.index != 5, 0.3)), "t_not_increasing", "t does not increase at row 7"),
        (lambda f: f.assign(pulses=0), "no_pulse", "no pulse at all"),
        (lambda f: f.assign(t=f["t"] * 10), "wrong_rate", "rows 1.00 s apart, not a 10 Hz stream"),
        (lambda f: f.assign(pulses=f["pulses"] * 100), "impossible_speed", "over twice max_speed_mps"),
        (lambda f: f[["t"]], "no_column", "no column pulses"),
        (lambda f: f.iloc[:1], "too_short", "fewer than 2 rows"),
    ],
)
def test_each_problem_is_named_with_its_row(edit: object, issue: str, reason: str) -> None:
    frame = edit(stream())  # type: ignore[operator]
    found = review_tacho(frame, D, TEETH, POSSESSION)
    assert issue in [f.issue for f in found]
    assert reason in str(unusable_reason(found))


def test_reset_and_decrease_rows_and_messages() -> None:
    f = stream()
    p = f["pulses"].to_numpy().copy()
    p[20:] -= p[19] - 1  # the counter restarts near 0 at row 20 (file line 22)
    p[40] = 0  # one low sample at row 40 (line 42) that recovers: a glitch
    f["pulses"] = p
    found = {x.issue: x for x in review_tacho(f, D, TEETH, POSSESSION)}
    reset, dec = found[TachoIssue.PULSE_RESET], found[TachoIssue.PULSE_DECREASE]
    assert reset.rows.tolist() == [20] and dec.rows.tolist() == [40]
    assert reset.detail is not None and reset.detail(0).startswith(f"pulse counter reset from {p[19]} to {p[20]}")
    assert dec.detail is not None and "must never decrease" in dec.detail(0)
    # the possession reason names the first drop, whichever kind it is
    assert unusable_reason(list(found.values())) == "pulses decrease (counter reset?) at row 22"


def test_wheel_fields_come_first() -> None:
    found = review_tacho(stream().assign(pulses=0), None, 0, POSSESSION)
    assert [f.issue for f in found][:2] == [TachoIssue.WHEEL_DIAMETER, TachoIssue.TEETH]
    assert unusable_reason(found) == "run.json wheel_diameter_m None is not a positive number"
    assert "teeth 0" in str(unusable_reason(found[1:]))


def test_speed_jump_is_a_wheel_event_not_a_defect() -> None:
    f = stream(speed_mps=3.0)
    p = f["pulses"].to_numpy().copy()
    p[30:] += 200  # 200 pulses (~6 m) in one cycle at row 30: slip
    f["pulses"] = p
    limits = TachoLimits(max_accel_mps2=5.0)
    (jump,) = review_tacho(f, D, TEETH, limits)
    assert jump.issue == TachoIssue.SPEED_JUMP and jump.rows.tolist() == [30, 31]
    assert jump.limit == pytest.approx(5.0 + 2.0 * K / 0.1**2)
    assert jump.detail is not None and "wheel slip/slide or counter glitch" in jump.detail(0)
    assert unusable_reason([jump]) is None


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.one_of(st.none(), st.integers(-5, 10_000)), min_size=0, max_size=40),
    st.lists(st.one_of(st.none(), st.floats(-1.0, 10.0)), min_size=0, max_size=40),
)
def test_never_raises_and_rows_are_inside_the_frame(pulses: list[int | None], t: list[float | None]) -> None:
    n = min(len(pulses), len(t))
    frame = pd.DataFrame({"t": pd.array(t[:n], dtype="Float64"), "pulses": pd.array(pulses[:n], dtype="Int64")})
    limits = TachoLimits(max_accel_mps2=5.0, max_median_step_s=0.35, max_speed_mps=14.0)
    for f in review_tacho(frame, D, TEETH, limits):
        assert all(0 <= r < n for r in f.rows.tolist())
        assert f.reason and "\n" not in f.reason
