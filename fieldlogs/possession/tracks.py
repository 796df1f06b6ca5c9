"""The wrong-track rule among n tracks: possessions on any track of a network (a station's
track 3 of four, a crossover) against the tracks the onboard unit claimed [S001 §3.1(e),
§4.2, §7; SPEC §8].

The up/down rule of :mod:`fieldlogs.possession.alarms` tells two tracks apart by the GPS
offset from a line's midline; it cannot say which of a station's four tracks a vehicle is
on. Where the plan names the possessed track (``track_id``), the run's positions from the
hypothesis engine (:mod:`fieldlogs.pipeline`: state ``determined`` on one ``track_id``, or
``ambiguous`` with the candidate tracks) are judged stretch by stretch
(:func:`fieldlogs.audit.track_path.track_path`), each at its first cycle, against the
tracks *allowed* then: the ``track_id`` of every possession started and not released at
that moment (:meth:`~fieldlogs.possession.plan.Possession.state_at`), plus every track
that is a *crossover between possessed tracks* — a track of kind ``crossover`` not
possessed itself whose two ends both join possessed tracks by a navigable connection
(:func:`dbtools.topology.topology`), the U → crossover → D ride of S001 §7 between two
possessed tracks.

* determined on an allowed track: nothing; on a crossover between possessed tracks: the
  ``crossover`` notice (the ride is recognised, no alarm);
* determined on any other track: the ``wrong_track`` alarm [S001 §3.1(e)];
* ambiguous, every candidate allowed: nothing (whichever it is, it is right);
* ambiguous, some candidate allowed and some not: the ``track_unconfirmed`` notice — not an
  alarm. This is the fail-safe reading of S001 §4.2: the paper's device does not decide a
  track before its evidence reaches 1:1000, and warns the worker meanwhile (its
  ``track_undecided`` notice); a wrong-track *alarm* on a guess would cry wolf at every
  facing switch. The alarm follows as soon as the unit determines a track that is not
  allowed;
* ambiguous, no candidate allowed: the ``wrong_track`` alarm (whichever track it is, it is
  wrong).

No possession started at that moment allows nothing, so every positioned stretch then
raises the alarm (the ``not_started`` alarm of the km rules says why).
"""

from __future__ import annotations

import json
from datetime import datetime, timedelta
from typing import Any

import pandas as pd

from dbtools.topology import BEGIN, END, Topology
from fieldlogs.audit.track_path import track_path
from fieldlogs.possession.plan import Possession, PossessionState
from fieldlogs.possession.results import Alarm, wall
from schemas.enums import AlarmType, Navigability, NoticeType, PositionState, TrackKind


def possessed_at(possessions: list[Possession], when: datetime) -> dict[str, str]:
    """track_id → work number of every possession with a track_id started at ``when``
    (the lowest work number where two possess the same track)."""
    out: dict[str, str] = {}
    for p in sorted(possessions, key=lambda p: p.work_no):
        if p.track_id is not None and p.state_at(when) == PossessionState.STARTED:
            out.setdefault(p.track_id, p.work_no)
    return out


def crossover_between(topo: Topology, track_id: str, possessed: dict[str, str]) -> list[str] | None:
    """The possessed tracks joined at the two ends of the crossover ``track_id`` (sorted) when
    both ends join a possessed track by a navigable connection; None otherwise (and for any
    track that is not a crossover)."""
    if track_id not in _crossovers(topo):
        return None
    ends = []
    for end in (BEGIN, END):
        links = topo.joined.get((track_id, end), [])
        joined = sorted({t for t, _, nav in links if t in possessed and nav != Navigability.NONE.value})
        if not joined:
            return None
        ends += joined
    return sorted(set(ends))


def _crossovers(topo: Topology) -> frozenset[str]:
    kind = topo.tracks["kind"].astype(str) == TrackKind.CROSSOVER.value
    return frozenset(str(t) for t in topo.tracks.loc[kind, "track_id"])


def track_alarms(
    positions: pd.DataFrame, possessions: list[Possession], start: datetime, topo: Topology
) -> tuple[list[Alarm], list[Alarm]]:
    """(alarms, notices) of the rule among n tracks over a run's positions (module docstring);
    only possessions with a ``track_id`` take part."""
    own = [p for p in possessions if p.track_id is not None]
    alarms: list[Alarm] = []
    notices: list[Alarm] = []
    if not own:
        return alarms, notices
    for r in track_path(positions).to_dict("records"):
        t = float(r["t_from"])
        possessed = possessed_at(own, start + timedelta(seconds=t))
        work = next(iter(sorted(possessed.values())), None)
        if r["state"] == PositionState.DETERMINED.value:
            tid = str(r["track_id"])
            if tid in possessed:
                continue
            between = crossover_between(topo, tid, possessed)
            if between is not None:
                ev: dict[str, Any] = {"track_id": tid, "between": between, "possessed": sorted(possessed)}
                notices.append(Alarm(NoticeType.CROSSOVER, t, wall(start, t), None, tid, possessed[between[0]], ev))
            else:
                ev = {"track_id": tid, "possessed": sorted(possessed), "until_t": float(r["t_to"])}
                alarms.append(Alarm(AlarmType.WRONG_TRACK, t, wall(start, t), None, tid, work, ev))
            continue
        cands = [str(c) for c in json.loads(r["candidates"] or "[]")]
        allowed = [c for c in cands if c in possessed or crossover_between(topo, c, possessed) is not None]
        ev = {"candidates": cands, "possessed": sorted(possessed), "until_t": float(r["t_to"])}
        if not allowed:
            alarms.append(Alarm(AlarmType.WRONG_TRACK, t, wall(start, t), None, None, work, ev))
        elif len(allowed) < len(cands):
            notices.append(Alarm(NoticeType.TRACK_UNCONFIRMED, t, wall(start, t), None, None, work, ev))
    return alarms, notices
