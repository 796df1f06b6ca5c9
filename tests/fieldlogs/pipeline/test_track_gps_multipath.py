"""The GPS offsets test after a facing switch against multipath steps (aids/track_gps.py): a
2–4 m step toward the neighbouring track shortly after the split never gives a wrong track.

Case: station4 network, U1 → W1 (facing, 1:9, station track 3 diverging to the left, 4.5 m
beside U2 once parallel) → U2; 10 m/s from km 0, fixes every second on the true track (U2)
with white noise 0.25 m, from ``step_t`` on moved ``step_m`` to the left, toward track 3. The
split is at 20.1 s (toe at km 200, margin 1 + 2 %)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gps import TrackGpsAid, chi2_upper
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.hypotheses import track_lines
from schemas.enums import EventType, PositionState
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net, travel


def _run(step_m: float, step_t: float) -> Solution:
    n = net("station4")
    lines = track_lines(n)
    k = math.pi / 180.0 * 6_371_000.0
    rows = []
    for t in np.arange(0.0, 45.0, 1.0):
        km = 10.0 * t
        tl, pos = (lines["U1"], km) if km < 200.0 else (lines["U2"], km - 200.0)
        x, y, ux, uy = tl.point(pos)
        off = (step_m if t >= step_t else 0.0) + float(np.random.default_rng(int(t)).normal(0.0, 0.25))
        x, y = x - off * uy, y + off * ux  # + to the left (track 3's side)
        lat0, lon0 = tl.origin
        rows.append((t, lat0 + y / k, lon0 + x / (k * math.cos(math.radians(lat0)))))
    t, lat, lon = (np.array(c) for c in zip(*rows, strict=True))
    aid = TrackGpsAid(t, lat, lon, lines, CFG, GpsConfig())
    return run_aids(
        travel(n, np.full(450, 10.0)), [Start("9004", "U", 0.0, 1), TopologyAid(lines, MARGIN), aid], MARGIN
    )  # type: ignore[list-item]


def _wrong(sol: Solution) -> bool:
    p = sol.positions
    det = p[(p["state"] == PositionState.DETERMINED.value) & (p["t"] > 20.2)]
    return bool((det["track_id"] != "U2").any())


@pytest.mark.parametrize("step_m", [2.18, 3.0, 4.0])
@pytest.mark.parametrize("step_t", [20.5, 21.5, 22.5, 23.5, 24.5])
def test_a_multipath_step_after_the_split_never_gives_the_wrong_track(step_m: float, step_t: float) -> None:
    sol = _run(step_m, step_t)
    assert not _wrong(sol)
    assert not [e for e in sol.events if e.type == EventType.TRACK_RESOLVED and e.detail["track_id"] != "U2"]


@pytest.mark.parametrize("step_m", [0.0, 1.0, 3.0])
def test_clean_or_steady_offsets_resolve_the_through_track(step_m: float) -> None:
    # no step, a constant 1 m bias from the start, or a 3 m step long before the split (t = 0)
    sol = _run(step_m, 0.0)
    res = [e for e in sol.events if e.type == EventType.TRACK_RESOLVED]
    assert len(res) == 1 and res[0].detail["track_id"] == "U2" and res[0].detail["evidence"] == "gps"
    assert res[0].detail["fixes"] == CFG.gps_min_fixes and not _wrong(sol)


def test_the_jump_test_sees_a_step_in_every_candidate() -> None:
    aid = TrackGpsAid(np.zeros(1), np.zeros(1), np.zeros(1), track_lines(net("station4")), CFG, GpsConfig())
    limit = CFG.gps_jump_sigma * 0.25 * math.sqrt(2.0)  # 1.24 m
    assert not aid._jumped(0.0, [0.1])
    assert aid._jumped(1.0, [0.1 + limit + 0.01, 0.1 + limit + 0.2])  # one previous offset: the parent track
    assert not aid._jumped(2.0, [0.1 + limit + 0.02, 0.1 + 0.2])  # the first candidate moved by noise
    assert not aid._jumped(5.0, [9.0, 9.0])  # 3 s after the last fix (> gps.max_gap_s): no test


@pytest.mark.parametrize("n", [1, 2, 5, 10, 30, 100])
def test_chi2_quantile_wilson_hilferty_is_close_and_not_below(n: int) -> None:
    from scipy.stats import chi2

    exact = float(chi2.ppf(1.0 - CFG.alpha, n))
    got = chi2_upper(1.0 - CFG.alpha, n)
    assert exact <= got <= exact * 1.08
