"""The per-fix shortcuts of the D-GPS along aid and the engine (branch engine-final): each gives
what the plain computation gives, bit for bit — the along aid's candidate, track and fix plane
looked up once per estimate (``TrackGpsAlongAid._basis``), the margin of one travel as floats
(:func:`fieldlogs.pipeline.positions.margin_at`), :meth:`TrackLine.project`'s loop without its
tuples and :class:`~fieldlogs.pipeline.aid.Observation`'s own ``__init__``."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.aid import Observation
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_gps_along import TrackGpsAlongAid
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.hypotheses import TrackLine, track_lines
from fieldlogs.pipeline.positions import margin_at, margin_m
from fieldlogs.pipeline.types import Fix, Hypothesis
from schemas.enums import FixSource
from tests.fieldlogs.pipeline.network_cases import CFG, MARGIN, Start, net, travel
from tests.fieldlogs.pipeline.test_track_gps_along import GPS, _fixes, _Uncertain
from tests.fieldlogs.pipeline.test_track_line_scalar import line, project_np, same

#: A margin growing 10 % of the travel: past 1.5·U again 18 m after each correction, every 6 s at
#: 3 m/s — many estimates within A1 (400 m from km 100).
_FAST = replace(MARGIN, distance_pct=10.0)


@dataclass(eq=False)
class _Uncached(TrackGpsAlongAid):
    """The aid looking its candidate, track and plane up at every fix (the plain computation)."""

    def _basis(self, fix: Fix, usable: bool) -> tuple[Hypothesis, TrackLine, list[float], list[float]]:
        self.basis = None
        return super()._basis(fix, usable)


def _solve(
    cls: type[TrackGpsAlongAid], along: list[tuple[float, float, float]], trusted_from: float, uncertain: bool
) -> Solution:
    n = net("junction")
    lines = track_lines(n)
    t, lat, lon = _fixes(along)
    late = t >= trusted_from
    aid = cls(t[late], lat[late], lon[late], lines, CFG, GPS, _FAST, usable=(t, lat, lon))
    extra = [_Uncertain()] if uncertain else []
    aids = [Start("9001", "S", 100.0, 1), TopologyAid(lines, _FAST), *extra, aid]
    return run_aids(travel(n, np.full(600, 3.0)), aids, _FAST)  # type: ignore[arg-type]


@settings(max_examples=25, deadline=None)
@given(
    st.lists(st.tuples(st.floats(-3.0, 3.0), st.floats(-4.5, 4.5)), min_size=50, max_size=50),
    st.floats(0.0, 40.0),
    st.booleans(),
)
def test_the_basis_once_per_estimate_hears_as_the_plain_aid(
    noise: list[tuple[float, float]], trusted_from: float, uncertain: bool
) -> None:
    # fixes every second from t = 8 s along A1 at 3 m/s, random along/across errors (some off
    # the track, some jumps): many corrections, so many estimates, each heard over several fixes;
    # trusted only from a random time, the usable ones read while uncertain
    along = [(8.0 + j, 100.0 + 3.0 * (8.0 + j) + a, o) for j, (a, o) in enumerate(noise)]
    got = _solve(TrackGpsAlongAid, along, trusted_from, uncertain)
    ref = _solve(_Uncached, along, trusted_from, uncertain)
    assert [(e.t, e.type, e.km_m, e.correction_m, e.detail) for e in got.events] == [
        (e.t, e.type, e.km_m, e.correction_m, e.detail) for e in ref.events
    ]
    pd.testing.assert_frame_equal(got.positions, ref.positions, check_exact=True)


def test_several_estimates_are_corrected_in_one_run() -> None:
    # the property above compares runs with many estimates: clean fixes correct every few seconds
    along = [(8.0 + j, 100.0 + 3.0 * (8.0 + j), 0.0) for j in range(50)]
    sol = _solve(TrackGpsAlongAid, along, 0.0, False)
    assert sum(e.detail.get("evidence") == "gps" for e in sol.events) >= 6


def _fix(u: float, d_ref: float, allowance_ref: float, since: float | None) -> Fix:
    fix = Fix(0.0, 0.0, d_ref, 0.0, 0.0, "9001", "S", 1, FixSource.BALISE, u, allowance_ref_m=allowance_ref)
    return replace(fix, uncertain_since_d=since)


def test_margin_at_hand_computed() -> None:
    cfg = MarginConfig(distance_pct=2.0, uncertain_growth_pct=10.0)
    # 1 + 0.02·|250 − 50| + max(7 − 3, 0) = 9 m; uncertain since d = 200: + 0.1·50 = 14 m
    assert margin_at(_fix(1.0, 50.0, 3.0, None), 250.0, 7.0, cfg) == pytest.approx(9.0)
    assert margin_at(_fix(1.0, 50.0, 3.0, 200.0), 250.0, 7.0, cfg) == pytest.approx(14.0)
    assert margin_at(_fix(1.0, 50.0, 9.0, None), 250.0, 7.0, cfg) == pytest.approx(5.0)  # no negative slip


_F = st.floats(-1e6, 1e6, allow_nan=False)


@given(st.floats(0.0, 100.0), _F, _F, st.one_of(st.none(), _F), _F, _F, st.floats(0.0, 10.0), st.floats(0.0, 50.0))
def test_margin_at_is_the_array_margin(
    u: float, d_ref: float, a_ref: float, since: float | None, d: float, a: float, pct: float, growth: float
) -> None:
    cfg = MarginConfig(distance_pct=pct, uncertain_growth_pct=growth)
    fix = _fix(u, d_ref, a_ref, since)
    one = margin_at(fix, d, a, cfg)
    assert type(one) is float
    assert one == float(margin_m(fix, np.array([d]), np.array([a]), cfg)[0])
    assert margin_m(fix, d, a, cfg) == one


@dataclass(frozen=True)
class _Generated:
    """Observation's fields with the dataclass's own ``__init__``."""

    t: float
    payload: Any = None
    version: int | None = None


@given(st.floats(allow_nan=False), st.one_of(st.none(), st.integers(), st.text()), st.one_of(st.none(), st.integers()))
def test_observation_init_is_the_dataclass_init(t: float, payload: object, version: int | None) -> None:
    for obs, gen in (
        (Observation(t, payload, version), _Generated(t, payload, version)),
        (Observation(t=t, version=version), _Generated(t=t, version=version)),
        (Observation(t), _Generated(t)),
    ):
        assert dataclasses.astuple(obs) == dataclasses.astuple(gen)
        assert vars(obs) == vars(gen)
        assert repr(obs).replace("Observation", "_Generated") == repr(gen)
        assert obs == replace(obs) and hash(obs) == hash(replace(obs))
    obs = Observation(t, payload, version)
    assert obs != Observation(t, payload, None if version is not None else 1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        obs.t = 1.0  # type: ignore[misc]


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.tuples(st.floats(-50.0, 50.0), st.floats(-50.0, 50.0)), min_size=2, max_size=8),
    st.sampled_from([math.nan, math.inf, -math.inf, 3.0]),
    st.sampled_from([math.nan, math.inf, -math.inf, -2.0]),
    st.floats(-20.0, 120.0),
    st.floats(0.0, 80.0),
)
def test_project_of_a_point_not_finite_is_the_array_formula(
    pts: list[tuple[float, float]], x: float, y: float, near: float, window: float
) -> None:
    # :meth:`TrackLine.project` with its clip inlined: a NaN foot stays NaN (and is the nearest, as
    # ``np.argmin`` takes it), an infinite point gives what the array formula gives
    xy = np.array(pts, dtype=float)
    steps = np.hypot(*np.diff(xy, axis=0).T)
    tl = line(xy, np.concatenate([[0.0], np.cumsum(steps)]))
    with np.errstate(invalid="ignore", over="ignore"):
        assert same(tl.project(x, y, near, window), project_np(tl, x, y, near, window))
