"""The positioning engine: aids applied in time order, knowing no sensor.

Between two absolute fixes the position is dead reckoning on the corrected travel
(:mod:`fieldlogs.pipeline.estimate`), so the loop only visits the moments when an aid has
something to say (:mod:`fieldlogs.pipeline.aid`) — a heap of observations ordered by
(time, aid priority, arrival). At each one the aid's :class:`~fieldlogs.pipeline.aid.Outcome`
is applied:

* a new estimate takes effect at once; its slip-allowance reference is the odometry's
  budget at its reference point; if it is absolute (balise, feature) and an event of the
  outcome carries a correction amount, that event gets its position-correction % =
  |amount| / travel since the previous absolute fix on the same line × 100 [S003 §5.2];
* ``forget`` ends the position (undetermined from now, and no previous absolute fix);
* every change of the estimate bumps its version: observations scheduled under an older
  version are dropped, and every aid is asked for its next estimate-dependent moment.

**Horizon.** When an aid's dynamic observation changed nothing, its next moment gets a fresh
arrival number; if it comes before the heap's first entry in (time, priority, arrival) order it
is the next one taken anyway, so it is heard at once without going through the heap (a fresh
arrival loses every tie of (time, priority) against the entries already there): the same
hearings in the same order as pushing every moment and popping the least. A static moment of
an aid that says it is *idle* for it (:class:`~fieldlogs.pipeline.aid.IdleAid`: hearing it now
would change nothing) is taken from the heap unheard, so it does not stop the horizon either.

**Lane.** Aids heard at many moments that say nothing at most of them (the D-GPS aids at every
trusted fix, both at the same times and priority, one after the other) declare ``lane``: once
one of their dynamic moments is taken, the engine keeps their next moments in a short sorted
list beside the heap and hears them from there, one view moved from moment to moment, while they
come first; an entry of theirs already in the heap joins the list when it comes first, idle and
stale ones are taken. At the first other entry, or the first moment that says something, the
list goes back to the heap with its arrivals: the order is that of the one heap throughout.

Per-cycle positions and margins are then evaluated vectorised from the recorded fixes
(:mod:`fieldlogs.pipeline.positions`).
"""

from __future__ import annotations

import bisect
import heapq
import itertools
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fieldlogs.pipeline.aid import Aid, IdleAid, Observation, Outcome, Resume, scanned
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.geometry import VehicleGeometry
from fieldlogs.pipeline.positions import positions_frame
from fieldlogs.pipeline.types import Event, Fix, FloatArray, evolved

#: Heap entry: (t, priority, arrival, aid index, observation).
_Entry = tuple[float, int, int, int, Observation]


@dataclass
class Solution:
    positions: pd.DataFrame
    events: list[Event]
    fixes: list[Fix] = field(default_factory=list)


@dataclass
class _View:
    """:class:`~fieldlogs.pipeline.aid.EngineView` of one observation."""

    engine: _Engine
    t: float
    i: int
    d: float
    s: float

    @property
    def motion(self) -> int:
        return int(self.engine.travel.motion[self.i])

    @property
    def travel(self) -> Travel:
        return self.engine.travel

    @property
    def estimate(self) -> Fix | None:
        return self.engine.fix

    @property
    def km(self) -> float | None:
        fix = self.engine.fix
        return None if fix is None else float(self.engine.travel.km(fix, self.s))

    def km_at(self, s: float) -> float:
        fix = self.engine.fix
        if fix is None:
            raise ValueError("no estimate in force")
        return float(self.engine.travel.km(fix, s))

    def km_estimate(self) -> FloatArray:
        return self.engine.km_estimate()

    def km_between(self, i0: int, i1: int) -> FloatArray:
        return self.engine.km_between(i0, i1)


class _Engine:
    """State of one run through the loop (see the module docstring)."""

    def __init__(self, travel: Travel, aids: Sequence[Aid]) -> None:
        self.travel = travel
        self.aids = list(aids)
        self.priority = [int(aid.priority) for aid in self.aids]
        self.idle = [aid.idle if isinstance(aid, IdleAid) else None for aid in self.aids]
        self.lane = [bool(getattr(aid, "lane", False)) for aid in self.aids]
        self.heap: list[_Entry] = []
        self.arrival = itertools.count()
        self.events: list[Event] = []
        self.fixes: list[Fix] = []
        self.fix: Fix | None = None
        self.version = 0
        self.last_abs: Fix | None = None
        self._km_cache: tuple[int, FloatArray] | None = None

    def push(self, k: int, obs: Observation, arrival: int | None = None) -> None:
        n = next(self.arrival) if arrival is None else arrival
        heapq.heappush(self.heap, (obs.t, self.priority[k], n, k, obs))

    def km_estimate(self) -> FloatArray:
        if self.fix is None:
            return np.full(self.travel.n, np.nan)
        if self._km_cache is None or self._km_cache[0] != self.version:
            self._km_cache = (self.version, self.travel.km(self.fix, self.travel.s))
        return self._km_cache[1]

    def km_between(self, i0: int, i1: int) -> FloatArray:
        """The estimate on cycles ``i0 ≤ i < i1`` only (clipped to the run): the same numbers
        as ``km_estimate()[i0:i1]`` (dead reckoning is elementwise), at a cost in the window's
        length, not the run's."""
        i0, i1 = max(i0, 0), min(i1, self.travel.n)
        if self.fix is None:
            return np.full(max(i1 - i0, 0), np.nan)
        if self._km_cache is not None and self._km_cache[0] == self.version:
            return self._km_cache[1][i0:i1]
        return self.travel.km(self.fix, self.travel.s[i0:i1])

    def run(self) -> None:
        for k, aid in enumerate(self.aids):
            for obs in aid.observations():
                self.push(k, obs)
        self.travel.prime(np.array([e[0] for e in self.heap], dtype=float))
        end = self.travel.t[-1] + 1e-9 if self.travel.n else -np.inf
        heap = self.heap
        while heap:
            entry: _Entry | None = heapq.heappop(heap)
            while entry is not None:
                t, _prio, n, k, obs = entry
                if t > end:
                    return
                if self.lane[k] and obs.version == self.version and not isinstance(obs.payload, Resume):
                    entry = self._lane(entry, end)
                else:
                    entry = self.step(t, k, obs, n)

    def step(self, t: float, k: int, obs: Observation, arrival: int | None = None) -> _Entry | None:
        """Hear aid ``k`` at ``t`` (unless its observation is stale or it needs the track and
        the vehicle is not on it), apply what it says, ask for what follows. A probe
        (:class:`~fieldlogs.pipeline.aid.Resume`) is no observation: its scan goes on, and
        what it finds keeps the probe's place (``arrival``) among simultaneous ones.

        Returns the aid's next moment instead of scheduling it when it would be the next one
        taken from the heap anyway (the *horizon*, module docstring): after a dynamic
        observation that changed nothing, when it comes before the heap's first entry in
        (time, priority, arrival) order — its arrival is a fresh number, so it loses every tie
        of (time, priority) against an entry already in the heap."""
        if obs.version is not None and obs.version != self.version:
            return None  # scheduled under an estimate that has changed since
        if obs.version is None and self._idle(k, obs):
            return None  # hearing it would change nothing
        if isinstance(obs.payload, Resume):
            found = scanned(obs.payload.scan)
            if found is not None:
                self.push(k, Observation(found.t, found.payload, obs.version), arrival)
            return None
        i, d, s = self.travel.at(t)
        aid = self.aids[k]
        if aid.needs_track and not self.travel.on_track[i]:
            return None  # the vehicle is not on the track: no position, nothing to aid
        view = _View(self, t, i, d, s)
        return self._heard(k, obs, view, aid.observe(obs, view))

    def _heard(self, k: int, obs: Observation, view: _View, out: Outcome) -> _Entry | None:
        """Apply what aid ``k`` said at ``obs`` and ask for what follows (:meth:`step`)."""
        if not out.silent:
            before = self.version
            for follow in out.follow_up:
                self.push(k, follow)
            self.apply(out, view)
            if self.version != before:
                self.ask_next(view, range(len(self.aids)))
                return None
        # its estimate-dependent moment was taken, nothing changed: the next one
        return None if obs.version is None else self._next(k, view)

    def _lane(self, first: _Entry, end: float) -> _Entry | None:
        """Hear the dynamic moments of lane aids (``lane``, :mod:`fieldlogs.pipeline.aid`) from
        ``first`` on, in (time, priority, arrival) order, while they come before every other
        entry of the heap (module docstring, *lane*): their next moments are kept in a short
        sorted list instead of the heap, those already in the heap join it when they come first,
        idle and stale entries before them are taken, one view is moved from moment to moment.
        Left at the first other entry (the list goes back to the heap) or at the first moment
        that says something (heard as :meth:`step` would, a view of its own for what follows)."""
        heap, lane, version = self.heap, [first], self.version
        travel, on_track = self.travel, self.travel.on_track
        view = _View(self, first[0], 0, 0.0, 0.0)
        while lane:
            while heap and heap[0] < lane[0]:
                top = heap[0]
                obs0 = top[4]
                if obs0.version is None and not self._idle(top[3], obs0):
                    return self._leave(lane)  # another aid's moment comes first
                if obs0.version == version and (not self.lane[top[3]] or isinstance(obs0.payload, Resume)):
                    return self._leave(lane)
                heapq.heappop(heap)
                if obs0.version == version:
                    bisect.insort(lane, top)  # a lane aid's moment: joins the list
            t, prio, _n, k, obs = entry = lane.pop(0)
            if t > end:
                lane.append(entry)
                return self._leave(lane)  # the loop ends at it
            i, d, s = travel.at(t)
            aid = self.aids[k]
            if aid.needs_track and not on_track[i]:
                continue  # not heard, no next moment (as in :meth:`step`)
            view.t, view.i, view.d, view.s = t, i, d, s
            out = aid.observe(obs, view)
            if not out.silent:
                self._leave(lane)
                return self._heard(k, obs, _View(self, t, i, d, s), out)
            nxt = aid.next_observation(view)
            if nxt is not None:
                bisect.insort(lane, (nxt.t, prio, next(self.arrival), k, Observation(nxt.t, nxt.payload, version)))
        return None

    def _leave(self, lane: list[_Entry]) -> _Entry | None:
        """The lane's moments back to the heap, with their arrivals (nothing to hear at once)."""
        for entry in lane:
            heapq.heappush(self.heap, entry)
        return None

    def _next(self, k: int, view: _View) -> _Entry | None:
        """Aid ``k``'s next dynamic moment: returned when it comes before the heap's first entry
        that is not idle (those before it taken), pushed otherwise (:meth:`step`)."""
        nxt = self.aids[k].next_observation(view)
        if nxt is None:
            return None
        entry = (nxt.t, self.priority[k], next(self.arrival), k, Observation(nxt.t, nxt.payload, self.version))
        heap = self.heap
        while heap and heap[0] < entry:  # arrivals are unique: (t, priority, arrival) decides
            _t, _p, _n, k0, obs0 = heap[0]
            if obs0.version is not None or not self._idle(k0, obs0):
                heapq.heappush(heap, entry)
                return None
            heapq.heappop(heap)  # an idle moment before it: taken, nothing heard
        return entry  # the next one taken anyway: heard at once, the heap left as it is

    def _idle(self, k: int, obs: Observation) -> bool:
        idle = self.idle[k]
        return idle is not None and idle(obs, self.fix)

    def apply(self, out: Outcome, view: _View) -> None:
        self.events.extend(out.events)
        if out.forget:
            self._forget(view)
        elif out.estimate is not None:
            self._take(out.estimate, out.events)

    def _forget(self, view: _View) -> None:
        if self.fix is None:
            return
        self.fix = None
        self.fixes.append(Fix.undetermined(view.t, view.s, view.d))
        self.version += 1
        self.last_abs = None

    def _take(self, new: Fix, events: list[Event]) -> None:
        # the reference point stays that of the fix that set it when an aid changes the
        # estimate (made uncertain, moved to another track): same allowance reference
        t_ref = new.reference_t
        new = evolved(new, t_ref=t_ref, allowance_ref_m=self.travel.allowance_at(t_ref))
        if new.source.absolute:
            prev = self.last_abs
            corrections = [e for e in events if e.correction_m is not None]
            if corrections and prev is not None and prev.line_code == new.line_code:
                dist = new.d_ref - prev.d_ref
                if dist > 0:
                    ev = corrections[-1]
                    ev.correction_pct = abs(float(ev.correction_m or 0.0)) / dist * 100.0
                    ev.detail["distance_since_correction_m"] = round(dist, 2)
            self.last_abs = new
        self.fix = new
        self.fixes.append(new)
        self.version += 1

    def ask_next(self, view: _View, which: Iterable[int]) -> None:
        for k in which:
            nxt = self.aids[k].next_observation(view)
            if nxt is not None:
                self.push(k, Observation(nxt.t, nxt.payload, self.version))


def run_aids(
    travel: Travel, aids: Sequence[Aid], margin: MarginConfig, geometry: VehicleGeometry | None = None
) -> Solution:
    """Apply ``aids`` in time order over ``travel``; per-cycle positions with their margins
    (and the vehicle's head and tail km when ``geometry`` knows its extent)."""
    engine = _Engine(travel, aids)
    engine.run()
    events = sorted(engine.events, key=lambda e: e.t)
    return Solution(positions_frame(travel, engine.fixes, margin, geometry), events, engine.fixes)
