"""Yaw-gyro bias and the exit crossing's uncertainty (feature unit, module docstring).

The line and noise of ``test_features``; the train stands still first, then runs at a
constant low speed, and its yaw gyro reads ``bias`` too much. A bias b reads as a κ error
b/v; on the 800 m right curve (κ < 0 in the travel direction) a positive b makes |κ|
smaller, so the lower-limit crossings move into the curve along the 60 m transitions.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from dbtools.gis.geometry import Projector
from dbtools.network import Network
from fieldlogs.pipeline.aids.features import FeatureUnit
from fieldlogs.pipeline.cycles import Cycles, standstill_mean
from fieldlogs.pipeline.estimate import signed_travel
from fieldlogs.pipeline.types import Odometry
from fieldlogs.simulate.networks.synthetic import build_network
from tests.fieldlogs.pipeline.test_features import CFG, DT, KM0, NOISE_RAD_S, SPEC, between, fix_at_start, outcomes

BIAS = 0.002  # rad/s (0.11 °/s, ~2σ of an ADIS16480)
V = 10.0  # m/s


@pytest.fixture(scope="module")
def net() -> Network:
    return build_network([SPEC], Projector(9))


def standing_then_running(stand_s: float, bias: float, seed: int = 1):
    """Track D, km increasing: stands at chainage 1500 m for ``stand_s``, then V up to
    chainage 2300 m (the 800 m right curve F002 lies at 1800–2000 m)."""
    rng = np.random.default_rng(seed)
    s0, run_s = 1500.0, 80.0
    t = np.arange(0.0, stand_s + run_s + 1e-9, DT)
    n = t.size
    moving = t > stand_s
    d_true = np.where(moving, V * (t - stand_s), 0.0)
    s_mid = s0 + np.where(moving, d_true - 0.5 * V * DT, 0.0)
    kappa = np.where(moving, SPEC.alignment.track_curvature(s_mid, SPEC.offset("D")), 0.0)
    v = np.where(moving, V, 0.0)
    wz = v * kappa + bias + rng.normal(0.0, NOISE_RAD_S, n)
    imu = {c: np.zeros(n) for c in ("ax", "ay", "az", "wx", "wy")}
    imu["wz"] = wz
    c = Cycles(t, d_true.copy(), d_true.copy(), v, imu, np.ones(n, np.int8), np.ones(n, np.int8), True, True)
    odo = Odometry(d_true.copy(), v.copy(), np.zeros(n, dtype=bool), np.zeros(n))
    return c, odo, KM0 + s0 + d_true


def f002(net: Network, c: Cycles, odo: Odometry, km_true, cfg=CFG):
    unit = FeatureUnit(c, odo, net, cfg)
    fix = fix_at_start("D", 1, km_true[0], 0.0)
    km_est = fix.km_m + fix.k * (signed_travel(c, odo) - fix.s_ref)
    (out,) = [o for _, o in outcomes(unit, fix, km_est) if o.feature_id == "F002"]
    return unit, out


def test_standstill_mean_by_hand() -> None:
    # 0.1 s cycles: 3 moving, 8 standing, 2 moving, 6 standing
    v = np.array([5, 5, 5, 0, 0, 0, 0, 0, 0, 0, 0, 5, 5, 0, 0, 0, 0, 0, 0], dtype=float)
    t = np.arange(v.size) * 0.1
    x = np.arange(v.size, dtype=float)  # the value is the cycle number
    mean, known = standstill_mean(t, v, x, settle_s=0.2, window_s=0.3, min_s=0.2)
    # counted: standing ≥ 0.2 s → cycles 5–10 and 15–18; mean of the last 3 counted up to i
    expect = {5: None, 6: 5.5, 7: 6.0, 8: 7.0, 9: 8.0, 10: 9.0, 11: 9.0, 14: 9.0, 15: 34 / 3, 16: 41 / 3, 18: 17.0}
    for i, e in expect.items():
        if e is None:
            assert not known[i] and mean[i] == 0.0
        else:
            assert known[i] and mean[i] == pytest.approx(e), i
    assert not known[:6].any()
    # a NaN value is skipped, not averaged
    x[9] = np.nan
    mean, _ = standstill_mean(t, v, x, settle_s=0.2, window_s=0.3, min_s=0.2)
    assert mean[10] == pytest.approx((7 + 8 + 10) / 3)
    # window 0 switches it off
    off, known = standstill_mean(t, v, x, 0.2, 0.0, 0.2)
    assert not off.any() and not known.any()


def test_standstill_estimate_removes_the_yaw_bias(net) -> None:
    c, odo, km_true = standing_then_running(30.0, BIAS)
    unit, out = f002(net, c, odo, km_true)
    assert unit.yaw_bias[-1] == pytest.approx(BIAS, abs=3 * NOISE_RAD_S / np.sqrt(280))
    assert out.accepted, (out.failed, out.detail)
    assert abs(km_true[out.i_ref] - out.km_db) <= 0.5 * V * DT + 1.5
    # without the estimate the exit crossing comes ~0.25·48 m early (|κ| reads 20 % low)
    _, raw = f002(net, c, odo, km_true, replace(CFG, yaw_bias_window_s=0.0))
    assert raw.accepted
    assert km_true[raw.i_ref] - raw.km_db < -6.0


def test_crossing_uncertainty_by_hand(net) -> None:
    fp = net.feature_points
    rows = fp[(fp.track == "D") & (fp.feature_id == "F002")].sort_values("seq")
    km = rows["km_m"].to_numpy()
    radius = float(rows["radius_m"].iloc[2])
    slope = 0.8 / radius / (km[4] - km[3])  # κ_lo over the DB exit transition
    c, odo, km_true = standing_then_running(30.0, BIAS)
    _, out = f002(net, c, odo, km_true)
    sigma_x = CFG.yaw_rate_sigma_rad_s / (V * slope)
    clock_m = CFG.clock_budget_s * V  # 0.5 s of IMU clock at 10 m/s: 5 m
    assert clock_m == pytest.approx(5.0)
    assert out.uncertainty_m == pytest.approx(max(CFG.fix_uncertainty_m, 3.0 * sigma_x) + clock_m)
    assert out.detail["uncertainty_m"] == pytest.approx(out.uncertainty_m, abs=0.01)
    # no standstill before the curve: the bias is unknown and adds in quadrature
    c, odo, km_true = standing_then_running(0.0, 0.0)
    _, out = f002(net, c, odo, km_true)
    sigma = np.hypot(CFG.yaw_rate_sigma_rad_s, CFG.yaw_bias_sigma_rad_s)
    assert out.uncertainty_m == pytest.approx(3.0 * sigma / (V * slope) + clock_m)
    assert out.uncertainty_m > CFG.fix_uncertainty_m + clock_m
    # fast trains keep the paper's 10 m, and the clock budget at their speed (50 m/s: 25 m)
    fast = FeatureUnit(c, replace(odo, v=odo.v * 5.0), net, CFG)
    cand = _candidate(fast, out.feature_id)
    at = fast._crossing_uncertainty(out.i_ref, cand, 0.8 / cand.radius_m)
    assert at == pytest.approx(CFG.fix_uncertainty_m + 25.0)
    # without the budget (clock_budget_s = 0) the crossing's own uncertainty alone
    bare = FeatureUnit(c, replace(odo, v=odo.v * 5.0), net, replace(CFG, clock_budget_s=0.0))
    assert bare._crossing_uncertainty(out.i_ref, cand, 0.8 / cand.radius_m) == CFG.fix_uncertainty_m


def _candidate(unit: FeatureUnit, feature_id: str):
    fix = fix_at_start("D", 1, KM0 + 1500.0, 0.0)
    km_est = fix.km_m + unit._d
    after = 0
    while (nxt := unit.next_evaluation(fix, after, between(km_est))) is not None:
        after, cand = nxt
        if cand.feature_id == feature_id:
            return cand
        unit.evaluate(cand, fix, between(km_est), after)
    raise AssertionError(feature_id)
