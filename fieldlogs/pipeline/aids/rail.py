"""Road-rail vehicles: a position exists only while on rail (PTO on) [S001 §4.2.4].

Going off rail forgets the position; going on rail again starts undetermined (the next
GPS decision, or for a train a balise pair, sets it). Trains have PTO 1 throughout, so this
aid has nothing to say for them.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.types import Event, FloatArray
from schemas.enums import EventType


@dataclass(eq=False)
class RailAid(StaticAid):
    """PTO changes on the cycle grid (``Cycles.pto``)."""

    t: FloatArray
    pto: np.ndarray
    name = "rail"
    priority = Priority.RAIL
    needs_track = False

    def observations(self) -> Iterator[Observation]:
        for i in np.flatnonzero(np.diff(self.pto.astype(np.int8))) + 1:
            yield Observation(float(self.t[i]), bool(self.pto[i]))

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        on = bool(obs.payload)
        ev = Event(view.t, EventType.ON_RAIL if on else EventType.OFF_RAIL, view.km)
        return Outcome([ev], forget=not on)
