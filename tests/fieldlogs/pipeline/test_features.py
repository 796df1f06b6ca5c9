"""Feature-point unit (SPEC §5.3, [S000 §3.2]) on hand-made κ traces.

A double-track line with two curves of known radius (400 m left, 800 m right, 60 m
transitions), its feature table from ``fieldlogs.simulate.networks.synthetic``; a train at constant speed
whose yaw rate is v·κ of the track it runs on (travel direction, left positive) plus
0.1 deg/s of white noise per cycle (about 7× an ADIS16480's). Independent of the simulator.

Accuracy seen with this noise (20 seeds × 4 direction cases × 2 curves, not asserted here):
exit crossing within σ ≈ 1.0 m (max 3.5 m) at 20 m/s; the correction at the nearest cycle
adds ≤ v·Δt/2 of quantisation (σ 1.2 m, max 4 m at 20 m/s).
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import fieldlogs.pipeline.aids.features as features_mod
from dbtools.gis.geometry import Projector
from dbtools.network import Network
from fieldlogs.pipeline.aids.balise import BaliseDb
from fieldlogs.pipeline.aids.features import FeatureUnit, KmBetween
from fieldlogs.pipeline.config import FeatureConfig, PipelineConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.estimate import signed_travel
from fieldlogs.pipeline.types import FeatureOutcome, Fix, FloatArray, Odometry
from fieldlogs.simulate.networks.alignment import Alignment, Curve
from fieldlogs.simulate.networks.synthetic import LineSpec, Station, build_network
from tests.fieldlogs.pipeline.engine_cases import solve

LINE = "0900"
KM0 = 10_000.0
CURVES = [Curve(1000.0, 60.0, 150.0, 400.0, True), Curve(1800.0, 60.0, 200.0, 800.0, False)]
SPEC = LineSpec(LINE, "Feature test line", Alignment(3000.0, CURVES, km0=KM0), [Station("01", "A", KM0 + 600.0)])
CFG = FeatureConfig()
DT = 0.1
NOISE_RAD_S = np.radians(0.1)


@pytest.fixture(scope="module")
def net() -> Network:
    return build_network([SPEC], Projector(9))


@pytest.fixture(scope="module")
def rows(net: Network) -> pd.DataFrame:
    return net.feature_points


def with_features(net: Network, fp: pd.DataFrame) -> Network:
    return Network({**net.tables, "feature_points": fp}, origin="test")


def make_run(
    track: str,
    k: int,
    cab: int,
    s0: float,
    seconds: float,
    *,
    v: float = 20.0,
    scale: float = 1.0,
    straight: bool = False,
    seed: int = 0,
) -> tuple[Cycles, Odometry, FloatArray]:
    """Cycles, odometry and true km per cycle: constant speed ``v`` from chainage ``s0``,
    km direction k·cab; ``scale`` = measured / true distance."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds + 1e-9, DT)
    n = t.size
    sdir = k * cab
    d_true = v * t
    s_mid = s0 + sdir * (d_true - 0.5 * v * DT)  # cycle means stand for mid-cycle
    kappa = np.zeros(n) if straight else sdir * SPEC.alignment.track_curvature(s_mid, SPEC.offset(track))
    wz = v * kappa + rng.normal(0.0, NOISE_RAD_S, n)
    d = d_true * scale
    imu = {c: np.zeros(n) for c in ("ax", "ay", "az", "wx", "wy")}
    imu["wz"] = wz
    c = Cycles(
        t,
        d.copy(),
        d.copy(),
        np.full(n, v * scale),
        imu,
        np.full(n, cab, dtype=np.int8),
        np.ones(n, dtype=np.int8),
        True,
        True,
    )
    odo = Odometry(d, np.full(n, v * scale), np.zeros(n, dtype=bool), np.zeros(n))
    return c, odo, KM0 + s0 + sdir * d_true


def fix_at_start(track: str, k: int, km_true0: float, error_m: float) -> Fix:
    km = km_true0 + error_m
    return Fix(0.0, 0.0, 0.0, km, km, LINE, track, k, "balise", 1.0)


def between(km_est: FloatArray) -> KmBetween:
    """The engine's windowed estimate over a whole-run array: cycles [i0, i1)."""
    return lambda i0, i1: km_est[max(i0, 0) : max(i1, 0)]


def outcomes(unit: FeatureUnit, fix: Fix, km_est: FloatArray) -> list[tuple[int, FeatureOutcome]]:
    """Evaluate every feature in turn under one fix (no re-anchoring)."""
    out, after = [], 0
    while (nxt := unit.next_evaluation(fix, after, between(km_est))) is not None:
        i_eval, cand = nxt
        out.append((i_eval, unit.evaluate(cand, fix, between(km_est), i_eval)))
        after = i_eval
    return out


def setup(net, track="D", k=1, cab=1, error_m=30.0, **kw):
    sdir = k * cab
    s0, seconds = (700.0, 90.0) if sdir > 0 else (2600.0, 100.0)
    c, odo, km_true = make_run(track, k, cab, s0, seconds, **kw)
    fix = fix_at_start(track, k, km_true[0], error_m)
    km_est = fix.km_m + fix.k * (signed_travel(c, odo) - fix.s_ref)
    return c, odo, km_true, fix, km_est


# -- curvature --------------------------------------------------------------------------
def test_kappa_is_travel_curvature_left_positive(net) -> None:
    c, odo, km_true, *_ = setup(net)
    unit = FeatureUnit(c, odo, net, CFG)
    s = km_true - KM0
    in_left_arc = (s > 1070) & (s < 1200)
    in_right_arc = (s > 1870) & (s < 2050)
    r_left = 1.0 / np.median(unit.kappa[in_left_arc])
    r_right = 1.0 / np.median(unit.kappa[in_right_arc])
    assert r_left == pytest.approx(400.0 - 1.9, abs=3.0)  # D track lies 1.9 m inside the left curve
    assert r_right == pytest.approx(-(800.0 + 1.9), abs=10.0)
    straight = (s > 750) & (s < 950)
    assert np.abs(unit.kappa[straight]).max() < CFG.straight_kappa_max
    assert unit.n_smooth % 2 == 1


# -- acceptance and accuracy ------------------------------------------------------------
@pytest.mark.parametrize(
    ("track", "k", "cab", "direction"),
    [("D", 1, 1, "normal"), ("U", -1, 1, "normal"), ("D", 1, -1, "reversed"), ("U", -1, -1, "reversed")],
)
@pytest.mark.parametrize("error_m", [30.0, -30.0])
def test_accepts_and_recovers_the_injected_error(net, track, k, cab, direction, error_m) -> None:
    c, odo, km_true, fix, km_est = setup(net, track, k, cab, error_m)
    unit = FeatureUnit(c, odo, net, CFG)
    res = outcomes(unit, fix, km_est)
    assert [o.feature_id for _, o in res] == (["F001", "F002"] if k * cab > 0 else ["F002", "F001"])
    tol = 20.0 * DT + 2.0  # v·0.1 s + 2 m
    fp = net.feature_points
    for _, o in res:
        assert o.accepted, (o.failed, o.detail)
        assert o.detail["direction"] == direction
        rows = fp[(fp.track == track) & (fp.feature_id == o.feature_id)].sort_values("seq")
        # correction point: row 4 in the track's normal direction, row 3 when reversed
        assert o.km_db == rows["km_m"].iloc[3 if direction == "normal" else 2]
        db_attr = rows["attribute"].iloc[2]
        assert o.detail["attribute"] == (
            db_attr if direction == "normal" else {"left": "right", "right": "left"}[db_attr]
        )
        correction = km_est[o.i_ref] - o.km_db  # computed − DB (SPEC §5.2 sign)
        assert correction == pytest.approx(error_m, abs=tol)
        assert abs(km_true[o.i_ref] - o.km_db) <= 0.5 * 20.0 * DT + 1.0  # crossing found within v·Δt/2 + 1 m
        assert o.detail["length_m"] == pytest.approx(o.detail["db_length_m"], abs=3.0)


def test_evaluation_point_is_exit_check_end_plus_margin(net) -> None:
    c, odo, _, fix, km_est = setup(net)
    unit = FeatureUnit(c, odo, net, CFG)
    i_eval, cand = unit.next_evaluation(fix, 0, between(km_est))
    assert cand.feature_id == "F001" and cand.margin_m == CFG.search_margin_m
    end = cand.km[5] + CFG.search_margin_m
    assert km_est[i_eval] >= end > km_est[i_eval - 1]
    # a later start on the same fix: already past F001's exit check end + margin → F002 next
    i2, cand2 = unit.next_evaluation(fix, i_eval, between(km_est))
    assert cand2.feature_id == "F002" and i2 > i_eval
    # the margin grows with the distance since the fix (2 %) once above the minimum
    far = fix_at_start("D", 1, KM0 - 10_000.0, 0.0)  # pretend the fix was 10 km back
    far = Fix(0.0, 0.0, -10_000.0, far.km_m, far.km_m, LINE, "D", 1, "balise", 1.0)
    assert unit.margin(far, i_eval) == pytest.approx(1.0 + 0.02 * (10_000.0 + odo.d[i_eval]))


def test_no_feature_ahead_or_no_imu(net) -> None:
    c, odo, _, fix, km_est = setup(net)
    unit = FeatureUnit(c, odo, net, CFG)
    assert unit.next_evaluation(fix, c.n - 1, between(km_est)) is None
    other_line = Fix(0.0, 0.0, 0.0, fix.km_m, fix.km_m, "0999", "D", 1, "balise", 1.0)
    assert unit.next_evaluation(other_line, 0, between(km_est)) is None
    c.imu["wz"][:] = np.nan
    c.has_imu = False
    assert FeatureUnit(c, odo, net, CFG).next_evaluation(fix, 0, between(km_est)) is None


def test_cab_reversal_evaluates_the_curve_again_the_other_way(net) -> None:
    """Forward over F001 on D, stop, change ends, back over it: both passes are corrected,
    the second with rows 6…1 and the attribute mirrored."""
    rng = np.random.default_rng(5)
    t = np.arange(0.0, 95.0, DT)
    v = np.where(t < 45.0, 20.0, np.where(t < 50.0, 0.0, 20.0))
    d = np.concatenate([[0.0], np.cumsum(v[1:] * DT)])
    cab = np.where(t < 47.0, 1, -1).astype(np.int8)
    sdir = cab.astype(float)
    s = 700.0 + np.concatenate([[0.0], np.cumsum(sdir[1:] * v[1:] * DT)])
    s_mid = s - sdir * 0.5 * v * DT
    wz = v * sdir * SPEC.alignment.track_curvature(s_mid, SPEC.offset("D")) + rng.normal(0.0, NOISE_RAD_S, t.size)
    imu = {k: np.zeros(t.size) for k in ("ax", "ay", "az", "wx", "wy")} | {"wz": wz}
    c = Cycles(t, d, d, v, imu, cab, np.ones(t.size, dtype=np.int8), True, True)
    odo = Odometry(d, v, np.zeros(t.size, dtype=bool), np.zeros(t.size))
    fix = fix_at_start("D", 1, KM0 + 700.0, 20.0)
    km_est = fix.km_m + signed_travel(c, odo)
    res = outcomes(FeatureUnit(c, odo, net, CFG), fix, km_est)
    assert [(o.feature_id, o.detail["direction"], o.detail["attribute"]) for _, o in res] == [
        ("F001", "normal", "left"),
        ("F001", "reversed", "right"),
    ]
    for _, o in res:
        assert o.accepted, o.failed
        assert km_est[o.i_ref] - o.km_db == pytest.approx(20.0, abs=20.0 * DT + 2.0)


# -- refusals ---------------------------------------------------------------------------
def first(unit: FeatureUnit, fix: Fix, km_est: FloatArray) -> FeatureOutcome:
    i_eval, cand = unit.next_evaluation(fix, 0, between(km_est))
    return unit.evaluate(cand, fix, between(km_est), i_eval)


def test_slip_during_the_feature_refuses(net) -> None:
    c, odo, km_true, fix, km_est = setup(net)
    odo.slipping[(km_true > KM0 + 1100) & (km_true < KM0 + 1120)] = True
    out = first(FeatureUnit(c, odo, net, CFG), fix, km_est)
    assert not out.accepted and out.failed == ["no_slip"]


def test_slow_train_refuses(net) -> None:
    c, odo, km_true = make_run("D", 1, 1, 700.0, 800.0, v=2.0)
    fix = fix_at_start("D", 1, km_true[0], 10.0)
    km_est = fix.km_m + signed_travel(c, odo)
    out = first(FeatureUnit(c, odo, net, CFG), fix, km_est)
    assert not out.accepted and "min_speed" in out.failed
    assert out.detail["min_speed_kmh"] == pytest.approx(7.2)


def test_wrong_radius_in_db_refuses(net, rows) -> None:
    fp = rows.copy()
    fp.loc[fp.radius_m > 0, "radius_m"] *= 1.5
    c, odo, _, fix, km_est = setup(net)
    out = first(FeatureUnit(c, odo, with_features(net, fp), CFG), fix, km_est)
    # lower limit crossed 0.27·60 m earlier at each end: 32 m longer, inside the 35 m tolerance
    assert not out.accepted and out.failed == ["upper_limit"]
    assert out.detail["length_m"] - out.detail["db_length_m"] == pytest.approx(32.0, abs=3.0)
    assert out.detail["measured_radius_m"] == pytest.approx(398.1, abs=3.0)


def test_wrong_curve_length_in_db_refuses(net, rows) -> None:
    fp = rows.copy()
    sel = (fp.feature_id == "F001") & (fp.seq >= 4)
    fp.loc[sel, "km_m"] += 60.0  # curve 60 m longer in the DB (tolerance max(20 %, 10 m) = 35 m)
    c, odo, _, fix, km_est = setup(net)
    out = first(FeatureUnit(c, odo, with_features(net, fp), CFG), fix, km_est)
    assert not out.accepted and out.failed == ["length"]


def test_mirrored_attribute_refuses(net, rows) -> None:
    fp = rows.copy()
    fp["attribute"] = fp["attribute"].replace({"left": "right", "right": "left"})
    c, odo, _, fix, km_est = setup(net)
    out = first(FeatureUnit(c, odo, with_features(net, fp), CFG), fix, km_est)
    assert not out.accepted and out.failed == ["sign"]
    assert out.detail["measured_sign"] == 1 and out.detail["attribute"] == "right"


def test_no_curve_in_the_data_refuses(net) -> None:
    c, odo, _, fix, km_est = setup(net, straight=True)
    out = first(FeatureUnit(c, odo, net, CFG), fix, km_est)
    assert not out.accepted and out.failed == ["start_point"] and out.i_ref is None
    assert "no curve" in out.detail["reason"]


def test_kink_in_the_entry_straight_refuses(net) -> None:
    c, odo, km_true, fix, km_est = setup(net)
    s = km_true - KM0
    c.imu["wz"][(s > 982) & (s < 992)] += 20.0 / 1000.0  # a 10 m kink of 1/1000 m in the entry straight
    out = first(FeatureUnit(c, odo, net, CFG), fix, km_est)
    assert not out.accepted and out.failed == ["entry_straight"]


def test_log_starting_inside_the_window_refuses(net) -> None:
    c, odo, km_true = make_run("D", 1, 1, 950.0, 40.0)
    fix = fix_at_start("D", 1, km_true[0], 0.0)
    out = first(FeatureUnit(c, odo, net, CFG), fix, fix.km_m + signed_travel(c, odo))
    assert not out.accepted and out.failed == ["start_point"]
    assert "incomplete" in out.detail["reason"]


def test_invalid_features_are_skipped_with_a_reason(net, rows) -> None:
    fp = rows[~((rows.feature_id == "F002") & (rows.track == "D") & (rows.seq == 6))]
    unit = FeatureUnit(*make_run("D", 1, 1, 700.0, 5.0)[:2], with_features(net, fp), CFG)
    assert unit.skipped == [{"line_code": LINE, "track": "D", "feature_id": "F002", "reason": "5 rows (6 expected)"}]
    assert list(unit.tables[(LINE, "D")].feature_id) == ["F001"]


# -- solver integration -----------------------------------------------------------------
def test_solver_applies_feature_corrections(net) -> None:
    """Initial pair at station 01 (D), odometry 2 % long: each curve's exit corrects the
    accumulated 2 % and the position stays within 10 m afterwards."""
    scale = 1.02
    c, odo, km_true = make_run("D", 1, 1, 200.0, 120.0, scale=scale)
    b = net.balises.set_index("balise_id")
    t_of = {kind: float(np.interp(b.loc[f"{LINE}-01-D-{kind}", "km_actual_m"], km_true, c.t)) for kind in ("I1", "I2")}
    telegrams = pd.DataFrame(
        [(t_of["I1"], "I1", LINE, None, None, None), (t_of["I2"], "I2", None, "01", "D", None)],
        columns=["t", "kind", "line_code", "station_code", "track", "signal_type"],
    )
    cfg = PipelineConfig()
    unit = FeatureUnit(c, odo, net, cfg.feature)
    sol = solve(c, odo, telegrams, BaliseDb.from_network(net), cfg, features=unit)
    types = [e.type for e in sol.events]
    assert types == ["initial_position", "feature_correction", "feature_correction"]
    pos = sol.positions
    err = pos["km_m"].to_numpy() - km_true
    prev_km = float(b.loc[f"{LINE}-01-D-I2", "km_actual_m"])
    for ev in sol.events[1:]:
        # expected amount: 2 % of the true travel since the previous fix
        assert ev.correction_m == pytest.approx((scale - 1.0) * (ev.km_m - prev_km), abs=3.0)
        assert ev.correction_pct == pytest.approx((scale - 1.0) / scale * 100.0, abs=0.3)
        after = (pos.t >= ev.t) & (km_true <= ev.km_m + 400.0)
        assert np.abs(err[after]).max() <= 10.0
        prev_km = ev.km_m
    assert sol.fixes[-1].source == "feature"


@pytest.mark.parametrize("chunk", [1, 7, 64])
def test_scheduling_scan_in_chunks_finds_the_same_cycles(net, monkeypatch, chunk) -> None:
    # the scan reads the estimate ahead in doubling chunks; where the chunks end must not
    # change which cycle a feature is evaluated at, nor what its diagnostics find
    c, odo, _, fix, km_est = setup(net)
    whole = outcomes(FeatureUnit(c, odo, net, CFG), fix, km_est)
    assert whole
    monkeypatch.setattr(features_mod, "SCAN_CHUNK", chunk)
    chunked = outcomes(FeatureUnit(c, odo, net, CFG), fix, km_est)
    assert [(i, o.feature_id, o.accepted, o.i_ref, o.failed) for i, o in chunked] == [
        (i, o.feature_id, o.accepted, o.i_ref, o.failed) for i, o in whole
    ]
    assert [o.detail for _, o in chunked] == [o.detail for _, o in whole]


def test_scheduling_reads_the_estimate_only_near_the_feature(net) -> None:
    # the windows asked of km_between cover the distance to the features, not the run
    c, odo, _, fix, km_est = setup(net)
    asked: list[int] = []

    def counting(i0: int, i1: int) -> FloatArray:
        asked.append(min(i1, c.n) - max(i0, 0))
        return km_est[max(i0, 0) : max(i1, 0)]

    unit = FeatureUnit(c, odo, net, CFG)
    i_eval, _ = unit.next_evaluation(fix, 0, counting)
    assert sum(asked) <= 2 * i_eval + features_mod.SCAN_CHUNK + 2
