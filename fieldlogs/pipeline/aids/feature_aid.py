"""Feature points as an aid of the engine (:mod:`fieldlogs.pipeline.aid`): the next feature ahead
of the estimate (:meth:`~fieldlogs.pipeline.aids.features.FeatureUnit.evaluation_scan`) is
evaluated once the estimate has passed it; an accepted one is an absolute fix at its exit
crossing [S000 §3.2, §4.3.2]. The scan for it is resumed as the engine comes
(:class:`~fieldlogs.pipeline.aid.Resume`): a GPS correction along the track every few seconds
changes the estimate long before the next curve, and the scan then ends unread; it starts only at
a lower bound on the evaluation's time read from the estimate and the travel alone
(:meth:`~fieldlogs.pipeline.aids.features.FeatureUnit.evaluation_not_before`), so most
estimates are replaced before anything is read."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, Resume, Scan, StaticAid, scanned
from fieldlogs.pipeline.aids.feature_table import Candidate
from fieldlogs.pipeline.aids.features import FeatureUnit, KmBetween
from fieldlogs.pipeline.types import Event, Fix
from schemas.enums import EventType, FixSource, PositionState

#: Cycles of the first chunk the engine's scan reads before it waits for the engine to reach
#: them (:class:`~fieldlogs.pipeline.aid.Resume`): an estimate changed meanwhile ends it.
PROBE_CHUNK = 128


@dataclass(eq=False)
class FeatureAid(StaticAid):
    """Feature points as an aid of the engine: the next feature ahead is evaluated once the
    estimate has passed it (an estimate-dependent moment); an accepted one is an absolute
    fix at its exit crossing, a refused one an event naming the failed diagnostics."""

    unit: FeatureUnit
    name = "feature"
    priority = Priority.FEATURE

    def observations(self) -> Iterator[Observation]:
        return iter(())

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or fix.state != PositionState.DETERMINED:
            return None
        scan = self._scan(fix, view.i, view.km_between)
        if not fix.line_code:  # only the line tables' features wait (see ``_scan``)
            return scanned(scan)
        slope = view.travel.metric(fix).max_slope * abs(fix.k)
        i_lb = self.unit.evaluation_not_before(fix, view.i, view.km_between, slope)
        if i_lb >= view.travel.n:
            return None  # the scan finds none
        if i_lb > view.i:
            return Observation(float(view.travel.t[i_lb]), Resume(scan))  # not read before then
        return scanned(scan)

    def _scan(self, fix: Fix, after_i: int, km_between: KmBetween) -> Scan:
        """:meth:`FeatureUnit.evaluation_scan` in time: read as the engine reaches it, from
        :meth:`FeatureUnit.evaluation_not_before` on (:meth:`next_observation`) — the same answer
        as read at once: the probe is dropped with the estimate, and under the same estimate the
        scan reads nothing else that changes but the unit's evaluated features, which only this
        aid's own evaluation (its one pending moment) adds to for a line table (the track aids'
        tables have no line code)."""
        t = self.unit.cycles.t
        scan = self.unit.evaluation_scan(fix, after_i, km_between, chunk=PROBE_CHUNK)
        while True:
            try:
                yield float(t[next(scan)])
            except StopIteration as stop:
                nxt: tuple[int, Candidate] | None = stop.value
                break
        return None if nxt is None else Observation(float(t[nxt[0]]), nxt[1])

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        if fix is None:
            return Outcome()
        out = self.unit.evaluate(obs.payload, fix, view.km_between, view.i)
        if out.detail.get("not_judged"):
            return Outcome()
        if not (out.accepted and out.i_ref is not None and out.km_db is not None):
            detail = {"feature_id": out.feature_id, "failed": out.failed, **out.detail}
            return Outcome([Event(view.t, EventType.FEATURE_REFUSED, view.km, detail=detail)])
        travel = view.travel
        s_ref, d_ref = float(travel.s[out.i_ref]), float(travel.d[out.i_ref])
        km_comp = view.km_at(s_ref)
        ev = Event(
            view.t,
            EventType.FEATURE_CORRECTION,
            out.km_db,
            km_comp - out.km_db,
            detail={"feature_id": out.feature_id, **out.detail},
        )
        new = Fix(
            view.t,
            s_ref,
            d_ref,
            out.km_db,
            out.km_db + (fix.km_equipment_m - fix.km_m),
            fix.line_code,
            fix.track,
            fix.k,
            FixSource.FEATURE,
            max(out.uncertainty_m or 0.0, self.unit.cfg.fix_uncertainty_m),
            t_ref=float(travel.t[out.i_ref]),
        )
        return Outcome([ev], new)
