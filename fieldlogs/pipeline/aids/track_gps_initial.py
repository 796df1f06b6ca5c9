"""An initial position on a network from D-GPS fixes: every track near them a candidate [SPEC §8.3; S001 §4.2].

Without a position, the line's GPS aid (:mod:`fieldlogs.pipeline.aids.gps`) starts one only from
an up/down decision between the line's two tracks; a train standing in a station on track 3 or
in a siding is on neither, and stays undetermined until a balise pair. On a network the fixes
can start the position themselves, among the network's own tracks, without deciding anything:

* a **steady chain** of ``track_select.gps_along_confirm`` trusted fixes, at most
  ``gps.max_gap_s`` apart, each step's length agreeing with the odometry's
  (| |p_i − p_i−1| − |S_i − S_i−1| | ≤ ``gps_along_step_m``; no track is known yet, so the
  plane distance is compared), whose last ``gps_along_confirm`` fixes span at least
  ``gps.km_dir_min_m`` of travel and move one way throughout — every step of S of one sign,
  every step of the fixes forward along their net displacement — so that the direction is seen
  (a chain through a standstill or a rollback the odometry counted forward would give it
  wrongly);
* **on a track**: the last fix lies within U of some centreline (U below); otherwise the train
  is on none the DB knows (an unmapped siding) and nothing is started;
* **candidates**: every track whose centreline passes within 20 m (Heirich's parallel radius,
  the same as for a line-based GPS decision placed on the network) of the last fix, at the
  nearest point inside it (not at one of its ends: a continuation beyond a joint is not
  another track), each at distance s − kp·x_a along it (x_a the antenna forward of the
  reference point) with uncertainty U (:func:`fieldlogs.pipeline.aids.track_gps_along.along_uncertainty`);
* **direction**: those fixes' displacement D = p_last − p_first against the candidate's tangent t
  (toward its end) and the signed travel ΔS over them: kp = sign(D·t)·sign(ΔS).

The position is ``ambiguous`` among those candidates (one alone: determined), an
``initial_position_gps`` event with ``detail.evidence`` = ``network`` and the candidates; the
GPS offsets test (:mod:`fieldlogs.pipeline.aids.track_gps`) then decides among them with their
true centrelines, as after a facing switch. Nothing is claimed that the fixes cannot tell
apart. ``gps.allow_initial`` = false switches it off, as it does the line's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.topology import PARALLEL_M, with_hyps
from fieldlogs.pipeline.aids.track_gps import NetworkFixes
from fieldlogs.pipeline.aids.track_gps_along import along_uncertainty
from fieldlogs.pipeline.hypotheses import Segments, equirect, segments
from fieldlogs.pipeline.types import Event, Fix, Hypothesis
from schemas.enums import EventType, FixSource

#: Keep the nearest point this far inside a candidate's ends [m] (as parallel_candidates does;
#: :meth:`~fieldlogs.pipeline.hypotheses.Segments.nearest` finds it).
_INSIDE_M = 0.5


@dataclass(eq=False)
class TrackGpsInitialAid(NetworkFixes):
    """The initial position among the network's tracks (module docstring)."""

    antenna_x_m: float = 0.0
    name: str = "track_gps_initial"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    chain: list[tuple[float, float, float, float]] | None = None
    """(t, S, x, y) of the current steady chain."""
    seg: Segments | None = None
    next_hid: int = -1
    """Lineage ids of the candidates started here (negative: apart from the topology aid's)."""

    def observations(self) -> list[Observation]:
        return [Observation(float(t), j) for j, t in enumerate(self.t)] if self.gps.allow_initial else []

    def next_observation(self, view: EngineView) -> Observation | None:
        return None

    def idle(self, obs: Observation, estimate: Fix | None) -> bool:
        """With an estimate in force and no chain, a moment only drops the chain it has not got."""
        return estimate is not None and self.chain is None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        if view.estimate is not None:
            self.chain = None
            return Outcome()
        if self.seg is None:
            self.seg = segments(self.lines)
        j: int = obs.payload
        (x,), (y,) = equirect(self.seg.origin, self.lat[j : j + 1], self.lon[j : j + 1])
        prev = self.chain[-1] if self.chain else None
        steady = (
            prev is not None
            and view.t - prev[0] <= self.gps.max_gap_s
            and abs(math.hypot(x - prev[2], y - prev[3]) - abs(view.s - prev[1])) <= self.cfg.gps_along_step_m
        )
        self.chain = [*(self.chain or []), (view.t, view.s, x, y)] if steady else [(view.t, view.s, x, y)]
        if len(self.chain) < self.cfg.gps_along_confirm:
            return Outcome()
        last = np.asarray(self.chain[-self.cfg.gps_along_confirm :], dtype=float)
        dx, dy, ds = last[-1, 2] - last[0, 2], last[-1, 3] - last[0, 3], last[-1, 1] - last[0, 1]
        steps = np.diff(last, axis=0)
        if abs(ds) < self.gps.km_dir_min_m or not (
            (steps[:, 1] * ds > 0.0).all() and (steps[:, 2] * dx + steps[:, 3] * dy > 0.0).all()
        ):
            return Outcome()  # standing, or not moving one way throughout: the direction is not seen
        return self._start(view, dx, dy, ds, x, y)

    def _start(self, view: EngineView, dx: float, dy: float, ds: float, x: float, y: float) -> Outcome:
        assert self.seg is not None
        near = self.seg.nearest(x, y, PARALLEL_M)
        u = along_uncertainty(self.cfg, self.gps)
        if not near or min(n[2] for n in near) > u:
            return Outcome()  # on no track of the DB (an unmapped siding?): nothing to claim
        hyps: list[Hypothesis] = []
        for j, pos, _dist, tx, ty in near:
            tl = self.lines[self.seg.ids[j]]
            kp = (1 if dx * tx + dy * ty >= 0.0 else -1) * (1 if ds > 0 else -1)
            p = pos - kp * self.antenna_x_m
            if _INSIDE_M < pos < tl.length_m - _INSIDE_M:
                hyps.append(Hypothesis(tl.track_id, p, kp, hid=self.next_hid))
                self.next_hid -= 1
        if not hyps:
            return Outcome()
        nan = math.nan
        seed = Fix(view.t, view.s, view.d, nan, nan, "", "", 1, FixSource.GPS, u, t_ref=view.t)
        new = replace(with_hyps(seed, hyps, view.t, view.s, self.lines), carried=False)
        detail = {"evidence": "network", "candidates": [h.track_id for h in hyps], "fixes": len(self.chain or [])}
        self.chain = None
        return Outcome([Event(view.t, EventType.INITIAL_POSITION_GPS, new.km_m, detail=detail)], new)
