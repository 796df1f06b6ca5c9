"""Fail safe on a network: a line-based aid (S001 GPS up/down/crossover, S002, balise, feature
point) may move the position only onto a track a navigable path reaches, and a GPS placement
leaves the parallel tracks within 20 m candidates (issue 31)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from dbtools.database import read_network
from fieldlogs.pipeline.aid import Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gps import TrackGpsAid
from fieldlogs.pipeline.aids.track_imu import TrackImuAid, turnouts
from fieldlogs.pipeline.config import GpsConfig, MarginConfig, PipelineConfig
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.hypotheses import parallel_candidates, reachable, segments, track_lines
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.track_truth import compare_tracks
from fieldlogs.pipeline.types import Fix, Hypothesis
from fieldlogs.runs.handle import read_run
from schemas.enums import EventType, FixSource
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net, travel

SAMPLE_LOGS = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"


class LineGps(StaticAid):
    """What the S001 logic does after a multipath-biased trace: at ``t`` a GPS-sourced fix
    on another track of the line at the dead-reckoned km."""

    name = "line_gps"
    priority = Priority.TELEGRAM

    def __init__(self, t: float, line: str, track: str, km: float, k: int, source: FixSource = FixSource.GPS) -> None:
        self.t, self.fix, self.source = t, (line, track, km, k), source

    def observations(self) -> list[Observation]:
        return [Observation(self.t)]

    def observe(self, obs: Observation, view: object) -> Outcome:
        line, track, km, k = self.fix
        return Outcome([], Fix(self.t, 10.0 * self.t, 10.0 * self.t, km, km, line, track, k, self.source, 2.5))


def _run(name: str, v: np.ndarray, start: Start, *extra: object) -> Solution:
    n = net(name)
    aids = [start, TopologyAid(track_lines(n), MARGIN), *extra]
    return run_aids(travel(n, v), aids, MARGIN)  # type: ignore[arg-type]


def test_reachable_hand_computed() -> None:
    # crossover network: D1 km 0–300 → W1 (km 300) → X1 (60.166 m) → W2 → U2 (km 360 on);
    # the X1–U1 relation is none. From D1 pos 100 running +: W1 is 200 m on.
    lines = track_lines(net("crossover"))
    h = [Hypothesis("D1", 100.0, 1)]
    assert reachable(h, 150.0, lines) == {"D1"}
    assert reachable(h, 200.5, lines) == {"D1", "X1", "D2"}
    assert reachable(h, 260.0, lines) == {"D1", "X1", "D2"}  # 200 + 60.166 > 260
    assert reachable(h, 260.5, lines) == {"D1", "X1", "D2", "U2"}
    # U1 lies 4 m beside D1 but no navigable path leads there, however far
    assert "U1" not in reachable(h, 5000.0, lines)
    # a candidate's own extra widens its reach: 150 + 51 ≥ 200
    assert "X1" in reachable([Hypothesis("D1", 100.0, 1, extra_m=51.0)], 150.0, lines)


def test_gps_track_change_without_a_crossover_is_refused() -> None:
    # on D at km 100, 10 m/s; at t = 5 s (km 150) a multipath-biased GPS decision says U:
    # U1 is 4 m away but unreachable (X1 joins D1 to U2, not U1) → refused, D kept; the
    # dead reckoning carries on: km 100 + 10·t on D1 until the margin reaches W1
    sol = _run("crossover", np.full(140, 10.0), Start("9003", "D", 100.0, 1), LineGps(5.0, "9003", "U", 150.0, 1))
    refused = [e for e in sol.events if e.type == EventType.TRACK_CHANGE_REFUSED]
    assert len(refused) == 1 and refused[0].t == pytest.approx(5.0)
    assert refused[0].detail["track_id"] == "U1" and refused[0].detail["candidates"] == ["D1"]
    p = sol.positions
    det = p[p["state"] == "determined"]
    assert set(det["track_id"]) == {"D1"}
    at10 = det[np.isclose(det["t"], 10.0)]
    assert at10["km_m"].iloc[0] == pytest.approx(200.0, abs=0.01)


@pytest.mark.parametrize(("source", "reopened"), [(FixSource.GPS, True), (FixSource.GNSS, False)])
def test_a_correction_on_the_determined_track_reopens_the_parallel_one_only_from_gps(
    source: FixSource, reopened: bool
) -> None:
    # on D1 from km 100 at 10 m/s; at t = 5 s a line fix on D itself at km 151 (1 m ahead of
    # the dead reckoning). A GPS decision compared only the line's tracks: U1, 4 m beside, is a
    # candidate again. A raw-GNSS correction was fitted on D1 itself (S002): D1 alone stays.
    fix = LineGps(5.0, "9003", "D", 151.0, 1, source)
    p = _run("crossover", np.full(90, 10.0), Start("9003", "D", 100.0, 1), fix).positions
    row = p[np.isclose(p["t"], 5.0)].iloc[0]
    if reopened:
        assert row["state"] == "ambiguous"
        assert sorted(c["track_id"] for c in json.loads(row["candidates"])) == ["D1", "U1"]
    else:
        assert row["state"] == "determined" and row["track_id"] == "D1"
        assert row["km_m"] == pytest.approx(151.0, abs=0.01)


def test_gps_track_change_over_the_crossover_is_taken_with_its_parallel_track() -> None:
    # from D km 250: W1 at km 300 splits into D2/X1; at t = 12 s (X1's end + 0 m … U2 km 370)
    # the GPS says U: U2 is reachable through X1 → taken, but D2 lies 4 m beside it, which the
    # line decision never tested against the network: both stay candidates (ambiguous)
    sol = _run("crossover", np.full(130, 10.0), Start("9003", "D", 250.0, 1), LineGps(12.0, "9003", "U", 370.0, 1))
    assert EventType.TRACK_CHANGE_REFUSED not in [e.type for e in sol.events]
    p = sol.positions
    row = p[np.isclose(p["t"], 12.0)].iloc[0]
    assert row["state"] == "ambiguous"
    cands = json.loads(row["candidates"])
    assert sorted(c["track_id"] for c in cands) == ["D2", "U2"]
    assert [c["pos_m"] for c in sorted(cands, key=lambda c: c["track_id"])] == pytest.approx([70.0, 10.0], abs=0.5)
    assert not (p["state"] == "determined")[p["t"] >= 12.0].any()


def test_parallel_candidates_in_the_four_track_station() -> None:
    # station4: D2 (km 200–800) with U2 and the station tracks 3 and 4 beside it; at km 500
    # (pos 300 on D2) every one lies within 20 m; D1/D3 (continuations) do not count
    lines = track_lines(net("station4"))
    out = parallel_candidates(Hypothesis("D2", 300.0, 1), 20.0, lines, segments(lines))
    assert sorted(h.track_id for h in out) == ["3", "4", "U2"]
    by = {h.track_id: h for h in out}
    assert by["U2"].pos_m == pytest.approx(300.0, abs=0.5) and by["U2"].kp == 1
    assert by["3"].pos_m == pytest.approx(600.41 / 2, abs=1.0) and by["4"].kp == 1
    # near the joint at km 200 (pos 5 on D2) D1 ends 5 m behind: a continuation, not parallel
    assert "D1" not in {h.track_id for h in parallel_candidates(Hypothesis("D2", 5.0, 1), 20.0, lines, segments(lines))}


def test_multipath_beside_a_parallel_track_never_claims_it(sample_network_db: Path) -> None:
    # sim-net-station (fieldlogs/simulate/samples_net.py): multipath pulls the fixes 2.5 m
    # toward U1 over D1 pos 3500–4500 while the train runs on D1; the S001 logic decides a
    # crossover D → U at t = 130 s where the network has none
    network = read_network(sample_network_db)
    run = read_run(SAMPLE_LOGS / "sim-net-station")
    res = run_pipeline(run, network, PipelineConfig())
    ev = res.events
    assert (ev["type"] == EventType.CROSSOVER.value).any()
    assert (ev["type"] == EventType.TRACK_CHANGE_REFUSED.value).any()
    truth = run.stream("truth")
    assert truth is not None
    cmp = compare_tracks(res.positions, truth, network)
    assert int(cmp["wrong"].sum()) == 0


@pytest.mark.parametrize(("pct", "tested"), [(7.0, True), (8.0, False)])
def test_imu_window_that_may_reach_the_crossovers_far_turnout_is_not_tested(pct: float, tested: bool) -> None:
    # crossover: D km 200, 10 m/s, margin 1 m + pct % of the travel; W1 (km 300, 1:10, R 200.5 m:
    # lead R·atan(0.1) = 19.99 m) splits into D2 and X1 (60.17 m). Split at d = 100: m = 1 + pct;
    # window end d = 100 + 19.99 + m: m_end = 1 + pct % of it. Tested while 2·19.99 + m + m_end
    # ≤ 60.17: 7 % → 8 + 9.96 = 17.96 ≤ 20.19 (test); 8 % → 9 + 11.32 = 20.32 > 20.19 (none)
    n = net("crossover")
    margin = MarginConfig(distance_pct=pct)
    tr = travel(n, np.full(400, 10.0))
    r = float(n.switches["diverging_radius_m"][n.switches["switch_id"] == "W1"].iloc[0])
    wz = np.where((tr.d >= 100.0) & (tr.d < 100.0 + r * math.atan(0.1)), 10.0 / r, 0.0)
    aid = TrackImuAid(wz, turnouts(n.switches), track_lines(n), CFG, margin)
    aids = [Start("9003", "D", 200.0, 1), TopologyAid(track_lines(n), margin), aid]
    sol = run_aids(tr, aids, margin)  # type: ignore[arg-type]
    imu = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED and e.detail["evidence"] == "imu"]
    assert bool(imu) == tested


def test_gps_fixes_while_standing_are_one_piece_of_evidence() -> None:
    # crossover: D km 250 at 10 m/s for 6 s, then standing at km 310 (10 m past W1) for 60 s;
    # a trusted fix every second from t = 5.5 on the D grid: 1 fix while moving past the
    # split (t = 5.5), 1 at t = 6.5 (travel 5 m since), then none of the standing ones
    n = net("crossover")
    v = np.concatenate([np.full(60, 10.0), np.zeros(600)])
    tr = travel(n, v)
    g = n.gis[(n.gis["line_code"] == "9003") & (n.gis["track"] == "D")].set_index("km_m")
    t = np.arange(5.5, 65.0, 1.0)
    km = 250.0 + np.minimum(10.0 * t, 60.0)
    lat, lon = np.interp(km, g.index, g["lat"]), np.interp(km, g.index, g["lon"])
    aid = TrackGpsAid(t, lat, lon, track_lines(n), CFG, GpsConfig())
    aids = [Start("9003", "D", 250.0, 1), TopologyAid(track_lines(n), MARGIN), aid]
    run_aids(tr, aids, MARGIN)  # type: ignore[arg-type]
    aid.flush()  # the fixes on the single candidate worked into the evidence
    assert len(aid.times) == 2
