"""Slip/slide fail-safe [S000 §3.1, eq. 13]: a correction still running after the maximum
correction time (10 s) ends as a fail-safe episode; from then on the position is
*uncertain* (the driver must not rely on it) until the next absolute fix, and its margin
grows by ``margin.uncertain_growth_pct`` of the travel since (:mod:`fieldlogs.pipeline.positions`).
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
        for ep in self.episodes:
            if ep.failsafe:
                yield Observation(ep.t_end, ep)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        ep: SlipEpisode = obs.payload
        ev = Event(
            view.t,
            EventType.FAILSAFE,
            view.km,
            detail={
                "reason": "slip/slide correction exceeded the maximum correction time",
                "t_start": ep.t_start,
                "kind": ep.kind,
            },
        )
        return uncertain_outcome(ev, view)


def uncertain_outcome(ev: Event, view: EngineView) -> Outcome:
    """``ev`` and, where a position exists, that position made *uncertain* from here (its margin
    growing with the travel since, until the next absolute fix)."""
    fix = view.estimate
    if fix is None:
        return Outcome([ev])
    return Outcome([ev], replace(fix, t_effective=view.t, state=PositionState.UNCERTAIN, uncertain_since_d=view.d))
