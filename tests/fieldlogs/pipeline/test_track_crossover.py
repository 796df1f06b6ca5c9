"""The IMU's crossover signature (:mod:`fieldlogs.pipeline.aids.track_crossover`): hand-computed
displacement, σ and LLR, engine cases on the hand-made crossover network (tests/data/networks,
1:10 crossovers between tracks 4.0 m apart) and a seeded property test over random routes
through its crossovers: never a wrong track."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_crossover import (
    Crossover,
    TrackCrossoverAid,
    crossovers,
    displacement_sigma,
    lateral_displacement,
)
from fieldlogs.pipeline.aids.track_imu import heading_llr, kept
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.track_truth import compare_tracks
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import EventType
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net, travel

DT = 0.1
B = math.radians(CFG.gyro_bias_dps)
Q = math.radians(CFG.gyro_noise_dps_rthz)


def _ride(cycles_curve: int, cycles_straight: int, w: float) -> np.ndarray:
    """ωz per cycle over a crossover ride: +w, 0, −w."""
    return np.concatenate([np.full(cycles_curve, w), np.zeros(cycles_straight), np.full(cycles_curve, -w)])


def test_displacement_of_a_crossover_ride_hand_computed() -> None:
    # 10 m/s, 0.1 s cycles: 20 cycles at ω = 0.05 rad/s (R = 200 m, α = 0.1 rad over 20 m),
    # 20 m straight, 20 cycles back: y = 2R(1 − cos α) + 20·sin α = 1.99833 + 1.99667 = 3.99500
    wz = np.concatenate([_ride(20, 20, 0.05), [0.0]])
    t = np.arange(wz.size, dtype=np.float64) * DT
    d = t * 10.0
    assert lateral_displacement(t, d, wz) == pytest.approx(400.0 * (1 - math.cos(0.1)) + 20.0 * math.sin(0.1), abs=1e-4)
    assert lateral_displacement(t, d, np.zeros(wz.size)) == 0.0  # the through route: none
    # a right-hand crossover mirrors it
    assert lateral_displacement(t, d, -wz) == pytest.approx(-3.99500, abs=1e-4)
    # a constant bias b over the window adds b·K, K = Σ τᵢ Δdᵢ = v·T²/2 (τ at the cycles' middles)
    k = 10.0 * (wz.size - 1) ** 2 * DT * DT / 2.0
    biased = lateral_displacement(t, d, wz + B)
    assert biased - 3.995 == pytest.approx(B * k, rel=0.01)


def test_sigma_hand_computed() -> None:
    # 10 s at 10 m/s (N = 100 cycles): K = v·T²/2 = 500 m·s, b_g·K = 0.43633 m; white noise
    # q²·v²·Δt³·Σₖ (N − k − ½)² = q²·v²·Δt³·(N³/3 − N/12) = 4.0615e-3 m²; σ_geo² = 0.09 m²
    t = np.arange(101, dtype=np.float64) * DT
    d = t * 10.0
    var = (B * 500.0) ** 2 + Q * Q * 100.0 * 1e-3 * (100**3 / 3 - 100 / 12) + 0.3**2
    assert displacement_sigma(t, d, CFG) == pytest.approx(math.sqrt(var), rel=1e-9)
    assert math.sqrt(var) == pytest.approx(0.53334, abs=1e-5)


def test_llr_at_a_given_bias_hand_computed() -> None:
    # the ride above with a 1σ bias (0.05 °/s): y = 3.995 + 0.43633 = 4.4313; σ = 0.53334:
    # LLR(crossover 3.995 vs through 0) = (4.4313² − 0.43633²)/(2·0.28445) = 34.18 ≥ A = 9.20
    y, s = 3.995 + B * 500.0, 0.53334
    llr = heading_llr(y, [3.995, 0.0], s)
    assert llr[0, 1] == pytest.approx((y * y - (B * 500.0) ** 2) / (2 * s * s), rel=1e-9)
    assert llr[0, 1] == pytest.approx(34.18, abs=0.01)
    assert kept(llr, CFG.threshold) == [0]
    # half-way (y = 2 m) decides nothing
    assert kept(heading_llr(2.0, [3.995, 0.0], s), CFG.threshold) == [0, 1]


def test_crossovers_of_the_hand_network() -> None:
    n = net("crossover")
    assert crossovers(n.switches, n.tracks) == {
        "W1": Crossover("D1", "end", "X1", "begin"),
        "W2": Crossover("U2", "begin", "X1", "end"),
        "W3": Crossover("U2", "end", "X2", "begin"),
        "W4": Crossover("D3", "begin", "X2", "end"),
    }
    assert crossovers(net("junction").switches, net("junction").tracks) == {}


# -- the engine on the hand-made crossover network -------------------------------------------
R, ALPHA = 200.5, math.atan(0.1)
LEAD = R * ALPHA  # 19.98 m
LX = 60.1663842  # the crossover tracks' length


def _wz(tr: Travel, d_toe: float, sign: float, scale: float = 1.0) -> np.ndarray:
    """ωz of a ride over a crossover whose toe the true travel d·``scale`` passes at ``d_toe``:
    sign·v/R over the lead, −sign·v/R over the far turnout's R·α before the crossover's end."""
    dd = tr.d * scale
    wz = np.zeros(tr.n)
    first = (dd >= d_toe) & (dd < d_toe + LEAD)
    last = (dd >= d_toe + LX - LEAD) & (dd < d_toe + LX)
    wz[first] = sign * tr.v[first] * scale / R
    wz[last] = -sign * tr.v[last] * scale / R
    return wz


def _run(n: Network, tr: Travel, start: Start, wz: np.ndarray) -> Solution:
    aid = TrackCrossoverAid(wz, crossovers(n.switches, n.tracks), track_lines(n), CFG, MARGIN)
    return run_aids(tr, [start, TopologyAid(track_lines(n), MARGIN), aid], MARGIN)


def _resolved(sol: Solution) -> list[dict[str, object]]:
    return [e.detail for e in sol.events if e.type == EventType.TRACK_RESOLVED]


@pytest.mark.parametrize(("diverging", "track", "y"), [(True, "U2", 4.085), (False, "D2", 0.0)])
def test_crossover_signature_resolves(diverging: bool, track: str, y: float) -> None:
    # D km 200 at 10 m/s, margin 1 m + 2 % of travel; W1 (km 300, left): the point passes the
    # toe at d_toe = 99.99999 (D1 rolls 299.99999 m on the line grid), split at the cycle d = 100,
    # m_t = 3 m: the window starts at the cycle at or before d = 96.99999, d = 96. The crossover's
    # candidate lies wholly beyond X1 (60.166 m) once d − 160.166 ≥ 1 + 0.02·d, d ≥ 164.46:
    # decided at d = 165 (65 m after the split). Diverging: 20 cycles at +v/R (d 100 … 119),
    # 21 m straight, 20 cycles at −v/R (d 141 … 160):
    # y = 2R(1 − cos 0.09975) + 21·sin 0.09975 = 1.9933 + 2.0917 = 4.085 m.
    # σ over 6.9 s: √((b_g·10·6.9²/2)² + q²·100·0.001·(69³/3 − 69/12) + 0.3²)
    # = √(0.20775² + 0.00133 + 0.09) = 0.3667 m; LLR = (4.085² − 0.085²)/(2·0.1345) = 62 ≥ A = 9.2
    n = net("crossover")
    tr = travel(n, np.full(300, 10.0))
    sol = _run(n, tr, Start("9003", "D", 200.0, 1), _wz(tr, 100.0, 1.0) if diverging else np.zeros(tr.n))
    (res,) = _resolved(sol)
    assert res["evidence"] == "imu_crossover" and res["track_id"] == track and res["switch_id"] == "W1"
    assert res["after_switch_m"] == pytest.approx(65.0)
    assert res["displacement_m"] == pytest.approx(y, abs=0.002)
    assert res["sigma_m"] == pytest.approx(0.367, abs=0.001)
    at = sol.positions[sol.positions["t"].sub(20.0).abs() < 1e-6].iloc[0]
    assert at["state"] == "determined" and at["track_id"] == track


def test_a_stop_on_the_crossover_decides_nothing() -> None:
    # the same diverging ride with a 3 s stop at d = 130 (on X1's straight middle)
    n = net("crossover")
    v = np.concatenate([np.full(130, 10.0), np.zeros(30), np.full(200, 10.0)])
    tr = travel(n, v)
    sol = _run(n, tr, Start("9003", "D", 200.0, 1), _wz(tr, 100.0, 1.0))
    assert _resolved(sol) == []
    assert set(sol.positions[sol.positions["t"] > 20.0]["state"]) == {"ambiguous"}


def test_reverse_direction_through_w4() -> None:
    # D km 800 running toward decreasing km (cab reversed: body-forward travel is −km): W4
    # (km 660, right as seen from D3) takes the train onto X2 and U2 — heading −α, then +α
    n = net("crossover")
    tr = travel(n, np.full(300, -10.0), cab=-1)
    sol = _run(n, tr, Start("9003", "D", 800.0, -1), _wz(tr, 140.0, -1.0))
    (res,) = _resolved(sol)
    assert res["track_id"] == "U2" and res["switch_id"] == "W4"
    assert res["displacement_m"] == pytest.approx(-4.085, abs=0.002)


# -- seeded property: random routes through the crossovers, never a wrong track ---------------
ROUTES = {
    # (start line track, km, k, toe km, diverging sign, truth after the ride: diverging, through)
    "W1": ("D", 200.0, 1, 300.0, 1.0, ("X1", "U2"), ("D2",)),
    "W3": ("U", 500.0, 1, 600.0, -1.0, ("X2", "D3"), ("U3",)),
    "W4": ("D", 760.0, -1, 660.0, -1.0, ("X2", "U2"), ("D2",)),
    "W2": ("U", 460.0, -1, 360.0, 1.0, ("X1", "D1"), ("U1",)),
}


@settings(max_examples=60, deadline=None)
@given(
    sw=st.sampled_from(sorted(ROUTES)),
    diverging=st.booleans(),
    speed=st.floats(2.0, 30.0),
    scale=st.floats(0.985, 1.015),
    bias=st.floats(-2.0, 2.0),
    stop_at=st.one_of(st.none(), st.floats(60.0, 200.0)),
    seed=st.integers(0, 2**16),
)
def test_never_a_wrong_track(
    sw: str, diverging: bool, speed: float, scale: float, bias: float, stop_at: float | None, seed: int
) -> None:
    # the odometry off by up to 1.5 % (inside the margin's 2 %), a gyro bias within ±2σ and the
    # model's white noise, sometimes a stop: resolved by the crossover test only to the truth
    track, km0, k, toe, sign, div_truth, thr_truth = ROUTES[sw]
    n = net("crossover")
    n_cyc = int(260.0 / speed / DT) + 1
    v = np.full(n_cyc, speed)
    if stop_at is not None:
        i = int(stop_at / speed / DT)
        v = np.concatenate([v[:i], np.zeros(20), v[i:]])
    tr = travel(n, k * v, cab=k)
    d_toe = abs(toe - km0)
    wz = _wz(tr, d_toe, sign, scale) if diverging else np.zeros(tr.n)
    rng = np.random.default_rng(seed)
    wz = wz + bias * B + rng.standard_normal(tr.n) * Q / math.sqrt(DT)
    sol = _run(n, tr, Start("9003", track, km0, k), wz)
    truth = set(div_truth if diverging else thr_truth)
    for res in _resolved(sol):
        assert res["track_id"] in truth
    p = sol.positions
    t_past = float(tr.t[min(int(np.searchsorted(tr.d * scale, d_toe + 1.0)), tr.n - 1)])
    late = p[(p["state"] == "determined") & (p["t"] >= t_past)]
    assert set(late["track_id"]) <= truth


# -- the network sample's X2 (1:10, R 220.5 m, 60.153 m), simulated and replayed --------------
def _x2_run(network: Network, tracks: list[str], root: Path) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    """IMU-only (no GPS) at 60 km/h from U2 over W7 (facing, left to X2), seed 1: events,
    positions and the truth comparison of the replay with the default settings."""
    sc = {
        "name": "x2",
        "seed": 1,
        "run": {"run_id": "X2"},
        "running": {"line_speed_kmh": 60.0},
        "network": {"tracks": tracks, "points": [["0420-U2", 300.0], [tracks[-1], 600.0]]},
        "sensors": {"gps": False},
    }
    streams, meta = simulate_run(network, scenario_from_dict(sc, source="test"))
    res = run_pipeline(read_run(write_run(root / "run", meta, streams)), network)
    return res.events, res.positions, compare_tracks(res.positions, streams["truth"], network)


@pytest.fixture(scope="module")
def sample_net(sample_network_db: Path) -> Network:
    return read_network(sample_network_db)


def test_x2_of_the_network_sample_resolved_by_its_signature(sample_net: Network, tmp_path: Path) -> None:
    # the margin at W7 (≈ 12 m) is beyond what the turnout test allows on a 60 m crossover
    # (m + m_end ≤ 16 m): before this test the candidates U5 and D5 stayed ambiguous until the
    # balise group past W9 (40 m beyond the next facing switch)
    events, _, tc = _x2_run(sample_net, ["0420-U2", "0420-U3", "0420-U4", "0420-X2", "0420-D5", "0420-D6"], tmp_path)
    res = [json.loads(d) for d in events.loc[events["type"] == EventType.TRACK_RESOLVED.value, "detail"]]
    first = res[0]
    assert first["evidence"] == "imu_crossover" and first["switch_id"] == "W7"
    assert first["track_id"] == "0420-D5" and first["candidates"] == ["0420-U5", "0420-D5"]
    assert first["displacement_m"] == pytest.approx(4.0, abs=3 * first["sigma_m"])  # U and D 4.0 m apart
    assert not tc["wrong"].any()


def test_x2_through_route_never_claims_d(sample_net: Network, tmp_path: Path) -> None:
    events, positions, tc = _x2_run(sample_net, ["0420-U2", "0420-U3", "0420-U4", "0420-U5"], tmp_path)
    res = [json.loads(d) for d in events.loc[events["type"] == EventType.TRACK_RESOLVED.value, "detail"]]
    assert res and all(r["track_id"] == "0420-U5" for r in res)  # the turnout test decides first here
    assert not tc["wrong"].any()
    assert "0420-D5" not in set(positions.loc[positions["state"] == "determined", "track_id"])
