"""Wrong track *suspected* at the decision target (S001 §3.1(e)): where the up/down evidence
leans when it does not decide, and the fail-safe alarm built on it.

The statistics are checked against hand computation on fixes placed by hand beside the demo
line's down track (its own grid, projected with the network's projector — not the
simulator's geometry); the alarm rule on hand-made periods; and two simulated runs whose
slow D-GPS error holds the fixes near the midline past 120 s.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.matching import track_index_for
from fieldlogs.pipeline.gps.analysis import TrackOdds, track_odds
from fieldlogs.possession.check import check_periods
from fieldlogs.possession.periods import RailPeriod
from fieldlogs.simulate.possession import make_case
from tests.fieldlogs.possession.test_possession import (
    CFG,
    GPS,
    LINE,
    NET,
    START,
    analysis,
    check_case,
    decided,
    possession,
    run_line,
    types,
)

KM0 = 3000.0
TOWARD_U = -1.0


def _point_beside(track: str, km: float, offset: float) -> tuple[float, float, float]:
    """(lat, lon, spacing to the other track) of a point ``offset`` m left of ``track`` at a grid km."""
    g = NET.gis[(NET.gis["line_code"].astype(str) == LINE) & (NET.gis["track"].astype(str) == track)]
    g = g.set_index("km_m")
    index = track_index_for(NET)
    x0, y0 = index.to_xy(g.loc[km, "lat"], g.loc[km, "lon"])
    x1, y1 = index.to_xy(g.loc[km + 20.0, "lat"], g.loc[km + 20.0, "lon"])
    dx, dy = float(x1 - x0), float(y1 - y0)
    norm = math.hypot(dx, dy)
    nx, ny = -dy / norm, dx / norm  # left of increasing km
    lon, lat = index.projector.to_lonlat(float(x0) + offset * nx, float(y0) + offset * ny)
    other = "U" if track == "D" else "D"
    spacing = index.match_xy([float(x0)], [float(y0)], track=other, max_offset_m=20.0)["offset_m"].iloc[0]
    return float(lat), float(lon), float(spacing)


def _fixes(offset: float, n: int, trusted: bool = True) -> tuple[pd.DataFrame, float]:
    lat, lon, spacing = _point_beside("D", KM0, offset)
    t = np.arange(1.0, n + 1.0)
    frame = pd.DataFrame({"t": t, "lat": np.full(n, lat), "lon": np.full(n, lon), "trusted": np.full(n, trusted)})
    return frame, spacing


def test_the_tracks_are_3_8_m_apart_and_up_is_to_the_right() -> None:
    _, _, spacing = _point_beside("D", KM0, 0.0)
    # the point on D lies 3.8 m left of U, i.e. U is to D's right: toward −offset
    assert spacing == pytest.approx(3.8, abs=0.05)
    assert TOWARD_U == -1.0


def test_track_odds_by_hand() -> None:
    """A vehicle standing 1.2 m from D toward U for 60 s: mean offsets −1.2 (D) and +2.6 (U);
    SE² = σ²·g(n) + σ_w²/n with the AR(1) factor g written out here; no scatter, no inflation."""
    o = 1.2 * TOWARD_U
    fixes, spacing = _fixes(o, 60)
    odds = track_odds(fixes, NET, GPS, 0.0, 60.0)
    assert [(o.line_code, o.track) for o in odds] == [(LINE, "D"), (LINE, "U")]
    d, u = odds
    assert d.n_fixes == u.n_fixes == 60
    assert d.mean_offset_m == pytest.approx(-1.2, abs=0.01)
    assert u.mean_offset_m == pytest.approx(o + spacing, abs=0.02) and u.mean_offset_m == pytest.approx(2.6, abs=0.02)
    rho = math.exp(-1.0 / 180.0)
    n = 60
    g = (n * (1 + rho) / (1 - rho) - 2 * rho * (1 - rho**n) / (1 - rho) ** 2) / n**2
    se2 = 0.75**2 * g + 0.25**2 / n
    assert d.sigma_m == pytest.approx(math.sqrt(se2), rel=1e-6)
    llr = (2.6**2 - 1.2**2) / (2 * se2)
    assert d.llr == pytest.approx(llr, rel=1e-3)
    assert u.llr == pytest.approx(-llr, rel=1e-3)
    # only the fixes inside (t_from, t_to] count; untrusted ones never
    assert track_odds(fixes, NET, GPS, 30.0, 60.0)[0].n_fixes == 30
    untrusted, _ = _fixes(o, 60, trusted=False)
    assert track_odds(untrusted, NET, GPS, 0.0, 60.0) == []


def test_track_odds_lean_past_the_midline() -> None:
    fixes, _ = _fixes(2.2 * TOWARD_U, 60)  # beyond the midline (1.9 m): U is the likelier
    odds = track_odds(fixes, NET, GPS, 0.0, 60.0)
    assert odds[0].track == "U" and 0.0 < odds[0].llr < math.log(1000.0)


def _period(odds: list[TrackOdds], decisions: tuple[object, ...] = ()) -> RailPeriod:
    ga = analysis(run_line(300), decisions=decisions)  # type: ignore[arg-type]
    return RailPeriod(5.0, 299.0, ga, None, odds)


def lean(track: str, llr: float) -> TrackOdds:
    return TrackOdds(LINE, track, 120, 0.9 if track == "U" else -2.9, 0.68, llr)


def test_suspected_alarm_when_undecided_and_leaning_away_from_the_plan() -> None:
    res = check_periods([_period([lean("U", 0.9), lean("D", -0.9)])], [possession(track="D")], START, GPS, CFG)
    assert types(res.alarms) == ["wrong_track_suspected"]
    assert types(res.notices) == ["track_undecided"]
    a = res.alarms[0]
    assert a.t == 125.0 and a.work_no == "W1"
    ev = a.evidence
    assert (ev["planned_track"], ev["likeliest_track"]) == ("D", "U")
    assert ev["odds"] == pytest.approx(math.exp(0.9), abs=0.01) and ev["n_fixes"] == 120
    assert res.to_json()["alarms"][0]["type"] == "wrong_track_suspected"


@pytest.mark.parametrize(
    "odds, decisions",
    [
        ([lean("D", 0.9), lean("U", -0.9)], ()),  # leaning to the plan's track
        ([lean("U", 0.0), lean("D", 0.0)], ()),  # on the midline: no lean (suspect_llr = 0)
        ([], ()),  # no trusted fix at all: the notice alone (GPS loss must not stop the work)
        ([lean("U", 0.9), lean("D", -0.9)], (decided(100.0, "D"),)),  # decided in time
    ],
)
def test_no_suspected_alarm(odds: list[TrackOdds], decisions: tuple[object, ...]) -> None:
    res = check_periods([_period(odds, decisions)], [possession(track="D")], START, GPS, CFG)
    assert "wrong_track_suspected" not in types(res.alarms)


def _check(kind: str, seed: int) -> tuple[object, object]:
    case = make_case(NET, kind, seed)
    return case, check_case(case)


def test_simulated_wrong_track_held_near_the_midline_is_suspected_at_120_s() -> None:
    # seed 1081: on U while the plan says D... the slow error holds the fixes 1.8 m from U
    case, res = _check("wrong_track", 1081)
    decisions = [d for p in res.periods for d in p.decisions]  # type: ignore[attr-defined]
    assert decisions and decisions[0].t - case.t_on > 120.0  # type: ignore[attr-defined]
    assert all(d.track == case.run_track for d in decisions)  # type: ignore[attr-defined]
    assert types(res.alarms) == ["wrong_track_suspected", "wrong_track"]  # type: ignore[attr-defined]
    a = res.alarms[0]  # type: ignore[attr-defined]
    assert a.t == pytest.approx(case.t_on + 120.0, abs=0.11)  # type: ignore[attr-defined]
    assert a.evidence["likeliest_track"] == case.run_track != case.plan_track  # type: ignore[attr-defined]


def test_simulated_correct_run_held_near_the_midline_is_not_suspected() -> None:
    # seed 1082: undecided at 120 s on the planned track; the evidence leans the right way
    case, res = _check("overrun", 1082)
    decisions = [d for p in res.periods for d in p.decisions]  # type: ignore[attr-defined]
    assert not decisions or decisions[0].t - case.t_on > 120.0  # type: ignore[attr-defined]
    assert "track_undecided" in types(res.notices)  # type: ignore[attr-defined]
    assert "wrong_track_suspected" not in types(res.alarms)  # type: ignore[attr-defined]
