"""Curve corrections on plain arcs (no transitions) along a network track, on the hand-made
junction's branch B1 (tests/data/networks/junction) with synthetic travel and yaw rate.

Hand computation. The arc: rows r1…r6 = [70, 110, 110, 250, 250, 290] (pos), R 500 m left, a
step of κ from 0 to 1/R at pos 110 and back at pos 250. The train runs B1 forward at v from
pos 2; its yaw rate is v × the *cycle mean* of κ (the fraction of the cycle's travel inside the
arc, over R): no noise. Δt = 0.1 s and the 1 s smoothing average n = 11 cycles, w = n·v·Δt
(11 m at 10 m/s). The smoothed κ ramps linearly over w about each step and crosses the lower
limit 0.8/R (1 − 20 %) at (½ − 0.2)·w = 0.3·w inside the arc: the exit crossing lies at
pos 250 − 3.3 = 246.7 at 10 m/s. Placed back by 0.3·n cycles the step is pos 250 exactly, so
the estimate's 8 m error is corrected to the nearest cycle's quantisation (≤ v·Δt/2 = 0.5 m);
taking the crossing itself would leave 3.3 m. The uncertainty (bias unknown: no standstill)
σ_ω = √(0.0006² + 0.0009²) = 1.0817 mrad/s, σ_x = σ_ω·R·n·Δt = 0.595 m; crossing_z = 3:
1.785 m, + clock_budget_s·v = 5 m → 6.785 m with fix_uncertainty_m 0.5 m.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import Network
from fieldlogs.pipeline.aids.feature_table import Candidate
from fieldlogs.pipeline.aids.features import FeatureUnit
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_features import TrackFeatureFixAid, track_feature_tables
from fieldlogs.pipeline.config import FeatureConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.types import Odometry
from schemas.enums import EventType
from tests.fieldlogs.pipeline.network_cases import MARGIN, Start, net

ARC = np.array([70.0, 110.0, 110.0, 250.0, 250.0, 290.0])
R = 500.0
DT = 0.1


def arc_rows(rows: np.ndarray = ARC) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "track_id": ["B1"] * 6,
            "feature_id": ["A1"] * 6,
            "seq": [1, 2, 3, 4, 5, 6],
            "pos_m": rows,
            "radius_m": [0.0, 0.0, R, 0.0, 0.0, 0.0],
            "attribute": ["straight", "transition", "left", "transition", "straight", "none"],
            "role": [None] * 6,
        }
    )


def arc_run(
    start_pos: float, seconds: float, v: float, lo: float = ARC[2], hi: float = ARC[3]
) -> tuple[Cycles, Odometry]:
    """A train running B1 forward at ``v`` from ``start_pos``; ωz = v × the cycle mean of κ
    (the share of cycle j's travel [d_{j−1}, d_j] inside the arc [lo, hi], over R)."""
    t = np.arange(0.0, seconds + 1e-9, DT)
    n = t.size
    d = v * t
    a = start_pos + np.concatenate([[d[0] - v * DT], d[:-1]])  # cycle j covers pos [a, b]
    b = start_pos + d
    inside = np.clip(np.minimum(b, hi) - np.maximum(a, lo), 0.0, None) / (b - a)
    imu = {c: np.zeros(n) for c in ("ax", "ay", "az", "wx", "wy")} | {"wz": v * inside / R}
    ones = np.ones(n, dtype=np.int8)
    c = Cycles(t, d.copy(), d.copy(), np.full(n, v), imu, ones, ones, True, True)
    return c, Odometry(d, np.full(n, v), np.zeros(n, dtype=bool), np.zeros(n))


def solve_arc(v: float, cfg: FeatureConfig, rows: np.ndarray = ARC) -> tuple[Any, FeatureUnit]:
    n = Network({**net("junction").tables, "track_feature_points": arc_rows(rows)}, origin="junction+arc")
    c, odo = arc_run(2.0, 380.0 / v, v, rows[2], rows[3])
    lines = track_lines(n)
    unit = FeatureUnit(c, odo, n, cfg)
    fix_aid = TrackFeatureFixAid(unit, track_feature_tables(n, lines).own, lines)
    # determined on B1 from pos 10 while the train is at pos 2: the estimate is 8 m ahead
    sol = run_aids(Travel.of(c, odo, n), [Start("9002", "S", 10.0, 1), TopologyAid(lines, MARGIN), fix_aid], MARGIN)
    return sol, unit


@pytest.mark.parametrize("v", [10.0, 20.0])
def test_an_arc_without_transitions_corrects_at_its_step(v: float) -> None:
    cfg = FeatureConfig(search_margin_m=40.0, fix_uncertainty_m=0.5)
    sol, _ = solve_arc(v, cfg)
    refused = [e for e in sol.events if e.type == EventType.FEATURE_REFUSED]
    assert not refused, refused[0].detail
    ev = [e for e in sol.events if e.type == EventType.FEATURE_CORRECTION]
    assert len(ev) == 1 and ev[0].detail["feature_id"] == "A1" and ev[0].detail["pos_db_m"] == pytest.approx(250.0)
    det = ev[0].detail
    assert det["length_m"] == pytest.approx(140.0, abs=1e-6)  # step to step, not 140 − 0.6·w
    # the estimate at the step: the truth + 8 m (the raw crossing would say 250 − 0.3·w + 8)
    assert det["km_est_exit_m"] == pytest.approx(258.0, abs=0.01)
    assert abs(det["ref_offset_m"]) <= v * DT / 2 + 1e-9
    sigma = math.hypot(0.0006, 0.0009) * R * 11 * DT
    assert det["uncertainty_m"] == pytest.approx(3.0 * sigma + 0.5 * v, abs=0.01)
    p = sol.positions
    t = p["t"].to_numpy(float)
    err = p["pos_m"].to_numpy(float) - (2.0 + v * t)
    after = (t >= ev[0].t - 1e-9) & (p["track_id"] == "B1").to_numpy()
    assert np.abs(err[after]).max() <= v * DT / 2 + 1e-6  # the nearest cycle's quantisation only


def test_an_arc_shorter_than_the_smoothing_is_not_judged() -> None:
    # a 15 m arc: at 20 m/s w = 22 m > 15 m (the ramps overlap, the body stays below 1/R):
    # no correction and no refusal; at 10 m/s (w = 11 m) it is corrected
    short = np.array([70.0, 110.0, 110.0, 125.0, 125.0, 165.0])
    cfg = FeatureConfig(search_margin_m=40.0)
    fast, _ = solve_arc(20.0, cfg, short)
    kinds = {e.type for e in fast.events}
    assert EventType.FEATURE_CORRECTION not in kinds and EventType.FEATURE_REFUSED not in kinds
    slow, _ = solve_arc(10.0, cfg, short)
    ev = [e for e in slow.events if e.type == EventType.FEATURE_CORRECTION]
    assert len(ev) == 1 and ev[0].detail["length_m"] == pytest.approx(15.0, abs=1e-6)


@settings(max_examples=40, deadline=None)
@given(v=st.floats(5.0, 30.0), start=st.floats(0.0, 3.0))
def test_step_placed_back_exactly(v: float, start: float) -> None:
    # any speed and any step phase within a cycle: the steps come back to pos 110 and 250
    # (up to rounding), entry and exit, from the lower-limit crossings of the smoothed κ
    n = Network({**net("junction").tables, "track_feature_points": arc_rows()}, origin="junction+arc")
    c, odo = arc_run(start, 330.0 / v, v)
    unit = FeatureUnit(c, odo, n, FeatureConfig())
    k = unit.kappa
    lo = 0.8 / R
    above = np.flatnonzero(k >= lo)
    i0, i1 = int(above[0]), int(above[-1])
    x = odo.d - 0.5 * v * DT  # the cycles' mid travel
    xe = x[i0 - 1] + (lo - k[i0 - 1]) / (k[i0] - k[i0 - 1]) * (x[i0] - x[i0 - 1])
    xx = x[i1] + (k[i1] - lo) / (k[i1] - k[i1 + 1]) * (x[i1 + 1] - x[i1])
    u = ARC.copy()
    cand = Candidate("A1", "", "B1", 1, False, u, u, R, 1, 40.0, 0)
    pe, px = unit._ends(cand, float(xe), float(xx))
    assert start + pe == pytest.approx(110.0, abs=1e-6) and start + px == pytest.approx(250.0, abs=1e-6)
    # with transitions the crossings are the rows themselves
    with_tr = Candidate("A1", "", "B1", 1, False, u + np.array([0, 0, 5, 0, 5, 5]), u, R, 1, 40.0, 0)
    assert unit._ends(with_tr, float(xe), float(xx)) == (float(xe), float(xx))
