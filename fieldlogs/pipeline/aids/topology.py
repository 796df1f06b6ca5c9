"""The topology aid: the estimate's candidate tracks carried along the network [SPEC §8.3].

The rules are in :mod:`fieldlogs.pipeline.hypotheses`; this aid applies them in the engine:

* an estimate set by a line-based aid (an S003 pair, a GPS decision, a C balise, a feature
  point: ``Fix.hyps`` empty, or its one candidate no longer where the fix says) is *placed*
  on the network track holding its line, track and km — the position is determined there; if
  it was ambiguous before, that is a ``track_resolved`` event naming the aid as evidence
  (an S003 pair beyond the innermost switch is decisive). A GPS or GNSS fix (``LINE_ONLY``)
  decided among the line's tracks only, so every other track within ``PARALLEL_M`` stays a
  candidate — except a GNSS correction of a position determined (or uncertain) on that very
  track, whose fit was constrained to it [S002] and says nothing about a parallel one;
* :meth:`TopologyAid.next_observation` finds, vectorised over the cycles ahead, the first
  cycle at which a rule applies to a candidate (its point passing a joint, its margin reaching
  a facing switch, its interval leaving a track or passing a buffer stop), and there
  :meth:`TopologyAid.observe` applies the rules: ``switch_split`` events, candidates dropped
  (``hypothesis_dropped``; with none left the position is forgotten), merges.

The aid only exists on a DB with connections (its factory returns None otherwise), so a
line-only run is untouched.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, Resume, Scan, scanned
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import (
    Segments,
    TrackLines,
    advance,
    after_switch_m,
    parallel_candidates,
    reachable,
    rebased,
    segments,
    triggers,
)
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.types import Event, Fix, Hypothesis, evolved
from schemas.enums import EventType, FixSource, PositionState

_LOCATE, _STEP = "locate", "step"
#: Sources that decide only among a line's tracks (S001 up/down, S002 on the decided track):
#: on a network they leave every track within ``PARALLEL_M`` a candidate.
LINE_ONLY = (FixSource.GPS, FixSource.GNSS)
#: Parallel tracks a line-based GNSS decision cannot have told apart [m] (Heirich 2016's radius).
PARALLEL_M = 20.0
#: First window of the forward search [cycles] (doubled until a rule applies or the run ends;
#: each after the first read once the engine reaches it).
_CHUNK = 64


def with_hyps(fix: Fix, hyps: list[Hypothesis], t: float, s: float, lines: TrackLines) -> Fix:
    """``fix`` carried to (t, s) with candidates ``hyps`` (pos at ``s``): one gives its track's
    line, track, km and k; several the state ambiguous with no line or km."""
    if len(hyps) > 1:
        nan = float("nan")
        return evolved(
            fix,
            t_effective=t,
            s_ref=s,
            km_m=nan,
            km_equipment_m=nan,
            line_code="",
            track="",
            state=PositionState.AMBIGUOUS,
            hyps=tuple(hyps),
            carried=True,
        )
    h = hyps[0]
    tl = lines[h.track_id]
    km = float(tl.km_of_pos(h.pos_m))
    off = fix.km_equipment_m - fix.km_m
    state = PositionState.UNCERTAIN if fix.uncertain_since_d is not None else PositionState.DETERMINED
    return evolved(
        fix,
        t_effective=t,
        s_ref=s,
        km_m=km,
        km_equipment_m=km + (off if np.isfinite(off) else 0.0),
        line_code=tl.line_code,
        track=tl.track,
        k=h.kp * tl.km_sign,
        state=state,
        hyps=(h,),
        carried=True,
    )


def _same_track(fix: Fix, prev: Fix | None, track_id: str) -> bool:
    """A raw-GNSS correction of a position determined (or uncertain) on that very track: the
    fit was constrained to the track in force [S002], so it moves the km along the track and
    says nothing for or against a parallel one — the single candidate is kept (re-opening the
    parallel tracks at every epoch would undo the raw-GNSS track test at every epoch)."""
    return (
        fix.source == FixSource.GNSS
        and prev is not None
        and prev.state in (PositionState.DETERMINED, PositionState.UNCERTAIN)
        and len(prev.hyps) == 1
        and prev.hyps[0].track_id == track_id
    )


def placed(fix: Fix, lines: TrackLines) -> bool:
    """The fix's candidates agree with what it says (a fix with several is its own truth)."""
    if len(fix.hyps) > 1:
        return True
    if len(fix.hyps) != 1:
        return False
    h = fix.hyps[0]
    tl = lines[h.track_id]
    if (tl.line_code, tl.track) != (fix.line_code, fix.track):
        return False
    if not tl.line_code:
        return True
    return bool(abs(float(tl.km_of_pos(h.pos_m)) - fix.km_m) < 0.01 and h.kp * tl.km_sign == fix.k)


@dataclass(eq=False)
class TopologyAid:
    """Candidates along the topology (module docstring)."""

    lines: TrackLines
    margin: MarginConfig
    name: str = "topology"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    next_id: int = 0
    previous: Fix | None = None
    """The last fix with candidates this aid saw (to report a resolution by another aid)."""
    unplaced: Fix | None = None
    """The last fix that lies on no network track (left as it is)."""
    segments: Segments | None = None
    """Every track's centreline in one plane (built at the first GPS placement)."""
    previous_d: float = 0.0
    """Unsigned travel d at which ``previous`` was in force (carried to)."""

    def observations(self) -> list[Observation]:
        return []

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or fix.state == PositionState.UNDETERMINED or fix is self.unplaced:
            return None
        if not placed(fix, self.lines):
            return Observation(view.t, _LOCATE)
        self._remember(fix, view.d)
        tr = view.travel
        i0 = view.i + 1 if tr.t[view.i] <= view.t else view.i
        i_lb = self.not_before(fix, i0, tr)
        if i_lb >= tr.n:
            return None  # the scan finds none
        scan = self._next_rule(fix, i0, tr)
        if i_lb > i0:
            return Observation(float(tr.t[i_lb]), Resume(scan))  # not read before then
        return scanned(scan)

    def not_before(self, fix: Fix, i0: int, tr: Travel) -> int:
        """A cycle the first rule from cycle ``i0`` on (:meth:`_next_rule`) is not before (the
        run's length: none). Every rule of :func:`~fieldlogs.pipeline.hypotheses.triggers`
        needs a candidate's point beyond an end of its track (past a joint, or past a buffer
        stop by its margin + extra, both ≥ 0); a point moves by |ΔS| ≤ Δd, so none applies on
        cycles with d < d(i0) + (the least distance of a point from its track's ends) − 1 m (the
        metre covers rounding). Read from the candidates and the travel only: the scan, whose
        answer depends on nothing else that changes under the same estimate, waits until then."""
        if i0 >= tr.n or fix.uncertainty_m < 0.0:
            return i0
        s0 = float(tr.s[i0])
        room = math.inf
        for h in fix.hyps:
            if h.extra_m < 0.0:
                return i0
            p = h.pos_m + h.kp * (s0 - fix.s_ref)
            room = min(room, p, self.lines[h.track_id].length_m - p)
        if not room > 1.0:  # NaN too
            return i0
        return int(np.searchsorted(tr.d, float(tr.d[i0]) + (room - 1.0), side="left"))

    def _next_rule(self, fix: Fix, i0: int, tr: Travel) -> Scan:
        """The first cycle from ``i0`` on where a candidate's interval reaches a rule of
        :func:`~fieldlogs.pipeline.hypotheses.triggers`, read in chunks of doubling length as
        the engine reaches them (:class:`~fieldlogs.pipeline.aid.Resume`)."""
        chunk, first = _CHUNK, i0
        while i0 < tr.n:
            if i0 > first:
                yield float(tr.t[i0])
            w = slice(i0, min(i0 + chunk, tr.n))
            m = margin_m(fix, tr.d[w], tr.allowance[w], self.margin)
            hit = np.zeros(w.stop - w.start, dtype=bool)
            for h in fix.hyps:
                hit |= triggers(h, h.pos_m + h.kp * (tr.s[w] - fix.s_ref), m, self.lines)
            if hit.any():
                return Observation(float(tr.t[i0 + int(np.argmax(hit))]), _STEP)
            i0, chunk = w.stop, chunk * 2
        return None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        if fix is None:
            return Outcome()
        if obs.payload == _LOCATE:
            return self._locate(fix, view)
        return self._step(fix, view)

    def _locate(self, fix: Fix, view: EngineView) -> Outcome:
        km = view.km
        hit = None if km is None or not fix.line_code else self.lines.locate(fix.line_code, fix.track, km)
        if hit is None:
            self.unplaced = fix
            return Outcome()
        tl, pos = hit
        prev = self.previous
        if prev is not None and prev.hyps and prev.state != PositionState.UNDETERMINED:
            refused = self._gate(fix, prev, tl.track_id, view)
            if refused is not None:
                return refused
        self.next_id += 1
        h = Hypothesis(tl.track_id, pos, fix.k * tl.km_sign, hid=self.next_id)
        hyps = [h]
        if fix.source in LINE_ONLY and not _same_track(fix, prev, tl.track_id):
            if self.segments is None:
                self.segments = segments(self.lines)
            hyps += parallel_candidates(h, PARALLEL_M, self.lines, self.segments)
            for j in range(1, len(hyps)):
                self.next_id += 1
                hyps[j] = replace(hyps[j], hid=self.next_id)
        new = with_hyps(fix, hyps, view.t, view.s, self.lines)
        events: list[Event] = []
        if prev is not None and len(prev.hyps) > 1 and len(hyps) == 1:
            events.append(self._resolved(view, prev.hyps, h, str(fix.source)))
        self._remember(new, view.d)
        return Outcome(events, new)

    def _remember(self, fix: Fix, d: float) -> None:
        if fix is not self.previous:
            self.previous, self.previous_d = fix, d

    def _gate(self, fix: Fix, prev: Fix, track_id: str, view: EngineView) -> Outcome | None:
        """None when ``track_id`` is reachable from ``prev``'s candidates within the travel since
        and the margin (:func:`~fieldlogs.pipeline.hypotheses.reachable`); otherwise the refusal:
        ``prev``'s candidates carried to now stay in force, a ``track_change_refused`` event."""
        m = float(margin_m(prev, view.d, view.travel.allowance_at(view.t), self.margin))
        hyps = rebased(prev.hyps, prev.s_ref, view.s)
        if track_id in reachable(hyps, abs(view.d - self.previous_d) + m, self.lines):
            return None
        hyps, _, self.next_id = advance(hyps, m, view.d, self.lines, self.next_id)
        detail: dict[str, Any] = {
            "evidence": str(fix.source),
            "track_id": track_id,
            "candidates": [h.track_id for h in prev.hyps],
            "reason": "no navigable path from the candidates within the travel and the margin",
        }
        events = [Event(view.t, EventType.TRACK_CHANGE_REFUSED, view.km, detail=detail)]
        if not hyps:
            self.previous = None
            return Outcome(events, forget=True)
        new = with_hyps(prev, hyps, view.t, view.s, self.lines)
        self._remember(new, view.d)
        return Outcome(events, new)

    def _resolved(self, view: EngineView, before: tuple[Hypothesis, ...], h: Hypothesis, evidence: str) -> Event:
        detail: dict[str, Any] = {
            "evidence": evidence,
            "track_id": h.track_id,
            "candidates": [c.track_id for c in before],
            "after_switch_m": after_switch_m(before, view.d),
            "switch_id": next((c.switch_id for c in before if c.switch_id), None),
        }
        return Event(view.t, EventType.TRACK_RESOLVED, view.km, detail=detail)

    def _step(self, fix: Fix, view: EngineView) -> Outcome:
        m = float(margin_m(fix, view.d, view.travel.allowance_at(view.t), self.margin))
        hyps, ch, self.next_id = advance(rebased(fix.hyps, fix.s_ref, view.s), m, view.d, self.lines, self.next_id)
        events = [
            Event(view.t, EventType.SWITCH_SPLIT, None, detail={"switch_id": sw, "from": a, "candidates": to})
            for sw, a, to in ch.splits
        ]
        events += [
            Event(view.t, EventType.HYPOTHESIS_DROPPED, None, detail={"track_id": tid, "reason": why})
            for tid, why in ch.drops
        ]
        if not hyps:
            self.previous = None
            return Outcome(events, forget=True)
        if len(fix.hyps) > 1 and len(hyps) == 1:
            events.append(self._resolved(view, fix.hyps, hyps[0], "topology"))
        new = with_hyps(fix, hyps, view.t, view.s, self.lines)
        self._remember(new, view.d)
        return Outcome(events, new)
