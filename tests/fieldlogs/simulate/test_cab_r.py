"""The R cab's own sensors (:mod:`fieldlogs.simulate.cab_r`, scenario ``[cab_r]``): hand-computed
frame and sign conventions, and the seeded sample turnback that records them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.database import read_network
from fieldlogs.simulate.cab_r import lever_arm, rate_of_change, turned
from fieldlogs.simulate.kinematics import BodyKinematics
from fieldlogs.simulate.running import Motion, Move
from fieldlogs.simulate.samples_net import network_sample_scenarios
from fieldlogs.simulate.scenario import ScenarioError, scenario_from_dict
from fieldlogs.simulate.sensors import tacho_stream, wheel_distance
from fieldlogs.simulate.simulator import simulate_run
from schemas.units import G


def _steady(n: int, **values: float) -> BodyKinematics:
    z = np.zeros(n)
    k = {a: np.full(n, values.get(a, 0.0)) for a in ("ax", "ay", "az", "wx", "wy", "wz")}
    return BodyKinematics(**k, pitch=z, roll=z)


def test_a_left_turn_seen_by_each_cab() -> None:
    """Steady left turn, 10 m/s on R = 500 m, the F end leading: at the reference point
    ωz = v/R = 0.02 rad/s, centripetal v²/R = 0.2 m/s² to the left (+y). The R cab's IMU 9.5 m
    behind: ω × (ω × r) = −ωz²·r = +0.0038 m/s² along x; no ω̇, so y is unchanged. In the R
    cab's frame (half a turn about z): ax = −0.0038, ay = −0.2 (the centre is on the R cab's
    right: it trails, moving toward its own back), az = G, ωz = +0.02 — a left turn in the
    direction of travel is ωz > 0 for either cab (κ = ωz/|v| = 1/500 for both)."""
    t = np.arange(100) * 0.01
    kin = _steady(100, ay=0.2, az=G, wz=0.02)
    at_r = lever_arm(kin, t, -9.5)
    assert at_r["ax"] == pytest.approx(np.full(100, 0.0038))
    assert at_r["ay"] == pytest.approx(np.full(100, 0.2))
    assert at_r["az"] == pytest.approx(np.full(100, G))
    r = turned(at_r)
    assert (r["ax"][0], r["ay"][0], r["az"][0]) == pytest.approx((-0.0038, -0.2, G))
    assert (r["wx"][0], r["wy"][0], r["wz"][0]) == pytest.approx((0.0, 0.0, 0.02))
    assert not np.signbit(r["wx"]).any()  # no negative zeros
    assert r["wz"][0] / 10.0 == pytest.approx(1 / 500)


def test_lever_arm_of_a_changing_yaw_rate() -> None:
    """ωz rising at 0.01 rad/s² (entering a curve): at x = 10 m the tangential term ω̇z·x adds
    0.1 m/s² to y; ω̇ over 1 s of a linear ramp is its slope, the ends held."""
    t = np.arange(300) * 0.01
    wz = 0.01 * t
    assert rate_of_change(t, wz)[50:250] == pytest.approx(np.full(200, 0.01))
    kin = BodyKinematics(*(np.zeros(300),) * 5, wz, np.zeros(300), np.zeros(300))
    at = lever_arm(kin, t, 10.0)
    assert at["ay"][150] == pytest.approx(0.1)
    assert at["ax"][150] == pytest.approx(-(wz[150] ** 2) * 10.0)


def _motion(u: np.ndarray) -> Motion:
    n = len(u)
    t = np.arange(n) * 0.01
    sigma = np.concatenate([[0.0], np.cumsum(u[1:] * 0.01)])
    return Motion(
        t=t, v=np.abs(u), a=np.zeros(n), p=np.cumsum(np.abs(u)) * 0.01, sigma=sigma, km=sigma, u=u,
        udot=np.zeros(n), move=np.zeros(n, dtype=np.int64), on_rail=np.ones(n, dtype=bool), facing=1,
        moves=[Move(0.0, 10.0, 1, "F")], cab_events=[(0.0, "F", None)], window_s=0.0,
    )  # fmt: skip


def test_each_cabs_tacho_gives_its_own_sense() -> None:
    """1 s toward the F end at 10 m/s, then 1 s back: a wheel of 1 m circumference (D = 1/π)
    with 10 teeth gives 10 pulses per cycle either way; the F cab's two-phase tacho says +1
    then −1, the R cab's (+1 toward the vehicle's R end) −1 then +1. The cycle (0.9, 1.0]
    still moved 0.8 m toward F."""
    motion = _motion(np.where(np.arange(200) < 100, 10.0, -10.0))
    rolled = wheel_distance(motion, np.ones(200))
    f = tacho_stream(rolled, motion, 1 / math.pi, 10, True)
    r = tacho_stream(rolled, motion, 1 / math.pi, 10, True, sense=-1)
    assert f["pulses"].tolist() == list(range(0, 200, 10))
    assert r["pulses"].tolist() == f["pulses"].tolist()
    assert f["direction"].tolist() == [0] + [1] * 10 + [-1] * 9
    assert r["direction"].tolist() == [0] + [-1] * 10 + [1] * 9


@pytest.fixture(scope="module")
def turnback(sample_network_db: Path) -> dict[str, tuple[dict[str, pd.DataFrame], object]]:
    """The sample turnback with and without the R cab's sensors, with and without noise."""
    net = read_network(sample_network_db)
    base = dict(network_sample_scenarios(net)["sim-net-turnback"])
    out = {}
    for name, extra in {
        "off": {"cab_r": {"sensors": False}},
        "on": {},
        "off-clean": {"cab_r": {"sensors": False}, "noise": False},
        "on-clean": {"noise": False},
    }.items():
        out[name] = simulate_run(net, scenario_from_dict({**base, **extra}, source="test"))
    return out


def test_the_sample_turnback_records_each_cabs_sensors(turnback: dict) -> None:
    off, meta_off = turnback["off"]
    on, meta = turnback["on"]
    assert set(on) - set(off) == {"imu_r", "tacho_r", "gps_r"}
    for name, frame in off.items():  # the F streams do not move: the R cab's draw from their own seeds
        pd.testing.assert_frame_equal(on[name].drop(columns=["slipping_r"], errors="ignore"), frame)
    assert on["truth"]["slipping_r"].isin([0, 1]).all()
    assert meta_off.vehicle is None
    assert meta.vehicle is not None
    assert meta.vehicle["gps_antenna_r"] == {"x_m": -9.5, "y_m": 0.0}
    assert meta.vehicle["imu_r"]["x_m"] == -9.5 and meta.vehicle["gps_antenna"]["x_m"] == 0.0
    cab_r = meta.extra["sim_truth"]["cab_r"]
    assert cab_r["wheel_diameter_true_m"] != meta.extra["sim_truth"]["wheel_diameter_true_m"]
    assert len(on["tacho_r"]) == len(on["tacho"]) and len(on["imu_r"]) == len(on["imu"])
    # rolled distances within the slip episodes' few metres of each other
    assert cab_r["wheel_rolled_m"] == pytest.approx(meta.extra["sim_truth"]["wheel_rolled_m"], abs=30.0)


def test_the_r_cabs_imu_is_the_body_turned_round(turnback: dict) -> None:
    """Without noise: the same yaw rate, roll and pitch rates of opposite sign, forward and
    lateral forces of opposite sign up to the lever arm's few cm/s² away from the turnouts."""
    on, _ = turnback["on-clean"]
    f, r = on["imu"], on["imu_r"]
    assert (r["wz"] == f["wz"]).all()
    assert (r["wx"] == -f["wx"]).all() and (r["wy"] == -f["wy"]).all()
    assert np.median(np.abs(r["ax"] + f["ax"])) < 0.01
    assert np.median(np.abs(r["ay"] + f["ay"])) < 0.01


def test_the_r_cabs_noise_is_its_own(turnback: dict) -> None:
    """The noise of each cab's IMU (noisy − clean) is uncorrelated with the other's."""
    noisy, clean = turnback["on"][0], turnback["on-clean"][0]
    e_f = (noisy["imu"]["wz"] - clean["imu"]["wz"]).to_numpy()
    e_r = (noisy["imu_r"]["wz"] - clean["imu_r"]["wz"]).to_numpy()
    assert e_f.std() > 0 and e_r.std() > 0
    assert abs(np.corrcoef(e_f, e_r)[0, 1]) < 0.05


def test_the_r_cabs_gps_antenna_is_at_its_end(turnback: dict) -> None:
    """Without noise each fix of the R cab's antenna lies 9.5 m along the track from the F's
    (the reference point): on this gently curved route the chord is the arc to < 1 cm."""
    on, _ = turnback["on-clean"]
    f, r = on["gps"], on["gps_r"]
    lat = np.radians(f["lat"].to_numpy())
    dn = np.radians(r["lat"].to_numpy() - f["lat"].to_numpy()) * 6_371_000.0
    de = np.radians(r["lon"].to_numpy() - f["lon"].to_numpy()) * 6_371_000.0 * np.cos(lat)
    gap = np.hypot(dn, de)
    assert np.nanmedian(gap) == pytest.approx(9.5, abs=0.05)


def test_cab_r_knobs_are_checked() -> None:
    with pytest.raises(ScenarioError, match="within ±10 m") as err:
        scenario_from_dict({"cab_r": {"sensors": True, "gps_x_m": -30.0}}, source="s.toml")
    assert err.value.key == "cab_r.gps_x_m"
    with pytest.raises(ScenarioError, match="±20 %") as err:
        scenario_from_dict({"cab_r": {"wheel_error_pct": 25.0}}, source="s.toml")
    assert err.value.key == "cab_r.wheel_error_pct"
