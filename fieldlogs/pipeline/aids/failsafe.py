"""Slip/slide fail-safe [S000 §3.1, eq. 13]: a correction still running after the maximum
correction time (10 s) ends as a fail-safe episode; from then on the position is
*uncertain* (the driver must not rely on it) until the next absolute fix, and its margin
grows by ``margin.uncertain_growth_pct`` of the travel since (:mod:`fieldlogs.pipeline.positions`).

Two more moments at which the correction cannot be trusted, so the position turns uncertain
(bench/NOTES.md, "Slip margin"):

* a correction whose start point did not adhere (``SlipEpisode.start_trusted`` false: none
  found, or |θ̄| beyond arcsin(Ta/G)) fails safe at its start: its v0 and θ0 come from slipping
  pulses, an error eq. 13's budget ½·Δa·T² does not bound;
* a detection after a fail-safe that no correction could follow (``SlipEpisode.after_failsafe_t``:
  inside the fail-safe watch, or before a new start point had room) — a new disturbance, or
  the old one going on, after an absolute fix may have made the position determined again:
  uncertain again at the detection (no event where it is uncertain already or there is none).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, replace

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.types import Event, SlipEpisode
from schemas.enums import EventType, PositionState


@dataclass(eq=False)
class FailsafeAid(StaticAid):
    """The fail-safe ends of the odometry's slip/slide episodes."""

    episodes: Sequence[SlipEpisode]
    name = "failsafe"
    priority = Priority.INTEGRITY

    def observations(self) -> Iterator[Observation]:
        moments = [(ep.t_end, ep, False) for ep in self.episodes if ep.failsafe]
        moments += [(t, ep, True) for ep in self.episodes if ep.failsafe for t in ep.after_failsafe_t]
        for t, ep, again in sorted(moments, key=lambda m: m[0]):
            yield Observation(t, (ep, again))

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        ep, again = obs.payload
        if again and (view.estimate is None or view.estimate.state == PositionState.UNCERTAIN):
            return Outcome([])
        ev = Event(
            view.t,
            EventType.FAILSAFE,
            view.km,
            detail={"reason": _reason(ep, again), "t_start": ep.t_start, "kind": ep.kind},
        )
        return uncertain_outcome(ev, view)


def _reason(ep: SlipEpisode, again: bool) -> str:
    """The fail-safe event's reason (module docstring)."""
    if again:
        return "slip/slide detected again after a fail-safe, with no room for a correction"
    if not ep.start_trusted:
        return "slip/slide correction from a start point that was not adhering"
    return "slip/slide correction exceeded the maximum correction time"


def uncertain_outcome(ev: Event, view: EngineView) -> Outcome:
    """``ev`` and, where a position exists, that position made *uncertain* from here (its margin
    growing with the travel since, until the next absolute fix)."""
    fix = view.estimate
    if fix is None:
        return Outcome([ev])
    return Outcome([ev], replace(fix, t_effective=view.t, state=PositionState.UNCERTAIN, uncertain_since_d=view.d))
