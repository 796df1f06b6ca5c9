"""The engine's horizon and lane (issue 31: the engine's cost, results unchanged): an aid's next
dynamic moment heard at once when it comes before the heap's first entry that is not idle, idle
static moments (:class:`~fieldlogs.pipeline.aid.IdleAid`) taken unheard, lane aids' moments heard
from a list beside the heap — the same hearings, events, fixes and positions as an engine that
pushes every moment and pops the least.

The reference (:class:`OneByOne`) is the engine with all three switched off. The aids mimic the
D-GPS ones: two lane aids heard at the same fix times and priority (the first never acting, the
second also at times of its own, as the along aid on the usable fixes, and acting at some), an
initial-position aid with static moments at those times (idle with an estimate and no chain), a
dynamic aid outside the lane at some of those times and priority (as a GNSS epoch aid), and
estimate changes by other aids at, before and after those times — ties of (time, priority)
included."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.aid import Aid, EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.engine import Solution, _Engine, _Entry, _View
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.positions import positions_frame
from fieldlogs.pipeline.types import Event, Fix
from schemas.enums import EventType, FixSource

V = 10.0  # m/s
Log = list[tuple[str, float, int]]


def travel(on_track: np.ndarray | None = None, seconds: float = 20.0) -> Travel:
    t = np.arange(0.0, seconds + 1e-9, 0.1)
    d = V * t
    n = t.size
    on = np.ones(n, bool) if on_track is None else on_track
    return Travel(t, d, d.copy(), np.full(n, V), np.ones(n, np.int8), on, np.zeros(n))


def fix_at(view: EngineView, source: FixSource, km0: float = 1000.0) -> Fix:
    km = km0 + V * view.t
    return Fix(view.t, view.s, view.d, km, km, "L", "D", 1, source, 1.0, t_ref=view.t)


@dataclass(eq=False)
class Changer(StaticAid):
    """A new estimate at each of ``times`` (``forget``: the position forgotten instead)."""

    times: tuple[float, ...]
    priority: Priority
    forget: bool = False
    name = "changer"
    needs_track = False

    def observations(self) -> Iterator[Observation]:
        return (Observation(t) for t in self.times)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        if self.forget:
            return Outcome(forget=True)
        return Outcome([], fix_at(view, FixSource.BALISE))


@dataclass(eq=False)
class Stream(StaticAid):
    """Dynamic, while an estimate is in force: the next of ``times`` after the engine's time
    (as the D-GPS aids' next fix). At the moments in ``acts`` it says something: an event
    (``kind`` 0), a new estimate (1) or a follow-up moment 0.5 s later (2)."""

    times: tuple[float, ...]
    log: Log
    name: str = "stream"
    acts: frozenset[float] = frozenset()
    kind: int = 0
    lane: bool = True
    priority: Priority = Priority.TRACK
    heard: int = 0

    def observations(self) -> Iterator[Observation]:
        return iter(())

    def next_observation(self, view: EngineView) -> Observation | None:
        if view.estimate is None:
            return None
        later = [t for t in self.times if t > view.t]
        return Observation(later[0]) if later else None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        self.heard += 1
        self.log.append((self.name, view.t, self.heard))
        if view.t not in self.acts or obs.version is None:
            return Outcome()
        if self.kind == 0:
            return Outcome([Event(view.t, EventType.GPS_CORRECTION, 1.0, detail={"by": self.name})])
        if self.kind == 1:
            return Outcome([], fix_at(view, FixSource.GPS, 2000.0))
        return Outcome(follow_up=[Observation(view.t + 0.5)])


@dataclass(eq=False)
class Initial(StaticAid):
    """Like the initial position from GPS: a static moment at each of ``times``; without an
    estimate a chain, ``confirm`` in a row start one; with one it drops the chain (idle when
    there is none)."""

    times: tuple[float, ...]
    log: Log
    confirm: int = 3
    name = "initial"
    priority = Priority.TRACK
    chain: list[float] | None = None
    with_estimate: list[float] = field(default_factory=list)

    def observations(self) -> Iterator[Observation]:
        return (Observation(t, j) for j, t in enumerate(self.times))

    def idle(self, obs: Observation, estimate: Fix | None) -> bool:
        return estimate is not None and self.chain is None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        if view.estimate is not None:
            self.with_estimate.append(view.t)
            self.chain = None
            return Outcome()
        self.chain = [*(self.chain or []), view.t]
        self.log.append((self.name, view.t, len(self.chain)))
        if len(self.chain) < self.confirm:
            return Outcome()
        self.chain = None
        return Outcome([], fix_at(view, FixSource.GPS))


class OneByOne(_Engine):
    """The engine without the horizon and the lane: every next moment pushed, every static moment
    heard, every moment taken from the heap."""

    def __init__(self, tr: Travel, aids: list[Aid]) -> None:
        super().__init__(tr, aids)
        self.idle = [None] * len(self.aids)
        self.lane = [False] * len(self.aids)

    def _next(self, k: int, view: _View) -> _Entry | None:
        nxt = self.aids[k].next_observation(view)  # pushed, whatever comes first
        if nxt is not None:
            self.push(k, Observation(nxt.t, nxt.payload, self.version))
        return None


def solve(engine: _Engine) -> Solution:
    engine.run()
    events = sorted(engine.events, key=lambda e: e.t)
    return Solution(positions_frame(engine.travel, engine.fixes, MarginConfig()), events, engine.fixes)


def aids_of(
    times: tuple[float, ...],
    changes: list[tuple[float, int]],
    acts: tuple[float, ...],
    kind: int,
    log: Log,
    extra: tuple[float, ...] = (),
) -> list[Aid]:
    """Estimate changes at ``changes`` ((time, priority); priority 4: a forget at RAIL), the two
    streams at ``times`` (the second also at ``extra``, as the along aid on the usable fixes,
    and acting at ``acts``), the initial aid, in registry order."""
    prio = [Priority.RAIL, Priority.TELEGRAM, Priority.TRACK, Priority.FEATURE]
    aids: list[Aid] = [Changer(tuple(t for t, p in changes if p == 4), Priority.RAIL, forget=True)]
    for p in range(4):
        aids.append(Changer(tuple(t for t, q in changes if q == p), prio[p]))
    aids.append(Stream(times, log, "g"))
    aids.append(Stream(tuple(sorted({*times, *extra})), log, "a", frozenset(acts), kind))
    aids.append(Initial(times, log))
    # a dynamic aid after them at the same priority and times, as a GNSS epoch aid would be
    aids.append(Stream(tuple(t for t in times if int(t * 2) % 3 == 0), log, "n", frozenset(acts[:1]), 1, False))
    return aids


def both(
    times: tuple[float, ...],
    changes: list[tuple[float, int]],
    acts: tuple[float, ...],
    kind: int,
    on: np.ndarray,
    extra: tuple[float, ...] = (),
) -> tuple[tuple[Log, Solution], tuple[Log, Solution]]:
    out = []
    for cls in (_Engine, OneByOne):
        log: Log = []
        sol = solve(cls(travel(on), aids_of(times, changes, acts, kind, log, extra)))
        out.append((log, sol))
    return out[0], out[1]


def test_ties_at_a_fix_time() -> None:
    # fixes every second; a balise fix (TELEGRAM) at 3, before the streams at 3: they are heard
    # from 4 on; a TRACK change at 6 (static: before the streams' fresh moments at 6) and a
    # FEATURE change at 8 (after them); the second stream corrects (event) at 5
    times = tuple(float(t) for t in range(12))
    (log_a, sol_a), (log_b, sol_b) = both(times, [(3.0, 1), (6.0, 2), (8.0, 3)], (5.0,), 0, np.ones(201, bool))
    assert log_a == log_b
    heard = [(name, t) for name, t, _ in log_a if name in "ga"]
    assert heard[:4] == [("g", 4.0), ("a", 4.0), ("g", 5.0), ("a", 5.0)]
    assert ("g", 6.0) not in heard and ("g", 8.0) in heard  # the TRACK change at 6 came first
    assert [f.t_effective for f in sol_a.fixes] == [f.t_effective for f in sol_b.fixes] == [2.0, 3.0, 6.0, 8.0]
    assert [e.t for e in sol_a.events] == [e.t for e in sol_b.events]


moments = st.lists(st.integers(0, 38).map(lambda k: k * 0.5), max_size=14, unique=True).map(lambda x: tuple(sorted(x)))
changes = st.lists(st.tuples(st.integers(0, 38).map(lambda k: k * 0.5), st.integers(0, 4)), max_size=6, unique=True)


@settings(max_examples=200, deadline=None)
@given(moments, changes, moments, st.integers(0, 2), st.lists(st.booleans(), min_size=201, max_size=201), moments)
def test_horizon_hears_what_one_by_one_hears(
    times: tuple[float, ...],
    ch: list[tuple[float, int]],
    acts: tuple[float, ...],
    kind: int,
    on_list: list[bool],
    extra: tuple[float, ...],
) -> None:
    on = np.asarray(on_list, dtype=bool)
    (log_a, sol_a), (log_b, sol_b) = both(times, ch, acts, kind, on, extra)
    assert log_a == log_b
    assert repr(sol_a.fixes) == repr(sol_b.fixes)  # NaN km of an undetermined fix: compared as text
    assert repr(sol_a.events) == repr(sol_b.events)
    assert sol_a.positions.equals(sol_b.positions)
