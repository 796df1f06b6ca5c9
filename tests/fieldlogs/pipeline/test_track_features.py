"""Feature points on network tracks (track_feature_points) as evidence of the track, on the
hand-made junction (tests/data/networks/junction) with synthetic travel and yaw rate.

The junction: line 9001 (track A1 km 0–400, A2 km 400–1000, straight east) and, from the toe
of W1 at km 400, line 9002 = track B1 (pos = its km 0–600) leaving to the left: arc R 190 m
to α = atan(1/9) (R·α = 21.03 m), 40 m straight, arc R 500 m to 30° (500·(30° − α) =
206.46 m, pos 61.03–267.49), straight. Its R 500 m curve is one track-form feature."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.gis.geometry import arc_turn
from dbtools.network import Network
from fieldlogs.pipeline.aid import Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.features import FeatureUnit
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_features import TrackFeatureAid, TrackFeatureFixAid, track_feature_tables
from fieldlogs.pipeline.config import FeatureConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.track_heading import headings, rises, sure_turns, turn_range, violation_llr
from fieldlogs.pipeline.types import Fix, Hypothesis, Odometry
from schemas.enums import EventType, FixSource, PositionState
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net, travel

ALPHA = math.atan(1 / 9)
LEAD = 190.0 * ALPHA  # 21.03 m
C0 = LEAD + 40.0  # the R 500 m curve: pos 61.03 …
C1 = C0 + 500.0 * (math.radians(30.0) - ALPHA)  # … 267.49
FEATURE = pd.DataFrame(
    {
        "track_id": ["B1"] * 6,
        "feature_id": ["F1"] * 6,
        "seq": [1, 2, 3, 4, 5, 6],
        "pos_m": [LEAD, C0, C0, C1, C1, C1 + 40.0],
        "radius_m": [0.0, 0.0, 500.0, 0.0, 0.0, 0.0],
        "attribute": ["straight", "transition", "left", "transition", "straight", "none"],
        "role": [None] * 6,
    }
)


def junction() -> Network:
    n = net("junction")
    return Network({**n.tables, "track_feature_points": FEATURE.copy()}, origin="junction+features")


class Ambiguous(StaticAid):
    """An ambiguous start at t = 0: the train is on B1 or on A2, both at pos ``pos`` and running
    toward W1 (kp −1), as after a balise-less start between two trailing branches."""

    name = "ambiguous_start"
    priority = Priority.TELEGRAM

    def __init__(self, pos: float) -> None:
        self.pos = pos

    def observations(self) -> list[Observation]:
        return [Observation(0.0)]

    def observe(self, obs: Observation, view: object) -> Outcome:
        hyps = (Hypothesis("B1", self.pos, -1, hid=1), Hypothesis("A2", self.pos, -1, hid=2))
        nan = float("nan")
        fix = Fix(0.0, 0.0, 0.0, nan, nan, "", "", 1, FixSource.BALISE, 1.0, PositionState.AMBIGUOUS, hyps=hyps)
        return Outcome([], fix)


def wz_on_curves(tr: Travel, pos_of_d: np.ndarray, turn: float) -> np.ndarray:
    """Yaw rate of a train whose pos on B1 is ``pos_of_d`` per cycle: v/R on both arcs,
    signed ``turn`` (+1: turning left in the travel direction)."""
    wz = np.zeros(tr.n)
    wz[(pos_of_d >= 0.0) & (pos_of_d < LEAD)] = turn * tr.v[0] / 190.0
    wz[(pos_of_d >= C0) & (pos_of_d < C1)] = turn * tr.v[0] / 500.0
    return wz


def solve(n: Network, tr: Travel, start: Start | Ambiguous, wz: np.ndarray) -> Solution:
    lines = track_lines(n)
    aid = TrackFeatureAid(track_feature_tables(n, lines), lines, wz, CFG, MARGIN)
    aids: list[Any] = [start, TopologyAid(lines, MARGIN), aid]
    return run_aids(tr, aids, MARGIN)


def resolved(sol: Solution) -> list[dict[str, Any]]:
    return [e.detail for e in sol.events if e.type == EventType.TRACK_RESOLVED]


def test_arc_turn_and_rises_hand_computed() -> None:
    u = np.array([0.0, 20.0, 50.0, 150.0, 180.0, 200.0])
    # body 100 m + half of each 30 m transition = 130 m at R 650: 0.2 rad
    assert arc_turn(u, 650.0) == pytest.approx(0.2)
    assert rises(np.array([0.0, 0.1, -0.2, 0.3, 0.25])) == pytest.approx((0.5, 0.3))
    assert turn_range(np.array([0.1, 0.0]), np.array([0.5, 2 * math.pi + 0.6])) == pytest.approx((0.4, 0.6))


def test_violation_llr_hand_computed() -> None:
    # δ 0.05 and 0.02 rad, σ 0.01 rad: LLR[1, 0] = (0.05² − 0.02²)/(2·0.01²) = 10.5; unknown → 0
    llr = violation_llr([0.05, 0.02, None], 0.01)
    assert llr[1, 0] == pytest.approx(10.5)
    assert llr[0, 1] == pytest.approx(-10.5)
    assert (llr[2] == 0).all() and (llr[:, 2] == 0).all()


def test_headings_along_the_branch_and_across_the_toe() -> None:
    lines = track_lines(junction())
    # B1 at the end of its R 500 m curve runs 30° left of A2's heading (east = 0)
    on_b = headings(lines, "B1", 1, 300.0, 310.0)
    assert on_b is not None and np.allclose(on_b, math.radians(30.0), atol=1e-3)
    # running B1 toward its begin: the opposite heading; behind the toe it continues on A1
    back = headings(lines, "B1", -1, -15.0, -5.0)
    assert back is not None and np.allclose(np.cos(back), -1.0, atol=1e-6)
    # beyond A1's end lies the facing switch W1: two exits, unknown
    assert headings(lines, "A1", 1, 390.0, 410.0) is None


def test_sure_turns_of_the_chords_run_over() -> None:
    # B1's grid points every 20 m of km (= pos); chords wholly within pos 70–260 run from
    # [80, 100] to [240, 260], all on the R 500 m arc: their headings differ by the arc between
    # their middles, (250 − 90)/500 rad = 18.33° — a left turn running begin → end, a right
    # turn the other way; on A2 (straight) none
    lines = track_lines(junction())
    left, right = sure_turns(lines, "B1", 1, 70.0, 260.0)
    # (within 0.05°: the local equirectangular plane against the grid's own projection)
    assert math.degrees(left) == pytest.approx(math.degrees(160.0 / 500.0), abs=0.05) and right == pytest.approx(0.0)
    assert sure_turns(lines, "B1", -1, 70.0, 260.0) == pytest.approx((0.0, left))
    assert sure_turns(lines, "A2", 1, 10.0, 500.0) == pytest.approx((0.0, 0.0), abs=2e-4)  # plane drift 0.01°
    assert sure_turns(lines, "B1", 1, 70.0, 95.0) == (0.0, 0.0)  # fewer than two chords


def test_tables_of_both_forms() -> None:
    n = junction()
    tabs = track_feature_tables(n, track_lines(n))
    assert set(tabs.own) == {"B1"} and tabs.own["B1"].km[0] == pytest.approx(FEATURE["pos_m"].to_numpy())
    assert tabs.own["B1"].left[0]
    # seen running toward the begin: rows in travel order are pos 307.5 … 21.0, a right curve
    u, pos, sign = tabs.own["B1"].travel_rows(-1)
    assert pos[0] == pytest.approx(FEATURE["pos_m"].to_numpy()[::-1]) and sign[0] == -1
    assert (np.diff(u[0]) >= 0).all()


@pytest.mark.parametrize(("truth", "kept"), [("B1", "B1"), ("A2", "A2")])
def test_curve_on_a_branch_seen_in_the_reverse_direction(truth: str, kept: str) -> None:
    # from pos 450 toward W1 at 10 m/s: on B1 the curve is met as a right turn of 23.66°
    # (pos 267.5 → 61.0); on A2 nothing turns. The test window ends at u = r5 + m, i.e. pos
    # 61.0 − m: m = 1 + 2 % of the travel ≈ 8.8 m → at t ≈ 39.8 s, before the toe (pos 0).
    n = junction()
    tr = travel(n, np.full(500, 10.0))
    pos = 450.0 - tr.d
    wz = wz_on_curves(tr, pos, -1.0) if truth == "B1" else np.zeros(tr.n)
    sol = solve(n, tr, Ambiguous(450.0), wz)
    res = resolved(sol)
    assert len(res) == 1 and res[0]["evidence"] == "feature" and res[0]["track_id"] == kept
    assert res[0]["feature_track_id"] == "B1" and res[0]["feature_id"] == "F1"
    t_res = next(e.t for e in sol.events if e.type == EventType.TRACK_RESOLVED)
    m = 1.0 + 0.02 * 10.0 * t_res
    assert 450.0 - 10.0 * t_res == pytest.approx(C0 - m, abs=0.2)
    expected = -math.degrees((C1 - C0) / 500.0) if truth == "B1" else 0.0  # −23.66° or 0
    assert res[0]["heading_change_deg"] == pytest.approx(expected, abs=0.12)  # one 1 m cycle: 0.115°
    p = sol.positions
    later = p[p["t"] > t_res + 0.05]
    assert later["state"].iloc[0] == "determined" and later["track_id"].iloc[0] == kept
    # on to the trailing toe (ambiguous while the margin spans the joint), then A1
    det = later[later["state"] == "determined"]
    assert set(det["track_id"]) == {kept, "A1"}


@pytest.mark.parametrize(("diverging", "kept"), [(True, "B1"), (False, "A2")])
def test_curve_on_the_other_candidate_after_the_facing_switch(diverging: bool, kept: str) -> None:
    # from A1 km 300 at 10 m/s; W1 splits into A2 and B1. On A2 (straight) the curve on B1 is
    # not seen and B1 is dropped; on B1 the curve (23.66° left) drops A2.
    n = junction()
    tr = travel(n, np.full(600, 10.0))
    pos = tr.d - 100.0
    wz = wz_on_curves(tr, pos, 1.0) if diverging else np.zeros(tr.n)
    sol = solve(n, tr, Start("9001", "S", 300.0, 1), wz)
    res = resolved(sol)
    assert len(res) == 1 and res[0]["track_id"] == kept and res[0]["evidence"] == "feature"
    assert res[0]["switch_id"] == "W1"
    assert res[0]["violation_deg"][kept] == pytest.approx(0.0, abs=0.12)  # the 1 m cycles
    other = "A2" if kept == "B1" else "B1"
    assert res[0]["violation_deg"][other] > 20.0


@settings(max_examples=30, deadline=None)
@given(diverging=st.booleans(), bias_dps=st.floats(-0.1, 0.1), start=st.floats(250.0, 350.0))
def test_never_a_wrong_track(diverging: bool, bias_dps: float, start: float) -> None:
    # a gyro bias up to 2σ of the model: resolved right or left ambiguous, never wrong
    n = junction()
    tr = travel(n, np.full(600, 10.0))
    pos = tr.d - (400.0 - start)
    wz = wz_on_curves(tr, pos, 1.0) if diverging else np.zeros(tr.n)
    wz = wz + math.radians(bias_dps)
    sol = solve(n, tr, Start("9001", "S", start, 1), wz)
    p = sol.positions
    det = p[(p["state"] == "determined") & (p["t"] > (400.0 - start) / 10.0 + 1.0)]
    assert set(det["track_id"]) <= ({"B1"} if diverging else {"A2"})


def test_no_features_no_aid_effect() -> None:
    # the same run without track feature points: ambiguous to the end (no other evidence)
    n = net("junction")
    tr = travel(n, np.full(600, 10.0))
    lines = track_lines(n)
    assert not track_feature_tables(n, lines)
    sol = run_aids(tr, [Start("9001", "S", 300.0, 1), TopologyAid(lines, MARGIN)], MARGIN)
    assert sol.positions["state"].iloc[-1] == "ambiguous"


#: A curve with 20 m clothoid transitions (R 500 m, left), rows r1…r6 along B1, for the
#: correction test: its κ is drawn into the yaw rate directly (the aid reads only ωz and the rows).
CLOTHOID = np.array([61.0, 81.0, 101.0, 277.5, 297.5, 337.5])


def _branch_run(start_pos: float, seconds: float, v: float = 10.0) -> tuple[Cycles, Odometry]:
    """Cycles and odometry of a train running B1 forward at ``v`` from ``start_pos``, its yaw
    rate v·κ of :data:`CLOTHOID`'s curve, no noise."""
    t = np.arange(0.0, seconds + 1e-9, 0.1)
    n = t.size
    d = v * t
    pos = start_pos + d - 0.05 * v  # cycle means stand for mid-cycle
    r = CLOTHOID
    kappa = np.interp(pos, [r[1], r[2], r[3], r[4]], [0.0, 1 / 500.0, 1 / 500.0, 0.0], left=0.0, right=0.0)
    imu = {c: np.zeros(n) for c in ("ax", "ay", "az", "wx", "wy")} | {"wz": v * kappa}
    ones = np.ones(n, dtype=np.int8)
    c = Cycles(t, d.copy(), d.copy(), np.full(n, v), imu, ones, ones, True, True)
    return c, Odometry(d, np.full(n, v), np.zeros(n, dtype=bool), np.zeros(n))


def test_correction_along_a_track_at_its_curve() -> None:
    # determined on B1 with the estimate 8 m ahead of the truth (pos 2 at t = 0), within the
    # 40 m search margin. The exit crossing of κ = (1 − 20 %)/R lies 20 % into the exit
    # transition, at pos 281.5 (the 1 s smoothing moves a linear ramp's crossing by nothing):
    # the fix is on B1 at row 4's pos 277.5 — the S000 correction point — and the 8 m error
    # becomes 281.5 − 277.5 = 4 m behind the truth.
    fp = FEATURE.assign(pos_m=CLOTHOID)
    n = Network({**net("junction").tables, "track_feature_points": fp}, origin="junction+F1")
    c, odo = _branch_run(2.0, 45.0)
    tr = Travel.of(c, odo, n)
    lines = track_lines(n)
    unit = FeatureUnit(c, odo, n, FeatureConfig(search_margin_m=40.0))
    fix_aid = TrackFeatureFixAid(unit, track_feature_tables(n, lines).own, lines)
    aids: list[Any] = [Start("9002", "S", 10.0, 1), TopologyAid(lines, MARGIN), fix_aid]
    sol = run_aids(tr, aids, MARGIN)
    ev = [e for e in sol.events if e.type == EventType.FEATURE_CORRECTION]
    assert len(ev) == 1 and ev[0].detail["track_id"] == "B1" and ev[0].detail["feature_id"] == "F1"
    assert ev[0].km_m == pytest.approx(277.5, abs=0.01) and ev[0].detail["pos_db_m"] == pytest.approx(277.5)
    assert ev[0].correction_m == pytest.approx(8.0 + 4.0, abs=1.0)
    p = sol.positions
    t = p["t"].to_numpy(float)
    err = p["pos_m"].to_numpy(float) - (2.0 + 10.0 * t)
    after = t >= ev[0].t - 1e-9
    assert np.allclose(err[~after & (t > 1.0)], 8.0, atol=0.01)  # pos from km 10 by the grid's length
    assert np.allclose(err[after], -4.0, atol=1.0)
    assert (p.loc[after, "track_id"] == "B1").all() and (p.loc[after, "state"] == "determined").all()


@settings(max_examples=60, deadline=None)
@given(p=st.floats(-30.0, 590.0), width=st.floats(0.0, 60.0))
def test_headings_reverse_by_half_a_turn(p: float, width: float) -> None:
    # the same stretch run the other way: every heading turned by π; behind B1's begin lies
    # A1 (one exit), beyond its end nothing (no exit: unknown)
    lines = track_lines(junction())
    fwd = headings(lines, "B1", 1, p, p + width)
    back = headings(lines, "B1", -1, p, p + width)
    if p + width > 600.0:
        assert fwd is None and back is None
        return
    assert fwd is not None and back is not None
    assert np.allclose(np.cos(back - fwd), -1.0, atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(h=st.lists(st.floats(-1.0, 1.0), min_size=1, max_size=30))
def test_rises_of_the_reversed_profile(h: list[float]) -> None:
    # run backwards, a left turn is a right one: rises(reversed) = (fall, rise)
    a = np.array(h)
    left, right = rises(a)
    assert rises(a[::-1]) == pytest.approx((right, left))
    assert left >= 0.0 and right >= 0.0 and max(left, right) <= np.ptp(a) + 1e-12
