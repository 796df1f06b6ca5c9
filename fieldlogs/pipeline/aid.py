"""The aid protocol: how a sensor or a correction plugs into the positioning engine.

The onboard position between two absolute fixes is pure dead reckoning on the corrected
travel (:mod:`fieldlogs.pipeline.estimate`). Everything else — a balise telegram, a curve
recognised as a feature point, a GPS up/down decision, the fail-safe end of a slip
correction, a road-rail vehicle put on rail — is an **aid**: a unit that says something
about the position at certain moments. The engine (:mod:`fieldlogs.pipeline.engine`)
visits those moments in time order and knows no sensor: it asks each aid

* :meth:`Aid.observations` — the moments known before the loop (telegram times, GPS
  decisions computed vectorised over the run, fail-safe times, PTO changes);
* :meth:`Aid.next_observation` — after every change of the estimate, the next moment that
  depends on it (a feature point is evaluated once the estimate has passed it, so where it
  lies depends on the fix in force); an observation scheduled under an older estimate is
  dropped when the estimate changes;
  a moment that takes a long scan ahead to find may be given as a :class:`Resume`: a
  *probe* at the time the scan has reached, which the engine resumes there (the scan goes on
  only as far as the engine has come, and ends unread when the estimate changes first);
* :meth:`Aid.observe` — what it says at that moment, given an :class:`EngineView` (time,
  cycle, travel, cab direction, the estimate in force and its km): events, and optionally a
  new estimate (an absolute fix, the same fix made *uncertain* or moved to another track) or
  the instruction to forget the position (off rail), and follow-up observations.

An aid whose static moment can be a no-op (:class:`IdleAid`) says so through ``idle``: the
engine then takes that moment from the heap without hearing it (nothing would change), and an
aid's next dynamic moment is heard at once when it comes before the heap's first entry that is
not idle (the *horizon*, :mod:`fieldlogs.pipeline.engine`).

An aid whose dynamic moments are many and mostly silent may set ``lane = True``: the engine then
hears them from a short list beside the heap while they come first, with one view moved from
moment to moment — such an aid must keep no view past the call it was given in.

Every estimate carries its uncertainty (``Fix.uncertainty_m``) from which the engine's
margin grows with travel; the engine, not the aid, turns a correction amount
(``Event.correction_m``) into its position-correction % [S003 §5.2], because only it knows
the previous absolute fix.

Simultaneous observations are taken in the order of the aids' :class:`Priority`; an aid
with ``needs_track`` is not heard while the vehicle is not on the track (a road-rail vehicle
on the road: PTO off).

Speed aids (a ground-speed sensor such as the 2-frequency CW radar [S004]) act one level
lower, on the odometry, through :class:`SpeedAid`.
"""

from __future__ import annotations

from collections.abc import Generator, Iterable, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from typing import TYPE_CHECKING, Any, Protocol, TypeVar, runtime_checkable

from fieldlogs.pipeline.types import Event, Fix, FloatArray

if TYPE_CHECKING:
    from fieldlogs.pipeline.cycles import Cycles
    from fieldlogs.pipeline.estimate import Travel


class Priority(IntEnum):
    """Order of observations at the same time (lower first)."""

    RAIL = -1
    """On/off rail: decides whether a position exists at all."""
    INTEGRITY = 0
    """Fail-safe: the position became uncertain."""
    TELEGRAM = 1
    """Balise telegrams: absolute fixes."""
    TRACK = 2
    """Track (up/down) decisions and crossovers from GNSS."""
    FEATURE = 3
    """Feature points, evaluated on the estimate the earlier aids left."""


@dataclass(frozen=True, init=False)
class Observation:
    """A moment at which an aid has something to say."""

    t: float
    payload: Any = None
    """Whatever the aid needs back in :meth:`Aid.observe` (a telegram, a decision, …)."""
    version: int | None = None
    """Estimate version it was scheduled under (dynamic observations); None: always valid."""

    def __init__(self, t: float, payload: Any = None, version: int | None = None) -> None:
        # the frozen dataclass's own __init__ sets each field through object.__setattr__: twice
        # the time of writing the instance dict, and the engine makes two per GPS fix heard
        d = self.__dict__
        d["t"], d["payload"], d["version"] = t, payload, version


_T = TypeVar("_T")

#: A resumable search for an aid's next moment: yields a time the moment is not before (the
#: scan has reached it), returns the moment (or None: there is none).
Scan = Generator[float, None, "Observation | None"]


@dataclass(frozen=True)
class Resume:
    """Payload of a probe: the moment is not before the probe's time; the engine resumes the
    scan there, and what it returns takes the probe's place in the order of simultaneous
    observations (so the answer is that of the whole scan made at once)."""

    scan: Scan


def scanned(scan: Scan) -> Observation | None:
    """Advance ``scan`` by one step: the moment it returns, or a probe at the time it reached."""
    try:
        t = next(scan)
    except StopIteration as stop:
        found: Observation | None = stop.value
        return found
    return Observation(t, Resume(scan))


def drained(scan: Generator[object, None, _T]) -> _T:
    """What a resumable scan returns, read to its end at once."""
    while True:
        try:
            next(scan)
        except StopIteration as stop:
            result: _T = stop.value
            return result


@dataclass
class Outcome:
    """What an aid says at an observation."""

    events: list[Event] = field(default_factory=list)
    estimate: Fix | None = None
    """A new estimate in force from now (an absolute fix, or the current one changed)."""
    forget: bool = False
    """The position no longer exists (off rail): undetermined from now."""
    follow_up: Sequence[Observation] = ()
    """Further static observations of this aid (e.g. a decision to re-take once moving)."""

    @property
    def silent(self) -> bool:
        """Nothing said: no events, no estimate, no forgetting, no follow-up."""
        return not (self.events or self.estimate is not None or self.forget or self.follow_up)


class EngineView(Protocol):
    """What an aid sees of the engine at an observation (read-only)."""

    @property
    def t(self) -> float: ...
    @property
    def i(self) -> int:
        """Cycle at or after ``t``."""
        ...

    @property
    def d(self) -> float:
        """Unsigned travel at ``t`` [m]."""
        ...

    @property
    def s(self) -> float:
        """Signed travel toward the cab's F end at ``t`` [m]."""
        ...

    @property
    def motion(self) -> int:
        """Sense of motion at cycle ``i``: +1 toward the F end, −1 toward the R end (the driving
        cab's direction, or a two-phase tachometer's where the run has one)."""
        ...

    @property
    def estimate(self) -> Fix | None:
        """The fix in force (None: never determined, or forgotten)."""
        ...

    @property
    def km(self) -> float | None:
        """Dead-reckoned km of the estimate at ``t`` (None without an estimate)."""
        ...

    def km_at(self, s: float) -> float:
        """Dead-reckoned km of the estimate at signed travel ``s``."""
        ...

    def km_estimate(self) -> FloatArray:
        """Dead-reckoned km of the estimate on every cycle of the run (computed once per
        estimate); costs O(run length): aids that scan ahead use :meth:`km_between`."""
        ...

    def km_between(self, i0: int, i1: int) -> FloatArray:
        """Dead-reckoned km of the estimate on cycles ``i0 ≤ i < i1`` (clipped to the run):
        ``km_estimate()[i0:i1]``, computed for the window only."""
        ...

    @property
    def travel(self) -> Travel:
        """The run's travel arrays (time, d, S, cab, slip budget) on the cycle grid."""
        ...


@runtime_checkable
class Aid(Protocol):
    """A position aid (see the module docstring)."""

    name: str
    priority: Priority
    needs_track: bool

    def observations(self) -> Iterable[Observation]: ...

    def next_observation(self, view: EngineView) -> Observation | None: ...

    def observe(self, obs: Observation, view: EngineView) -> Outcome: ...


@runtime_checkable
class IdleAid(Protocol):
    """An aid that can tell, before hearing a static observation, that hearing it would change
    nothing: no events, no estimate, no follow-up, and its own state unchanged."""

    def idle(self, obs: Observation, estimate: Fix | None) -> bool:
        """Whether hearing ``obs`` now, with ``estimate`` in force, would be a no-op."""
        ...


class StaticAid:
    """Base of aids whose moments are all known before the loop."""

    name = "aid"
    priority = Priority.FEATURE
    needs_track = True

    def next_observation(self, view: EngineView) -> Observation | None:
        return None


@dataclass(frozen=True)
class SpeedOnCycles:
    """An independent ground speed on the cycle grid (NaN where there is none)."""

    v_mps: FloatArray
    """Speed over ground, unsigned [m/s]."""
    sigma_mps: FloatArray
    """Its 1σ [m/s]."""
    source: str
    signed_mps: FloatArray | None = None
    """The speed along the body x axis, + toward the F end (None: the sensor gives no
    direction) [m/s]; the odometry checks it against the cab's direction."""
    frame_s: float = 0.0
    """Time over which consecutive cycles share one measurement and its error (a radar
    frame; 0: every cycle is its own) [s]."""


@runtime_checkable
class SpeedAid(Protocol):
    """A ground-speed sensor for the odometry (independent of wheel slip and slide)."""

    name: str

    def on_cycles(self, cycles: Cycles) -> SpeedOnCycles | None: ...
