"""Slip/slide odometry (SPEC §5.1) on hand-built cycle arrays (no simulator).

Each scenario is integrated exactly on a 100 Hz grid: a rotation matrix R = Rz(Ψ)·Ry(−θ)·Rx(ψ)
(heading Ψ, nose-up pitch θ, roll ψ; SPEC §4.1 frame) gives the specific force
Rᵀ·(dv/dt + G·ẑ) and the body rates from Rᵀ·Ṙ — independently of the kinematic formulas the
module uses. IMU cycle means lag the pulses by 300 ms (what the 3-cycle pulse delay
compensates); pulses are counts of a 90-tooth, 0.86 m wheel (≈ 3 cm quantum).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import Cycles, cycle_means
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.pipeline.odometry.detection import Detections, detect
from fieldlogs.pipeline.odometry.diagnostics import EpisodeDiagnostics
from fieldlogs.pipeline.odometry.streams import AlignedStreams, align_streams
from fieldlogs.pipeline.types import Odometry, SlipEpisode, slip_budget_m
from schemas.units import G, kmh_s_to_mps2

Q = np.pi * 0.86 / 90  # metres per pulse
H = 0.01  # fine grid [s]
CFG = OdometryConfig()
Fn = Callable[[np.ndarray], np.ndarray]


def const(x: float) -> Fn:
    return lambda t: np.full_like(t, x, dtype=float)


def ramp(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 before t0, 1 after t1, linear between."""
    return np.clip((t - t0) / (t1 - t0), 0.0, 1.0)


def slip_pulse(t0: float, dur: float, factor: float, edge: float = 0.3) -> Fn:
    """Wheel speed × (1 + factor) from t0 for ``dur`` s (linear edges of ``edge`` s inside)."""
    return lambda t: factor * (ramp(t, t0, t0 + edge) - ramp(t, t0 + dur - edge, t0 + dur))


@dataclass
class Scenario:
    cycles: Cycles
    s_true: np.ndarray
    v_true: np.ndarray
    theta: np.ndarray
    psi: np.ndarray


def scenario(
    seconds: float,
    accel: Fn,
    v0: float,
    *,
    theta: Fn = const(0.0),
    roll: Fn = const(0.0),
    yaw_rate: Fn = const(0.0),
    slip: Fn = const(0.0),
    cab: int = 1,
    ax_noise_kmh_s: float = 0.0,
    imu_lag_s: float = 0.3,
    pulse_phase_m: float = 0.013,
    seed: int = 0,
) -> Scenario:
    rng = np.random.default_rng(seed)
    tf = np.arange(-2.0, seconds + 0.5, H)
    a = accel(tf)
    v = v0 + np.concatenate([[0.0], np.cumsum(0.5 * (a[1:] + a[:-1]) * H)])
    v = v - np.interp(0.0, tf, v) + v0  # v(0) = v0
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * H)])
    s -= np.interp(0.0, tf, s)
    th, ps = theta(tf), roll(tf)
    yaw = np.concatenate([[0.0], np.cumsum(0.5 * (yaw_rate(tf)[1:] + yaw_rate(tf)[:-1]) * H)])
    ct, st_, cp, sp, cy, sy = np.cos(th), np.sin(th), np.cos(ps), np.sin(ps), np.cos(yaw), np.sin(yaw)
    one, zero = np.ones_like(tf), np.zeros_like(tf)
    rz = np.stack([np.stack([cy, -sy, zero], -1), np.stack([sy, cy, zero], -1), np.stack([zero, zero, one], -1)], 1)
    ry = np.stack([np.stack([ct, zero, -st_], -1), np.stack([zero, one, zero], -1), np.stack([st_, zero, ct], -1)], 1)
    rx = np.stack([np.stack([one, zero, zero], -1), np.stack([zero, cp, -sp], -1), np.stack([zero, sp, cp], -1)], 1)
    rot = rz @ ry @ rx  # body (travel frame) → world, x forward, y left, z up
    vel = v[:, None] * rot[:, :, 0]
    f_world = np.gradient(vel, H, axis=0) + np.array([0.0, 0.0, G])
    f = np.einsum("nji,nj->ni", rot, f_world)
    omega = np.einsum("nji,njk->nik", rot, np.gradient(rot, H, axis=0))
    w = np.stack([omega[:, 2, 1], omega[:, 0, 2], omega[:, 1, 0]], -1)

    n = round(seconds / 0.1) + 1
    t = np.arange(n) * 0.1
    s_wheel = np.concatenate([[0.0], np.cumsum(0.5 * ((v * (1 + slip(tf)))[1:] + (v * (1 + slip(tf)))[:-1]) * H)])
    s_wheel -= np.interp(0.0, tf, s_wheel)
    pulses = np.floor((np.interp(t, tf, s_wheel) + pulse_phase_m) / Q)
    d_pulse = (pulses - pulses[0]) * Q
    v_pulse = np.diff(d_pulse, prepend=d_pulse[0]) / 0.1
    sign = np.array([cab, cab, 1, cab, cab, 1], dtype=float)  # travel frame → body frame
    cols = np.concatenate([f, w], axis=1) * sign
    imu = {c: cycle_means(t, tf + imu_lag_s, cols[:, j]) for j, c in enumerate(("ax", "ay", "az", "wx", "wy", "wz"))}
    imu["ax"] = imu["ax"] + rng.normal(0.0, ax_noise_kmh_s / 3.6, n) if ax_noise_kmh_s else imu["ax"]
    cycles = Cycles(
        t=t,
        pulses=pulses,
        d_pulse=d_pulse,
        v_pulse=v_pulse,
        imu=imu,
        cab=np.full(n, cab, dtype=np.int8),
        pto=np.ones(n, dtype=np.int8),
        has_tacho=True,
        has_imu=True,
    )
    return Scenario(cycles, np.interp(t, tf, s), np.interp(t, tf, v), np.interp(t, tf, th), np.interp(t, tf, ps))


def assert_odometry_sane(odo: Odometry, sc: Scenario) -> None:
    assert np.all(np.diff(odo.d) >= -1e-12), "distance must never decrease"
    assert np.all(np.diff(odo.allowance) >= -1e-12)
    assert np.all(odo.v >= 0)
    starts = [ep.i_start for ep in odo.episodes[1:]] + [odo.d.size - 1]
    for ep, nxt in zip(odo.episodes, starts, strict=True):
        assert odo.slipping[ep.i_start + 1 : ep.i_end + 1].all()
        after = slice(ep.i_end, nxt + 1)
        # after the episode the distance follows the pulses with a constant offset
        off = odo.d[after] - sc.cycles.d_pulse[after]
        if not ep.truncated:
            np.testing.assert_allclose(off, off[0], atol=1e-9)


def internals(odo: Odometry, ep: SlipEpisode) -> EpisodeDiagnostics:
    """The algorithm internals of episode ``ep`` of ``odo``."""
    assert odo.diagnostics is not None
    return odo.diagnostics.episodes[odo.episodes.index(ep)]


def episode_error(odo: Odometry, sc: Scenario) -> tuple[float, float, float]:
    """(relative error of the corrected distance, of the pulse distance, true distance) over the episode."""
    (ep,) = odo.episodes
    true = sc.s_true[ep.i_end] - sc.s_true[ep.i_start]
    return (ep.d_corrected_m - true) / true, (ep.d_pulse_m - true) / true, true


# --------------------------------------------------------------------------- slips and slides


def test_slip_while_accelerating_level() -> None:
    onset = 20.0
    sc = scenario(40.0, const(0.5), 5.0, slip=slip_pulse(onset, 4.0, 0.3), ax_noise_kmh_s=0.1)
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.kind == "slip"
    assert 0.0 < ep.t_detect - onset < 1.0  # 0.3 s pulse delay + filter response
    assert ep.start_found
    assert ep.t_start < onset - 0.5  # look-back lands before the onset (pulses still adhering)
    assert ep.readhered and not ep.failsafe
    assert ep.t_end > onset + 4.0
    err, err_pulse, true = episode_error(odo, sc)
    assert abs(err) < 0.02
    assert err_pulse > 0.05  # what the correction removed
    assert abs(ep.theta0_rad) < 0.002
    # from the end on the allowance is the eq. 13 budget of the actual duration
    T = ep.t_end - ep.t_start
    assert odo.allowance[ep.i_end :] == pytest.approx(0.5 * CFG.delta_a_mps2 * T**2)
    assert ep.max_error_m == pytest.approx(slip_budget_m(T, CFG.delta_a_mps2))
    assert odo.allowance[: ep.i_start + 1].max() == 0.0
    # the whole-run distance error stays inside the budget
    assert abs(odo.d[-1] - sc.s_true[-1]) < 0.02 * true
    assert abs(odo.d[-1] - sc.s_true[-1]) < ep.max_error_m


def test_slide_while_braking() -> None:
    onset = 15.0
    sc = scenario(35.0, const(-0.7), 25.0, slip=slip_pulse(onset, 3.0, -0.25), ax_noise_kmh_s=0.1, seed=1)
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.kind == "slide"
    assert 0.0 < ep.t_detect - onset < 1.0
    assert ep.readhered and not ep.failsafe
    err, err_pulse, _ = episode_error(odo, sc)
    assert abs(err) < 0.02
    assert err_pulse < -0.05


def test_slip_on_25_permil_gradient() -> None:
    onset = 20.0
    grade = np.arctan(0.025)
    sc = scenario(40.0, const(0.3), 4.0, theta=const(grade), slip=slip_pulse(onset, 3.5, 0.35), ax_noise_kmh_s=0.1)
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.kind == "slip"
    assert ep.theta0_rad == pytest.approx(grade, abs=0.002)
    assert internals(odo, ep).theta_end_rad == pytest.approx(grade, abs=0.002)
    err, _, true = episode_error(odo, sc)
    assert abs(err) < 0.02
    # without the gravity term (θ = 0) the error would be ½·G·sinθ·T², far outside 2 %
    T = ep.t_end - ep.t_start
    assert 0.5 * G * np.sin(grade) * T**2 > 0.05 * true


def test_slip_in_canted_curve_keeps_pitch() -> None:
    """Left curve R = 400 m entered through a 4 s transition (roll 0 → −0.08 rad) on 10 ‰.

    θ̇ = −wy·cosψ + wz·sinψ must stay ≈ 0: integrating −wy alone drifts by wz·sinψ
    (≈ 0.003 rad/s here), a flipped sign by twice that.
    """
    onset, v0 = 14.0, 15.0
    grade = np.arctan(0.010)
    sc = scenario(
        34.0,
        const(0.0),
        v0,
        theta=const(grade),
        roll=lambda t: -0.08 * ramp(t, 11.0, 15.0),
        yaw_rate=lambda t: v0 / 400.0 * ramp(t, 11.0, 15.0),
        slip=slip_pulse(onset, 3.5, 0.3),
        ax_noise_kmh_s=0.1,
    )
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.readhered
    assert ep.t_start < 15.0 < ep.t_end  # the correction spans the transition into the curve
    assert sc.psi[ep.i_start] < -0.01  # ... and starts inside it
    assert internals(odo, ep).psi0_rad == pytest.approx(sc.psi[ep.i_start], abs=0.003)  # eq. 11
    assert ep.theta0_rad == pytest.approx(grade, abs=0.002)
    assert internals(odo, ep).theta_end_rad == pytest.approx(grade, abs=0.002)
    err, _, _ = episode_error(odo, sc)
    assert abs(err) < 0.01


def test_reversed_running_gives_the_same_result() -> None:
    onset = 20.0
    kw = {"slip": slip_pulse(onset, 3.5, 0.3), "theta": const(np.arctan(0.015))}
    fwd = scenario(40.0, const(0.4), 6.0, cab=1, **kw)
    rev = scenario(40.0, const(0.4), 6.0, cab=-1, **kw)
    assert np.nanmean(rev.cycles.imu["ax"]) < 0 < np.nanmean(fwd.cycles.imu["ax"])
    odo_f, odo_r = correct_odometry(fwd.cycles, CFG), correct_odometry(rev.cycles, CFG)
    assert_odometry_sane(odo_r, rev)
    (ep,) = odo_r.episodes
    assert ep.kind == "slip" and ep.readhered
    assert ep.theta0_rad == pytest.approx(np.arctan(0.015), abs=0.002)
    np.testing.assert_allclose(odo_r.d, odo_f.d, atol=1e-9)
    err, _, _ = episode_error(odo_r, rev)
    assert abs(err) < 0.02


def test_failsafe_after_max_correction_time() -> None:
    """A wheel spinning up for 15 s (excess acceleration 0.6 m/s² > Ta): never re-adheres."""
    onset = 15.0
    sc = scenario(45.0, const(0.0), 10.0, slip=lambda t: 0.9 * ramp(t, onset, onset + 15.0))
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    ep = odo.episodes[0]
    assert ep.failsafe and not ep.readhered
    assert ep.t_end - ep.t_start == pytest.approx(CFG.max_correction_s, abs=1e-6)
    assert ep.max_error_m == pytest.approx(22.8, abs=0.1)
    assert odo.allowance[ep.i_end] == pytest.approx(ep.max_error_m)
    # after the fail-safe the distance runs on the (still slipping) pulses again
    assert not odo.slipping[ep.i_end + 1 :].any() or len(odo.episodes) > 1
    k = ep.i_end + 20
    assert odo.d[k] - odo.d[ep.i_end] == pytest.approx(sc.cycles.d_pulse[k] - sc.cycles.d_pulse[ep.i_end])
    # no second episode while |a_x − A_p| stays above Ta (re-arm needs a falling edge)
    assert all(e.t_detect > ep.t_end for e in odo.episodes[1:])


def test_two_episodes_accumulate_allowance() -> None:
    slips = [slip_pulse(15.0, 3.0, 0.3), slip_pulse(35.0, 3.0, -0.3)]
    sc = scenario(60.0, const(0.2), 5.0, slip=lambda t: slips[0](t) + slips[1](t), ax_noise_kmh_s=0.1)
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    assert [ep.kind for ep in odo.episodes] == ["slip", "slide"]
    assert all(ep.readhered for ep in odo.episodes)
    assert odo.allowance[-1] == pytest.approx(sum(ep.max_error_m for ep in odo.episodes))
    first = odo.episodes[0]
    assert odo.allowance[odo.episodes[1].i_start] == pytest.approx(first.max_error_m)
    assert abs(odo.d[-1] - sc.s_true[-1]) < 0.01 * sc.s_true[-1]


def test_second_slip_right_after_failsafe_is_not_corrected_from_a_slipping_start() -> None:
    """Slips at 15–18 s and 21–23 s: one correction, fail-safe after 10 s; the end of the
    second slip is detected (as a slide) too soon after the fail-safe to find an adhering
    start point, so it must not open a correction initialised from slipping pulses."""
    slips = [slip_pulse(15.0, 3.0, 0.3), slip_pulse(21.0, 2.0, 0.3)]
    sc = scenario(60.0, const(0.2), 5.0, slip=lambda t: slips[0](t) + slips[1](t), ax_noise_kmh_s=0.1)
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.failsafe
    assert len(internals(odo, ep).redetect_t) >= 2
    # the distance error is what the pulses slipped after the fail-safe, nothing worse
    pulse_excess_after = (sc.cycles.d_pulse[-1] - sc.cycles.d_pulse[ep.i_end]) - (sc.s_true[-1] - sc.s_true[ep.i_end])
    err_at_end = odo.d[ep.i_end] - sc.s_true[ep.i_end]
    assert odo.d[-1] - sc.s_true[-1] == pytest.approx(err_at_end + pulse_excess_after, abs=0.05)
    assert abs(err_at_end) < ep.max_error_m


def test_eq13_budget_at_10_s() -> None:
    assert slip_budget_m(10.0, CFG.delta_a_mps2) == pytest.approx(22.8, abs=0.1)
    assert slip_budget_m(5.0, CFG.delta_a_mps2) == pytest.approx(22.8 / 4, abs=0.03)


# --------------------------------------------------------------------------- second criterion


def streams(sc: Scenario, cfg: OdometryConfig = CFG) -> AlignedStreams:
    return align_streams(sc.cycles, cfg)


def detections(sc: Scenario, cfg: OdometryConfig = CFG) -> Detections:
    return detect(align_streams(sc.cycles, cfg), cfg)


THR = kmh_s_to_mps2(CFG.residual_threshold_kmh_s)  # 0.125 m/s²


@pytest.mark.parametrize(
    ("accel", "v0", "factor", "kind"),
    [(0.1, 5.0, 0.08, "slip"), (-0.1, 11.0, -0.08, "slide")],
)
def test_shallow_slip_below_ta_found_by_the_residual(accel: float, v0: float, factor: float, kind: str) -> None:
    """8 m/s at the onset (t = 30 s), wheel speed ±8 % = ±0.64 m/s ramped in over 1 s and
    out over 1 s, 3 s in all, on a level line. K = MA3∘MA1 turns the 0.64 m/s step into a
    bump of 0.64/3 ≈ 0.21 m/s² (+ 8 % of the 0.1 m/s² acceleration): below Ta = 0.34 m/s²,
    so eq. 1 never fires, but far above the residual's 0.125 m/s²."""
    onset, dur = 30.0, 3.0
    sc = scenario(50.0, const(accel), v0, slip=slip_pulse(onset, dur, factor, edge=1.0), ax_noise_kmh_s=0.1)
    s = streams(sc)
    assert np.nanmax(np.abs(s.diff[s.warm :])) < CFG.ta_mps2  # invisible to the SPEC criterion
    assert 1.5 * THR < np.nanmax(np.abs(detections(sc).residual)) < CFG.ta_mps2
    assert correct_odometry(sc.cycles, replace(CFG, residual_threshold_kmh_s=0.0)).episodes == []
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.kind == kind and ep.criterion == "residual"
    assert np.sign(internals(odo, ep).residual_at_detect_kmh_s) == (-1 if kind == "slip" else 1)
    assert 0.0 < ep.t_detect - onset < 1.8
    assert ep.t_start < onset and ep.readhered and not ep.failsafe
    assert onset + dur <= ep.t_end < onset + dur + 2.0  # not before the wheel re-adheres
    err, err_pulse, _ = episode_error(odo, sc)
    assert abs(err) < 0.01
    assert abs(err_pulse) > 0.02
    pulse_excess = sc.cycles.d_pulse[-1] - sc.s_true[-1]  # ≈ ±0.64 m/s × 2 s
    assert abs(pulse_excess) > 1.0
    assert abs(odo.d[-1] - sc.s_true[-1]) < 0.2 * abs(pulse_excess)


def test_residual_quiet_over_a_vertical_curve_onto_25_permil() -> None:
    """0 → 25 ‰ over 5 s at 10 m/s (a 2 km vertical curve) while accelerating and braking,
    no slip: G·sinθ grows by 0.245 m/s², 0.2 m/s² of it within the residual's 4 s horizon —
    K·(a_x − A_p) changes by more than the threshold, the gyro pitch takes it out."""

    def accel(t: np.ndarray) -> np.ndarray:
        return 0.4 * ramp(t, 10, 12) - 0.4 * ramp(t, 24, 26) - 0.5 * ramp(t, 40, 42)

    sc = scenario(60.0, accel, 10.0, theta=lambda t: np.arctan(0.025 * ramp(t, 20, 25)), ax_noise_kmh_s=0.1)
    s, d = streams(sc), detections(sc)
    h = d.horizon
    assert np.nanmax(np.abs(s.diff[h:] - s.diff[:-h])[s.warm :]) > 1.4 * THR  # the grade is in a_x − A_p
    assert np.nanmax(np.abs(d.residual)) < 0.4 * THR
    assert correct_odometry(sc.cycles, CFG).episodes == []


def test_residual_quiet_in_a_canted_curve() -> None:
    """R = 300 m at 20 m/s (ω_z = 0.067 rad/s) entered through a 6 s transition to 100 mrad
    of cant, on 10 ‰, no slip. The pitch gyro reads Ψ̇·cosθ·sinψ ≈ −6.7 mrad/s in the
    curve: −wy alone would be a pitch change of 27 mrad (0.26 m/s²) within 4 s; eq. 12's
    wz·sinψ cancels it."""
    v0 = 20.0
    sc = scenario(
        60.0,
        const(0.0),
        v0,
        theta=const(np.arctan(0.010)),
        roll=lambda t: -0.1 * ramp(t, 20, 26),
        yaw_rate=lambda t: v0 / 300.0 * ramp(t, 20, 26),
        ax_noise_kmh_s=0.1,
    )
    d = detections(sc)
    wy = sc.cycles.imu["wy"]
    naive = G * np.abs(np.convolve(-wy * 0.1, np.ones(d.horizon), "valid")).max()  # ∫ −wy over 4 s
    assert naive > 2.0 * THR
    assert np.nanmax(np.abs(d.residual)) < 0.4 * THR
    assert correct_odometry(sc.cycles, CFG).episodes == []


def test_short_shallow_slip_seen_only_at_its_end_starts_before_it() -> None:
    """A 2 s slip of 10 % at 3 m/s (0.3 m/s of excess): its onset lobe in the residual stays
    below the threshold, the end lobe (the wheel slowing back) crosses it ≈ 3 s after the
    slip, with the opposite sign. The look-back must count from the onset lobe, not from
    the detection (that start point would lie after the slip), and the kind is a slip."""
    onset, dur = 20.0, 2.0
    sc = scenario(45.0, const(0.1), 1.0, slip=slip_pulse(onset, dur, 0.1, edge=0.7), ax_noise_kmh_s=0.1)
    d = detections(sc)
    on = slice(round(onset / 0.1), round((onset + 2.5) / 0.1))
    assert -THR < np.nanmin(d.residual[on]) < -0.5 * THR  # the onset lobe: seen, not detected
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.criterion == "residual-end" and ep.kind == "slip"
    assert ep.t_detect > onset + dur + 1.0
    assert ep.t_start < onset and ep.readhered
    err, _, _ = episode_error(odo, sc)
    assert abs(err) < 0.02


def test_gyro_bias_is_estimated_and_removed() -> None:
    """A pitch-gyro bias of 2 mrad/s (0.11 °/s): uncorrected, the pitch drifts 20 mrad in a
    10 s correction and the inertial speed by ≈ 1 m/s. The slope of u over the 40 s of
    adhering running before the slip gives it back."""
    onset = 40.0
    sc = scenario(60.0, const(0.3), 3.0, slip=slip_pulse(onset, 6.0, 0.3), ax_noise_kmh_s=0.1)
    sc.cycles.imu["wy"] = sc.cycles.imu["wy"] + 0.002
    before = slice(0, round(onset / 0.1))
    assert np.nanmax(np.abs(detections(sc).residual[before])) < 0.4 * THR  # G·b·H = 0.08 m/s² uncorrected
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert internals(odo, ep).gyro_bias_rad_s == pytest.approx(-0.002, abs=2e-4)  # θ̇ = −wy + …
    assert ep.readhered
    err, _, _ = episode_error(odo, sc)
    assert abs(err) < 0.01
    assert abs(odo.d[-1] - sc.s_true[-1]) < 1.0
    off = correct_odometry(sc.cycles, replace(CFG, bias_window_s=0.0))
    assert off.episodes[0].failsafe  # the drifting inertial speed never meets the pulses again
    assert abs(off.d[-1] - sc.s_true[-1]) > 3.0


def _jerky(t: np.ndarray) -> np.ndarray:
    return 0.6 * ramp(t, 0, 1) - 0.6 * ramp(t, 30, 31) - 0.5 * ramp(t, 80, 82) + 0.5 * ramp(t, 115, 116)


@pytest.mark.parametrize(("lag_s", "cycles"), [(0.0, 0), (0.3, 3), (0.6, 6)])
def test_pulse_delay_is_found_from_the_run(lag_s: float, cycles: int) -> None:
    """The IMU lags the pulses by ``lag_s``; four jerk-limited transitions in 120 s are enough
    evidence. Without the search the SPEC's 3 cycles stay, and a wrong delay shows in
    K·(a_x − A_p) as delay error × jerk (0.3 s × 0.6 m/s³ → ≈ 0.06 m/s² after K)."""
    sc = scenario(120.0, _jerky, 0.5, imu_lag_s=lag_s, ax_noise_kmh_s=0.1, seed=3)
    s = streams(sc)
    assert s.delay == cycles
    spec = streams(sc, replace(CFG, pulse_delay_search_cycles=0))
    assert spec.delay == 3
    quiet = np.nanmax(np.abs(s.diff[s.warm + 6 :]))
    assert quiet < 0.035
    if cycles != 3:
        assert np.nanmax(np.abs(spec.diff[spec.warm + 6 :])) > quiet + 0.03


def test_pulse_delay_stays_without_jerk() -> None:
    """Constant acceleration: no jerk, no evidence about the delay — the SPEC value stays."""
    sc = scenario(120.0, const(0.3), 5.0, imu_lag_s=0.0, ax_noise_kmh_s=0.1)
    assert streams(sc).delay == CFG.pulse_delay_cycles


# --------------------------------------------------------------------------- re-adhesion


def test_shallow_long_slip_does_not_readhere_while_slipping() -> None:
    """6 s of 8 % slip at 11 m/s: 0.9 m/s of excess. With β·t = 0.8 km/h/s·t (the former
    rule) the inertial and pulse speeds "agree" 4 s after the start point, 2 s before the
    wheel stops slipping; with 0.1 m/s + 0.15 km/h/s·t they agree only after it."""
    onset, dur = 30.0, 6.0
    sc = scenario(60.0, const(0.2), 5.0, slip=slip_pulse(onset, dur, 0.08, edge=1.0), ax_noise_kmh_s=0.1)
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert ep.readhered and onset + dur <= ep.t_end < onset + dur + 1.5
    assert abs(odo.d[-1] - sc.s_true[-1]) < 0.5
    loose = correct_odometry(sc.cycles, replace(CFG, beta_kmh_s=0.8))
    assert loose.episodes[0].t_end < onset + dur - 1.0
    assert abs(loose.d[-1] - sc.s_true[-1]) > 1.0


def test_filter_echo_after_readhesion_is_not_a_new_episode() -> None:
    """SPEC criterion only, a 3 s slip of 10 % at 11 m/s: the speeds agree again ≈ 1 s after
    the slip, but the end of the slip is still in the 3.9 s filter and |a_x − A_p| crosses
    Ta once more. The speeds still agree, so it is the filter's echo: ignored, not a
    re-opened correction."""
    onset, dur = 30.0, 3.0
    cfg = replace(CFG, residual_threshold_kmh_s=0.0)
    sc = scenario(50.0, const(0.2), 5.0, slip=slip_pulse(onset, dur, 0.1, edge=1.0), ax_noise_kmh_s=0.1)
    odo = correct_odometry(sc.cycles, cfg)
    assert_odometry_sane(odo, sc)
    (ep,) = odo.episodes
    assert internals(odo, ep).echo_t and not internals(odo, ep).redetect_t
    assert ep.readhered and ep.t_end < internals(odo, ep).echo_t[0] < onset + dur + 3.0
    err, _, _ = episode_error(odo, sc)
    assert abs(err) < 0.01


# --------------------------------------------------------------------------- clean runs


def test_clean_run_no_episode() -> None:
    """Start, cruise, brake, with vertical curves between −20 ‰ and +20 ‰, a_x noise
    0.1 km/h/s and 1-pulse quantisation: nothing is detected, d is the pulse distance."""

    def accel(t: np.ndarray) -> np.ndarray:
        return 0.6 * ramp(t, 0, 1) - 0.6 * ramp(t, 30, 31) - 0.5 * ramp(t, 80, 82) + 0.5 * ramp(t, 115, 116)

    def grade(t: np.ndarray) -> np.ndarray:
        return np.arctan(0.020 * ramp(t, 10, 25) - 0.040 * ramp(t, 45, 70) + 0.020 * ramp(t, 90, 100))

    sc = scenario(120.0, accel, 0.5, theta=grade, ax_noise_kmh_s=0.1, seed=3)
    assert sc.v_true.min() > 0
    odo = correct_odometry(sc.cycles, CFG)
    assert odo.episodes == []
    np.testing.assert_array_equal(odo.d, sc.cycles.d_pulse)
    assert not odo.slipping.any() and not odo.allowance.any()


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    a=st.floats(-0.5, 0.8),
    v0=st.floats(5.0, 30.0),
    grade_permil=st.floats(-30.0, 30.0),
    phase=st.floats(0.0, Q),
    seed=st.integers(0, 2**16),
)
def test_property_clean_constant_runs(a: float, v0: float, grade_permil: float, phase: float, seed: int) -> None:
    seconds = 40.0
    if v0 + a * seconds < 2.0:
        a = (2.0 - v0) / seconds
    sc = scenario(
        seconds,
        const(a),
        v0,
        theta=const(np.arctan(grade_permil / 1000)),
        ax_noise_kmh_s=0.1,
        pulse_phase_m=phase,
        seed=seed,
    )
    odo = correct_odometry(sc.cycles, CFG)
    assert odo.episodes == []
    np.testing.assert_array_equal(odo.d, sc.cycles.d_pulse)


# --------------------------------------------------------------------------- inputs


def test_without_imu_returns_pulse_odometry() -> None:
    sc = scenario(20.0, const(0.5), 5.0, slip=slip_pulse(10.0, 3.0, 0.3))
    sc.cycles.has_imu = False
    odo = correct_odometry(sc.cycles, CFG)
    assert odo.episodes == []
    np.testing.assert_array_equal(odo.d, sc.cycles.d_pulse)


def test_missing_imu_cycles() -> None:
    onset = 20.0
    sc = scenario(40.0, const(0.5), 5.0, slip=slip_pulse(onset, 3.5, 0.3), ax_noise_kmh_s=0.1, seed=5)
    gaps = np.random.default_rng(7).random(sc.cycles.n) < 0.05
    gaps[150:155] = True  # and one 0.5 s hole
    for c in sc.cycles.imu.values():
        c[gaps] = np.nan
    odo = correct_odometry(sc.cycles, CFG)
    assert_odometry_sane(odo, sc)
    assert np.isfinite(odo.d).all()
    assert len(odo.episodes) == 1
    err, _, _ = episode_error(odo, sc)
    assert abs(err) < 0.02
