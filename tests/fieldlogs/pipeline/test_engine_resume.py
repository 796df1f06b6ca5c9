"""The engine's resumable scans (:class:`~fieldlogs.pipeline.aid.Resume`) and the per-run
memos it reads through (issue 31: the engine's cost, results unchanged): a moment found by a
scan resumed as the engine comes is heard exactly when, and in the order, it would be if the
scan had been read at once; an estimate changed before the scan's end leaves it unread."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, Scan, StaticAid, drained, scanned
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.engine import run_aids
from fieldlogs.pipeline.estimate import Travel, interp_at
from fieldlogs.pipeline.types import Fix
from schemas.enums import FixSource

V = 10.0  # m/s


def travel(seconds: float = 20.0) -> Travel:
    t = np.arange(0.0, seconds + 1e-9, 0.1)
    d = V * t
    n = t.size
    return Travel(t, d, d.copy(), np.full(n, V), np.ones(n, np.int8), np.ones(n, bool), np.zeros(n))


@dataclass(eq=False)
class Fixer(StaticAid):
    """An absolute fix at each of ``times``."""

    times: tuple[float, ...]
    name = "fixer"
    priority = Priority.TELEGRAM

    def observations(self) -> Iterator[Observation]:
        return (Observation(t) for t in self.times)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        km = 1000.0 + V * view.t
        return Outcome([], Fix(view.t, view.s, view.d, km, km, "L", "D", 1, FixSource.BALISE, 1.0, t_ref=view.t))


@dataclass(eq=False)
class Later(StaticAid):
    """Dynamic: ``delay_s`` after the estimate's time, once per estimate; found by a scan that
    stops at every whole second on the way (``resumable``) or at once."""

    delay_s: float
    resumable: bool
    heard: list[tuple[str, float]]
    name = "later"
    priority = Priority.FEATURE
    steps: list[list[float]] = field(default_factory=list)
    """Per scan started: the probe times it yielded."""
    asked_t: float = -1.0

    def observations(self) -> Iterator[Observation]:
        return iter(())

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or view.t == self.asked_t or view.t > fix.t_effective:
            return None  # one moment per estimate
        self.asked_t = view.t
        target = fix.t_effective + self.delay_s
        if not self.resumable:
            return Observation(target)
        return scanned(self._scan(view.t, target))

    def _scan(self, t0: float, target: float) -> Scan:
        probes: list[float] = []
        self.steps.append(probes)
        t = float(np.floor(t0)) + 1.0
        while t < target:
            probes.append(t)
            yield t
            t += 1.0
        return Observation(target)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        self.heard.append((self.name, view.t))
        return Outcome()


def heard_order(resumable: bool, first: str) -> tuple[list[tuple[str, float]], Later]:
    heard: list[tuple[str, float]] = []
    a = Later(3.0, resumable, heard)
    b = Later(3.0, False, heard)
    a.name, b.name = "scan", "plain"
    pair = [a, b] if first == "scan" else [b, a]
    run_aids(travel(), [Fixer((5.0,)), *pair], MarginConfig())
    return heard, a


def test_a_resumed_moment_keeps_its_place_among_simultaneous_ones() -> None:
    # both asked at t = 5 (the fix), both due at 8.0, same priority: heard in the order asked
    for first, other in (("scan", "plain"), ("plain", "scan")):
        heard, scan = heard_order(True, first)
        assert heard == [(first, 8.0), (other, 8.0)]
        assert scan.steps == [[6.0, 7.0]]  # probes at 6 and 7, then the moment
        assert heard_order(False, first)[0] == heard  # as if read at once


def test_a_changed_estimate_leaves_the_scan_unread() -> None:
    heard: list[tuple[str, float]] = []
    a = Later(3.0, True, heard)
    run_aids(travel(), [Fixer((5.0, 6.5)), a], MarginConfig())
    # the first scan (asked at 5) reached its probe at 7 only after the fix at 6.5: never resumed
    assert a.steps == [[6.0, 7.0], [7.0, 8.0, 9.0]]
    assert heard == [("later", 9.5)]


def test_scanned_and_drained() -> None:
    def scan() -> Scan:
        yield 1.0
        yield 2.0
        return Observation(3.0, "x")

    s = scan()
    probe = scanned(s)
    assert probe is not None and probe.t == 1.0 and probe.payload.scan is s
    assert drained(scan()) == Observation(3.0, "x")

    def empty() -> Scan:
        return None
        yield 0.0  # a generator

    assert scanned(empty()) is None


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.floats(0.01, 5.0), min_size=2, max_size=40),
    st.lists(st.floats(-10.0, 200.0), min_size=1, max_size=30),
    st.booleans(),
)
def test_primed_travel_equals_one_time_at_a_time(steps: list[float], times: list[float], on_cycles: bool) -> None:
    t = np.cumsum(steps)
    d = np.cumsum(np.abs(np.sin(t)) * 3.0)
    n = t.size
    fresh = Travel(t, d, -d, np.ones(n), np.ones(n, np.int8), np.ones(n, bool), d * 0.01)
    primed = Travel(t, d, -d, np.ones(n), np.ones(n, np.int8), np.ones(n, bool), d * 0.01)
    qs = [float(t[int(abs(q)) % n]) if on_cycles else q for q in times]
    primed.prime(np.array(qs))
    for q in qs:
        i = min(int(np.searchsorted(t, q, side="left")), n - 1)
        expected = (i, interp_at(q, t, d), interp_at(q, t, -d))
        assert primed.at(q) == expected == fresh.at(q)
        assert primed.allowance_at(q) == interp_at(q, t, d * 0.01) == fresh.allowance_at(q)
