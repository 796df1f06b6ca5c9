"""Rolling back seen by the IMU, not by the tacho [S003 §2, §5.3(2)]: at the end of each
rollback :func:`fieldlogs.pipeline.rollback.detect_rollbacks` found (a tachometer without the
``direction`` column), the ``rollback_suspected`` event; the travel has been taken as backward
over it (the inferred sense of motion), but that rests on an inference, so the position is
*uncertain* (the driver must not rely on it) until the next absolute fix, its margin growing
by ``margin.uncertain_growth_pct`` of the travel since, as after a slip/slide fail-safe
(:mod:`fieldlogs.pipeline.aids.failsafe`).
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.failsafe import uncertain_outcome
from fieldlogs.pipeline.rollback import Rollback
from fieldlogs.pipeline.types import Event
from schemas.enums import EventType


@dataclass(eq=False)
class RollbackAid(StaticAid):
    """The rollbacks the IMU found against the cab."""

    rollbacks: Sequence[Rollback]
    name = "rollback"
    priority = Priority.INTEGRITY

    def observations(self) -> Iterator[Observation]:
        for rb in self.rollbacks:
            yield Observation(rb.t_end, rb)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        rb: Rollback = obs.payload
        detail = {"t_start": rb.t_start, "distance_m": round(rb.distance_m, 3), "imu_ratio": round(rb.ratio, 3)}
        return uncertain_outcome(Event(view.t, EventType.ROLLBACK_SUSPECTED, view.km, detail=detail), view)
