"""The GPS offsets test's evidence on a single candidate gathered a stretch of fixes at once
(:meth:`~fieldlogs.pipeline.aids.track_gps.TrackGpsAid.flush`; issue 31: the engine's cost,
results unchanged): the centreline points (:meth:`~fieldlogs.pipeline.hypotheses.TrackLine.points`)
and offsets computed at once are the ones computed fix by fix, bit for bit,
and the evidence, jump test state and decisions are those of an aid that works every fix in
when it is heard."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome
from fieldlogs.pipeline.aids import track_gps
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gps import TrackGpsAid, offset, offsets_at
from fieldlogs.pipeline.aids.track_gps_initial import TrackGpsInitialAid
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.hypotheses import track_lines
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, net, travel
from tests.fieldlogs.pipeline.test_track_gps_along import _fixes_on

GPS = GpsConfig()
LINES = track_lines(net("crossover"))


@settings(max_examples=150, deadline=None)
@given(
    st.sampled_from(sorted(LINES.lines)),
    st.lists(
        st.tuples(st.floats(-60.0, 1200.0), st.floats(-30.0, 30.0), st.floats(-30.0, 30.0)), min_size=1, max_size=40
    ),
)
def test_points_and_offsets_at_once_as_one_at_a_time(track_id: str, rows: list[tuple[float, float, float]]) -> None:
    tl = LINES[track_id]
    cp = [float(c) for c in tl.cpos]
    # positions on the knots, just beside them and beyond both ends, as well as anywhere
    pos = [p if k % 3 else cp[int(abs(p)) % len(cp)] for k, (p, _, _) in enumerate(rows)]
    x0, y0, _ux, _uy = tl.point(0.0)
    px, py = [x0 + dx for _, dx, _ in rows], [y0 + dy for _, _, dy in rows]
    points = [c.tolist() for c in tl.points(np.asarray(pos))]
    assert list(zip(*points, strict=True)) == [tl.point(p) for p in pos]  # bit for bit
    got = offsets_at(tl, np.asarray(pos), px, py)
    want = [offset(tl, p, x, y) for p, x, y in zip(pos, px, py, strict=True)]
    assert got == want  # bit for bit


def test_offsets_at_of_a_nan_position_is_nan() -> None:
    tl = LINES["D1"]
    x, y, _, _ = tl.point(10.0)
    got = offsets_at(tl, np.asarray([math.nan, 10.0]), [x, x], [y, y])
    assert math.isnan(got[0]) and math.isnan(offset(tl, math.nan, x, y))
    assert got[1] == offset(tl, 10.0, x, y)


class Eager(TrackGpsAid):
    """Works every fix in when it is heard (a stretch of one fix)."""

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        out = super().observe(obs, view)
        self.flush()
        return out


def state(aid: TrackGpsAid) -> tuple[object, ...]:
    aid.flush()
    return (aid.times, aid.cols, aid.tracks, aid.prev, aid.last_d, aid.set_t, aid.jump_t, aid.key)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(-0.2, 0.2), min_size=30, max_size=30),
    st.lists(st.sampled_from([0.0, 2.0, 4.0, 6.0, 8.0]), min_size=22, max_size=22),
    st.sets(st.integers(8, 29), max_size=4),
    st.sets(st.integers(8, 29), max_size=6),
)
def test_flushed_evidence_is_the_one_worked_in_fix_by_fix(
    noise: list[float], speeds: list[float], jumps: set[int], dropped: set[int]
) -> None:
    # crossover network, 30 s: 6 m/s from pos 50 on D1 for 8 s, then a speed per second (0:
    # standing); a fix every second but the ``dropped`` ones (gaps), ``noise`` m left of D1 and
    # a 4 m step toward U1 at the ``jumps``; the initial aid starts D1/U1 after five steady
    # fixes, the offsets test decides D1, then a stretch on the single candidate
    n = net("crossover")
    lines = track_lines(n)
    per_s = [6.0] * 8 + speeds
    pos = np.concatenate([[50.0], 50.0 + np.cumsum(per_s)])
    along = [(float(t), float(pos[t]), noise[t] + (4.0 if t in jumps else 0.0)) for t in range(30) if t not in dropped]
    t, lat, lon = _fixes_on("crossover", "D1", along)
    results, pending = [], []
    for cls in (TrackGpsAid, Eager):
        aid = cls(t, lat, lon, lines, CFG, GPS)
        aids = [TopologyAid(lines, MARGIN), TrackGpsInitialAid(t, lat, lon, lines, CFG, GPS), aid]
        sol = run_aids(travel(n, np.repeat(per_s, 10)), aids, MARGIN)  # type: ignore[arg-type]
        pending.append(len(aid.pending))
        results.append((repr(sol.fixes), repr(sol.events), state(aid)))
    assert results[0] == results[1]
    assert pending[0] >= 10 and pending[1] == 0  # the stretch on D1 was gathered at once


def test_worked_in_by_chunks_on_a_long_stretch() -> None:
    # at most MAX_PENDING fixes wait (memory on a long run): chunks of 3 give the same evidence
    n = net("crossover")
    lines = track_lines(n)
    per_s = [6.0] * 8 + [4.0, 0.0, 0.0, 8.0] * 5
    pos = np.concatenate([[50.0], 50.0 + np.cumsum(per_s)])
    t, lat, lon = _fixes_on("crossover", "D1", [(float(k), float(pos[k]), 0.1 * (k % 3)) for k in range(28)])
    saved = track_gps.MAX_PENDING
    results = []
    try:
        for cls, most in ((TrackGpsAid, 3), (Eager, saved)):
            track_gps.MAX_PENDING = most
            aid = cls(t, lat, lon, lines, CFG, GPS)
            aids = [TopologyAid(lines, MARGIN), TrackGpsInitialAid(t, lat, lon, lines, CFG, GPS), aid]
            sol = run_aids(travel(n, np.repeat(per_s, 10)), aids, MARGIN)  # type: ignore[arg-type]
            assert len(aid.pending) < 3
            results.append((repr(sol.fixes), repr(sol.events), state(aid)))
    finally:
        track_gps.MAX_PENDING = saved
    assert results[0] == results[1]
