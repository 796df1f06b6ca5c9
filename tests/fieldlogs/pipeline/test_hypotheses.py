"""Track-selective positioning on the hand-made networks (tests/data/networks): candidates
carried along the topology and the evidence aids, on synthetic travel (no simulator)."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import Network
from fieldlogs.gnss.config import GnssConfig
from fieldlogs.gnss.ontrack import TrackSolutions
from fieldlogs.pipeline.aids.balise_group import BaliseGroupAid, group_table
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gnss import TrackGnssAid
from fieldlogs.pipeline.aids.track_gps import TrackGpsAid, gps_llr
from fieldlogs.pipeline.aids.track_imu import TrackImuAid, heading_llr, kept, turnouts
from fieldlogs.pipeline.config import BaliseConfig, GpsConfig
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import one_split, track_lines
from fieldlogs.pipeline.types import Fix, Hypothesis
from schemas.enums import EventType, FixSource
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net, travel


def run(network: Network, tr: Travel, start: Start, *extra: object) -> Solution:
    aids = [start, TopologyAid(track_lines(network), MARGIN), *extra]
    return run_aids(tr, aids, MARGIN)  # type: ignore[arg-type]


def types(sol: Solution) -> list[str]:
    return [str(e.type) for e in sol.events]


def test_facing_switch_splits_into_both_branches() -> None:
    # junction: A1 (km 0–400) → W1 (facing) → A2 (through) | B1 (diverging); 10 m/s from km 300,
    # margin 1 m + 2 % of the travel: the switch is within it from 300 + 10t + 1 + 0.2t = 400, t = 9.706 s
    n = net("junction")
    sol = run(n, travel(n, np.full(300, 10.0)), Start("9001", "S", 300.0, 1))
    p = sol.positions
    before = p[p["t"] <= 9.7]
    assert (before["state"] == "determined").all() and (before["track_id"] == "A1").all()
    assert before["pos_m"].iloc[50] == pytest.approx(350.0, abs=0.01)  # 5 s later: 50 m on
    near = p[(p["t"] >= 9.8) & (p["t"] < 10.0)]
    assert (near["state"] == "ambiguous").all() and near["km_m"].isna().all()
    first = json.loads(near["candidates"].iloc[0])  # t = 9.8: pos 398, margin 2.96 m
    assert [c["track_id"] for c in first] == ["A1", "A2", "B1"]
    assert [c["pos_m"] for c in first] == pytest.approx([398.0, -2.0, -2.0], abs=0.01)
    assert first[0]["margin_m"] == pytest.approx(1.0 + 0.02 * 98.0)
    after = p[p["t"] > 10.2]
    assert (after["state"] == "ambiguous").all() and after["track_id"].isna().all() and after["km_m"].isna().all()
    late = json.loads(after["candidates"].iloc[-1])
    assert sorted(c["track_id"] for c in late) == ["A2", "B1"]
    assert late[0]["pos_m"] == late[1]["pos_m"]
    split = [e for e in sol.events if e.type == EventType.SWITCH_SPLIT]
    assert len(split) == 1 and split[0].detail["switch_id"] == "W1" and split[0].t == pytest.approx(10.1)


def test_buffer_stop_drops_and_forgets() -> None:
    # the line ends 600 m after W1 on both branches: beyond the end by more than the margin
    n = net("junction")
    sol = run(n, travel(n, np.full(900, 10.0)), Start("9001", "S", 300.0, 1))
    drops = [e for e in sol.events if e.type == EventType.HYPOTHESIS_DROPPED]
    assert {e.detail["track_id"] for e in drops} == {"A2", "B1"}
    p = sol.positions
    last = p.iloc[-1]
    assert last["state"] == "undetermined"
    # dropped only once the whole interval is beyond the end: km 1000 + margin
    t_drop = drops[0].t
    s_drop = 10.0 * t_drop
    margin = 1.0 + 0.02 * s_drop
    assert 300.0 + s_drop - 1000.0 == pytest.approx(margin, abs=1.1)


def test_trailing_switch_moves_without_split_and_never_crosses_none() -> None:
    # from B1 km 100 running toward its begin (k = −1): trailing through W1 onto A1 (no split);
    # the B1–A2 relation is "none", so A2 is never a candidate; within the margin of W1 the
    # cycle is ambiguous between B1 and A1 only
    n = net("junction")
    sol = run(n, travel(n, np.full(300, 10.0)), Start("9002", "S", 100.0, -1))
    p = sol.positions
    assert EventType.SWITCH_SPLIT not in [e.type for e in sol.events]
    assert set(p["state"]) == {"determined", "ambiguous"}
    assert set(p["track_id"].dropna()) == {"B1", "A1"}
    assert "A2" not in "".join(p["candidates"].dropna())
    amb = p[p["state"] == "ambiguous"]
    travelled = 10.0 * amb["t"]
    dist = np.abs(100.0 - travelled)  # from the toe
    assert (dist <= 1.0 + 0.02 * travelled + 1e-6).all()
    on_a1 = p[p["track_id"] == "A1"]
    assert on_a1["km_m"].iloc[-1] == pytest.approx(400.0 - (29.9 * 10.0 - 100.0), abs=0.05)


def test_split_then_reversal_merges_back() -> None:
    # over W1 onto both branches, then back: both candidates return onto A1 and merge
    n = net("junction")
    v = np.concatenate([np.full(150, 10.0), np.full(150, -10.0)])
    sol = run(n, travel(n, v), Start("9001", "S", 350.0, 1))
    p = sol.positions
    assert "ambiguous" in set(p["state"])
    end = p.iloc[-1]
    assert end["state"] == "determined" and end["track_id"] == "A1"
    assert end["km_m"] == pytest.approx(350.0 + 1.0, abs=0.01)  # 150 cycles on, 149 back


def _g(t: float, group: int, pig: int) -> dict[str, object]:
    return {"t": t, "kind": "G", "nid_c": 230, "nid_bg": group, "n_pig": pig}


def _group_aid(n: Network, rows: list[dict[str, object]]) -> BaliseGroupAid:
    return BaliseGroupAid(group_table(n), track_lines(n), BaliseConfig(), rows)


def test_balise_group_beyond_the_switch_is_decisive() -> None:
    # group 3 stands on B1 at its km 40 (diverging branch): read 14 s after km 300
    n = net("junction")
    aid = _group_aid(n, [_g(14.0, 3, 0)])
    sol = run(n, travel(n, np.full(300, 10.0)), Start("9001", "S", 300.0, 1), aid)
    p = sol.positions
    late = p[p["t"] >= 14.0]
    assert (late["state"] == "determined").all() and (late["track_id"] == "B1").all()
    assert late["km_m"].iloc[0] == pytest.approx(40.0, abs=0.01)
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert res[0].detail["evidence"] == "balise_group" and res[0].detail["after_switch_m"] == pytest.approx(40, abs=1)


def test_balise_group_on_no_candidate_forgets() -> None:
    # group 1 stands on A1 (before the switch): read after the split it contradicts both candidates
    n = net("junction")
    aid = _group_aid(n, [_g(14.0, 1, 0)])
    sol = run(n, travel(n, np.full(300, 10.0)), Start("9001", "S", 300.0, 1), aid)
    assert EventType.BALISE_ANOMALY in [e.type for e in sol.events]
    assert (sol.positions[sol.positions["t"] >= 14.0]["state"] == "undetermined").all()


def test_balise_group_pair_sets_initial_position_and_direction() -> None:
    # no estimate: balises 0 then 1 of group 4 (A2 km 800, 803) read 0.3 s apart: km increasing
    n = net("junction")
    aid = _group_aid(n, [_g(1.0, 4, 0), _g(1.3, 4, 1)])
    tr = travel(n, np.full(100, 10.0))
    sol = run_aids(tr, [TopologyAid(track_lines(n), MARGIN), aid], MARGIN)
    p = sol.positions
    assert p.loc[p["t"].sub(3.3).abs().idxmin(), "km_m"] == pytest.approx(823.0, abs=0.01)
    assert p.loc[p["t"].sub(3.3).abs().idxmin(), "track_id"] == "A2"


def test_heading_llr_hand_computed() -> None:
    # 1:10: α = atan(0.1) = 5.711°; measured 5.5°, σ 0.5°: LLR(div vs through) = (5.5² − 0.211²)/(2·0.25)
    a = math.degrees(math.atan(0.1))
    llr = heading_llr(math.radians(5.5), [math.radians(a), 0.0], math.radians(0.5))
    assert llr[0, 1] == pytest.approx((5.5**2 - (5.5 - a) ** 2) / 0.5, rel=1e-9)
    assert kept(llr, CFG.threshold) == [0]
    assert kept(heading_llr(math.radians(a / 2), [math.radians(a), 0.0], math.radians(0.5)), CFG.threshold) == [0, 1]


def _imu_case(diverging: bool, noise_deg: float = 0.0) -> Solution:
    # crossover: D1 km 200 at 10 m/s; W1 (km 300, 1:10, left) splits into D2 (through) and X1
    n = net("crossover")
    tr = travel(n, np.full(400, 10.0))
    sw = turnouts(n.switches)
    r = float(n.switches.set_index("switch_id").loc["W1", "diverging_radius_m"])
    wz = np.zeros(tr.n)
    if diverging:  # on the lead's curve: ωz = v/R for R·α of travel after the toe (left: +)
        on = (tr.d >= 100.0) & (tr.d < 100.0 + r * math.atan(0.1))
        wz[on] = 10.0 / r
    wz[np.searchsorted(tr.d, 100.0)] += math.radians(noise_deg) / 0.1
    aid = TrackImuAid(wz, sw, track_lines(n), CFG, MARGIN)
    return run(n, tr, Start("9003", "D", 200.0, 1), aid)


@pytest.mark.parametrize(("diverging", "track", "after"), [(True, "X1", 8.0), (False, "D2", 14.0)])
def test_turnout_yaw_signature_resolves(diverging: bool, track: str, after: float) -> None:
    # looks every 2 m past the split (d = 100, m = 1 + 2 % of 100 = 3 m; lead R·α = 19.99 m,
    # x_end = 22.99 m: L = 12 looks). Diverging, look x = 8: window d 97 … 108 holds 9 cycles of
    # the curve, Δψ = 9·0.1 s·10/200.5 = 2.572° inside X1's span 5.71°·[5, 11]/19.99 =
    # [1.43°, 3.14°]: LLR = 2.572²/(2·0.504²) = 13.02 ≥ A + ln 12 + ln(1 + 1.71°·√(2/π)/0.504°)
    # = 9.20 + 2.48 + 1.31 = 12.99. Through, Δψ = 0: at x = 12 X1's span starts at 2.57°,
    # LLR 12.8 < 13.0; at x = 14 at 3.14°, LLR = 3.14²/(2·0.509²) = 19.0.
    sol = _imu_case(diverging)
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert len(res) == 1 and res[0].detail["evidence"] == "imu" and res[0].detail["track_id"] == track
    assert res[0].detail["after_switch_m"] == pytest.approx(after)
    expected = math.degrees(0.9 * 10.0 / 200.5) if diverging else 0.0
    assert res[0].detail["heading_change_deg"] == pytest.approx(expected, abs=0.01)
    # 25 s: 250 m from D km 200, past the crossover (≈ 60 m) onto U2, or on D2 at km 450
    at = sol.positions[sol.positions["t"].sub(25.0).abs() < 1e-6].iloc[0]
    assert at["state"] == "determined" and at["track_id"] == ("U2" if diverging else "D2")


@settings(max_examples=40, deadline=None)
@given(diverging=st.booleans(), noise=st.floats(-1.0, 1.0))
def test_no_determined_cycle_on_a_wrong_track(diverging: bool, noise: float) -> None:
    # gyro noise within 2σ of the model: either resolved right or left ambiguous, never wrong
    sol = _imu_case(diverging, noise)
    p = sol.positions
    truth = {"X1", "U2"} if diverging else {"D2"}
    after = p[(p["t"] > 10.1) & (p["state"] == "determined")]
    assert set(after["track_id"]) <= truth


def test_gps_llr_hand_computed() -> None:
    # two tracks 4 m apart, fixes 1 m off A toward B: r_A = 1, r_B = −3; Q = n·r²/(σw² + n·σb²)
    r = lambda k: np.array([[1.0] * k, [-3.0] * k])  # noqa: E731
    llr = gps_llr(r(3), 1.0, 0.1)
    assert llr[0, 1] == pytest.approx(0.5 * 3 * (9 - 1) / (1.0 + 3 * 0.01))
    assert kept(gps_llr(r(2), 1.0, 0.1), CFG.threshold) == [0, 1]  # 7.84: not yet
    assert kept(gps_llr(r(3), 1.0, 0.1), CFG.threshold) == [0]  # 11.65: A wins
    # a large bias σ: the evidence saturates at 8/(2·9) — ambiguous however many fixes
    assert kept(gps_llr(r(500), 1.0, 3.0), CFG.threshold) == [0, 1]


def test_gps_offsets_resolve_the_crossover() -> None:
    # crossover: split at W1 (km 300) into D2 and X1; the train is on D2: fixes on D's grid
    n = net("crossover")
    tr = travel(n, np.full(400, 10.0))
    g = n.gis[(n.gis["line_code"] == "9003") & (n.gis["track"] == "D")].set_index("km_m")
    t = np.arange(12.0, 20.0, 1.0)  # km 320 … 390
    km = 200.0 + 10.0 * t
    lat, lon = np.interp(km, g.index, g["lat"]), np.interp(km, g.index, g["lon"])
    aid = TrackGpsAid(t, lat, lon, track_lines(n), CFG, GpsConfig())
    sol = run(n, tr, Start("9003", "D", 200.0, 1), aid)
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert res and res[0].detail["evidence"] == "gps" and res[0].detail["track_id"] == "D2"
    assert (sol.positions[sol.positions["t"] >= 20.0]["track_id"] == "D2").all()


def test_joint_inside_a_line_track_keeps_km_behind_only_the_track_it_came_from() -> None:
    # from A2 km 500 toward W1 (k = −1): trailing onto A1 at t = 10 s (100 m). Then the interval
    # reaches back over A1's end: behind is A2 only (it came from there, B1 never), and A1/A2
    # being one line track (9001/S) the cycle keeps line, track and km, without a track_id
    n = net("junction")
    sol = run(n, travel(n, np.full(150, 10.0)), Start("9001", "S", 500.0, -1))
    p = sol.positions
    row = p[p["t"].sub(10.2).abs() < 1e-6].iloc[0]  # on A1 2 m from its end, margin 1 + 2.04 m
    assert row["state"] == "ambiguous" and pd.isna(row["track_id"])
    assert row["line_code"] == "9001" and row["track"] == "S" and row["km_m"] == pytest.approx(398.0, abs=0.01)
    cands = json.loads(row["candidates"])
    assert [c["track_id"] for c in cands] == ["A1", "A2"]
    assert [c["pos_m"] for c in cands] == pytest.approx([398.0, -2.0], abs=0.01)
    assert [c["km_m"] for c in cands] == pytest.approx([398.0, 398.0], abs=0.01)
    ahead = p[p["t"].sub(9.9).abs() < 1e-6].iloc[0]  # on A2 1 m before the joint: ahead is A1 only
    assert [c["track_id"] for c in json.loads(ahead["candidates"])] == ["A2", "A1"]
    behind = p[p["t"].sub(10.1).abs() < 1e-6].iloc[0]  # on A1 1 m past it: behind is A2, not B1
    assert [c["track_id"] for c in json.loads(behind["candidates"])] == ["A1", "A2"]
    clear = p[p["t"] >= 10.4]  # x m past the joint clear once x > 1 + 0.02·(100 + x): x > 3.12 m
    assert (clear["state"] == "determined").all() and (clear["track_id"] == "A1").all()


def test_balise_group_on_the_determined_track_corrects_its_position() -> None:
    # group 4 (A2 km 800) read at 35.5 s, 355 m from km 440: dead reckoning says 795, placed at 800
    n = net("junction")
    aid = _group_aid(n, [_g(35.5, 4, 0)])
    sol = run(n, travel(n, np.full(400, 10.0)), Start("9001", "S", 440.0, 1), aid)
    p = sol.positions
    at = p[p["t"].sub(35.5).abs() < 1e-6].iloc[0]
    assert at["state"] == "determined" and at["track_id"] == "A2"
    u = BaliseConfig().fix_uncertainty_m + BaliseConfig().latency_budget_s * 10.0
    assert at["km_m"] == pytest.approx(800.0, abs=0.01) and at["margin_m"] == pytest.approx(u)
    before = p[p["t"].sub(35.4).abs() < 1e-6].iloc[0]
    assert before["km_m"] == pytest.approx(794.0, abs=0.01)
    assert EventType.TRACK_RESOLVED not in [e.type for e in sol.events]


class _Fits:
    """Constrained-fit tables per (line, track, facing): test statistic ``good`` on 9001/S,
    ``bad`` on 9002/S, one receiver, epochs every 1 s, 4 satellites (dof 1)."""

    def __init__(self, good: float, bad: float) -> None:
        self.test = {("9001", "S", 1): good, ("9002", "S", 1): bad}

    def solutions(self, line_code: str, track: str, direction: int) -> TrackSolutions:
        ep = np.arange(41)
        tb = pd.DataFrame({"receiver": "r", "epoch": ep, "t": ep.astype(float), "dof": 1, "n_used": 4, "ok": True})
        tb["test"] = self.test[(line_code, track, direction)]
        return TrackSolutions(line_code, track, direction, None, tb, tb)  # type: ignore[arg-type]


@pytest.mark.parametrize(("bad", "resolved"), [(40.0, True), (4.4, True), (4.0, False), (2.5, False)])
def test_gnss_fit_on_the_wrong_branch_leaves_large_residuals(bad: float, resolved: bool) -> None:
    # split at W1 at 10.1 s; epochs 11…15 are the first gnss.split_epochs = 5 on both branches,
    # all favouring A2 (share 1 ≥ 0.9): B1 (line 9002) is dropped at t = 15 s when 5 × the
    # excess (bad − 2) is above gnss.track_chi2 = 10.83: 190 and 12 are, 10 and 2.5 never are
    n = net("junction")
    g = GnssConfig()
    aid = TrackGnssAid(_Fits(2.0, bad), np.arange(41.0), track_lines(n), g)
    sol = run(n, travel(n, np.full(400, 10.0)), Start("9001", "S", 300.0, 1), aid)
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    if resolved:
        assert len(res) == 1 and res[0].t == 15.0 and res[0].detail["evidence"] == "track_gnss"
        assert res[0].detail["track_id"] == "A2"
    else:
        assert not res and (sol.positions[sol.positions["t"] > 11.0]["state"] == "ambiguous").all()


def test_one_split_of_the_candidates() -> None:
    def fix(*hyps: Hypothesis) -> Fix:
        return Fix(0.0, 0.0, 0.0, math.nan, math.nan, "", "", 1, FixSource.BALISE, 1.0, hyps=hyps)

    a = Hypothesis("A", 5.0, 1, switch_id="W1", split_d=120.0)
    b = Hypothesis("B", 5.0, 1, switch_id="W1", split_d=120.0)
    assert one_split(fix(a, b)) == ("W1", 120.0)
    assert one_split(None) is None and one_split(fix(a)) is None  # fewer than two candidates
    assert one_split(fix(a, Hypothesis("B", 5.0, 1, switch_id="W1", split_d=80.0))) is None  # two splits of W1
    assert one_split(fix(a, Hypothesis("B", 5.0, 1, switch_id="W2", split_d=120.0))) is None  # two switches
    assert one_split(fix(Hypothesis("A", 5.0, 1), Hypothesis("B", 7.0, 1))) is None  # out of no split
    assert one_split(fix(a, Hypothesis("B", 5.0, 1, switch_id="W1"))) is None  # a split without its travel
