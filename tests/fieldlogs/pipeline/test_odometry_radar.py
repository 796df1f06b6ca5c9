"""The radar's ground speed in the odometry (issue 18 item 3): detection, the fused
correction, re-adhesion and fail-safe on it, the watch, low speed and standstill, the
direction check and the wheel calibration.

Scenarios from ``test_odometry`` (exact 100 Hz kinematics, 3 cm pulses); the radar is the
true speed plus Gaussian noise of its stated σ (its frames' errors shared by 3 cycles).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fieldlogs.pipeline.aid import SpeedOnCycles
from fieldlogs.pipeline.aids.radar_if import frames_on_cycles
from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.pipeline.odometry.detection import detect
from fieldlogs.pipeline.odometry.fusion import GATE_Z, Filtered, kalman_speed, rts
from fieldlogs.pipeline.odometry.ground import GROUND_BIAS_MPS, WEAR_SHARE, align_ground
from fieldlogs.pipeline.odometry.ground_products import CAL_MIN_M
from fieldlogs.pipeline.odometry.streams import align_streams
from fieldlogs.pipeline.types import slip_budget_m
from tests.fieldlogs.pipeline.test_odometry import (
    Scenario,
    assert_odometry_sane,
    const,
    episode_error,
    internals,
    scenario,
    slip_pulse,
)

CFG = OdometryConfig()
FRAME_S = 0.307


def radar(sc: Scenario, sigma: float = 0.03, seed: int = 3, signed: bool = False) -> SpeedOnCycles:
    """True speed + one N(0, σ) error per 0.3 s frame, as the IF aid gives it."""
    rng = np.random.default_rng(seed)
    frame = (sc.cycles.t // FRAME_S).astype(int)
    v = sc.v_true + sigma * rng.standard_normal(frame.max() + 1)[frame]
    sd = np.full(v.size, sigma)
    return SpeedOnCycles(np.abs(v), sd, "radar_if", signed_mps=v if signed else None, frame_s=FRAME_S)


def smoothed(k: Filtered, m_end: int) -> np.ndarray:
    return rts(np.array(k.v), np.array(k.p), np.array(k.v_prior), np.array(k.p_prior), m_end)


# --------------------------------------------------------------------------- hand-computed
def test_kalman_update_and_smoother_by_hand() -> None:
    """v0 = 10 ± 1, a ground value 12 ± 1 at the first cycle, none at the second: K = ½,
    v = 11, P = ½; nothing to predict (Δv = q = 0), the second keeps it; the smoother's gain
    C = P_0 / P⁻_1 = 1 carries v_1 back unchanged."""
    nan = float("nan")
    k = kalman_speed(10.0, 1.0, np.zeros(2), np.zeros(2), np.array([12.0, nan]), np.array([1.0, nan]), 3)
    assert k.v == [11.0, 11.0] and k.p == [0.5, 0.5] and k.used == [True, False]
    assert k.v_prior == [10.0, 11.0] and k.p_prior == [1.0, 0.5]
    np.testing.assert_allclose(smoothed(k, 2), np.array([11.0, 11.0]))
    # a process noise q and an inertial increment: v⁻ = 11 + 0.5, P⁻ = 0.5 + 0.5; the
    # update with 13 ± 1: K = ½ → 12.25; the smoother moves cycle 0 by C = 0.5 / 1 of
    # (12.25 − 11.5)
    k = kalman_speed(10.0, 1.0, np.array([0.0, 0.5]), np.array([0.0, 0.5]), np.array([12.0, 13.0]), np.ones(2), 3)
    assert k.v == [11.0, 12.25] and k.p == [0.5, 0.5]
    np.testing.assert_allclose(smoothed(k, 2), np.array([11.0 + 0.5 * 0.75, 12.25]))


def test_kalman_gate_refuses_an_outlier_and_reseats_on_a_lasting_one() -> None:
    """The cross-check: one ground value 20σ off is refused; more than ``max_run`` in a
    row mean the inertial solution left the radar, and the filter re-seats on it."""
    n = 8
    z = np.full(n, 10.0)
    z[2] = 10.0 + 20.0 * 0.1
    k = kalman_speed(10.0, 0.01, np.zeros(n), np.zeros(n), z, np.full(n, 0.01), 3)
    assert k.refused == 1 and k.reseated == 0 and not k.used[2]
    assert abs(k.v[2] - 10.0) < 1e-9
    far = np.full(n, 15.0)  # 15 vs 10 ± 0.14: beyond GATE_Z·√S
    assert 5.0 > GATE_Z * np.sqrt(0.02)
    k = kalman_speed(10.0, 0.01, np.zeros(n), np.zeros(n), far, np.full(n, 0.01), 3)
    assert k.refused == 4 and k.reseated == 1  # the 4th refusal in a row re-seats
    assert k.used[:4] == [False, False, False, True] and k.v[3] == 15.0 and k.p[3] == 0.01
    assert k.v[:3] == [10.0] * 3 and k.used[4:] == [True] * 4


def test_frames_on_cycles_by_hand() -> None:
    """Frames [0, 0.3) and [0.3, 0.6) (centres 0.15, 0.45): each cycle (t − 0.1, t] takes
    the frame holding its midpoint; a frame without a speed, and time after the last
    frame, give none."""
    t = np.arange(1, 8, dtype=np.float64) * 0.1
    v, sd = frames_on_cycles(
        np.array([0.15, 0.45]), np.array([-2.0, 3.0]), np.array([0.1, 0.2]), 0.3, t, np.full(7, 0.1)
    )
    np.testing.assert_array_equal(v[:6], [-2.0, -2.0, -2.0, 3.0, 3.0, 3.0])
    np.testing.assert_array_equal(sd[:6], [0.1, 0.1, 0.1, 0.2, 0.2, 0.2])
    assert np.isnan(v[6]) and np.isnan(sd[6])
    v, sd = frames_on_cycles(
        np.array([0.15, 0.45]), np.array([np.nan, 3.0]), np.array([np.nan, 0.2]), 0.3, t, np.full(7, 0.1)
    )
    assert np.isnan(v[:3]).all() and np.isnan(sd[:3]).all()


def test_ground_criterion_is_the_pulse_minus_ground_speed_against_its_tolerance() -> None:
    """At constant speed: e = v̄_p − v̄_g of the 1 s means, threshold tol0 + wear·v + z·σ̄
    with σ̄ = σ/√(P/n_c) (a 1 s mean holds 10/3.07 independent frames); no detection."""
    sc = scenario(30.0, const(0.0), 15.0)
    g_in = radar(sc, sigma=0.04)
    s = align_streams(sc.cycles, CFG)
    g = align_ground(s, g_in)
    d = detect(s, CFG, g)
    assert d.ground_e is not None and d.ground_thr is not None and d.ground_mask is not None
    k = 200
    np.testing.assert_allclose(d.ground_e[k], s.vp1[k] - np.mean(g.v[k - 9 : k + 1]))
    sigma1 = 0.04 / np.sqrt(10 / (FRAME_S / 0.1))
    want = CFG.readhesion_tol_kmh / 3.6 + WEAR_SHARE * g.v1[k] + CFG.ground_detect_z * sigma1
    assert d.ground_thr[k] == pytest.approx(want)
    assert not d.ground_mask.any()
    assert correct_odometry(sc.cycles, CFG, g_in).episodes == []


# --------------------------------------------------------------------------- episodes
def test_radar_detects_and_carries_the_episode() -> None:
    """The slip of the eq. 1 test, with a radar: detected by the ground-speed criterion no
    later than by eq. 1; the distance is the radar's (error a few tenths of a per cent,
    within a budget from its σ, far below eq. 13's); re-adhered on the radar speed."""
    onset = 20.0
    sc = scenario(40.0, const(0.5), 5.0, slip=slip_pulse(onset, 4.0, 0.3), ax_noise_kmh_s=0.1)
    plain = correct_odometry(sc.cycles, CFG)
    odo = correct_odometry(sc.cycles, CFG, radar(sc))
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.speed_source == "radar" and ep.criterion == "radar" and ep.kind == "slip"
    assert ep.readhered and not ep.failsafe
    assert onset < ep.t_detect <= plain.episodes[0].t_detect
    assert ep.t_start < onset and ep.t_end > onset + 4.0
    err, err_pulse, true = episode_error(odo, sc)
    assert abs(err) < 0.003 and err_pulse > 0.05
    assert abs(err) * true <= ep.max_error_m < 0.01 * ep.d_corrected_m + 0.5  # the former radar rule
    assert ep.max_error_m < 0.1 * plain.episodes[0].max_error_m
    assert odo.allowance[-1] == pytest.approx(ep.max_error_m)
    assert internals(odo, ep).ground_share == 1.0


def test_radar_gap_inside_the_episode_is_bridged_inertially() -> None:
    """2 s without radar frames inside the correction: the inertial increments bridge them;
    the distance stays accurate and the budget grows by eq. 13 over the gap."""
    onset = 20.0
    sc = scenario(40.0, const(0.5), 5.0, slip=slip_pulse(onset, 4.0, 0.3), ax_noise_kmh_s=0.1)
    full = radar(sc)
    ep_full = correct_odometry(sc.cycles, CFG, full).episodes[0]
    v = full.v_mps.copy()
    v[(sc.cycles.t > onset + 0.5) & (sc.cycles.t < onset + 2.5)] = np.nan
    odo = correct_odometry(sc.cycles, CFG, replace(full, v_mps=v))
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.speed_source == "radar" and ep.readhered
    assert 0.5 < internals(odo, ep).ground_share < 1.0
    err, _, true = episode_error(odo, sc)
    assert abs(err) < 0.005
    gap_budget = 0.5 * CFG.delta_a_mps2 * 2.0**2
    assert ep.max_error_m > ep_full.max_error_m + 0.9 * gap_budget
    assert abs(err) * true <= ep.max_error_m


def long_slide(depth: float = 0.3, onset: float = 15.0, dur: float = 15.0) -> Scenario:
    """Braking at 0.4 m/s² from 22 m/s, the wheel sliding ``depth`` for ``dur`` s."""
    return scenario(50.0, const(-0.4), 22.0, slip=slip_pulse(onset, dur, -depth, edge=0.5), ax_noise_kmh_s=0.1)


def test_a_15_s_slide_readheres_on_the_radar_instead_of_failing_safe() -> None:
    sc = long_slide()
    plain = correct_odometry(sc.cycles, CFG)
    assert plain.episodes[0].failsafe
    odo = correct_odometry(sc.cycles, CFG, radar(sc, seed=5))
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.readhered and not ep.failsafe and ep.speed_source == "radar"
    assert 30.0 < ep.t_end < 32.5  # the slide ends at 30 s; the speeds agree for 1 s
    err, _, true = episode_error(odo, sc)
    assert abs(err) < 0.003
    assert abs(err) * true <= ep.max_error_m < 1.5
    assert (np.abs(odo.d - sc.s_true) <= odo.allowance + 0.05).all()


def test_radar_watch_uses_the_radar_speed() -> None:
    """With ``ground_max_correction_s`` below the slide's length the correction fails safe
    there; the watch follows the radar: it adds the pulses' loss, not Δa·t."""
    sc = long_slide()
    cfg = replace(CFG, ground_max_correction_s=8.0)
    odo = correct_odometry(sc.cycles, cfg, radar(sc, seed=5))
    ep = odo.episodes[0]
    assert ep.failsafe and ep.watch is not None and ep.watch.speed_source == "radar"
    assert ep.t_end - ep.t_start == pytest.approx(8.0, abs=1e-6)
    plain_watch = correct_odometry(sc.cycles, CFG).episodes[0].watch
    assert plain_watch is not None
    assert ep.watch.readhered and ep.watch.allowance_m < 0.6 * plain_watch.allowance_m
    err = np.abs(odo.d - sc.s_true)
    assert (err[ep.i_end :] <= odo.allowance[ep.i_end :]).all()


def test_failsafe_when_the_radar_is_lost_for_the_whole_correction() -> None:
    """No radar frame over the correction: its budget is eq. 13's, so it fails safe at
    ``max_correction_s`` as without radar."""
    sc = long_slide()
    g = radar(sc, seed=5)
    v = g.v_mps.copy()
    v[(sc.cycles.t > 10.0) & (sc.cycles.t < 40.0)] = np.nan
    odo = correct_odometry(sc.cycles, CFG, replace(g, v_mps=v))
    ep = odo.episodes[0]
    assert ep.failsafe and ep.speed_source == "inertial"
    assert ep.t_end - ep.t_start == pytest.approx(CFG.max_correction_s, abs=0.15)
    assert ep.max_error_m == pytest.approx(22.8, abs=0.2)


def test_an_episode_without_radar_values_is_tested_as_without_radar() -> None:
    """The radar has no frame from 15 to 35 s: the slip is found by the same criterion at
    the same cycle, re-adheres within a few cycles of the S000 path (its tolerance, β·t from
    i0) and carries eq. 13's budget."""
    sc = scenario(40.0, const(0.5), 5.0, slip=slip_pulse(20.0, 4.0, 0.3), ax_noise_kmh_s=0.1)
    g = radar(sc)
    v = g.v_mps.copy()
    v[(sc.cycles.t > 15.0) & (sc.cycles.t < 35.0)] = np.nan
    odo = correct_odometry(sc.cycles, CFG, replace(g, v_mps=v))
    (ep,) = odo.episodes
    (pe,) = correct_odometry(sc.cycles, CFG).episodes
    assert ep.speed_source == "inertial" and ep.readhered
    assert (ep.criterion, ep.t_detect, ep.t_start) == (pe.criterion, pe.t_detect, pe.t_start)
    assert abs(ep.t_end - pe.t_end) <= 0.3
    assert ep.max_error_m == pytest.approx(slip_budget_m(ep.duration_s, CFG.delta_a_mps2), abs=1e-6)
    err, _, _ = episode_error(odo, sc)
    assert abs(err) < 0.02


def test_locked_wheel_at_walking_pace_is_found_only_with_the_radar() -> None:
    """At 0.7 m/s (below ``min_speed_kmh``: eq. 1 and the residual do not look) the wheel
    almost stops for 3 s: pulses count 0.07 m/s, the radar the true speed."""
    sc = scenario(30.0, const(0.0), 0.7, slip=slip_pulse(12.0, 3.0, -0.9), ax_noise_kmh_s=0.1)
    assert correct_odometry(sc.cycles, CFG).episodes == []
    odo = correct_odometry(sc.cycles, CFG, radar(sc, sigma=0.02))
    (ep,) = odo.episodes
    assert ep.kind == "slide" and ep.criterion == "radar" and ep.readhered
    err, err_pulse, true = episode_error(odo, sc)
    assert err_pulse < -0.35 and abs(err) * true < 0.1


# --------------------------------------------------------------------------- low speed, direction
def test_speed_at_low_speed_and_standstill_is_the_radars() -> None:
    """Standing 5 s, then 0.2 m/s² to 5 m/s: below ``ground_low_speed_kmh`` the speed is the
    radar's (the pulses' counts whole pulses: 0.3 m/s steps), at standstill exactly 0; the
    distance stays on the pulses."""
    sc = scenario(30.0, lambda t: 0.2 * ((t > 5.0) & (t < 30.0)), 0.0)
    g = radar(sc, sigma=0.02)
    v = g.v_mps.copy()
    v[sc.v_true == 0.0] = 0.0  # standstill frames: 0 ± the lowest measurable speed
    g = replace(g, v_mps=v, sigma_mps=np.where(sc.v_true == 0.0, 0.077, g.sigma_mps))
    plain = correct_odometry(sc.cycles, CFG)
    odo = correct_odometry(sc.cycles, CFG, g)
    assert odo.episodes == plain.episodes == []
    np.testing.assert_array_equal(odo.d, plain.d)
    slow = (sc.v_true > 0.0) & (sc.v_true < CFG.ground_low_speed_kmh / 3.6 - 0.5)
    rms = [float(np.sqrt(np.mean((o.v[slow] - sc.v_true[slow]) ** 2))) for o in (plain, odo)]
    assert rms[1] < 0.04 < 0.1 < rms[0]
    assert (odo.v[sc.cycles.t < 5.0] == 0.0).all()
    assert odo.ground is not None and odo.ground.low_speed_share > 0.5


def test_radar_against_the_cab_direction_is_not_used() -> None:
    """A signed speed the wrong way (radar mounted toward R but declared F, or rolling
    back): the direction check drops it; the odometry is the pulses + IMU one."""
    sc = scenario(40.0, const(0.5), 5.0, slip=slip_pulse(20.0, 4.0, 0.3), ax_noise_kmh_s=0.1)
    g = radar(sc, signed=True)
    assert g.signed_mps is not None
    wrong = replace(g, signed_mps=-g.signed_mps)
    odo = correct_odometry(sc.cycles, CFG, wrong)
    assert odo.ground is not None and odo.ground.against_cab_s > 35.0
    assert [e.speed_source for e in odo.episodes] == ["inertial"]
    assert odo.ground.calibration is None
    right = correct_odometry(sc.cycles, CFG, g)
    assert right.ground is not None and right.ground.against_cab_s == 0.0
    assert [e.speed_source for e in right.episodes] == ["radar"]


# --------------------------------------------------------------------------- wheel calibration
@pytest.mark.parametrize("wear", [0.0, 0.003])
def test_wheel_calibration_measures_the_wheel(wear: float) -> None:
    """A wheel 0.3 % smaller than nominal turns 1/(1 − 0.003) times as often: the pulse
    distance is that much long. r = ground / pulse distance while adhering is the true
    over the nominal diameter, inside its 95 % interval; with ``wheel_calibration`` the
    distance comes out in the true scale."""
    factor = 1.0 / (1.0 - wear) - 1.0
    sc = scenario(200.0, const(0.0), 15.0, slip=const(factor), ax_noise_kmh_s=0.1)
    g = radar(sc, sigma=0.04, seed=11)
    odo = correct_odometry(sc.cycles, CFG, g)
    assert odo.episodes == []
    assert odo.ground is not None
    cal = odo.ground.calibration
    assert cal is not None and not cal.applied and cal.applied_from_t is None
    assert abs(cal.ratio - (1.0 - wear)) <= cal.half_width
    assert cal.half_width < 1.96 * 2 * GROUND_BIAS_MPS / 15.0  # statistics and b, no more
    assert cal.distance_m == pytest.approx(sc.cycles.d_pulse[-1], rel=0.01)
    scaled = correct_odometry(sc.cycles, replace(CFG, wheel_calibration=True), g)
    assert scaled.ground is not None and scaled.ground.calibration is not None
    assert scaled.ground.calibration.applied
    t_on = scaled.ground.calibration.applied_from_t
    assert t_on is not None and sc.s_true[int(t_on / 0.1)] >= CAL_MIN_M * (1.0 - wear) - 1.0
    err_plain = odo.d[-1] - sc.s_true[-1]
    err_scaled = scaled.d[-1] - sc.s_true[-1]
    assert err_plain == pytest.approx(wear / (1.0 - wear) * sc.s_true[-1], abs=0.1)
    # the pulses' error before the scale applies, and the estimate's own (within its interval)
    before = wear / (1.0 - wear) * sc.s_true[int(t_on / 0.1)]
    assert abs(err_scaled) <= before + cal.half_width * sc.s_true[-1] + 0.1
    assert abs(err_scaled) < 0.3 * abs(err_plain) + 1.0


def test_calibration_leaves_out_the_episodes() -> None:
    """The slip's pulses are not in the ratio: with it the estimate still finds the wheel."""
    sc = scenario(120.0, const(0.1), 8.0, slip=slip_pulse(40.0, 5.0, 0.3), ax_noise_kmh_s=0.1)
    odo = correct_odometry(sc.cycles, CFG, radar(sc, seed=2))
    assert len(odo.episodes) == 1 and odo.ground is not None and odo.ground.calibration is not None
    cal = odo.ground.calibration
    assert abs(cal.ratio - 1.0) <= cal.half_width < 0.002
    assert cal.stretches == 2
    assert cal.distance_m < sc.cycles.d_pulse[-1] - odo.episodes[0].d_pulse_m
