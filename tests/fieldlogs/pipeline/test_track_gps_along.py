"""D-GPS on a network's tracks (fieldlogs/pipeline/aids/track_gps_along.py, track_gps_initial.py):
hand-computed projections, gates, the end of an uncertain position and the initial position."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import numpy as np
import pytest

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gps_along import TrackGpsAlongAid, along_uncertainty
from fieldlogs.pipeline.aids.track_gps_initial import TrackGpsInitialAid
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.hypotheses import TrackLine, equirect, segments, track_lines
from schemas.enums import EventType, PositionState
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net, travel

GPS = GpsConfig()
#: U = 4·√(0.75² + 0.25²) + 0.5 = 3.662 m with the default settings.
U = 4.0 * math.hypot(0.75, 0.25) + 0.5


def _straight() -> TrackLine:
    """A 100 m track running east from the plane's origin."""
    xy = np.array([[0.0, 0.0], [50.0, 0.0], [100.0, 0.0]])
    cpos = np.array([0.0, 50.0, 100.0])
    return TrackLine("T", "", "", 100.0, None, 0.0, 1, np.empty(0), np.empty(0), xy, cpos, (35.0, 139.0))


def test_projection_hand_computed() -> None:
    tl = _straight()
    assert tl.project(30.0, 2.0, 50.0, 60.0) == pytest.approx((30.0, 2.0))  # north is left of east
    assert tl.project(70.0, -1.5, 60.0, 20.0) == pytest.approx((70.0, -1.5))
    assert tl.project(130.0, -1.0, 90.0, 50.0) == pytest.approx((100.0, -1.0))  # beyond the end: its end
    assert all(math.isnan(v) for v in tl.project(30.0, 0.0, 500.0, 10.0))  # no segment near 500 ± 10


def test_along_uncertainty_default() -> None:
    assert along_uncertainty(CFG, GPS) == pytest.approx(U)
    assert U == pytest.approx(3.662, abs=1e-3)


def _fixes(along: list[tuple[float, float, float]]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fixes on the junction network's A1 (9001/S, pos = km): (t, pos, offset + left)."""
    tl = track_lines(net("junction"))["A1"]
    lat0, lon0 = tl.origin
    k = math.pi / 180.0 * 6_371_000.0
    t, lat, lon = [], [], []
    for ti, pos, off in along:
        x, y, ux, uy = tl.point(pos)
        x, y = x - off * uy, y + off * ux
        t.append(ti)
        lat.append(lat0 + y / k)
        lon.append(lon0 + x / (k * math.cos(math.radians(lat0))))
    return np.array(t), np.array(lat), np.array(lon)


def _run(fixes: list[tuple[float, float, float]], *extra: object, seconds: float = 28.0) -> Solution:
    n = net("junction")
    lines = track_lines(n)
    aid = TrackGpsAlongAid(*_fixes(fixes), lines, CFG, GPS, MARGIN)
    tr = travel(n, np.full(int(seconds * 10), 10.0))
    aids = [Start("9001", "S", 100.0, 1), TopologyAid(lines, MARGIN), *extra, aid]
    return run_aids(tr, aids, MARGIN)  # type: ignore[arg-type]


def _at(sol: Solution, t: float) -> dict[str, object]:
    p = sol.positions
    return dict(p[p["t"].sub(t).abs() < 1e-6].iloc[0])


def test_a_steady_chain_of_fixes_corrects_once_the_margin_is_wide() -> None:
    # 10 m/s from km 100, margin 1 m + 2 % of the travel; fixes every second from t = 21 s, each
    # 2 m beyond dead reckoning and 0.3 m to the left. The fifth of the chain (t = 25 s) is the
    # first usable one, and the margin there (6 m) exceeds 1.5·U = 5.49 m: km 352, margin U.
    # Afterwards dead reckoning agrees with the fixes and the margin is small: no more.
    sol = _run([(t, 100.0 + 10.0 * t + 2.0, 0.3) for t in np.arange(21.0, 28.0)])
    ev = [e for e in sol.events if e.type == EventType.GPS_CORRECTION]
    assert len(ev) == 1 and ev[0].t == 25.0
    assert ev[0].correction_m == pytest.approx(-2.0, abs=0.01)
    assert ev[0].detail["margin_before_m"] == pytest.approx(6.0, abs=0.01)
    assert ev[0].detail["offset_m"] == pytest.approx(0.3, abs=0.01)
    at = _at(sol, 25.0)
    assert at["km_m"] == pytest.approx(352.0, abs=0.01) and at["margin_m"] == pytest.approx(U, abs=1e-6)
    assert at["track_id"] == "A1" and at["state"] == PositionState.DETERMINED.value
    assert _at(sol, 24.9)["km_m"] == pytest.approx(349.0, abs=0.01)
    assert _at(sol, 27.0)["km_m"] == pytest.approx(372.0, abs=0.01)  # 20 m on from the correction


def _corrections(fixes: list[tuple[float, float, float]]) -> list[float]:
    return [e.t for e in _run(fixes).events if e.type == EventType.GPS_CORRECTION]


def test_fixes_off_the_track_against_the_estimate_or_after_a_jump_are_not_used() -> None:
    t = np.arange(15.0, 28.0)
    clean = [(ti, 100.0 + 10.0 * ti, 0.0) for ti in t]
    assert _corrections(clean) == [23.0]  # margin 1 + 0.02·230 = 5.6 m > 5.49 m
    # 4 m to the side at t = 22 (> U): the chain restarts, five more fixes (t = 23 … 27) are needed
    side = [(ti, p, 4.0 if ti == 22.0 else o) for ti, p, o in clean]
    assert _corrections(side) == [27.0]
    # every fix 12 m ahead: the chain is steady but beyond margin + U (7.9 … 9.7 m): never used
    assert _corrections([(ti, p + 12.0, o) for ti, p, o in clean]) == []
    # from t = 20 the fixes are 3 m ahead (a multipath plateau): the step at 20 (3 m against the
    # odometry's 10 m) is a jump, and nothing is used for gps.jump_hold_s = 30 s
    assert _corrections([(ti, p + (3.0 if ti >= 20.0 else 0.0), o) for ti, p, o in clean]) == []


class _Uncertain(StaticAid):
    """Makes the position uncertain at t = 5 s (as a slip fail-safe does)."""

    name = "failsafe"
    priority = Priority.INTEGRITY

    def observations(self) -> list[Observation]:
        return [Observation(5.0)]

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        assert fix is not None
        return Outcome([], replace(fix, t_effective=view.t, state=PositionState.UNCERTAIN, uncertain_since_d=view.d))


@pytest.mark.parametrize(("bad_at", "back_at"), [(None, 14.0), (12.0, 17.0)])
def test_five_agreeing_fixes_make_an_uncertain_position_determined(bad_at: float | None, back_at: float) -> None:
    # uncertain from t = 5 s; fixes every second from t = 10, 1 m beyond dead reckoning. Five in a
    # row passing the gates (t = 10 … 14) end it; a fix 5 m to the side at t = 12 restarts the count
    # (t = 13 … 17).
    fixes = [(t, 100.0 + 10.0 * t + 1.0, 5.0 if t == bad_at else 0.2) for t in np.arange(10.0, 19.0)]
    sol = _run(fixes, _Uncertain())
    p = sol.positions
    assert (p[(p["t"] > 5.0) & (p["t"] < back_at)]["state"] == PositionState.UNCERTAIN.value).all()
    at = _at(sol, back_at)
    assert at["state"] == PositionState.DETERMINED.value and at["margin_m"] == pytest.approx(U, abs=1e-6)
    assert at["km_m"] == pytest.approx(100.0 + 10.0 * back_at + 1.0, abs=0.01)
    ev = [e for e in sol.events if e.type == EventType.GPS_CORRECTION]
    assert ev[0].t == back_at and ev[0].detail["confirmed_by_fixes"] == 5


def test_fixes_that_disagree_among_themselves_leave_it_uncertain() -> None:
    # the along-track residuals alternate +1 / +6 m (spread 5 m > U): the odometry and the fixes
    # do not tell one story, so the fail-safe holds
    fixes = [(t, 100.0 + 10.0 * t + (1.0 if int(t) % 2 else 6.0), 0.2) for t in np.arange(10.0, 19.0)]
    sol = _run(fixes, _Uncertain())
    p = sol.positions
    assert (p[p["t"] > 5.0]["state"] == PositionState.UNCERTAIN.value).all()
    assert not [e for e in sol.events if e.type == EventType.GPS_CORRECTION]


def _fixes_on(network: str, track_id: str, along: list[tuple[float, float, float]]) -> tuple[np.ndarray, ...]:
    """Fixes (t, pos, offset + left) on any track of a test network."""
    tl = track_lines(net(network))[track_id]
    lat0, lon0 = tl.origin
    k = math.pi / 180.0 * 6_371_000.0
    rows = []
    for ti, pos, off in along:
        x, y, ux, uy = tl.point(pos)
        x, y = x - off * uy, y + off * ux
        rows.append((ti, lat0 + y / k, lon0 + x / (k * math.cos(math.radians(lat0)))))
    t, lat, lon = (np.array(c) for c in zip(*rows, strict=True))
    return t, lat, lon


def test_near_tracks_hand_computed() -> None:
    # crossover network: D1 and U1 run parallel; a point 1 m left of D1 at pos 100 is 1 m from D1
    # (at pos 100) and, the tracks being 4 m apart, 3 m from U1
    lines = track_lines(net("crossover"))
    seg = segments(lines)
    _t, lat, lon = _fixes_on("crossover", "D1", [(0.0, 100.0, 1.0)])
    (x,), (y,) = equirect(seg.origin, lat, lon)
    got = {seg.ids[j]: (pos, dist) for j, pos, dist, _tx, _ty in seg.nearest(float(x), float(y), 20.0)}
    assert set(got) == {"D1", "U1"}
    assert got["D1"] == pytest.approx((100.0, 1.0), abs=0.01)
    assert got["U1"][1] == pytest.approx(3.0, abs=0.05)


def _initial(fixes: tuple[np.ndarray, ...], v: float = 10.0, cab: int = 1) -> Solution:
    n = net("crossover")
    lines = track_lines(n)
    aid = TrackGpsInitialAid(*fixes, lines, CFG, GPS)
    tr = travel(n, np.full(150, v), cab=cab)
    return run_aids(tr, [TopologyAid(lines, MARGIN), aid], MARGIN)  # type: ignore[list-item]


@pytest.mark.parametrize("v", [10.0, -10.0])
def test_a_steady_chain_starts_the_position_among_the_parallel_tracks(v: float) -> None:
    # no balise: fixes every second on D1 from pos 50 with the train running toward D1's end
    # (v > 0 with cab F) or toward its begin (the same fixes reversed in time, v < 0: the cab's
    # forward is then toward D1's begin, kp = −1 for the same body-forward sign). The fifth fix
    # (t = 4 s, 40 m travelled ≥ 10 m) starts it, ambiguous between D1 and U1 (4 m apart).
    pos = [50.0 + 10.0 * t for t in range(8)] if v > 0 else [120.0 - 10.0 * t for t in range(8)]
    sol = _initial(
        _fixes_on("crossover", "D1", [(float(t), p, 0.2) for t, p in enumerate(pos)]), v=abs(v), cab=1 if v > 0 else -1
    )
    ev = [e for e in sol.events if e.type == EventType.INITIAL_POSITION_GPS]
    assert len(ev) == 1 and ev[0].t == 4.0
    assert ev[0].detail["evidence"] == "network" and sorted(ev[0].detail["candidates"]) == ["D1", "U1"]
    at = _at(sol, 4.0)
    assert at["state"] == PositionState.AMBIGUOUS.value
    cands = {c["track_id"]: c for c in json.loads(str(at["candidates"]))}
    assert cands["D1"]["pos_m"] == pytest.approx(pos[4], abs=0.05)
    later = json.loads(str(_at(sol, 6.0)["candidates"]))
    d1 = next(c for c in later if c["track_id"] == "D1")
    assert d1["pos_m"] == pytest.approx(pos[6], abs=0.05)  # carried the right way along D1
    assert (sol.positions[sol.positions["t"] < 4.0]["state"] == PositionState.UNDETERMINED.value).all()


def _never_started(sol: Solution) -> None:
    assert not sol.events and (sol.positions["state"] == PositionState.UNDETERMINED.value).all()


def test_no_start_off_every_track_or_on_a_jumping_chain() -> None:
    along = [(float(t), 50.0 + 10.0 * t, 0.2) for t in range(8)]
    off = [(t, p, 10.0) for t, p, _ in along]  # 10 m left of D1, 14 m from U1: on no track (> U)
    _never_started(_initial(_fixes_on("crossover", "D1", off)))
    jumpy = [(t, p + (6.0 if int(t) % 2 else 0.0), o) for t, p, o in along]  # steps of 16 m / 4 m for 10 m
    _never_started(_initial(_fixes_on("crossover", "D1", jumpy)))


def test_no_start_before_the_fixes_move_one_way() -> None:
    # 10 m/s toward D1's end for 3 s from pos 100, then back: the fixes t = 0 … 3 and 3 … 7 each
    # move one way, but a window holding the turn does not. The first window of five one-way
    # fixes ends at t = 7 (fixes 3 … 7, all backward); from there pos falls with the travel.
    v = np.where(np.arange(150) < 30, 10.0, -10.0)
    pos = [100.0 + 10.0 * t if t <= 3 else 130.0 - 10.0 * (t - 3) for t in range(15)]
    n = net("crossover")
    lines = track_lines(n)
    aid = TrackGpsInitialAid(
        *_fixes_on("crossover", "D1", [(float(t), p, 0.1) for t, p in enumerate(pos)]), lines, CFG, GPS
    )
    sol = run_aids(travel(n, v), [TopologyAid(lines, MARGIN), aid], MARGIN)  # type: ignore[list-item]
    ev = [e for e in sol.events if e.type == EventType.INITIAL_POSITION_GPS]
    assert ev and ev[0].t == 7.0
    later = {c["track_id"]: c for c in json.loads(str(_at(sol, 9.0)["candidates"]))}
    assert later["D1"]["pos_m"] == pytest.approx(pos[9], abs=0.05)


def test_an_uncertain_position_is_confirmed_from_usable_fixes_the_trust_filter_holds_back() -> None:
    # the same clean fixes from t = 10, but none trusted before t = 40 (the trust filter's window
    # after a burst): the uncertain position reads every usable fix and ends at t = 14 as above;
    # a determined one would use only trusted fixes (none here before t = 40: no correction)
    along = [(t, 100.0 + 10.0 * t + 1.0, 0.2) for t in np.arange(10.0, 19.0)]
    n = net("junction")
    lines = track_lines(n)
    t, lat, lon = _fixes(along)
    late = t >= 40.0
    aid = TrackGpsAlongAid(t[late], lat[late], lon[late], lines, CFG, GPS, MARGIN, usable=(t, lat, lon))
    aids = [Start("9001", "S", 100.0, 1), TopologyAid(lines, MARGIN), _Uncertain(), aid]
    sol = run_aids(travel(n, np.full(280, 10.0)), aids, MARGIN)  # type: ignore[arg-type]
    ev = [e for e in sol.events if e.type == EventType.GPS_CORRECTION]
    assert len(ev) == 1 and ev[0].t == 14.0 and ev[0].detail["confirmed_by_fixes"] == 5
    assert _at(sol, 15.0)["state"] == PositionState.DETERMINED.value
