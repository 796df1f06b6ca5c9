"""Track-constrained solution: hand-computed single epochs, FDE, batch = per-epoch reference."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from fieldlogs.gnss.constrained import (
    STATUS_FAULT,
    STATUS_OK,
    STATUS_TOO_FEW,
    ConstrainedConfig,
    Rows,
    solve_constrained,
)
from fieldlogs.gnss.geodesy import enu_basis, geodetic_to_ecef
from fieldlogs.gnss.lsq import solve_lsq
from fieldlogs.gnss.reference import solve_epoch
from fieldlogs.gnss.track import Antenna, TrackLine

LAT, LON = np.radians(35.7), np.radians(139.7)
BASE = geodetic_to_ecef(LAT, LON, 40.0)
ENU = enu_basis(LAT, LON)


def straight_north(length: float = 2000.0) -> TrackLine:
    return TrackLine.from_ecef(BASE + np.outer(np.linspace(0.0, length, 101), ENU[1]))


def sat_at(p: np.ndarray, az_deg: float, el_deg: float, r: float = 2.2e7) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    d = np.cos(el) * np.sin(az) * ENU[0] + np.cos(el) * np.cos(az) * ENU[1] + np.sin(el) * ENU[2]
    return np.asarray(p + r * d, dtype=float)


def rows_of(sats: np.ndarray, pr: np.ndarray, sigma: float = 1.0) -> Rows:
    n = pr.size
    return Rows(
        sats[None],
        pr[None],
        np.full((1, n), sigma),
        np.ones((1, n), bool),
        np.zeros((1, n)),
        np.zeros((1, n), np.int64),
        np.ones(1),
    )


def test_two_satellites_ahead_and_behind_exact() -> None:
    """Satellites due north (ahead, 30°) and due south (behind, 25°) of a train facing north:
    g = −û·t = −cos 30° and +cos 25°, so σ_s = σ·√(1/(g1−g2)²·2)... and s, b come back exactly."""
    track = straight_north()
    s_true, b_true = 734.2, 1234.5
    p = track.point(np.array([s_true]))[0]
    sats = np.array([sat_at(p, 0.0, 30.0), sat_at(p, 180.0, 25.0)])
    pr = np.linalg.norm(sats - p, axis=1) + b_true
    sol = solve_constrained(track, rows_of(sats, pr), [Antenna()], s_init=np.array([100.0]))
    assert sol.status[0] == STATUS_OK
    assert sol.s[0] == pytest.approx(s_true, abs=1e-6)
    assert sol.clock_m[0, 0] == pytest.approx(b_true, abs=1e-6)
    g1, g2 = -np.cos(np.radians(30.0)), np.cos(np.radians(25.0))
    # H = [[g1, 1], [g2, 1]], σ = 1: (HᵀH)⁻¹_ss = 2/(g1 − g2)²
    assert sol.sigma_s[0] == pytest.approx(np.sqrt(2.0) / abs(g1 - g2), rel=1e-3)
    assert sol.adop[0] == pytest.approx(sol.sigma_s[0], rel=1e-9)
    assert sol.dof[0] == 0


def test_antenna_offsets_and_direction() -> None:
    """An antenna 7 m ahead, 1 m left, 3.8 m up on a vehicle facing south (direction −1): the
    solved reference-point s is the truth although the antenna is at s − 7."""
    track = straight_north()
    s_true = 900.0
    ant = Antenna(7.0, 1.0, 3.8)
    pos, _ = track.antenna(np.array([s_true]), ant, -1.0)
    sats = np.array([sat_at(pos[0], 10.0, 35.0), sat_at(pos[0], 170.0, 20.0), sat_at(pos[0], 90.0, 70.0)])
    pr = np.linalg.norm(sats - pos[0], axis=1) + 50.0
    rows = rows_of(sats, pr)
    rows = Rows(rows.sat_pos, rows.pr_m, rows.sigma_m, rows.usable, rows.omega_e, rows.receiver, -np.ones(1))
    sol = solve_constrained(track, rows, [ant])
    assert sol.s[0] == pytest.approx(s_true, abs=1e-5)
    # the antenna itself is 7 m behind the reference point in s, 1 m to the vehicle's left (= east)
    assert np.dot(pos[0] - track.point(np.array([s_true]))[0], ENU[0]) == pytest.approx(1.0, abs=1e-6)


def _three_with_step(step: float) -> tuple[TrackLine, np.ndarray, np.ndarray, float]:
    track = straight_north()
    s_true = 734.2
    p = track.point(np.array([s_true]))[0]
    sats = np.array([sat_at(p, 0.0, 30.0), sat_at(p, 180.0, 25.0), sat_at(p, 60.0, 50.0)])
    pr = np.linalg.norm(sats - p, axis=1) + 1234.5
    pr[2] += step
    return track, sats, pr, s_true


def test_step_on_one_of_three_excluded_with_a_prior() -> None:
    track, sats, pr, s_true = _three_with_step(50.0)
    sol = solve_constrained(track, rows_of(sats, pr), [Antenna()], prior=(np.array([s_true + 3.0]), np.array([5.0])))
    assert sol.status[0] == STATUS_OK
    np.testing.assert_array_equal(sol.excluded[0], [False, False, True])
    assert sol.s[0] == pytest.approx(s_true, abs=1e-6)


def test_step_on_one_of_three_detected_not_identified_without_prior() -> None:
    """One redundant observation (dof 1): the three normalised residuals are equal — detected,
    never excluded at random."""
    track, sats, pr, _ = _three_with_step(50.0)
    sol = solve_constrained(track, rows_of(sats, pr), [Antenna()])
    assert sol.status[0] == STATUS_FAULT
    assert not sol.excluded.any()


def test_step_on_one_of_five_excluded_without_prior() -> None:
    track = straight_north()
    s_true = 1500.0
    p = track.point(np.array([s_true]))[0]
    sats = np.array([sat_at(p, az, el) for az, el in ((0, 30), (180, 25), (60, 50), (120, 40), (300, 60))])
    pr = np.linalg.norm(sats - p, axis=1) - 77.0
    pr[3] += 50.0
    sol = solve_constrained(track, rows_of(sats, pr), [Antenna()])
    assert sol.status[0] == STATUS_OK
    np.testing.assert_array_equal(sol.excluded[0], [False, False, False, True, False])
    assert sol.s[0] == pytest.approx(s_true, abs=1e-6)


def test_pseudorange_with_no_on_track_solution_rejected() -> None:
    """A 30 km error on one of four: the full solution leaves the 2 km track; leaving that
    pseudorange out gives the on-track solution."""
    track = straight_north()
    s_true = 1000.0
    p = track.point(np.array([s_true]))[0]
    sats = np.array([sat_at(p, az, el) for az, el in ((0, 30), (180, 25), (60, 50), (240, 45))])
    pr = np.linalg.norm(sats - p, axis=1)
    pr[0] += 30_000.0
    sol = solve_constrained(track, rows_of(sats, pr), [Antenna()], s_init=np.array([1000.0]))
    np.testing.assert_array_equal(sol.no_track[0], [True, False, False, False])
    assert sol.status[0] == STATUS_OK
    assert sol.s[0] == pytest.approx(s_true, abs=1e-5)


def test_two_receivers_joint_three_satellites() -> None:
    """K = 2: unknowns (s, b1, b2); two satellites on one receiver and one on the other suffice."""
    track = straight_north()
    s_true = 640.0
    a1, a2 = Antenna(8.0, 0.0, 3.8), Antenna(-8.0, 0.0, 3.8)
    p1, _ = track.antenna(np.array([s_true]), a1)
    p2, _ = track.antenna(np.array([s_true]), a2)
    s_a, s_b = sat_at(p1[0], 0.0, 30.0), sat_at(p1[0], 180.0, 25.0)
    sats = np.array([s_a, s_b, s_a])
    pr = np.array(
        [np.linalg.norm(s_a - p1[0]) + 10.0, np.linalg.norm(s_b - p1[0]) + 10.0, np.linalg.norm(s_a - p2[0]) - 20.0]
    )
    rows = Rows(
        sats[None],
        pr[None],
        np.ones((1, 3)),
        np.ones((1, 3), bool),
        np.zeros((1, 3)),
        np.array([[0, 0, 1]]),
        np.ones(1),
    )
    sol = solve_constrained(track, rows, [a1, a2])
    assert sol.status[0] == STATUS_OK
    assert sol.s[0] == pytest.approx(s_true, abs=1e-6)
    np.testing.assert_allclose(sol.clock_m[0], [10.0, -20.0], atol=1e-6)


def test_one_satellite_is_too_few() -> None:
    track = straight_north()
    p = track.point(np.array([500.0]))[0]
    sats = np.array([sat_at(p, 0.0, 30.0)])
    sol = solve_constrained(
        track, rows_of(sats, np.linalg.norm(sats - p, axis=1)), [Antenna()], s_init=np.array([500.0])
    )
    assert sol.status[0] == STATUS_TOO_FEW


def test_batch_equals_per_epoch_reference() -> None:
    """Random epochs with noise, faults and priors: the batched solver and the per-epoch
    reference (``reference.solve_epoch``) agree."""
    rng = np.random.default_rng(7)
    track = TrackLine.from_ecef(
        BASE + np.outer(np.linspace(0.0, 3000.0, 151), ENU[1]) + np.outer(np.sin(np.linspace(0, 3, 151)) * 40.0, ENU[0])
    )
    e, n_s = 60, 7
    s_true = rng.uniform(200.0, 2800.0, e)
    ant = Antenna(5.0, 0.0, 3.5)
    pos, _ = track.antenna(s_true, ant)
    az = rng.uniform(0, 360, (e, n_s))
    el = rng.uniform(10, 80, (e, n_s))
    sats = np.array([[sat_at(pos[i], az[i, j], el[i, j]) for j in range(n_s)] for i in range(e)])
    sigma = rng.uniform(0.5, 3.0, (e, n_s))
    pr = np.linalg.norm(sats - pos[:, None, :], axis=-1) + 300.0 + sigma * rng.standard_normal((e, n_s))
    pr[::5, 2] += 60.0
    usable = rng.random((e, n_s)) > 0.35
    prior_s = s_true + rng.normal(0, 3, e)
    rows = Rows(sats, pr, sigma, usable, np.full((e, n_s), 7.2921151467e-5), np.zeros((e, n_s), np.int64), np.ones(e))
    cfg = ConstrainedConfig()
    sol = solve_constrained(track, rows, [ant], cfg, prior=(prior_s, np.full(e, 5.0)))
    for i in range(e):
        ref = solve_epoch(
            track,
            sats[i],
            pr[i],
            sigma[i],
            rows.omega_e[i],
            list(usable[i]),
            ant,
            1.0,
            prior_s[i],
            (prior_s[i], 5.0),
            cfg,
        )
        assert ref.status == sol.status[i], i
        assert ref.used == list(sol.used[i]), i
        if ref.status == STATUS_OK:
            assert ref.s == pytest.approx(sol.s[i], abs=2e-3)
            assert ref.sigma_s == pytest.approx(sol.sigma_s[i], rel=1e-6)


def test_lsq_exact_and_dops() -> None:
    """Noise-free ranges: the position comes back; four satellites at the zenith and 3 at
    elevation 0° 120° apart give the textbook DOPs (HDOP = √(2/3)·..., computed from H)."""
    p = BASE
    sats = np.array([sat_at(p, az, el) for az, el in ((0, 90), (0, 0), (120, 0), (240, 0))])
    pr = np.linalg.norm(sats - p, axis=1) + 99.0
    n = 4
    sol = solve_lsq(
        sats[None], pr[None], np.ones((1, n)), np.ones((1, n), bool), np.full((1, n), "G"), np.zeros((1, n))
    )
    np.testing.assert_allclose(sol.pos[0], p, atol=1e-4)
    assert sol.clock_m[0] == pytest.approx(99.0, abs=1e-4)
    u = np.array(
        [
            [0, 0, 1],
            [0, 1, 0],
            [np.sin(np.radians(120)), np.cos(np.radians(120)), 0],
            [np.sin(np.radians(240)), np.cos(np.radians(240)), 0],
        ]
    )
    h = np.hstack([-u, np.ones((4, 1))])
    q = np.linalg.inv(h.T @ h)
    assert sol.hdop[0] == pytest.approx(np.sqrt(q[0, 0] + q[1, 1]), rel=1e-3)
    assert sol.vdop[0] == pytest.approx(np.sqrt(q[2, 2]), rel=1e-3)
    assert sol.tdop[0] == pytest.approx(np.sqrt(q[3, 3]), rel=1e-3)


def test_one_satellite_with_a_coasted_clock() -> None:
    """With the receiver clock predicted (σ 0.3 m) one satellite fixes s: b from the prior row,
    s from the range; σ_s = √(σ² + σ_b²)/|g|."""
    track = straight_north()
    s_true, b_true = 812.0, 77.0
    p = track.point(np.array([s_true]))[0]
    sats = np.array([sat_at(p, 0.0, 20.0)])
    pr = np.linalg.norm(sats - p, axis=1) + b_true
    rows = replace(rows_of(sats, pr), clock_prior_m=np.array([[b_true]]), clock_prior_sigma_m=np.array([[0.3]]))
    sol = solve_constrained(track, rows, [Antenna()], s_init=np.array([700.0]))
    assert sol.status[0] == STATUS_OK
    assert sol.s[0] == pytest.approx(s_true, abs=1e-6)
    assert sol.sigma_s[0] == pytest.approx(np.hypot(1.0, 0.3) / np.cos(np.radians(20.0)), rel=1e-3)


def test_clock_prediction_is_causal_and_bounded() -> None:
    from fieldlogs.gnss.coasting import predict_clock

    rng = np.random.default_rng(4)
    t = np.arange(200.0)
    b = 30.0 + 2.5 * t + np.cumsum(rng.normal(0.0, 0.1, t.size))
    est = b + rng.normal(0.0, 2.0, t.size)
    ok = np.ones(t.size, bool)
    ok[100:140] = False
    pred, sig = predict_clock(np.full(t.size, "rx"), t, est, np.full(t.size, 2.0), ok)
    assert np.isinf(sig[:5]).all()  # fewer than 5 solved epochs before
    assert np.isinf(sig[131:140]).all()  # more than 30 s after the last solved epoch
    have = np.isfinite(sig)
    z = (pred[have] - b[have]) / sig[have]
    assert np.mean(np.abs(z) < 3.29) > 0.99
    changed = est.copy()
    changed[150:] += 1000.0  # a later jump must not change earlier predictions
    pred2, _ = predict_clock(np.full(t.size, "rx"), t, changed, np.full(t.size, 2.0), ok)
    np.testing.assert_array_equal(pred2[:151][have[:151]], pred[:151][have[:151]])
