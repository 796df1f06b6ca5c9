"""Runs routed over a network (issue 31 item 4) on the hand-made networks of tests/data/networks.

The crossover network (``make_networks.crossover``): double-track line 9003, U at y = +2 m and
D at −2 m, crossover X1 from D km 300 (switch W1, toe west, diverging left) up to U km 360
(W2), four 1:10 turnouts of radius R = (e − d·cot α)/(2·tan(α/2)) for the x-extent e = 60 m
and the track distance d = 4 m, α = atan(1/10).
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
from dbtools.gis.geometry import Projector
from dbtools.network import Network, canonical
from fieldlogs.simulate.netsim import network_plan
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.networks.topology import station_network
from fieldlogs.simulate.scenario import ScenarioError, scenario_from_dict
from fieldlogs.simulate.simulator import SimulatedRun, simulate_run
from schemas.network import NETWORK_TABLES
from schemas.tables import BALISES

NETWORKS = Path(__file__).resolve().parents[2] / "data" / "networks"
ALPHA = math.atan(1 / 10)
D_TRACKS = 4.0
RADIUS = (60.0 - D_TRACKS / math.tan(ALPHA)) / (2 * math.tan(ALPHA / 2))
#: Length of the crossover: two arcs R·α and the straight between them (module docstring).
X_LENGTH = 2 * RADIUS * ALPHA + (D_TRACKS - 2 * RADIUS * (1 - math.cos(ALPHA))) / math.sin(ALPHA)


@pytest.fixture(scope="module")
def crossover(tmp_path_factory: pytest.TempPathFactory) -> Network:
    db = tmp_path_factory.mktemp("xo") / "xo.sqlite"
    build_db(NETWORKS / "crossover", db)
    return read_network(db)


def run(net: Network, network: dict[str, Any], **over: Any) -> SimulatedRun:
    base = {"noise": False, "slip": {"slips": 0, "slides": 0}, "running": {"line_speed_kmh": 60.0}}
    return simulate_run(net, scenario_from_dict({**base, **over, "network": network}))


def changes(values: pd.Series) -> list[str]:
    v = values.astype(str).tolist()
    return [a for i, a in enumerate(v) if i == 0 or a != v[i - 1]]


def test_hand_computed_radius_and_length() -> None:
    assert RADIUS == pytest.approx(200.5, abs=0.05)  # the switches table's diverging_radius_m
    assert X_LENGTH == pytest.approx(60.166, abs=0.001)  # 0.166 m more than the 60 m of km it spans


def test_crossover_run_truth_goes_u_crossover_d(crossover: Network) -> None:
    streams, meta = run(crossover, {"from_track": "D1", "to_track": "U3", "via": ["X1"]})
    truth = streams["truth"]
    assert changes(truth["track_id"]) == ["D1", "X1", "U2", "U3"]
    on_x = truth[truth["track_id"] == "X1"]
    assert on_x["track"].isna().all() and on_x["line_code"].isna().all()
    assert set(changes(truth["track"].dropna())) == {"D", "U"}
    assert [r["track_id"] for r in meta.extra["sim_truth"]["route"]] == ["D1", "X1", "U2", "U3"]
    # travel on the crossover is longer than the km it spans [S003]: X_LENGTH vs 60 m of km;
    # the route's ground arc length over X1 (splines through the true turnout arcs) is X_LENGTH
    geom = network_plan(crossover, scenario_from_dict({"network": {"tracks": ["D1", "X1", "U2"]}})).geom
    x1 = geom.segments[1]
    assert x1.length == pytest.approx(X_LENGTH, abs=0.001)
    arc = float(np.diff(geom.sigma([x1.rho0, x1.rho0 + x1.length]))[0])
    assert arc == pytest.approx(X_LENGTH, abs=0.02)
    assert on_x["km_m"].max() - on_x["km_m"].min() == pytest.approx(60.0, abs=1.0)
    assert on_x["pos_m"].is_monotonic_increasing and 0.0 <= on_x["pos_m"].min() <= on_x["pos_m"].max() <= X_LENGTH


def test_turnout_yaw_from_imu(crossover: Network) -> None:
    """The diverging branch turns by atan(1/10) at ωz ≈ v/R; the through branch does not."""
    streams, _ = run(crossover, {"tracks": ["D1", "X1", "U2", "U3"]})
    imu, truth = streams["imu"], streams["truth"]
    t, wz = imu["t"].to_numpy(), imu["wz"].to_numpy()
    tt, tid, pos = truth["t"].to_numpy(), truth["track_id"].to_numpy(), truth["pos_m"].to_numpy()
    on_x = tt[tid == "X1"]
    t_mid = tt[(tid == "X1") & (pos <= X_LENGTH / 2)][-1]
    first = (t >= on_x[0] - 5.0) & (t <= t_mid)
    assert np.trapezoid(wz[first], t[first]) == pytest.approx(ALPHA, rel=0.02)  # left: + heading
    second = (t > t_mid) & (t <= on_x[-1] + 5.0)
    assert np.trapezoid(wz[second], t[second]) == pytest.approx(-ALPHA, rel=0.02)
    # on the first arc (pos 2…R·α − 2 m, clear of the spline's ringing at the curvature steps)
    arc = (tid == "X1") & (pos > 2.0) & (pos < RADIUS * ALPHA - 2.0)
    v = np.abs(truth["speed_mps"].to_numpy()[arc])
    w = np.interp(tt[arc], t, wz)
    assert np.median(w / (v / RADIUS)) == pytest.approx(1.0, abs=0.03)
    # through: D1 → D2 → D3 never turns
    through, _ = run(crossover, {"tracks": ["D1", "D2", "D3"]})
    assert np.abs(through["imu"]["wz"]).max() < 1e-3


def test_switch_speed(crossover: Network) -> None:
    streams, meta = run(crossover, {"tracks": ["D1", "X1", "U2", "U3"]})
    truth = streams["truth"]
    v_x = truth.loc[truth["track_id"] == "X1", "speed_mps"].abs().max()
    assert v_x <= math.sqrt(0.8 * 200.5) + 1e-6  # the DB's R 200.5 m, a_ub 0.8 m/s², no cant
    assert [t["switch_id"] for t in meta.extra["sim_truth"]["turnouts"]] == ["W1", "W2"]
    slow, _ = run(crossover, {"tracks": ["D1", "X1", "U2", "U3"], "switch_speed_kmh": 25.0})
    truth = slow["truth"]
    assert truth.loc[truth["track_id"] == "X1", "speed_mps"].abs().max() <= 25.0 / 3.6 + 1e-6


def test_navigability_none_is_never_crossed(crossover: Network) -> None:
    # D2's begin meets X1's begin at W1 as its two branches: navigability none
    with pytest.raises(ScenarioError, match="navigability none") as exc:
        run(crossover, {"tracks": ["D2", "X1"], "direction": -1})
    assert exc.value.key == "network.tracks[1]"
    with pytest.raises(ScenarioError, match="no navigable route from D2 to X1"):
        run(crossover, {"from_track": "D2", "to_track": "X1", "direction": -1})
    with pytest.raises(ScenarioError, match="did you mean 'X1'"):
        run(crossover, {"tracks": ["D1", "X11"]})


def test_turnback_retraces_with_cab_change(crossover: Network) -> None:
    streams, _ = run(crossover, {"tracks": ["D1", "D2"], "points": [["D1", 100.0], ["D2", 200.0], ["D1", 150.0]]})
    truth = streams["truth"]
    assert changes(truth["track_id"]) == ["D1", "D2", "D1"]
    assert truth["speed_mps"].min() < -1.0 < 1.0 < truth["speed_mps"].max()  # second leg toward the R end
    assert streams["cab"]["direction"].tolist() == ["F", "R"]
    end = truth.iloc[-1]
    assert (end["track_id"], end["pos_m"]) == ("D1", pytest.approx(150.0, abs=0.05))
    # the group on D2 at 320/323 m km: read N_PIG 0, 1 going east, 1, 0 coming back
    b = streams["balise"]
    assert b.loc[b["nid_bg"] == 2, "n_pig"].tolist() == [0, 1, 1, 0]
    assert b["kind"].unique().tolist() == ["G"]
    assert b.loc[b["nid_bg"] == 1, "n_pig"].tolist() == [0, 1, 1, 0]


def test_gnss_outage_and_multipath_by_track_range(crossover: Network) -> None:
    streams, _ = run(
        crossover,
        {
            "tracks": ["D1", "X1", "U2", "U3"],
            "gnss_outages": [["X1", 0.0, 70.0]],
            "multipath": [["D1", 100.0, 250.0, 3.0]],
        },
    )
    gps, truth = streams["gps"], streams["truth"]
    tid = np.asarray(pd.Series(truth["track_id"]).iloc[np.searchsorted(truth["t"], gps["t"])], dtype=object)
    assert (gps.loc[tid == "X1", "fix"] == 0).all() and (gps.loc[tid == "X1", "lat"]).isna().all()
    assert (gps.loc[tid == "D1", "fix"] == 2).all()
    # D at y = −2 m, U at +2 m: biased 3 m toward U the fixes are 1 m north of the line's axis
    from pyproj import Proj

    proj = Proj(proj="aeqd", lat_0=60.2, lon_0=24.9, ellps="GRS80", units="m")
    _, y = proj(gps["lon"].to_numpy(float), gps["lat"].to_numpy(float))
    pos = np.interp(gps["t"], truth["t"], truth["pos_m"])
    biased = (tid == "D1") & (pos > 100.0) & (pos < 250.0)
    plain = (tid == "D1") & ((pos < 95.0) | (pos > 255.0))
    assert y[biased] == pytest.approx(1.0, abs=0.05)
    assert y[plain] == pytest.approx(-2.0, abs=0.05)


def test_raw_gnss_reflector_at_the_neighbouring_track(crossover: Network) -> None:
    """``network.multipath`` on raw GNSS: a surface at U's centreline, 4 m left of D travelling
    east, amplitude min(3 m / 4 m, 0.5); the pseudoranges change there, the truth does not."""
    route = {"tracks": ["D1", "X1", "U2", "U3"], "multipath": [["D1", 100.0, 250.0, 3.0]]}
    plan = network_plan(crossover, scenario_from_dict({"network": route}))
    at = plan.reflectors()
    assert (
        at is not None
        and network_plan(crossover, scenario_from_dict({"network": {"tracks": ["D1"]}})).reflectors() is None
    )
    d1 = plan.geom.segments[0]
    r = at(d1.rho_of(np.array([50.0, 150.0, 240.0, 260.0])))
    assert r.side.tolist() == [0.0, 1.0, 1.0, 0.0]
    assert r.dist_m[1:3] == pytest.approx(4.0, abs=0.05)
    assert r.amp.tolist() == pytest.approx([0.0, 0.5, 0.5, 0.0])
    raw = {"gnss_raw": {"enabled": True}}
    with_mp, meta = run(crossover, route, **raw)
    plain, _ = run(crossover, {"tracks": route["tracks"]}, **raw)
    pd.testing.assert_frame_equal(with_mp["truth"], plain["truth"])
    refl = meta.extra["sim_truth"]["gnss_raw"]["reflection"]
    assert refl["observations"] > 0 and refl["code_min_m"] < 0 < refl["code_max_m"]
    diff = with_mp["gnss_obs"]["pseudorange_m"].to_numpy() - plain["gnss_obs"]["pseudorange_m"].to_numpy()
    assert int((diff != 0).sum()) == refl["observations"]


def test_network_knobs_are_checked() -> None:
    with pytest.raises(ScenarioError) as exc:
        scenario_from_dict({"network": {"tracks": ["A"], "from_track": "B", "to_track": "C"}})
    assert exc.value.key == "network.tracks"
    with pytest.raises(ScenarioError) as exc:
        scenario_from_dict({"network": {"tracks": ["A"]}, "gps": {"outages_km_m": [[1.0, 2.0]]}})
    assert exc.value.key == "gps.outages_km_m"
    with pytest.raises(ScenarioError) as exc:
        scenario_from_dict({"network": {"tracks": ["A"], "gnss_outages": [["A", 5.0, 1.0]]}})
    assert exc.value.key == "network.gnss_outages[0]"


def synthetic_stations() -> Network:
    """The demo line with the synthetic station layouts of :mod:`fieldlogs.simulate.networks.topology`."""
    spec, proj = demo_line(), Projector(9)
    net = build_network([spec], proj)
    parts = station_network(spec, proj)
    tables = dict(net.tables)
    tables[BALISES.name] = canonical(BALISES, pd.concat([net.balises, parts.pop("balises")], ignore_index=True))
    tables.update({t.name: canonical(t, parts[t.name]) for t in NETWORK_TABLES})
    return Network(tables, meta=net.meta)


def test_synthetic_loop_turns_by_the_frog_angle() -> None:
    """Entering loop 3 of a synthetic station: the route's heading turns by atan(1/8) against the
    main track's at the same km (the layout's 1:8 turnout), and the IMU shows it."""
    net = synthetic_stations()
    w1 = net.switches.set_index("switch_id").loc[["0900-02-3-W1"]].iloc[0]
    n, radius = float(w1["switch_number"]), float(w1["diverging_radius_m"])
    loop = {"from_track": "0900-D-0", "to_track": "0900-D-9", "via": ["0900-02-3"]}
    plan = network_plan(net, scenario_from_dict({"network": loop}))
    through = network_plan(net, scenario_from_dict({"network": {"from_track": "0900-D-0", "to_track": "0900-D-9"}}))
    seg = next(s for s in plan.geom.segments if s.track_id == "0900-02-3")
    rho = seg.rho0 + radius * math.atan(1 / n)  # the end of the turnout curve
    km = float(plan.geom.locate([rho])["km_m"][0])
    rho_main = float(np.interp(km, *_km_rho(through)))
    a, b = plan.geom.state([rho]), through.geom.state([rho_main])
    turn = math.atan2(a.sin_psi[0], a.cos_psi[0]) - math.atan2(b.sin_psi[0], b.cos_psi[0])
    assert turn == pytest.approx(math.atan(1 / n), rel=0.02)  # D's loop 3 lies left: + heading
    streams, _ = simulate_run(
        net, scenario_from_dict({"noise": False, "slip": {"slips": 0, "slides": 0}, "network": loop})
    )
    assert np.abs(streams["imu"]["wz"]).max() > 0.5 * 8.0 / radius  # seen at any speed above 8 m/s


def _km_rho(plan: Any) -> tuple[np.ndarray, np.ndarray]:
    rho = np.arange(plan.geom.km_min, plan.geom.km_max, 1.0)
    return plan.geom.locate(rho)["km_m"], rho


def test_cli_network_scenario(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from cli.main import app
    from fieldlogs.runs.handle import read_run

    db = tmp_path / "xo.sqlite"
    build_db(NETWORKS / "crossover", db)
    scen = tmp_path / "xo.toml"
    scen.write_text('[network]\ntracks = ["D1", "X1", "U2", "U3"]\n[slip]\nslips = 0\nslides = 0\n', encoding="utf-8")
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["simulate", "--db", str(db), "--out", str(out), "--scenario", str(scen)])
    assert res.exit_code == 0, res.output
    run = read_run(out)
    streams = run.load_all()
    assert run.findings == []
    assert set(streams["truth"]["track_id"].dropna()) == {"D1", "X1", "U2", "U3"}
    assert run.raw_json["sim_truth"]["turnouts"][0]["switch_id"] == "W1"
    bad = tmp_path / "bad.toml"
    bad.write_text('[network]\ntracks = ["D2", "X1"]\ndirection = -1\n', encoding="utf-8")
    res = CliRunner().invoke(app, ["simulate", "--db", str(db), "--out", str(tmp_path / "r2"), "--scenario", str(bad)])
    assert res.exit_code == 2
    assert "network.tracks[1]" in res.output and "navigability none" in res.output
    assert "Traceback" not in res.output
