"""The feature aid's lower bound on its next evaluation
(:meth:`~fieldlogs.pipeline.aids.features.FeatureUnit.evaluation_not_before`): never after the
cycle the full scan (:meth:`~fieldlogs.pipeline.aids.features.FeatureUnit.next_evaluation`)
finds, on hand-worked and random runs (speed profiles with stops, a cab reversal, metrics with
slopes up to 1.7 and kilometrage jumps); and the engine's answers identical with and without
the wait on a sample run.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.gis.geometry import Projector
from dbtools.network import Network
from fieldlogs.pipeline.aids.feature_table import load_tables
from fieldlogs.pipeline.aids.features import FeatureUnit
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.estimate import km_along, signed_travel
from fieldlogs.pipeline.metric import IDENTITY, TrackMetric
from fieldlogs.pipeline.types import Fix, FloatArray, Odometry
from fieldlogs.simulate.networks.synthetic import build_network
from schemas.enums import FixSource
from tests.fieldlogs.pipeline.test_features import CFG, DT, KM0, LINE, SPEC, between  # the two-curve line


@pytest.fixture(scope="module")
def net() -> Network:
    return build_network([SPEC], Projector(9))


def run_of(v: FloatArray, cab: FloatArray, seed: int = 0) -> tuple[Cycles, Odometry]:
    """Cycles and odometry of speeds ``v`` [m/s] and driving cab ``cab`` per cycle (yaw-rate noise only:
    the scan and the bound never read κ)."""
    n = v.size
    t = np.arange(n, dtype=np.float64) * DT
    d = np.concatenate([[0.0], np.cumsum(v[1:] * DT)])
    imu = {c: np.zeros(n) for c in ("ax", "ay", "az", "wx", "wy")}
    imu["wz"] = np.random.default_rng(seed).normal(0.0, 1e-3, n)
    cyc = Cycles(t, d.copy(), d.copy(), v.copy(), imu, cab.astype(np.int8), np.ones(n, dtype=np.int8), True, True)
    allowance = np.cumsum(np.where(np.arange(n) % 97 == 0, 0.7, 0.0))  # a slip budget growing now and then
    return cyc, Odometry(d, v.copy(), np.zeros(n, dtype=bool), allowance)


def test_bound_of_a_constant_run_is_the_exit_check_end_plus_margin_less_a_metre(net: Network) -> None:
    """20 m/s on D from km 10 600 (2 m a cycle), the fix exact: F001's row 6 lies at km r6, so the
    estimate reaches r6 + search margin at d = r6 + 100 − 10 600 and the bound is one metre short
    of it: the first cycle with 2·i ≥ r6 + 100 − 10 600 − 1."""
    n = 900
    cyc, odo = run_of(np.full(n, 20.0), np.ones(n))
    unit = FeatureUnit(cyc, odo, net, CFG)
    fix = Fix(0.0, 0.0, 0.0, KM0 + 600.0, KM0 + 600.0, LINE, "D", 1, FixSource.BALISE, 1.0)
    km = fix.km_m + signed_travel(cyc, odo)
    fp = net.feature_points
    r6 = float(fp[(fp.track == "D") & (fp.feature_id == "F001")].sort_values("seq")["km_m"].iloc[5])
    dist = r6 + CFG.search_margin_m - (KM0 + 600.0)
    want = math.ceil((dist - 1.0) / 2.0)
    lb = unit.evaluation_not_before(fix, 0, between(km), 1.0)
    assert lb == want
    first = unit.next_evaluation(fix, 0, between(km))
    assert first is not None
    i_eval, cand = first
    assert cand.feature_id == "F001" and want <= i_eval <= want + 1
    # 5 m past row 6 but not yet past it by the margin: F001 is still the one ahead, same bound
    a = math.ceil((dist - CFG.search_margin_m + 5.0) / 2.0)
    assert unit.evaluation_not_before(fix, a, between(km), 1.0) == want
    again = unit.next_evaluation(fix, a, between(km))
    assert again is not None and again[1].feature_id == "F001"
    # a metric twice as steep (km per metre of travel) halves the distance the bound allows
    assert unit.evaluation_not_before(fix, 0, between(km), 2.0) == math.ceil((dist / 2.0 - 1.0) / 2.0)
    # past the last feature's end: nothing ahead in this direction, the bound is the run's end
    assert unit.evaluation_not_before(fix, 0, between(km + 5_000.0), 1.0) == n
    # no table for the line/track, or no κ: the scan answers at once, the bound does not wait
    other = Fix(0.0, 0.0, 0.0, fix.km_m, fix.km_m, "0999", "D", 1, FixSource.BALISE, 1.0)
    assert unit.evaluation_not_before(other, 5, between(km), 1.0) == 5


def test_a_cab_reversal_ends_the_wait(net: Network) -> None:
    """Reversing at cycle 100 (before F001 is reached): the scan of the reversed segment starts
    there, so the bound is not after it."""
    n = 900
    cab = np.where(np.arange(n) < 100, 1, -1)
    cyc, odo = run_of(np.full(n, 20.0), cab)
    unit = FeatureUnit(cyc, odo, net, CFG)
    fix = Fix(0.0, 0.0, 0.0, KM0 + 600.0, KM0 + 600.0, LINE, "D", 1, FixSource.BALISE, 1.0)
    km = fix.km_m + signed_travel(cyc, odo)
    assert unit.evaluation_not_before(fix, 0, between(km), 1.0) == 100


def metric_of(data: st.DataObject) -> TrackMetric:
    """A random metric over the line: grid steps of 20–200 m, km per metre of rail 0.6–1.7, and
    maybe a kilometrage jump (50 m of km over 0.5 m of rail)."""
    km, c = [KM0 - 4_000.0], [0.0]
    jump_at = data.draw(st.one_of(st.none(), st.integers(5, 60)))
    while km[-1] < KM0 + 8_000.0:
        if len(km) == jump_at:
            km.append(km[-1] + 50.0)
            c.append(c[-1] + 0.5)
            continue
        step = data.draw(st.floats(20.0, 200.0))
        km.append(km[-1] + step)
        c.append(c[-1] + step / data.draw(st.floats(0.6, 1.7)))
    return TrackMetric(np.array(km), np.array(c))


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_bound_never_after_the_scans_evaluation(net: Network, data: st.DataObject) -> None:
    """Random speed profiles (stops included), an optional cab reversal, a fix anywhere on the
    line with an error, random metrics: at every evaluation found in turn and at random cycles,
    the bound lies in [after, scan's cycle] (n only when the scan finds none)."""
    n = data.draw(st.integers(200, 1500))
    speed = st.integers(0, 350).map(lambda x: x / 10.0)  # m/s, stops included
    pieces = data.draw(st.lists(st.tuples(st.integers(10, 300), speed), min_size=1, max_size=8))
    v = np.concatenate([np.full(k, s) for k, s in pieces])
    v = np.resize(v, n)
    rev = data.draw(st.one_of(st.none(), st.integers(1, n - 1)))
    cab = np.ones(n) if rev is None else np.where(np.arange(n) < rev, 1, -1) * data.draw(st.sampled_from([1, -1]))
    cyc, odo = run_of(v, cab, data.draw(st.integers(0, 3)))
    unit = FeatureUnit(cyc, odo, net, CFG)
    track = data.draw(st.sampled_from(["D", "U"]))
    k = data.draw(st.sampled_from([1, -1]))
    km0 = KM0 + data.draw(st.floats(-500.0, 3_500.0))
    unc = data.draw(st.floats(1.0, 40.0))
    fix = Fix(0.0, 0.0, 0.0, km0, km0, LINE, track, k, FixSource.BALISE, unc)
    metric = data.draw(st.one_of(st.just(IDENTITY), st.builds(lambda: metric_of(data))))
    km = km_along(fix, signed_travel(cyc, odo), metric)
    slope = metric.max_slope
    afters = data.draw(st.lists(st.integers(0, n - 1), max_size=4))
    after = 0
    while True:
        _check(unit, fix, after, km, slope, n)
        nxt = unit.next_evaluation(fix, after, between(km))
        if nxt is None:
            break
        unit.evaluate(nxt[1], fix, between(km), nxt[0])  # marks it evaluated, as the aid does
        after = nxt[0]
    for a in afters:
        _check(unit, fix, a, km, slope, n)


def _check(unit: FeatureUnit, fix: Fix, after: int, km: FloatArray, slope: float, n: int) -> None:
    lb = unit.evaluation_not_before(fix, after, between(km), slope)
    nxt = unit.next_evaluation(fix, after, between(km))
    assert after <= lb <= n
    if nxt is None:
        return
    assert lb <= nxt[0], (lb, nxt[0], nxt[1].feature_id)
    assert lb < n


def test_engine_answers_identical_with_and_without_the_wait(sample_network_db, monkeypatch) -> None:  # type: ignore[no-untyped-def]
    """run_pipeline of a sample run along the line with feature points: positions, events and
    fixes equal whether the feature aid waits for its bound or scans at every estimate; the
    bound did make it wait."""
    from cli.demo import sample_logs_dir
    from dbtools.database import read_network
    from fieldlogs.pipeline.run import run_pipeline
    from fieldlogs.runs.handle import read_run

    net = read_network(sample_network_db)
    real = FeatureUnit.evaluation_not_before
    waits: list[int] = []

    def counted(self: FeatureUnit, fix: Fix, after_i: int, km_between, slope: float) -> int:  # type: ignore[no-untyped-def]
        lb = real(self, fix, after_i, km_between, slope)
        waits.append(lb - after_i)
        return lb

    monkeypatch.setattr(FeatureUnit, "evaluation_not_before", counted)
    waited = run_pipeline(read_run(sample_logs_dir() / "sim-u-tunnel"), net, PipelineConfig())
    assert sum(w > 100 for w in waits) > len(waits) // 2  # mostly far ahead: nothing read then
    monkeypatch.setattr(FeatureUnit, "evaluation_not_before", lambda self, fix, after_i, kb, slope: after_i)
    at_once = run_pipeline(read_run(sample_logs_dir() / "sim-u-tunnel"), net, PipelineConfig())
    assert waited.positions.equals(at_once.positions)
    assert waited.events.equals(at_once.events)
    assert repr(waited.fixes) == repr(at_once.fixes)  # NaN km of ambiguous fixes: compared as text
    assert (waited.events["type"] == "feature_correction").any()


def test_feature_tables_built_once_per_network(net: Network) -> None:
    """The line feature tables are a function of the DB: every unit on one network (a long run's
    windows, an audit's runs) shares one build, equal to load_tables'; another network (its rows
    changed) gets its own."""
    v, cab = np.full(50, 10.0), np.ones(50)
    a = FeatureUnit(*run_of(v, cab), net, CFG)
    b = FeatureUnit(*run_of(v, cab, seed=1), net, CFG)
    assert a.tables is b.tables and a.skipped is b.skipped
    fresh, skipped = load_tables(net.feature_points)
    assert sorted(fresh) == sorted(a.tables) == [(LINE, "D"), (LINE, "U")]
    for key, tab in fresh.items():
        np.testing.assert_array_equal(tab.km, a.tables[key].km)
        assert list(tab.feature_id) == list(a.tables[key].feature_id)
    assert skipped == a.skipped
    fp = net.feature_points.copy()
    first = (fp["feature_id"] == fp["feature_id"].iloc[0]) & (fp["track"] == fp["track"].iloc[0])
    fp.loc[first, "radius_m"] = 0.0  # that feature's row 3 no longer a curve
    other = FeatureUnit(*run_of(v, cab), Network({**net.tables, "feature_points": fp}, origin="test"), CFG)
    assert other.tables is not a.tables
    assert [s["reason"] for s in other.skipped] == [*(s["reason"] for s in a.skipped), "row 3 radius is not > 0"]
