"""Fail-safe watch and the residual's lobe rule (``odometry.watch``, ``odometry.start_point``).

Scenarios from ``test_odometry`` (exact 100 Hz kinematics, 3 cm pulses). A slide longer
than the maximum correction time fails safe with the wheel still sliding; from then on the
distance runs on the sliding pulses, and only the watch's allowance keeps
|distance error| ≤ allowance. The lobe rule is tested on hand-written residual traces.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.pipeline.odometry.start_point import LOBE_RATIO, lobe
from tests.fieldlogs.pipeline.test_odometry import (
    THR,
    assert_odometry_sane,
    const,
    detections,
    ramp,
    scenario,
    slip_pulse,
    streams,
)

CFG = OdometryConfig()


def long_slide(depth: float = 0.3, onset: float = 15.0, dur: float = 15.0):
    """Braking at 0.5 m/s² from 22 m/s, the wheel sliding ``depth`` for ``dur`` s."""
    return scenario(50.0, const(-0.4), 22.0, slip=slip_pulse(onset, dur, -depth, edge=0.5), ax_noise_kmh_s=0.1)


def test_allowance_covers_the_pulses_sliding_on_after_the_failsafe() -> None:
    sc = long_slide()
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    ep = odo.episodes[0]
    assert ep.failsafe and ep.t_end < 30.0  # the slide lasts until 30 s
    d = ep.watch
    assert d is not None
    assert d.readhered and d.speed_source == "inertial"
    assert 30.0 < d.end_t < 33.0  # the speeds agree again soon after the slide
    err = np.abs(odo.d - sc.s_true)
    after = slice(ep.i_end, None)
    assert (err[after] <= odo.allowance[after]).all()
    # the pulses lost ≈ 0.3 × 18 m/s × 5 s after the fail-safe: the watch gave at least that
    lost = (sc.s_true[-1] - sc.s_true[ep.i_end]) - (sc.cycles.d_pulse[-1] - sc.cycles.d_pulse[ep.i_end])
    assert lost > 15.0
    assert d.allowance_m >= lost
    assert odo.allowance[-1] == pytest.approx(ep.max_error_m + d.allowance_m)
    # without the watch the allowance stops at eq. 13's budget and the error outgrows it
    off = correct_odometry(sc.cycles, replace(CFG, failsafe_watch_s=0.0))
    assert off.episodes[0].watch is None
    assert (np.abs(off.d - sc.s_true) > off.allowance).any()


def test_watch_after_a_slide_ending_with_the_failsafe_is_short() -> None:
    """The slide ends just before the time limit: the watch only waits for the re-adhesion
    test (1 s mean speeds agreeing for 1 s) and grows by about Δa·T per second then."""
    sc = long_slide(onset=15.0, dur=9.0)
    odo = correct_odometry(sc.cycles, CFG)
    ep = odo.episodes[0]
    assert ep.failsafe
    d = ep.watch
    assert d is not None
    assert d.readhered
    watch_s = d.end_t - ep.t_end
    assert 1.0 <= watch_s <= 3.0
    rate = CFG.delta_a_mps2 * CFG.max_correction_s  # 4.6 m/s at 10 s from the start point
    # plus the rest of the slide (≈ 0.3 × 12 m/s over its last ~0.6 s) and its 1 s mean
    assert rate * watch_s <= d.allowance_m <= rate * watch_s + 0.5 * CFG.delta_a_mps2 * watch_s**2 + 5.0


# --------------------------------------------------------------------------- lobe rule
def lobes(end_peak: float) -> str:
    """Residual: noise-free zero, an opposite (negative) lobe of −0.7·THR over 10–12 s, the
    detected positive lobe from 15 s peaking at ``end_peak``·THR; the criterion ``lobe``
    gives for the detection at its threshold crossing."""
    sc = scenario(30.0, const(0.0), 10.0)
    s, d = streams(sc), detections(sc)
    t = sc.cycles.t
    res = -0.7 * THR * (ramp(t, 10.0, 10.5) - ramp(t, 11.5, 12.0))
    res += end_peak * THR * (ramp(t, 15.0, 16.0) - ramp(t, 17.0, 18.0))
    det = int(np.flatnonzero(res > THR)[0])
    crit, ref = lobe(res, det, d.horizon, s.filters.M, THR)
    if crit == "residual-end":
        assert 10.2 <= t[ref] <= 10.45  # the look-back counts from the onset lobe beyond half THR
    return crit


def test_end_lobe_like_its_onset_lobe_is_a_short_slips_end() -> None:
    assert lobes(1.5) == "residual-end"
    assert lobes(0.7 * LOBE_RATIO * 0.99) == "residual-end"


def test_end_lobe_far_larger_than_the_opposite_lobe_is_a_new_disturbance() -> None:
    assert lobes(0.7 * LOBE_RATIO * 1.01) == "residual"
    assert lobes(20.0) == "residual"


def test_a_slip_going_on_at_constant_speed_keeps_the_watch_growing() -> None:
    """From 3 m/s: +0.5 m/s² up to 20 s, then 13 m/s steady; the wheel +30 % over 5–55 s. From
    20 s the wheel's and the body's accelerations agree (both 0) while the pulses run 3.9 m/s
    ahead: agreeing accelerations are no sign of adhesion (bench/NOTES.md, "Slide label": a
    watch ended on them after a filter length stopped at 19.7 s with 76 m of error at 35 s
    against 67 m of allowance). Only the speeds' agreement ends the watch: it runs its 20 s."""
    sc = scenario(
        70.0, lambda t: np.where(t < 20.0, 0.5, 0.0), 3.0, slip=slip_pulse(5.0, 50.0, 0.3, edge=0.5), ax_noise_kmh_s=0.1
    )
    odo = correct_odometry(sc.cycles, CFG)
    slip = odo.episodes[0]
    assert slip.kind == "slip" and slip.failsafe and slip.t_end == pytest.approx(14.9)
    assert slip.watch is not None and not slip.watch.readhered
    assert slip.watch.end_t == pytest.approx(slip.t_end + CFG.failsafe_watch_s)
    t = sc.cycles.t
    on = (t >= slip.t_start) & (t <= 55.0)
    err = (odo.d - sc.s_true)[on] - (odo.d - sc.s_true)[np.flatnonzero(on)[0]]
    assert err.max() > 150.0  # the pulses' 30 % over 40 s after the fail-safe
    assert (np.abs(err) <= odo.allowance[on] + 0.03).all()  # + one 3 cm pulse
