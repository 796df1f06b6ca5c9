"""Hand-computed physics of the simulator (SPEC §4.1 frame), noise switched off.

Each test builds a small crafted line with ``fieldlogs.simulate.networks.synthetic`` (an alignment we specify),
builds an onboard DB in a tmp folder, runs ``simulate_run`` through its public API and
checks the output streams against values computed here by hand — never with the
simulator's own helpers.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import PolylineIndex, Projector
from dbtools.gis.georef import projector_for_points
from dbtools.network import Network
from dbtools.sources import write_source_set
from fieldlogs.simulate.networks.alignment import Alignment, Curve
from fieldlogs.simulate.networks.synthetic import LineSpec, Station, build_network, demo_line
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.units import KMH_PER_S, G

D_NOM = 0.86
TEETH = 90
#: Ground length per metre of km on these level lines: their km is plane chainage in zone
#: IX (scale 0.9999 on its central meridian, where they start; < 1e-6 more within 5 km of
#: it) and the rail lies 30 m above the ellipsoid, so the wheels roll (1 + 30/R_E)/0.9999.
GROUND = (1.0 + 30.0 / 6_371_000.0) / 0.9999
WEAR_PCT = 0.4
QUIET: dict[str, Any] = {
    "noise": False,
    "imu": {"accel_lsb_mps2": 0.0, "gyro_lsb_deg_s": 0.0},
    "slip": {"slips": 0, "slides": 0},
    "tacho": {"wear_pct": [WEAR_PCT, WEAR_PCT], "wheel_diameter_m": D_NOM, "teeth": TEETH},
    "running": {"stop_at_stations": False},
}


def _merge(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    out = dict(a)
    for k, v in b.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _db(root: Path, spec: LineSpec) -> Network:
    net = build_network([spec], Projector(9))
    write_source_set(net, root / "src")
    build_db(root / "src", root / "net.sqlite", db_version="phys-1")
    return read_network(root / "net.sqlite")


def run(net: Network, seed: int = 1, **over: Any) -> tuple[dict[str, pd.DataFrame], dict[str, Any]]:
    sc = scenario_from_dict(_merge(QUIET, over), source="test")
    streams, meta = simulate_run(net, sc, seed)
    return streams, meta.to_json()


@pytest.fixture(scope="module")
def straight(tmp_path_factory: pytest.TempPathFactory) -> Network:
    """6 km level straight double-track line heading 40° north of east, stations at 2 and 4 km."""
    a = Alignment(6000.0, [], heading0=math.radians(40.0), km0=0.0)
    st = [Station("01", "A", 2000.0), Station("02", "B", 4000.0)]
    return _db(tmp_path_factory.mktemp("straight"), LineSpec("0100", "Straight", a, st))


@pytest.fixture(scope="module")
def left_curve(tmp_path_factory: pytest.TempPathFactory) -> Network:
    """Single track, one long left curve R = 600 m (100 m clothoids, 1800 m arc), level."""
    a = Alignment(6000.0, [Curve(1500.0, 100.0, 1800.0, 600.0, left=True)], heading0=-1.0)
    return _db(tmp_path_factory.mktemp("curve"), LineSpec("0200", "Curve", a, [], tracks=("S",)))


@pytest.fixture(scope="module")
def grade(tmp_path_factory: pytest.TempPathFactory) -> Network:
    """Single track straight with a constant 25 ‰ up-gradient in increasing km."""
    a = Alignment(4000.0, [], heading0=0.3, grade_knots=[(0.0, 0.025)])
    return _db(tmp_path_factory.mktemp("grade"), LineSpec("0300", "Grade", a, [], tracks=("S",)))


def at(frame: pd.DataFrame, t: np.ndarray, col: str) -> np.ndarray:
    return np.interp(t, frame["t"].to_numpy(), frame[col].to_numpy(dtype=float))


def cruising(streams: dict[str, pd.DataFrame], km_lo: float = -np.inf, km_hi: float = np.inf) -> pd.DataFrame:
    """IMU rows (at the 10 Hz truth times) at constant top speed (±1 mm/s over ±5 s), truth km in [km_lo, km_hi]."""
    imu, truth = streams["imu"], streams["truth"]
    v = np.abs(truth["speed_mps"].to_numpy())
    steady = pd.Series(np.abs(v - v.max()) < 1e-3).rolling(101, center=True).min().fillna(0).to_numpy(dtype=bool)
    km = truth["km_m"].to_numpy()
    ok = steady & (km >= km_lo) & (km <= km_hi)
    t_ok = truth["t"].to_numpy()[ok]
    sel = imu[np.isin(np.round(imu["t"].to_numpy(), 2), np.round(t_ok, 2))].copy()
    sel["v"] = at(truth, sel["t"].to_numpy(), "speed_mps")
    assert len(sel) > 300, "no steady cruising found"
    return sel


# -- level straight ------------------------------------------------------------------------
def test_level_straight_constant_speed(straight: Network) -> None:
    streams, _ = run(straight, route={"track": "D", "path_km_m": [200.0, 5800.0]}, running={"line_speed_kmh": 90.0})
    c = cruising(streams)
    assert c["v"].mean() == pytest.approx(25.0, abs=1e-3)
    assert c["ax"].abs().max() < 1e-3
    assert c["ay"].abs().max() < 1e-3
    assert c["az"].to_numpy() == pytest.approx(G, abs=1e-3)
    for w in ("wx", "wy", "wz"):
        assert c[w].abs().max() < 1e-4


def test_rest_level_and_forward_acceleration(straight: Network) -> None:
    streams, _ = run(straight, route={"track": "D", "path_km_m": [200.0, 3000.0]})
    imu, truth = streams["imu"], streams["truth"]
    rest = imu[imu["t"] < 5.0]
    assert rest["az"].to_numpy() == pytest.approx(G, abs=1e-9)
    assert rest["ax"].to_numpy() == pytest.approx(0.0, abs=1e-9)
    # ax is the travel acceleration: d(speed)/dt of the truth, and peaks at 2.5 km/h/s
    t = truth["t"].to_numpy()
    dv = np.gradient(truth["speed_mps"].to_numpy(), t)
    assert at(imu, t, "ax") == pytest.approx(dv, abs=5e-3)
    assert imu["ax"].max() == pytest.approx(2.5 * KMH_PER_S, abs=0.01)
    assert imu["ax"].min() == pytest.approx(-3.0 * KMH_PER_S, abs=0.01)
    # jerk limit 0.3 m/s³
    jerk = np.diff(imu["ax"].to_numpy()) / 0.01
    assert np.abs(jerk).max() <= 0.3 * 1.02


# -- curve with cant -----------------------------------------------------------------------
R = 600.0
V = 95.0 / 3.6
CANT = min(0.105, 11.8 * 95.0**2 / R / 1000.0)  # 105 mm: the cap
PSI = -math.asin(CANT / 1.067)  # left curve: left side down


def test_steady_left_curve_with_cant(left_curve: Network) -> None:
    streams, _ = run(left_curve, route={"path_km_m": [200.0, 5800.0]}, running={"line_speed_kmh": 95.0})
    arc = cruising(streams, 1500.0 + 100.0 + 100.0, 1500.0 + 100.0 + 1800.0 - 100.0)
    v = arc["v"].to_numpy()
    assert v == pytest.approx(V, abs=1e-3)
    assert (arc["wz"] > 0).all()
    assert arc["wz"].to_numpy() == pytest.approx(v / R * math.cos(PSI), rel=2e-3)
    kappa = arc["wz"] / arc["v"]
    assert kappa.to_numpy() == pytest.approx(1 / R, rel=1e-2)
    assert arc["ay"].to_numpy() == pytest.approx(v**2 / R * math.cos(PSI) + G * math.sin(PSI), abs=3e-3)
    assert arc["az"].to_numpy() == pytest.approx(G * math.cos(PSI) - v**2 / R * math.sin(PSI), abs=3e-3)
    assert arc["ax"].abs().max() < 1e-3
    assert arc["wx"].abs().max() < 1e-4
    # the yaw rate seen by a rolled body also shows on its y axis: wy = Ψ̇·cosθ·sinψ < 0
    assert arc["wy"].to_numpy() == pytest.approx(v / R * math.sin(PSI), rel=2e-3)


def test_roll_builds_up_along_the_entry_transition(left_curve: Network) -> None:
    streams, _ = run(left_curve, route={"path_km_m": [200.0, 5800.0]})
    imu, truth = streams["imu"], streams["truth"]
    t_mid = float(np.interp(2500.0, truth["km_m"], truth["t"]))
    # roll ψ = ∫ wx dt from the straight to the middle of the arc: left side down
    roll = imu.loc[imu["t"] <= t_mid, "wx"].sum() * 0.01
    assert roll == pytest.approx(PSI, abs=2e-3)
    # heading change through the whole curve = deflection (arc + transition)/R, to the left
    yaw = imu["wz"].sum() * 0.01
    assert yaw == pytest.approx((1800.0 + 100.0) / R, rel=5e-3)


def test_left_curve_run_backwards_is_a_right_curve(left_curve: Network) -> None:
    """Running toward decreasing km (body facing that way): right curve, right side down."""
    streams, _ = run(left_curve, route={"path_km_m": [5800.0, 200.0]})
    arc = cruising(streams, 1700.0, 3300.0)
    v = arc["v"].to_numpy()
    assert (arc["wz"] < 0).all()
    assert arc["wz"].to_numpy() == pytest.approx(-v / R * math.cos(PSI), rel=2e-3)
    assert arc["ay"].to_numpy() == pytest.approx(-(v**2 / R * math.cos(PSI) + G * math.sin(PSI)), abs=3e-3)


def test_curve_speed_limit(left_curve: Network) -> None:
    """120 km/h line speed: the curve limit √((0.8 + G·cant/1.067)·R) holds in the arc."""
    streams, _ = run(left_curve, route={"path_km_m": [200.0, 5800.0]}, running={"line_speed_kmh": 120.0})
    truth = streams["truth"]
    v_max = math.sqrt((0.8 + G * 0.105 / 1.067) * R)
    design_cant = min(0.105, 11.8 * 120.0**2 / R / 1000.0)
    assert design_cant == 0.105
    arc = truth[(truth["km_m"] > 1700.0) & (truth["km_m"] < 3300.0)]
    assert arc["speed_mps"].max() <= v_max * 1.005
    assert arc["speed_mps"].max() == pytest.approx(v_max, rel=0.01)
    assert truth["speed_mps"].max() == pytest.approx(120 / 3.6, abs=0.01)


# -- gradient ------------------------------------------------------------------------------
SIN_GRADE = math.sin(math.atan(0.025))


def test_standing_on_25_permille_facing_uphill(grade: Network) -> None:
    streams, _ = run(grade, route={"path_km_m": [200.0, 3800.0]})
    rest = streams["imu"][streams["imu"]["t"] < 5.0]
    assert rest["ax"].to_numpy() == pytest.approx(G * SIN_GRADE, abs=1e-4)
    assert rest["az"].to_numpy() == pytest.approx(G * math.cos(math.atan(0.025)), abs=1e-4)
    assert rest["wy"].abs().max() < 1e-9
    # climbing at constant speed: still G·sin θ along x, no pitch rate
    c = cruising(streams)
    assert c["ax"].to_numpy() == pytest.approx(G * SIN_GRADE, abs=1e-3)
    assert c["wy"].abs().max() < 1e-4


def test_standing_on_25_permille_facing_downhill(grade: Network) -> None:
    streams, _ = run(grade, route={"path_km_m": [3800.0, 200.0]})
    rest = streams["imu"][streams["imu"]["t"] < 5.0]
    assert rest["ax"].to_numpy() == pytest.approx(-G * SIN_GRADE, abs=1e-4)


def test_nose_up_pitch_rate_is_negative(tmp_path: Path) -> None:
    """Level → 20 ‰ over a 400 m vertical curve: the nose pitches up, wy < 0, ∫wy = −θ."""
    a = Alignment(4000.0, [], heading0=0.0, grade_knots=[(0.0, 0.0), (1500.0, 0.0), (1900.0, 0.02)])
    net = _db(tmp_path, LineSpec("0400", "Sag", a, [], tracks=("S",)))
    streams, _ = run(net, route={"path_km_m": [200.0, 3800.0]}, running={"line_speed_kmh": 72.0})
    imu, truth = streams["imu"], streams["truth"]
    t0, t1 = (float(np.interp(k, truth["km_m"], truth["t"])) for k in (1620.0, 1780.0))
    mid = imu[(imu["t"] > t0) & (imu["t"] < t1)]
    assert (mid["wy"] < 0).all()
    # constant speed 20 m/s on a vertical curve of radius 400 m / 0.02 = 20 km: v·dθ/ds
    assert mid["wy"].to_numpy() == pytest.approx(-20.0 * 0.02 / 400.0, rel=0.02)
    # vertical acceleration of a sag: az ≈ G + v²/R_v
    assert mid["az"].to_numpy() == pytest.approx(G + 20.0**2 * 0.02 / 400.0, abs=3e-3)
    assert imu["wy"].sum() * 0.01 == pytest.approx(-math.atan(0.02), abs=2e-4)


# -- tachometer ----------------------------------------------------------------------------
def test_pulse_distance_matches_truth_and_wheel_error(straight: Network) -> None:
    streams, meta = run(straight, route={"track": "D", "path_km_m": [300.0, 5500.0]})
    d_true = D_NOM * (1 - WEAR_PCT / 100)
    assert meta["sim_truth"]["wheel_diameter_true_m"] == pytest.approx(d_true, abs=1e-6)
    assert meta["wheel_diameter_m"] == D_NOM
    tacho, truth = streams["tacho"], streams["truth"]
    assert (tacho["t"].to_numpy() == truth["t"].to_numpy()).all()
    pulse = math.pi * D_NOM / TEETH
    by_pulses = tacho["pulses"].to_numpy() * pulse
    expected = (truth["km_m"].to_numpy() - 300.0) * GROUND * D_NOM / d_true
    err = expected - by_pulses
    assert err.min() >= -1e-3
    assert err.max() <= pulse + 1e-3
    assert by_pulses[-1] > 5200.0 * 1.003  # the worn wheel over-reads by 0.4 %


# -- up track, balises ---------------------------------------------------------------------
def test_up_track_runs_toward_decreasing_km_with_balises_in_order(straight: Network) -> None:
    streams, _ = run(straight, route={"track": "U"})
    truth, bal = streams["truth"], streams["balise"]
    km = truth["km_m"].to_numpy()
    assert np.all(np.diff(km) <= 1e-9) and km[-1] < km[0] - 5000.0
    assert (truth["speed_mps"] >= 0).all()  # travelling toward the F end
    db = straight.balises[straight.balises["track"] == "U"]
    for code in ("01", "02"):
        pair = db[db["station_code"] == code]
        i1_km = float(pair.loc[pair["kind"] == "I1", "km_actual_m"].iloc[0])
        i2_km = float(pair.loc[pair["kind"] == "I2", "km_actual_m"].iloc[0])
        assert i1_km == i2_km + 5.0  # U: the pair is laid for decreasing km
        at_i1 = np.isclose(at(truth, bal["t"].to_numpy(), "km_m"), i1_km, atol=0.05)
        t_i1 = float(bal.loc[(bal["kind"] == "I1") & at_i1, "t"].iloc[0])
        i2 = bal[(bal["kind"] == "I2") & (bal["station_code"] == code)]
        assert len(i2) == 1
        assert t_i1 < float(i2["t"].iloc[0])
        assert i2["track"].iloc[0] == "U"
        assert at(truth, i2["t"].to_numpy(), "km_m")[0] == pytest.approx(i2_km, abs=0.05)
    i1 = bal[bal["kind"] == "I1"]
    assert (i1["line_code"] == "0100").all() and i1["station_code"].isna().all() and i1["track"].isna().all()
    c = bal[bal["kind"] == "C"]
    assert len(c) == len(db[db["kind"] == "C"])
    assert c["signal_type"].notna().all() and c["line_code"].isna().all()
    # every telegram at the true km of a DB balise of that track
    kms = at(truth, bal["t"].to_numpy(), "km_m")
    assert np.min(np.abs(kms[:, None] - db["km_actual_m"].to_numpy()[None, :]), axis=1).max() < 0.05


def test_down_track_i1_before_i2(straight: Network) -> None:
    streams, _ = run(straight, route={"track": "D"})
    bal = streams["balise"]
    kinds = bal.loc[bal["kind"] != "C", "kind"].tolist()
    assert kinds == ["I1", "I2", "I1", "I2"]
    assert (streams["truth"]["km_m"].diff().dropna() >= -1e-9).all()


# -- reversal ------------------------------------------------------------------------------
def test_reversal_changes_ends(straight: Network) -> None:
    streams, meta = run(straight, route={"track": "D", "path_km_m": [300.0, 3000.0, 1500.0]})
    truth, cab, imu, tacho = streams["truth"], streams["cab"], streams["imu"], streams["tacho"]
    assert cab["direction"].tolist() == ["F", "R"]
    t_rev = float(cab["t"].iloc[1])
    speed = truth["speed_mps"].to_numpy()
    t = truth["t"].to_numpy()
    assert abs(np.interp(t_rev, t, speed)) < 1e-9
    assert speed[t < t_rev].max() > 10 and speed[t < t_rev].min() >= 0
    assert speed[t > t_rev].min() < -10 and speed[t > t_rev].max() <= 0
    assert np.interp(t_rev, t, truth["km_m"]) == pytest.approx(3000.0, abs=0.01)
    assert truth["km_m"].iloc[-1] == pytest.approx(1500.0, abs=0.01)
    # the body does not turn round: ax = d(speed toward F)/dt, so pulling away reversed gives ax < 0
    after = imu[imu["t"] > t_rev]
    assert after["ax"].min() == pytest.approx(-2.5 * KMH_PER_S, abs=0.01)
    assert at(imu, t, "ax") == pytest.approx(np.gradient(speed, t), abs=5e-3)
    assert np.all(np.diff(tacho["pulses"].to_numpy()) >= 0)
    assert tacho["pulses"].iloc[-1] * math.pi * D_NOM / TEETH == pytest.approx(
        (2700 + 1500) * GROUND * D_NOM / (D_NOM * (1 - WEAR_PCT / 100)), abs=0.05
    )
    assert meta["sim_truth"]["f_end_toward"] == "increasing_km"


def test_start_cab_r_runs_reversed_from_the_start(straight: Network) -> None:
    streams, _ = run(straight, route={"track": "D", "path_km_m": [300.0, 2000.0], "start_cab": "R"})
    assert streams["cab"]["direction"].tolist() == ["R"]
    assert streams["truth"]["speed_mps"].max() <= 0
    assert streams["imu"]["ax"].min() == pytest.approx(-2.5 * KMH_PER_S, abs=0.01)


# -- GPS -----------------------------------------------------------------------------------
def test_gps_on_the_gis_track_and_outage(straight: Network) -> None:
    streams, meta = run(
        straight, route={"track": "D", "path_km_m": [300.0, 5500.0]}, gps={"outages_km_m": [[2000.0, 2600.0]]}
    )
    gps, truth = streams["gps"], streams["truth"]
    km = at(truth, gps["t"].to_numpy(), "km_m")
    inside = (km >= 2000.0) & (km <= 2600.0)
    assert inside.sum() > 10
    assert (gps.loc[inside, "fix"] == 0).all()
    assert gps.loc[inside, ["lat", "lon"]].isna().all().all()
    assert (gps.loc[~inside, "fix"] > 0).all() and gps.loc[~inside, "lat"].notna().all()
    # fix 1 only in the 10 s after the tunnel
    t_exit = gps.loc[inside, "t"].max()
    fix1 = gps[gps["fix"] == 1]
    assert len(fix1) > 0 and (fix1["t"] > t_exit).all() and (fix1["t"] <= t_exit + 10).all()
    assert meta["sim_truth"]["gps_outages_s"][0][0] == pytest.approx(gps.loc[inside, "t"].min())
    # noise off: every fix lies on the DB's GIS polyline of track D at the true km
    g = straight.gis[straight.gis["track"] == "D"].sort_values("km_m")
    proj = projector_for_points(g["lat"], g["lon"])
    idx = PolylineIndex(*proj.to_xy(g["lon"], g["lat"]), g["km_m"])
    ok = gps["fix"] > 0
    x, y = proj.to_xy(gps.loc[ok, "lon"], gps.loc[ok, "lat"])
    p = idx.project(x, y)
    assert np.abs(p.offset_m).max() < 0.01
    assert p.km_m == pytest.approx(km[ok.to_numpy()], abs=0.01)


# -- slip / slide --------------------------------------------------------------------------
def test_scripted_slip_reads_more_distance(straight: Network) -> None:
    ep = {"t0_s": 25.0, "duration_s": 6.0, "kind": "slip", "depth": 0.3}
    streams, meta = run(straight, route={"track": "D", "path_km_m": [300.0, 3000.0]}, slip={"episodes": [ep]})
    truth, tacho = streams["truth"], streams["tacho"]
    assert meta["sim_truth"]["slip_episodes"] == [
        {"t0": 25.0, "t1": 31.0, "kind": "slip", "depth": 0.3, "on_grade_curve": False}
    ]
    flag = truth["slipping"].to_numpy() == 1
    t = truth["t"].to_numpy()
    assert (flag == ((t >= 25.0) & (t < 31.0 - 1e-9))).all()
    pulse = math.pi * D_NOM / TEETH
    k0, k1 = np.searchsorted(t, [25.0, 31.0])
    d_true = (truth["km_m"].iloc[k1] - truth["km_m"].iloc[k0]) * D_NOM / (D_NOM * (1 - WEAR_PCT / 100))
    d_wheel = (tacho["pulses"].iloc[k1] - tacho["pulses"].iloc[k0]) * pulse
    assert truth["speed_mps"].iloc[k1] > truth["speed_mps"].iloc[k0]  # accelerating
    assert d_wheel > d_true * 1.15


def test_random_slip_and_slide_placed_in_their_phases(straight: Network) -> None:
    streams, meta = run(
        straight,
        seed=4,
        route={"track": "D"},
        running={"stop_at_stations": True},
        slip={"slips": 2, "slides": 2, "on_grade_curve": False},
    )
    eps = meta["sim_truth"]["slip_episodes"]
    assert sorted(e["kind"] for e in eps) == ["slide", "slide", "slip", "slip"]
    truth, tacho = streams["truth"], streams["tacho"]
    t = truth["t"].to_numpy()
    pulse = math.pi * D_NOM / TEETH
    scale = 1 / (1 - WEAR_PCT / 100)
    for e in eps:
        assert 1.0 <= e["t1"] - e["t0"] <= 12.0 and 0.1 <= e["depth"] <= 0.4
        k0, k1 = np.searchsorted(t, [e["t0"], e["t1"]])
        v0, v1 = truth["speed_mps"].iloc[[k0, k1]]
        d_true = (truth["km_m"].iloc[k1] - truth["km_m"].iloc[k0]) * scale
        d_wheel = (tacho["pulses"].iloc[k1] - tacho["pulses"].iloc[k0]) * pulse
        assert truth["slipping"].iloc[k0:k1].all()
        if e["kind"] == "slip":
            assert v1 > v0 and d_wheel > d_true + pulse
        else:
            assert v1 < v0 and d_wheel < d_true - pulse
    inside = np.zeros(len(t), dtype=bool)
    for e in eps:
        inside |= (t >= e["t0"] - 1e-9) & (t < e["t1"] - 1e-9)
    assert (truth["slipping"].to_numpy() == inside).all()


def test_slip_on_a_gradient_plus_curve_section(tmp_path: Path) -> None:
    spec = demo_line("0900", seed=7)
    net = _db(tmp_path, spec)
    _, meta = run(net, seed=3, running={"stop_at_stations": True}, slip={"slips": 1, "slides": 1})
    eps = [e for e in meta["sim_truth"]["slip_episodes"] if e["on_grade_curve"]]
    assert len(eps) == 1
    streams, _ = run(net, seed=3, running={"stop_at_stations": True}, slip={"slips": 1, "slides": 1})
    km = at(streams["truth"], np.array([eps[0]["t0"], eps[0]["t1"]]), "km_m")
    s = spec.alignment.chainage(km)
    a = spec.alignment
    assert np.all(np.abs(a.grade(s)) >= 0.005 - 1e-4)
    assert np.all(np.abs(a.curvature(s)) >= 1 / 1500 * 0.95)


# -- determinism ---------------------------------------------------------------------------
def test_deterministic_per_seed(straight: Network) -> None:
    noisy = {
        "noise": True,
        "imu": {"accel_lsb_mps2": 0.00785, "gyro_lsb_deg_s": 0.02},
        "slip": {"slips": 2, "slides": 2},
    }
    sc = scenario_from_dict(_merge(QUIET, {**noisy, "route": {"track": "D"}, "sensors": {"radar": True}}), "t")
    a, ma = simulate_run(straight, sc, 11)
    b, mb = simulate_run(straight, sc, 11)
    c, _ = simulate_run(straight, sc, 12)
    assert ma.to_json() == mb.to_json()
    for name in a:
        pd.testing.assert_frame_equal(a[name], b[name])
    assert not np.array_equal(a["imu"]["ax"].to_numpy(), c["imu"]["ax"].to_numpy())
    assert not a["gps"]["lat"].equals(c["gps"]["lat"])


def test_imu_white_noise_level_at_100_ms(straight: Network) -> None:
    """σ of 100 ms averages ≈ 0.1 km/h/s and 0.1 deg/s at standstill (bias removed)."""
    sc = {"noise": True, "imu": {"accel_drift_kmh_s": 0.0, "gyro_drift_deg_s": 0.0}}
    streams, _ = run(
        straight,
        seed=9,
        route={"track": "D", "path_km_m": [300.0, 1000.0]},
        running={"standstill_start_s": 200.0},
        **sc,
    )
    rest = streams["imu"].iloc[:19_000]
    avg = rest.groupby(np.arange(len(rest)) // 10).mean()
    for axis in ("ax", "ay", "az"):
        assert avg[axis].std() == pytest.approx(0.1 * KMH_PER_S, rel=0.1)
    for axis in ("wx", "wy", "wz"):
        assert avg[axis].std() == pytest.approx(math.radians(0.1), rel=0.1)
    assert rest["az"].mean() == pytest.approx(G, abs=0.15)  # constant bias σ 0.1 km/h/s
