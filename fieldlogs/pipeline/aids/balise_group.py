"""ETCS balise groups as an aid: decisive evidence of the track [SPEC §8.2, §8.3; SUBSET-026 §3.4].

A telegram of kind ``G`` names its group (NID_C, NID_BG) and the balise's place in it (N_PIG);
the DB's ``balises`` rows of that group give its track and km, so one read is an absolute fix
on a known track:

* **with candidates** (:mod:`fieldlogs.pipeline.hypotheses`): the candidate on the group's
  track is kept, placed at the balise (the reader's offset taken off), every other one dropped
  (``track_resolved``, evidence ``balise_group``, when several remained); a group on none of the
  candidates' tracks contradicts the estimate: ``balise_anomaly`` and the position is forgotten
  (fail-safe: no claim rather than a wrong one);
* **without an estimate**: two balises of one group read within ``balise.pair_max_travel_m``
  give the direction — the order of N_PIG against the order of their positions on the track —
  and set the initial position (``initial_position``).

A group on a track off a line (a crossover: no line km) is placed by the km of the track's
own ``track_points``, as the DB's balise rules place it (:func:`balise_pos`): the km interpolated
between the points' (km, pos) pairs, within 1 m of their km range.

Its uncertainty is the balise aid's: ``balise.fix_uncertainty_m`` + ``balise.latency_budget_s``
× speed. Groups not in the DB are reported (``balise_anomaly``) and change nothing.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.aids.balise import Telegram, telegram_observations
from fieldlogs.pipeline.aids.topology import with_hyps
from fieldlogs.pipeline.config import BaliseConfig
from fieldlogs.pipeline.hypotheses import TrackLine, TrackLines, after_switch_m
from fieldlogs.pipeline.types import Event, Fix, Hypothesis
from schemas.enums import BaliseKind, EventType, FixSource

GroupKey = tuple[int, int]


def group_table(net: Network) -> dict[GroupKey, dict[int, tuple[str, float]]]:
    """(NID_C, NID_BG) → N_PIG → (track_id, km) of the DB's G balises."""
    b = net.balises
    b = b[b["kind"] == BaliseKind.G.value]
    out: dict[GroupKey, dict[int, tuple[str, float]]] = {}
    cols = ("nid_c", "nid_bg", "n_pig", "track_id", "km_actual_m")
    for c, g, p, tid, km in zip(*(b[k].tolist() for k in cols), strict=True):
        if pd.notna(c) and pd.notna(g) and pd.notna(p) and pd.notna(tid):
            out.setdefault((int(c), int(g)), {})[int(p)] = (str(tid), float(km))
    return out


def balise_pos(tl: TrackLine, km: float) -> float:
    """pos of a balise at ``km`` on track ``tl``: along its line (:meth:`TrackLine.pos_of_km`);
    off a line by the track points' km, pos = interp(km; km_j, pos_j) within 1 m of their km range
    (:func:`dbtools.rules.balise_groups.locate`); NaN where neither places it."""
    pos = tl.pos_of_km(km)
    if np.isfinite(pos) or tl.km.size < 2:
        return pos
    k, p = tl.by_km
    if not (np.all(np.diff(k) > 0) and k[0] - 1.0 <= km <= k[-1] + 1.0):
        return float("nan")
    return float(np.interp(km, k, p))


@dataclass
class _Read:
    key: GroupKey
    pig: int
    d: float
    s: float


@dataclass(eq=False)
class BaliseGroupAid(StaticAid):
    """ETCS group telegrams in time order (module docstring)."""

    groups: dict[GroupKey, dict[int, tuple[str, float]]]
    lines: TrackLines
    cfg: BaliseConfig
    telegrams: Sequence[Telegram] = field(repr=False)
    """The run's telegrams of every kind (:func:`~fieldlogs.pipeline.aids.balise.telegram_rows`): the aid hears G."""
    reader_x_m: float = 0.0
    last: _Read | None = None
    name = "balise_group"
    priority = Priority.TELEGRAM

    def observations(self) -> Iterator[Observation]:
        return telegram_observations(self.telegrams, lambda row: row["kind"] == BaliseKind.G)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        tel: dict[str, Any] = obs.payload
        if tel.get("nid_c") is None or tel.get("nid_bg") is None:
            return Outcome([Event(view.t, EventType.BALISE_ANOMALY, view.km, detail={"reason": "G without NID"})])
        key = (int(tel["nid_c"]), int(tel["nid_bg"]))
        pig = int(tel["n_pig"]) if tel.get("n_pig") is not None else 0
        group = self.groups.get(key)
        if group is None or pig not in group:
            why = "balise group not in DB" if group is None else f"N_PIG {pig} not in the group"
            detail = {"reason": why, "group": f"{key[0]}:{key[1]}"}
            return Outcome([Event(view.t, EventType.BALISE_ANOMALY, view.km, detail=detail)])
        last, self.last = self.last, _Read(key, pig, view.d, view.s)
        fix = view.estimate
        if fix is None:
            return self._initial(last, key, pig, view)
        if not fix.hyps:
            return Outcome()
        return self._select(fix, key, group[pig], view)

    def _u(self, view: EngineView) -> float:
        return self.cfg.fix_uncertainty_m + self.cfg.latency_budget_s * float(view.travel.v[view.i])

    def _fix(self, h: Hypothesis, view: EngineView) -> Fix:
        """An absolute fix on candidate ``h`` (pos at the present travel)."""
        nan = float("nan")
        new = Fix(view.t, view.s, view.d, nan, nan, "", "", 1, FixSource.BALISE, self._u(view), t_ref=view.t)
        return replace(with_hyps(new, [h], view.t, view.s, self.lines), carried=False)

    def _initial(self, last: _Read | None, key: GroupKey, pig: int, view: EngineView) -> Outcome:
        if last is None or last.key != key or last.pig == pig or view.d - last.d > self.cfg.pair_max_travel_m:
            return Outcome()
        (t0, _k0), (t1, k1) = self.groups[key][last.pig], self.groups[key][pig]
        tl = self.lines[t1]
        p0, p1 = balise_pos(tl, self.groups[key][last.pig][1]), balise_pos(tl, k1)
        ds = view.s - last.s
        if t0 != t1 or not np.isfinite(p1 - p0) or p1 == p0 or ds == 0:
            return Outcome()
        kp = int(np.sign(p1 - p0) * np.sign(ds))
        h = Hypothesis(t1, p1 - kp * self.reader_x_m, kp)
        new = self._fix(h, view)
        detail = {"group": f"{key[0]}:{key[1]}", "track_id": t1}
        return Outcome([Event(view.t, EventType.INITIAL_POSITION, new.km_m, detail=detail)], new)

    def _select(self, fix: Fix, key: GroupKey, where: tuple[str, float], view: EngineView) -> Outcome:
        tid, km = where
        group = f"{key[0]}:{key[1]}"
        on = [h for h in fix.hyps if h.track_id == tid]
        names = [h.track_id for h in fix.hyps]
        if not on:
            why = {"reason": "balise group on none of the candidate tracks", "group": group, "candidates": names}
            return Outcome([Event(view.t, EventType.BALISE_ANOMALY, view.km, detail=why)], forget=True)
        h = on[0]
        pos = balise_pos(self.lines[tid], km)
        if not np.isfinite(pos):
            return Outcome()
        new = self._fix(replace(h, pos_m=pos - h.kp * self.reader_x_m, extra_m=0.0), view)
        events: list[Event] = []
        if len(fix.hyps) > 1:
            detail: dict[str, Any] = {
                "evidence": "balise_group",
                "group": group,
                "track_id": tid,
                "candidates": names,
                "after_switch_m": after_switch_m(fix.hyps, view.d),
                "switch_id": h.switch_id,
            }
            events.append(Event(view.t, EventType.TRACK_RESOLVED, new.km_m, detail=detail))
        return Outcome(events, new)
