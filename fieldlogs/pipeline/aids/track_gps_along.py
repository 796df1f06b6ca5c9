"""D-GPS fixes along the determined track: the distance along it corrected [SPEC §8.3; S001 §4.2].

On a network the margin decides how soon a claim turns ambiguous: a candidate whose interval
(pos ± margin) reaches over a joint or a facing switch lists the tracks beyond. Between balises
the margin grows with the travel (``margin.distance_pct``), so after a few hundred metres a
station's joints keep the position ambiguous for tens of metres each. S001's D-GPS is a
position, not only an up/down decision: this aid uses it along the one track the estimate is
determined on.

For a trusted fix (:mod:`fieldlogs.pipeline.gps.trust`; fix quality ≥ ``gps.min_fix``, D-GPS by
default) at travel S, the antenna's dead-reckoned distance along the candidate's track is
s_dr = pos + kp·(S − S_ref) + kp·x_a (x_a the antenna forward of the reference point); the fix
is projected on the centreline within s_dr ± (m + U + 20 m) (:meth:`TrackLine.project`): s_g
along, o across. The fix's error is the slow bias b (σ_b = ``gps.noise_sigma_m``) plus white
noise (σ_w = ``gps.noise_white_m``) in each axis, so along the track

    U = k·√(σ_b² + σ_w²) + e_map        (k = ``track_select.gps_along_k``, e_map = ``gps_along_map_m``)

with e_map the centreline's own along-track error. The fix is used only when

* it lies on this track: |o| ≤ U (a fix between two tracks or on the neighbour says nothing
  about the distance along this one);
* it closes a **steady chain**: ``gps_along_confirm`` fixes in a row on this track, at most
  ``gps.max_gap_s`` apart, each step agreeing with the odometry,
  |(s_g,i − s_g,i−1) − kp·(S_i − S_i−1)| ≤ ``gps_along_step_m``. Over one second the slow bias
  hardly moves (σ_b·√(2(1 − e^(−Δt/τ))) ≈ 0.08 m at τ = 180 s) and the white noise gives
  σ_w·√2 ≈ 0.35 m, so a larger step is a jump — multipath, a reflection near a station roof —
  whose error may then stay for seconds at a level the chain alone would not notice: after a
  jump no fix is used for ``gps.jump_hold_s`` (the trust filter's hold, here measured against
  the odometry instead of the fix's own history, which is far more sensitive);
* it agrees with the estimate: |s_g − s_dr| ≤ m + U (the innovation gate with both bounds; a
  fix outside is a multipath or a wrong estimate, and correcting to it could make the claim
  wrong — it is left out, the dead-reckoned margin keeps holding);
* it tightens the claim: m > ``gps_along_ratio``·U (a correction at every fix would fill the
  events without narrowing anything).

Then the candidate's pos becomes s_g − kp·x_a with margin U from here (a ``gps_correction``
event, source ``gps``; ``correction_m`` = s_dr − s_g).

**An uncertain position** (a slip or slide fail-safe, the IMU lost: the odometry's margin may
not hold) is corrected by the fix closing a steady chain gathered under it whose residuals
s_g − s_dr agree among themselves (spread ≤ U: the odometry carried the position consistently
between them) and that lies on this track on average (|mean o| ≤ ``gps.decide_max_mean_m``, the
up/down test's "not between two tracks"). Its error is then that of the fix, independent of the
odometry that failed: the position is *determined* again (detail ``confirmed_by_fixes``), as a
balise pair would make it. For this the aid reads every *usable* fix (quality, HDOP), not only
the trusted ones: the trust filter keeps a multipath burst's fixes out for its 30 s RMS window
and hold, during which the fail-safe would otherwise last (hundreds of metres), while the
confirmation carries its own checks against a burst — each step against the odometry (a larger
one holds every fix back for ``gps.jump_hold_s``), each fix on the track, the five residuals
within U of each other (a burst ramping on moves them apart) and on the track on average.

The aid only exists on a DB with connections and acts only on a determined (or uncertain) single
candidate, so line-only runs and ambiguous estimates are untouched (the offsets test of
:mod:`fieldlogs.pipeline.aids.track_gps` resolves those).
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.topology import with_hyps
from fieldlogs.pipeline.aids.track_gps import NetworkFixes
from fieldlogs.pipeline.config import GpsConfig, MarginConfig, TrackSelectConfig
from fieldlogs.pipeline.hypotheses import TrackLine
from fieldlogs.pipeline.positions import margin_at
from fieldlogs.pipeline.types import Event, Fix, FloatArray, Hypothesis, evolved
from schemas.enums import EventType, FixSource, PositionState

#: Search window beyond margin + U either way along the track [m].
_WINDOW_M = 20.0

#: The states the aid acts on (module docstring).
_ACTING = (PositionState.DETERMINED, PositionState.UNCERTAIN)


def along_uncertainty(cfg: TrackSelectConfig, gps: GpsConfig) -> float:
    """U of the module docstring [m]."""
    return cfg.gps_along_k * math.hypot(gps.noise_sigma_m, gps.noise_white_m) + cfg.gps_along_map_m


@dataclass(eq=False)
class TrackGpsAlongAid(NetworkFixes):
    """D-GPS corrections along the determined track (module docstring)."""

    margin: MarginConfig
    antenna_x_m: float = 0.0
    name: str = "track_gps_along"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    lane = True
    """Heard in the engine's lane (:mod:`fieldlogs.pipeline.aid`): it keeps no view past a call."""
    anchor: tuple[float, float] = (math.nan, math.nan)
    """(t_effective, s_ref) of the estimate the confirmation below was gathered under."""
    seen: list[tuple[float, float]] = field(default_factory=list)
    """(s_g − s_dr, o) of the fixes of the current chain under the current estimate."""
    last: tuple[float, float, float, str] | None = None
    """(t, S, s_g, track id) of the last fix on the track."""
    chain: int = 0
    """Fixes in a row on the track, each step agreeing with the odometry."""
    hold_until: float = -math.inf
    """No fix is used before this time (a jump was seen)."""
    usable: tuple[FloatArray, FloatArray, FloatArray] | None = None
    """(t, lat, lon) of every usable fix (quality, HDOP), trusted or not: an uncertain position
    is confirmed from these (module docstring)."""
    usable_planes: dict[tuple[float, float], tuple[list[float], list[float]]] = field(default_factory=dict, repr=False)
    """The usable fixes in each track's local plane, made on first use."""
    usable_t: list[float] = field(default_factory=list, repr=False)
    """Their times as a list (:meth:`NetworkFixes.fix_times`)."""
    basis: tuple[Fix, Hypothesis, TrackLine, list[float], list[float]] | None = field(default=None, repr=False)
    """(estimate, :meth:`_basis` of it) of the last fix heard."""

    @cached_property
    def along_u(self) -> float:
        """:func:`along_uncertainty` of the aid's settings."""
        return along_uncertainty(self.cfg, self.gps)

    def observations(self) -> list[Observation]:
        return []

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or len(fix.hyps) != 1:
            return None
        usable = self.usable is not None and fix.state == PositionState.UNCERTAIN
        if self.usable is not None and usable:
            if not self.usable_t and self.usable[0].size:
                self.usable_t.extend(self.usable[0].tolist())
            t = self.usable_t
        else:
            t = self.fix_times()
        j = bisect.bisect_right(t, view.t)
        return Observation(t[j], (j, usable)) if j < len(t) else None

    def _plane(self, tl: TrackLine, usable: bool) -> tuple[list[float], list[float]]:
        """The trusted (or usable) fixes in ``tl``'s local plane, each track's computed once."""
        if self.usable is None or not usable:
            return self.plane(tl)
        xy = self.usable_planes.get(tl.origin)
        if xy is None:
            x, y = tl.plane(self.usable[1], self.usable[2])
            xy = self.usable_planes[tl.origin] = (x.tolist(), y.tolist())
        return xy

    def _basis(self, fix: Fix, usable: bool) -> tuple[Hypothesis, TrackLine, list[float], list[float]]:
        """The estimate's one candidate, its track and the fixes in the track's plane
        (:meth:`_plane`): looked up once per estimate, not at each of its fixes (``usable``
        follows from the estimate's state, :meth:`next_observation`)."""
        if self.basis is None or self.basis[0] is not fix:
            h = fix.hyps[0]
            tl = self.lines[h.track_id]
            self.basis = (fix, h, tl, *self._plane(tl, usable))
        return self.basis[1:]

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        if fix is None or len(fix.hyps) != 1 or fix.state not in _ACTING:
            return Outcome()
        if (fix.t_effective, fix.s_ref) != self.anchor:
            self.anchor, self.seen = (fix.t_effective, fix.s_ref), []  # a new estimate: confirmation restarts
        h, tl, xs, ys = self._basis(fix, obs.payload[1])
        u = self.along_u
        m = margin_at(fix, view.d, view.travel.allowance_at(view.t), self.margin) + h.extra_m
        s_dr = h.pos_m + h.kp * (view.s - fix.s_ref) + h.kp * self.antenna_x_m
        j = obs.payload[0]
        s_g, off = tl.project(xs[j], ys[j], s_dr, m + u + _WINDOW_M)
        if not self._steady(view, h, s_g, off, s_dr, u, tl.length_m):
            return Outcome()
        uncertain = fix.state == PositionState.UNCERTAIN
        if not abs(s_g - s_dr) <= m + u:
            self.seen = []
            return Outcome()  # against the estimate: not used
        if not (self._confirmed(u) if uncertain else m > self.cfg.gps_along_ratio * u):
            return Outcome()
        pos = s_g - h.kp * self.antenna_x_m
        anchored = evolved(fix, d_ref=view.d, t_ref=view.t, uncertainty_m=u, source=FixSource.GPS)
        if uncertain:
            anchored = evolved(anchored, state=PositionState.DETERMINED, uncertain_since_d=None)
        new = evolved(
            with_hyps(anchored, [evolved(h, pos_m=pos, extra_m=0.0)], view.t, view.s, self.lines), carried=False
        )
        detail: dict[str, object] = {
            "evidence": "gps",
            "track_id": h.track_id,
            "offset_m": round(off, 3),
            "margin_before_m": round(m, 3),
            "uncertainty_m": round(u, 3),
        }
        if uncertain:
            detail["confirmed_by_fixes"] = len(self.seen)
        ev = Event(view.t, EventType.GPS_CORRECTION, new.km_m, correction_m=s_dr - s_g, detail=detail)
        return Outcome([ev], new)

    def _steady(
        self, view: EngineView, h: Hypothesis, s_g: float, off: float, s_dr: float, u: float, length: float
    ) -> bool:
        """Record the fix in the chain; whether it may be used: on the track (within its ends,
        |o| ≤ U), ``gps_along_confirm`` fixes in a row whose steps agree with the odometry
        (|Δs_g − kp·ΔS| ≤ ``gps_along_step_m``, at most ``gps.max_gap_s`` apart), and no jump
        within the last ``gps.jump_hold_s`` (module docstring)."""
        track_id, kp = h.track_id, h.kp
        on = 0.0 <= s_g <= length and abs(off) <= u
        prev, self.last = self.last, ((view.t, view.s, s_g, track_id) if on else None)
        if not on:
            self.chain, self.seen = 0, []
            return False
        linked = prev is not None and prev[3] == track_id and view.t - prev[0] <= self.gps.max_gap_s
        if prev is not None and linked:
            if abs((s_g - prev[2]) - kp * (view.s - prev[1])) > self.cfg.gps_along_step_m:
                self.hold_until = view.t + self.gps.jump_hold_s  # the fix jumped against the odometry
                linked = False
        if not linked:
            self.chain, self.seen = 0, []
        self.chain += 1
        self.seen.append((s_g - s_dr, off))
        return self.chain >= self.cfg.gps_along_confirm and view.t >= self.hold_until

    def _confirmed(self, u: float) -> bool:
        """The last ``gps_along_confirm`` fixes agree among themselves along the track (spread of
        s_g − s_dr ≤ U) and lie on this track on average (|mean offset| ≤ ``gps.decide_max_mean_m``)."""
        k = self.cfg.gps_along_confirm
        if len(self.seen) < k:
            return False  # the chain began under another estimate
        r = np.asarray(self.seen[-k:], dtype=float)
        return bool(np.ptp(r[:, 0]) <= u and abs(float(np.mean(r[:, 1]))) <= self.gps.decide_max_mean_m)
