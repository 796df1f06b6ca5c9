"""The engine and the aid protocol, with small aids written here (issue 14: the loop knows
no sensor; aids plug in)."""

from __future__ import annotations

import ast
import inspect
import re
from collections.abc import Iterator
from dataclasses import dataclass, field, replace

import numpy as np
import pytest

import fieldlogs.pipeline.engine as engine_mod
from fieldlogs.pipeline.aid import Aid, EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.registry import POSITION_AIDS, SPEED_AIDS
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.types import Event, Fix
from schemas.enums import EventType, FixSource, PositionState

V = 10.0  # m/s


def travel(seconds: float = 60.0, pto: np.ndarray | None = None) -> Travel:
    t = np.arange(0.0, seconds + 1e-9, 0.1)
    d = V * t
    n = t.size
    on = np.ones(n, bool) if pto is None else pto != 0
    return Travel(t, d, d.copy(), np.full(n, V), np.ones(n, np.int8), on, np.zeros(n))


@dataclass(eq=False)
class Beacon(StaticAid):
    """An absolute fix at given times: km = true km (10 m/s from km 1000) + an offset."""

    times: tuple[float, ...]
    offset_m: float = 0.0
    name = "beacon"
    priority = Priority.TELEGRAM
    seen: list[float] = field(default_factory=list)

    def observations(self) -> Iterator[Observation]:
        return (Observation(t, None) for t in self.times)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        self.seen.append(view.t)
        km = 1000.0 + V * view.t + self.offset_m
        amount = None if view.km is None else view.km - km
        ev = Event(view.t, EventType.BALISE_CORRECTION, km, amount)
        fix = Fix(view.t, view.s, view.d, km, km, "L", "D", 1, FixSource.BALISE, 1.0, t_ref=view.t)
        return Outcome([ev], fix)


@dataclass(eq=False)
class Ahead(StaticAid):
    """A dynamic aid: 100 m ahead of every new estimate, once per estimate."""

    name = "ahead"
    priority = Priority.FEATURE
    asked: list[int] = field(default_factory=list)
    heard: list[float] = field(default_factory=list)

    def observations(self) -> Iterator[Observation]:
        return iter(())

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or fix.state != PositionState.DETERMINED or len(self.asked) > 20:
            return None
        self.asked.append(view.i)
        km = view.km_estimate()
        j = np.flatnonzero(km >= fix.km_m + 100.0)
        return Observation(float(view.travel.t[j[0]]), fix.km_m) if j.size else None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        self.heard.append(view.t)
        return Outcome([Event(view.t, EventType.FEATURE_REFUSED, view.km)])


def _code_without_docs(module: object) -> str:
    """Source with docstrings and comments removed (the code, not its explanation)."""
    tree = ast.parse(inspect.getsource(module))  # type: ignore[arg-type]
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list) and body and isinstance(body[0], ast.Expr):
            if isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
                body.pop(0)
    return ast.unparse(tree).lower()


def test_engine_module_names_no_sensor() -> None:
    src = _code_without_docs(engine_mod)
    assert "def run_aids" in src
    for word in ("balise", "gps", "gnss", "feature", "radar", "telegram", "pto", "imu", "tacho", "slip"):
        assert not re.search(rf"\b{word}", src), word


def test_registered_aids_follow_the_protocol(sample_run_context) -> None:  # type: ignore[no-untyped-def]
    aids = [a for f in POSITION_AIDS if (a := f(sample_run_context)) is not None]
    # the sample run has balises, GPS and an IMU without gaps, no raw GNSS
    assert {a.name for a in aids} == {"rail", "failsafe", "balise", "gps", "feature"}
    assert all(isinstance(a, Aid) for a in aids)
    assert len({a.name for a in aids}) == len(aids)
    assert SPEED_AIDS


def test_correction_percentage_is_the_engines_over_the_previous_absolute_fix() -> None:
    # the first fix has no previous one; the second, 2 m off after 200 m of travel → 1 %
    sol = run_aids(travel(), [Beacon((5.0,), 0.0), Beacon((25.0,), -2.0)], MarginConfig())
    first, second = sol.events
    assert first.correction_m is None and first.correction_pct is None
    assert second.correction_m == pytest.approx(2.0)
    assert second.correction_pct == pytest.approx(1.0)
    assert second.detail["distance_since_correction_m"] == pytest.approx(200.0, abs=0.01)


def test_positions_margin_grows_from_the_fix() -> None:
    sol = run_aids(travel(), [Beacon((10.0,))], MarginConfig(distance_pct=2.0))
    pos = sol.positions.set_index(sol.positions.t.round(1))
    assert pos.loc[9.9, "state"] == "undetermined" and np.isnan(pos.loc[9.9, "margin_m"])
    assert pos.loc[30.0, "km_m"] == pytest.approx(1300.0)
    assert pos.loc[30.0, "margin_m"] == pytest.approx(1.0 + 0.02 * 200.0)
    assert pos.loc[30.0, "last_fix_source"] == "balise"


def test_dynamic_observation_dropped_when_the_estimate_changes() -> None:
    # a new fix at 15 s (before the 100 m-ahead point of the 10 s fix at 20 s) replaces it
    ahead = Ahead()
    run_aids(travel(40.0), [Beacon((10.0, 15.0)), ahead], MarginConfig())
    assert ahead.heard[0] == pytest.approx(25.0)  # 100 m after the 15 s fix, not 20 s
    assert 20.0 not in [round(t, 1) for t in ahead.heard]


def test_dynamic_aid_is_asked_again_after_its_own_observation() -> None:
    ahead = Ahead()
    run_aids(travel(40.0), [Beacon((10.0,)), ahead], MarginConfig())
    # asked at the fix, then after each of its own observations (same estimate → same
    # point: the aid itself decides whether there is a next moment; here it is the same)
    assert ahead.heard[:2] == [pytest.approx(20.0), pytest.approx(20.0)]
    assert len(ahead.asked) >= 2


def test_simultaneous_observations_by_priority_then_arrival() -> None:
    order: list[str] = []

    @dataclass(eq=False)
    class Tag(StaticAid):
        label: str
        priority: Priority  # type: ignore[misc]
        name = "tag"

        def observations(self) -> Iterator[Observation]:
            return iter([Observation(5.0), Observation(5.0)])

        def observe(self, obs: Observation, view: EngineView) -> Outcome:
            order.append(self.label)
            return Outcome()

    run_aids(
        travel(10.0), [Tag("f", Priority.FEATURE), Tag("r", Priority.RAIL), Tag("t", Priority.TELEGRAM)], MarginConfig()
    )
    assert order == ["r", "r", "t", "t", "f", "f"]


def test_off_rail_silences_on_rail_aids_and_forget_ends_the_position() -> None:
    t = np.arange(0.0, 60.0 + 1e-9, 0.1)
    pto = np.where((t >= 20.0) & (t < 40.0), 0, 1).astype(np.int8)

    @dataclass(eq=False)
    class Rail(StaticAid):
        name = "rail"
        priority = Priority.RAIL
        needs_track = False

        def observations(self) -> Iterator[Observation]:
            return iter([Observation(20.0, False), Observation(40.0, True)])

        def observe(self, obs: Observation, view: EngineView) -> Outcome:
            return Outcome(
                [Event(view.t, EventType.ON_RAIL if obs.payload else EventType.OFF_RAIL)], forget=not obs.payload
            )

    beacon = Beacon((10.0, 30.0, 50.0))
    sol = run_aids(travel(60.0, pto), [Rail(), beacon], MarginConfig())
    assert beacon.seen == [pytest.approx(10.0), pytest.approx(50.0)]  # not heard off rail
    pos = sol.positions.set_index(sol.positions.t.round(1))
    assert pos.loc[19.9, "state"] == "determined"
    assert pos.loc[30.0, "state"] == "undetermined" and pos.loc[45.0, "state"] == "undetermined"
    assert pos.loc[55.0, "state"] == "determined"
    # after a forget there is no previous absolute fix: the 50 s fix has no correction %
    assert next(e for e in sol.events if e.t == pytest.approx(50.0)).correction_pct is None


def test_a_changed_estimate_keeps_its_reference_point() -> None:
    """An aid that makes the estimate uncertain keeps the fix's reference: the margin keeps
    counting from the fix, plus the uncertain growth."""

    @dataclass(eq=False)
    class Doubt(StaticAid):
        name = "doubt"
        priority = Priority.INTEGRITY

        def observations(self) -> Iterator[Observation]:
            return iter([Observation(20.0)])

        def observe(self, obs: Observation, view: EngineView) -> Outcome:
            assert view.estimate is not None
            fix = replace(view.estimate, t_effective=view.t, state=PositionState.UNCERTAIN, uncertain_since_d=view.d)
            return Outcome([Event(view.t, EventType.FAILSAFE, view.km)], fix)

    cfg = MarginConfig(distance_pct=2.0, uncertain_growth_pct=5.0)
    sol = run_aids(travel(), [Beacon((10.0,)), Doubt()], cfg)
    pos = sol.positions.set_index(sol.positions.t.round(1))
    assert pos.loc[30.0, "state"] == "uncertain"
    assert pos.loc[30.0, "margin_m"] == pytest.approx(1.0 + 0.02 * 200.0 + 0.05 * 100.0)
    assert sol.fixes[-1].t_ref == pytest.approx(10.0)


def test_a_trains_pto_column_is_ignored(sample_db, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Issue 15: a train's cab stream from another producer carries pto = 0 (recorders write
    every column); the train must not be 'off rail' for the whole run."""
    import shutil

    from dbtools.database import read_network
    from fieldlogs.pipeline.run import run_pipeline
    from fieldlogs.runs.handle import read_run
    from tests.fieldlogs.pipeline.conftest import SAMPLE_LOGS

    run_dir = tmp_path / "run"
    shutil.copytree(SAMPLE_LOGS / "sim-d-slips", run_dir)
    run = read_run(run_dir)
    cab = run.stream("cab")
    assert (cab is not None and "pto" not in cab.columns) or cab["pto"].isna().all()
    net = read_network(sample_db)
    plain = run_pipeline(run, net)
    cab = cab.assign(pto=0)
    cab.to_parquet(run_dir / "cab.parquet", index=False)
    with_pto = run_pipeline(read_run(run_dir), net)
    assert with_pto.summary["n_corrections"] == plain.summary["n_corrections"] > 0
    assert with_pto.positions["state"].tolist() == plain.positions["state"].tolist()


def test_an_imu_gap_makes_the_position_uncertain_and_the_margin_hold(sample_db, tmp_path) -> None:  # type: ignore[no-untyped-def]
    """Issue 15 (found by tests/test_damage.py): an IMU silent for the last 75 % of a run
    left slips undetected and 23 % of the determined cycles outside their margin."""
    import shutil

    import pandas as pd

    from dbtools.database import read_network
    from fieldlogs.pipeline.run import run_pipeline
    from fieldlogs.runs.handle import read_run
    from tests.fieldlogs.pipeline.conftest import SAMPLE_LOGS

    run_dir = tmp_path / "run"
    shutil.copytree(SAMPLE_LOGS / "sim-d-slips", run_dir)
    imu = pd.read_parquet(run_dir / "imu.parquet")
    imu.iloc[: len(imu) // 4].to_parquet(run_dir / "imu.parquet", index=False)
    res = run_pipeline(read_run(run_dir), read_network(sample_db))
    lost = res.events[res.events["type"] == "imu_lost"]
    assert len(lost) == 1
    t_lost = float(lost["t"].iloc[0])
    after = res.positions[res.positions["t"] > t_lost + 1.0]
    assert (after["state"] != "determined").all()
    assert res.summary["truth"]["within_margin_share"] >= 0.999


def test_windowed_estimate_is_the_whole_run_estimate_sliced() -> None:
    tr = travel(30.0)
    seen: list[tuple[bool, bool]] = []

    @dataclass(eq=False)
    class Probe(StaticAid):
        name = "probe"
        priority = Priority.FEATURE

        def observations(self) -> Iterator[Observation]:
            return iter([Observation(1.0), Observation(20.0)])

        def observe(self, obs: Observation, view: EngineView) -> Outcome:
            windows = ((0, 5), (-3, 4), (100, 180), (tr.n - 2, tr.n + 9), (7, 7))
            parts = [view.km_between(i0, i1) for i0, i1 in windows]  # before the whole run is cached
            whole = view.km_estimate()
            for (i0, i1), part in zip(windows, parts, strict=True):
                ref = whole[max(i0, 0) : i1]
                seen.append((part.shape == ref.shape, bool(np.array_equal(part, ref, equal_nan=True))))
            return Outcome()

    run_aids(tr, [Beacon((10.0,)), Probe()], MarginConfig())
    assert len(seen) == 10 and all(a and b for a, b in seen)


def test_travel_interpolation_at_one_time_is_np_interp() -> None:
    from fieldlogs.pipeline.estimate import interp_at

    rng = np.random.default_rng(5)
    xp = np.cumsum(rng.random(200))
    xp[50:53] = xp[52]  # repeated times
    fp = np.cumsum(rng.standard_normal(200))
    xs = np.concatenate([rng.uniform(xp[0] - 1.0, xp[-1] + 1.0, 2000), xp, [xp[0] - 3.0, xp[-1] + 3.0]])
    assert all(interp_at(float(x), xp, fp) == float(np.interp(x, xp, fp)) for x in xs)
