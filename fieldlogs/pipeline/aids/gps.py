"""GPS track decisions and crossovers as an aid [S001 §4.2, §7; SPEC §5.4].

The decisions and crossovers are computed vectorised over the whole run
(:func:`fieldlogs.pipeline.gps.analysis.analyse_gps`); this aid applies them to the estimate in
time order:

* **no estimate**: a decision with a known km direction sets a GPS-derived initial
  position (``gps.allow_initial``; uncertainty ``gps.initial_uncertainty_m``, source
  ``gps``) — k = km direction × cab; a decision taken while standing is reported and taken
  again at the first later trusted fix whose km has moved ``gps.km_dir_min_m``;
* **same track**: reported (``agrees``);
* **another track of the same line after a detected crossover**: the track changes; a
  balise-given track is only overruled in a fail-safe way — the new track is shown but the
  position is *uncertain* until the next initial pair confirms it (a false crossover must
  never give a determined wrong track); a GPS-given track simply changes;
* **another track without a crossover**: ``gps_track_disagrees``, the estimate is kept.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.types import Event, Fix, GpsAnalysis, TrackDecision
from schemas.enums import EventType, FixSource, PositionState


@dataclass(eq=False)
class GpsAid(StaticAid):
    """Up/down decisions and crossovers of one run's GPS analysis."""

    gps: GpsAnalysis
    cfg: GpsConfig
    antenna_x_m: float = 0.0
    """The GPS antenna's position forward of the vehicle's reference point [m]."""
    crossover_pending: bool = False
    name = "gps"
    priority = Priority.TRACK

    def observations(self) -> Iterator[Observation]:
        for dec in self.gps.decisions:
            yield Observation(dec.t, dec)
        for ev in self.gps.crossovers:
            yield Observation(ev.t, ev)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        if isinstance(obs.payload, Event):  # a crossover
            self.crossover_pending = True
            return Outcome([obs.payload])
        dec: TrackDecision = obs.payload
        fix = view.estimate
        if fix is None:
            return self._initial(dec, view)
        if dec.line_code == fix.line_code and dec.track != fix.track:
            return self._other_track(dec, fix, view)
        self.crossover_pending = False
        detail = {"line_code": dec.line_code, "track": dec.track, "agrees": True, **dec.evidence}
        return Outcome([Event(view.t, EventType.TRACK_DECISION, view.km, detail=detail)])

    def _initial(self, dec: TrackDecision, view: EngineView) -> Outcome:
        detail = {"line_code": dec.line_code, "track": dec.track, **dec.evidence}
        if self.cfg.allow_initial and dec.km_dir != 0:
            ev = Event(view.t, EventType.INITIAL_POSITION_GPS, dec.km_m, detail=detail)
            k = dec.km_dir * view.motion
            km = dec.km_m - k * self.antenna_x_m  # the fix is at the antenna (geometry.py)
            new = Fix(
                view.t,
                view.s,
                view.d,
                km,
                km,
                dec.line_code,
                dec.track,
                k,
                FixSource.GPS,
                self.cfg.initial_uncertainty_m,
                t_ref=view.t,
            )
            return Outcome([ev], new)
        ev = Event(view.t, EventType.TRACK_DECISION, dec.km_m, detail=detail)
        later = direction_evidence(self.gps, dec, self.cfg.km_dir_min_m) if self.cfg.allow_initial else None
        # standing at the decision: initialise once the km moves
        return Outcome([ev], follow_up=[Observation(later.t, later)] if later is not None else ())

    def _other_track(self, dec: TrackDecision, fix: Fix, view: EngineView) -> Outcome:
        if not self.crossover_pending:
            detail = {"track": fix.track, "gps_track": dec.track, **dec.evidence}
            return Outcome([Event(view.t, EventType.GPS_TRACK_DISAGREES, view.km, detail=detail)])
        gps_only = fix.source == FixSource.GPS
        detail = {"from": fix.track, "to": dec.track, "confirmed": gps_only, **dec.evidence}
        ev = Event(view.t, EventType.TRACK_CHANGE, view.km, detail=detail)
        new = replace(fix, t_effective=view.t, track=dec.track)
        if not gps_only:
            new = replace(new, state=PositionState.UNCERTAIN, uncertain_since_d=view.d)
        self.crossover_pending = False
        return Outcome([ev], new)


def direction_evidence(gps: GpsAnalysis, dec: TrackDecision, min_km_m: float) -> TrackDecision | None:
    """After a decision taken while standing (no km direction), the first later trusted fix
    on the decided track whose km differs from the decision's by ``min_km_m``: the decision
    again, at that time and km, with the direction the km moved in."""
    f = gps.fixes
    if f is None or len(f) == 0:
        return None
    track_col = "decided_track" if "decided_track" in f.columns else "track"
    ok = (f["t"].to_numpy(dtype=float) > dec.t) & f["trusted"].to_numpy(dtype=bool)
    ok &= (f[track_col].astype("string").fillna("") == dec.track).to_numpy(dtype=bool)
    km = f["km_m"].to_numpy(dtype=float, na_value=np.nan)
    moved = ok & np.isfinite(km) & (np.abs(km - dec.km_m) >= min_km_m)
    if not moved.any():
        return None
    j = int(np.argmax(moved))
    return replace(
        dec,
        t=float(f["t"].iloc[j]),
        km_m=float(km[j]),
        km_dir=1 if km[j] > dec.km_m else -1,
        evidence={**dec.evidence, "direction_from_t": dec.t},
    )
