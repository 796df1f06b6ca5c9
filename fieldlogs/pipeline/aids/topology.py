"""The topology aid: the estimate's candidate tracks carried along the network [SPEC §8.3].

The rules are in :mod:`fieldlogs.pipeline.hypotheses`; this aid applies them in the engine:

* an estimate set by a line-based aid (an S003 pair, a GPS decision, a C balise, a feature
  point: ``Fix.hyps`` empty, or its one candidate no longer where the fix says) is *placed*
  on the network track holding its line, track and km — the position is determined there; if
  it was ambiguous before, that is a ``track_resolved`` event naming the aid as evidence
  (an S003 pair beyond the innermost switch is decisive);
* :meth:`TopologyAid.next_observation` finds, vectorised over the cycles ahead, the first
  cycle at which a rule applies to a candidate (its point passing a joint, its margin reaching
  a facing switch, its interval leaving a track or passing a buffer stop), and there
  :meth:`TopologyAid.observe` applies the rules: ``switch_split`` events, candidates dropped
  (``hypothesis_dropped``; with none left the position is forgotten), merges.

The aid only exists on a DB with connections (its factory returns None otherwise), so a
line-only run is untouched.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.hypotheses import TrackLines, advance, rebased, triggers
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.types import Event, Fix, Hypothesis
from schemas.enums import EventType, PositionState

_LOCATE, _STEP = "locate", "step"
#: First window of the forward search [cycles] (doubled until a rule applies or the run ends).
_CHUNK = 512


def with_hyps(fix: Fix, hyps: list[Hypothesis], t: float, s: float, lines: TrackLines) -> Fix:
    """``fix`` carried to (t, s) with candidates ``hyps`` (pos at ``s``): one gives its track's
    line, track, km and k; several the state ambiguous with no line or km."""
    if len(hyps) > 1:
        nan = float("nan")
        return replace(
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
    return replace(
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

    def observations(self) -> list[Observation]:
        return []

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or fix.state == PositionState.UNDETERMINED or fix is self.unplaced:
            return None
        if not placed(fix, self.lines):
            return Observation(view.t, _LOCATE)
        self.previous = fix
        t = self._next_rule(fix, view)
        return None if t is None else Observation(t, _STEP)

    def _next_rule(self, fix: Fix, view: EngineView) -> float | None:
        tr = view.travel
        i0 = view.i + 1 if tr.t[view.i] <= view.t else view.i
        chunk = _CHUNK
        while i0 < tr.n:
            w = slice(i0, min(i0 + chunk, tr.n))
            m = margin_m(fix, tr.d[w], tr.allowance[w], self.margin)
            hit = np.zeros(w.stop - w.start, dtype=bool)
            for h in fix.hyps:
                hit |= triggers(h, h.pos_m + h.kp * (tr.s[w] - fix.s_ref), m, self.lines)
            if hit.any():
                return float(tr.t[i0 + int(np.argmax(hit))])
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
        self.next_id += 1
        h = Hypothesis(tl.track_id, pos, fix.k * tl.km_sign, hid=self.next_id)
        new = with_hyps(fix, [h], view.t, view.s, self.lines)
        events: list[Event] = []
        prev = self.previous
        if prev is not None and len(prev.hyps) > 1:
            events.append(self._resolved(view, prev.hyps, h, str(fix.source)))
        self.previous = new
        return Outcome(events, new)

    def _resolved(self, view: EngineView, before: tuple[Hypothesis, ...], h: Hypothesis, evidence: str) -> Event:
        split = [c.split_d for c in before if c.split_d is not None]
        detail: dict[str, Any] = {
            "evidence": evidence,
            "track_id": h.track_id,
            "candidates": [c.track_id for c in before],
            "after_switch_m": round(view.d - max(split), 2) if split else None,
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
        self.previous = new
        return Outcome(events, new)
