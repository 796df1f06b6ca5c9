"""Re-adhesion speed update of the slip correction (``odometry.episodes`` docstring).

The scenarios are those of ``test_odometry`` (exact 100 Hz kinematics, 3 cm pulses). A known
inertial error is injected by hand: from the slip's onset on the accelerometer reads
``C`` too much (a bias shift, or the same as a pitch error of C/G), which the start point
(before the onset) cannot see. The inertial speed is then off by C·(t − onset), the
correction's distance by ½·C·(t_end − onset)², and at re-adhesion the 1 s means differ by
≈ C·(t_end − onset − 0.45 s) (the mean over the last second is centred 0.45 s before
t_end): the update subtracts δ·(t − t0)/T and moves the distance by −δ·0.05·(m + 1) m on
a 0.1 s grid of m cycles.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.correct import correct_odometry
from tests.fieldlogs.pipeline.test_odometry import (
    Scenario,
    assert_odometry_sane,
    const,
    internals,
    ramp,
    scenario,
    slip_pulse,
)

ON = OdometryConfig()
OFF = replace(ON, readhesion_speed_update=False)
C = 0.03  # accelerometer error from the onset on [m/s²] (≈ 0.1 km/h/s, the ADIS16480 class bias)
ONSET = 15.0
LAG = 0.3  # the harness's IMU lag: the IMU cycle at t holds the motion of t − 0.3 s


def _low_speed_slip(c: float) -> Scenario:
    """Slip of 5 s at 4 m/s (1 m/s + 0.2 m/s² from t = 0), a ≈ 35 m correction; from the
    onset on the accelerometer reads ``c`` too much."""
    sc = scenario(35.0, const(0.2), 1.0, slip=slip_pulse(ONSET, 5.0, 0.3))
    sc.cycles.imu["ax"] = sc.cycles.imu["ax"] + c * (sc.cycles.t >= ONSET + LAG - 1e-9)
    return sc


def test_speed_update_removes_a_linear_speed_error() -> None:
    clean, sc = _low_speed_slip(0.0), _low_speed_slip(C)  # the same pulses
    clean_off, clean_on = correct_odometry(clean.cycles, OFF), correct_odometry(clean.cycles, ON)
    (r0,), (r1,) = clean_off.episodes, clean_on.episodes
    off, on = correct_odometry(sc.cycles, OFF), correct_odometry(sc.cycles, ON)
    assert_odometry_sane(on, sc)
    (e0,), (e1,) = off.episodes, on.episodes
    # detection, start point and re-adhesion do not depend on the update, nor on C
    assert (e0.i_start, e0.i_end, e0.readhered) == (e1.i_start, e1.i_end, True)
    assert (r0.i_start, r0.i_end) == (e1.i_start, e1.i_end)
    s, e = e1.i_start, e1.i_end
    m = e - s
    T = 0.1 * m
    tau = sc.cycles.t[e] - ONSET  # how long the error acted
    assert sc.cycles.t[s] < ONSET and tau > 5.0

    # open loop, C adds ½·C·τ² to the distance (hand: 0.03/2 · 6.5² = 0.63 m of ≈ 34 m) …
    assert e0.d_corrected_m - r0.d_corrected_m == pytest.approx(0.5 * C * tau**2, abs=0.02)
    # … and C·(τ − 0.45 s) to δ, the 1 s means' difference at re-adhesion
    delta = internals(on, e1).end_speed_error_mps
    assert delta == internals(off, e0).end_speed_error_mps
    assert delta - internals(clean_on, r1).end_speed_error_mps == pytest.approx(C * (tau - 0.45), abs=0.005)
    assert e0.speed_update_m == 0.0

    # the ramp δ·(t − t0)/T: distance −δ·Σ_k k·0.01/T = −δ·0.05·(m + 1), the end speed δ lower
    assert e1.speed_update_m == pytest.approx(-delta * 0.05 * (m + 1), rel=1e-9)
    assert e1.d_corrected_m - e0.d_corrected_m == pytest.approx(e1.speed_update_m, abs=1e-9)
    assert on.v[e] == pytest.approx(off.v[e] - delta, abs=1e-9)
    assert on.v[s + 1] == pytest.approx(off.v[s + 1] - delta * 0.1 / T, abs=1e-9)
    assert on.d[-1] - off.d[-1] == pytest.approx(e1.speed_update_m, abs=1e-9)

    # closed: C's part left is ½·C·τ² − C·(τ − 0.45)·0.05·(m + 1) (hand: 0.63 − 0.69 m)
    left = e1.d_corrected_m - r1.d_corrected_m
    assert left == pytest.approx(0.5 * C * tau**2 - C * (tau - 0.45) * 0.05 * (m + 1), abs=0.02)
    assert abs(left) < 0.15 * 0.5 * C * tau**2
    true = sc.s_true[e] - sc.s_true[s]
    assert abs(e1.d_corrected_m - true) < 0.005 * true < abs(e0.d_corrected_m - true)
    # bounded by the re-adhesion tolerance, whatever the cause of δ
    bound = (ON.readhesion_tol_kmh / 3.6 + ON.beta_mps2 * T) * 0.05 * (m + 1)
    assert abs(e1.speed_update_m) <= bound


def test_no_speed_update_without_an_adhering_end() -> None:
    """A fail-safe ends without a pulse speed to compare with: no δ, nothing moved."""
    onset = 15.0
    sc = scenario(45.0, const(0.0), 10.0, slip=lambda t: 0.9 * ramp(t, onset, onset + 15.0))
    on, off = correct_odometry(sc.cycles, ON), correct_odometry(sc.cycles, OFF)
    ep = on.episodes[0]
    assert ep.failsafe and not ep.readhered
    assert internals(on, ep).end_speed_error_mps is None
    assert ep.speed_update_m == 0.0
    np.testing.assert_array_equal(on.d, off.d)


def test_speed_update_leaves_an_exact_correction_alone() -> None:
    """Without any IMU error δ is within the 1 s mean quantisation (one pulse per second) and
    the update moves the distance by at most that over half the correction time."""
    sc = _low_speed_slip(0.0)
    on = correct_odometry(sc.cycles, ON)
    (ep,) = on.episodes
    assert ep.readhered
    T = ep.t_end - ep.t_start
    assert abs(internals(on, ep).end_speed_error_mps) <= 0.035
    assert abs(ep.speed_update_m) <= 0.035 * (T / 2 + 0.05)
    true = sc.s_true[ep.i_end] - sc.s_true[ep.i_start]
    assert abs(ep.d_corrected_m - true) < 0.005 * true
