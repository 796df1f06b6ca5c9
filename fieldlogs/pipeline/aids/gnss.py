"""Track-constrained GNSS from raw pseudoranges as an aid [S002; SPEC §5.6].

The run's ``gnss_obs`` + ``gnss_nav`` are positioned on the GIS grid of a known line/track
(the 3-D polyline of lat/lon/height, :mod:`fieldlogs.gnss.gis`), every epoch at once and without
a prior (:func:`fieldlogs.gnss.ontrack.solve_on_track`; solutions per (line, track, facing) are
computed the first time the engine needs them). The antennas sit where the vehicle block puts
them; x points toward increasing km when the estimate's k = +1 (km grows toward the F end).
At every epoch (an observation of the engine) with the estimate in force:

* **correction**: the epoch's along-track uncertainty U (``ontrack``: the best receiver) is
  below the current margin m (:func:`fieldlogs.pipeline.positions.margin_m` of the estimate at
  that time) by at least ``gnss.correction_gain_m``, and the two agree, |km_GNSS − km_est| ≤ m
  + U (else one of them is wrong and neither is believed: ``gnss_refused``, once per stretch
  of disagreeing epochs). The new estimate is the GNSS km with uncertainty U, source ``gnss``;
  its event carries the correction amount km_est − km_GNSS. GNSS is not an absolute fix for the
  position-correction % (:attr:`schemas.enums.FixSource.absolute`), which keeps measuring the
  wheel between balises. An *uncertain* estimate stays uncertain (its doubt may be the track,
  which the constrained solution presupposes), with its growth restarted at the correction;
* **track evidence**: when the fits on another track of the same line are far better over the
  last ``gnss.track_window_s`` (:class:`fieldlogs.gnss.ontrack.TrackEvidence`), the aid reports
  ``gnss_track_disagrees`` once and makes no correction while it lasts: evidence for the up/down
  decision, never a decision — the track is never changed here;
* **initial position** (``gnss.allow_initial``), when nothing has set one: the track must be
  known, from the latest GPS up/down decision of the current on-track period (a balise pair
  would have set a position itself), and not contradicted by the fits on the other track. The
  km direction k comes from the motion: an earlier epoch of the same receiver at least
  ``gnss.direction_min_travel_m`` of travel away whose km differs by more than both
  uncertainties, consistently with the travel (|Δkm| within U_i + U_j + 2 % of |ΔS| of |ΔS|),
  gives k = sign(Δkm/ΔS). The epoch's U must be ≤ ``gnss.initial_max_uncertainty_m``; the
  position is flagged (``initial_position_gnss``, source ``gnss``) with U as its uncertainty.

The aid refuses to run on a track whose GIS grid cannot carry it (no heights, heights partly
empty, orthometric heights) and on a run whose GNSS part cannot be positioned (no
ephemerides, a receiver without an antenna): one ``gnss_refused`` notice each, no correction.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from dbtools.network import Network
from fieldlogs.gnss.config import GnssConfig, position_config
from fieldlogs.gnss.gis import GnssTrackError, gis_track, points_track
from fieldlogs.gnss.ontrack import TrackEvidence, TrackSolutions, solve_on_track
from fieldlogs.gnss.runinputs import GnssInputError, RunGnss, run_gnss
from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.types import Event, Fix, GpsAnalysis
from fieldlogs.runs.handle import Run
from schemas.enums import EventType, FixSource, PositionState


@dataclass(eq=False)
class GnssUnit:
    """The run's GNSS inputs and its solutions per (line, track, facing), computed on demand."""

    network: Network = field(repr=False)
    cfg: GnssConfig
    inputs: RunGnss | None = field(repr=False)
    problem: GnssInputError | None = None
    """Why the run's GNSS part cannot be positioned (the aid reports it once)."""
    _solutions: dict[tuple[str, str, int], TrackSolutions | GnssTrackError] = field(default_factory=dict, repr=False)
    _evidence: dict[tuple[str, str, int], list[TrackEvidence]] = field(default_factory=dict, repr=False)

    @classmethod
    def for_run(cls, run: Run, network: Network, cfg: GnssConfig) -> GnssUnit:
        """The run's unit; without gnss_obs (or with the aid switched off) it has no epochs, like
        the GPS analysis of a run without GPS."""
        if not cfg.enabled or not run.has("gnss_obs"):
            return cls(network, cfg, None)
        try:
            return cls(network, cfg, run_gnss(run))
        except GnssInputError as exc:
            return cls(network, cfg, None, exc)

    def epoch_times(self) -> np.ndarray:
        return self.inputs.epoch_times if self.inputs is not None else np.zeros(0)

    def solutions(self, line_code: str, track: str, direction: int) -> TrackSolutions | GnssTrackError:
        """The run's solutions on a track for a facing (cached), or why there are none; with
        ``line_code`` empty, ``track`` is a network track id fitted on its ``track_points``
        (:func:`fieldlogs.gnss.gis.points_track`)."""
        key = (line_code, track, direction)
        if key not in self._solutions:
            assert self.inputs is not None
            try:
                gt = gis_track(self.network, line_code, track) if line_code else points_track(self.network, track)
                self._solutions[key] = solve_on_track(self.inputs, gt, direction, position_config(self.cfg))
            except GnssTrackError as exc:
                self._solutions[key] = exc
        return self._solutions[key]

    def other_track_better(self, this: TrackSolutions, t: float) -> str | None:
        """Another track of the line whose fits are far better up to ``t`` (``ontrack``), if any."""
        key = (this.line_code, this.track, this.direction)
        if key not in self._evidence:
            g = self.network.gis
            tracks = sorted(set(g.loc[g["line_code"] == this.line_code, "track"].astype(str)) - {this.track})
            others = [self.solutions(this.line_code, tr, this.direction) for tr in tracks]
            self._evidence[key] = [TrackEvidence.between(this, o) for o in others if isinstance(o, TrackSolutions)]
        c = self.cfg
        for ev in self._evidence[key]:
            if ev.far_better(t, c.track_window_s, c.track_min_epochs, c.track_chi2, c.track_share):
                return ev.other_track
        return None


@dataclass(eq=False)
class GnssAid(StaticAid):
    """Epochs of the run's GNSS solutions as observations (module docstring)."""

    unit: GnssUnit
    margin: MarginConfig
    gps: GpsAnalysis | None = None
    name = "gnss"
    priority = Priority.TRACK
    _notified: set[tuple[str, ...]] = field(default_factory=set)
    _refusing: bool = False
    _disagreeing: bool = False

    def observations(self) -> Iterator[Observation]:
        times = self.unit.epoch_times()
        if self.unit.problem is not None:  # reported once, at the start of the run
            yield Observation(0.0, "problem")
            return
        for k, t in enumerate(times):
            yield Observation(float(t), k)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        if obs.payload == "problem":
            exc = self.unit.problem
            assert exc is not None
            return Outcome(
                [Event(view.t, EventType.GNSS_REFUSED, detail={"reason": exc.reason, "message": exc.message})]
            )
        fix = view.estimate
        if fix is None:
            return self._initial(int(obs.payload), view)
        if fix.state == PositionState.AMBIGUOUS:
            return Outcome()  # no line track to constrain to (network candidates: the track aids)
        sols = self._solutions(fix.line_code, fix.track, fix.k, view)
        if not isinstance(sols, TrackSolutions):
            return sols
        row = sols.at(int(obs.payload))
        if row is None:
            return Outcome()
        other = self.unit.other_track_better(sols, view.t)
        if other is not None:
            return self._disagrees(fix.track, other, view)
        self._disagreeing = False
        return self._correct(fix, row, view)

    # -- helpers --------------------------------------------------------------------------
    def _solutions(self, line_code: str, track: str, k: int, view: EngineView) -> TrackSolutions | Outcome:
        sols = self.unit.solutions(line_code, track, 1 if k >= 0 else -1)
        if isinstance(sols, TrackSolutions):
            return sols
        key = (line_code, track, sols.reason)
        if key in self._notified:
            return Outcome()
        self._notified.add(key)
        detail = {"reason": sols.reason, "line_code": line_code, "track": track, "message": sols.message}
        return Outcome([Event(view.t, EventType.GNSS_REFUSED, view.km, detail=detail)])

    def _disagrees(self, track: str, other: str, view: EngineView) -> Outcome:
        if self._disagreeing:
            return Outcome()
        self._disagreeing = True
        detail = {"track": track, "gnss_track": other, "window_s": self.unit.cfg.track_window_s}
        return Outcome([Event(view.t, EventType.GNSS_TRACK_DISAGREES, view.km, detail=detail)])

    def _correct(self, fix: Fix, row: Any, view: EngineView) -> Outcome:
        u = float(row["uncertainty_m"])
        km_gnss = float(row["km_m"])
        m = float(margin_m(fix, view.d, view.travel.allowance_at(view.t), self.margin))
        if not u < m - self.unit.cfg.correction_gain_m:
            return Outcome()
        km_est = float(view.km if view.km is not None else np.nan)
        detail = _detail(row, m)
        if not abs(km_gnss - km_est) <= m + u:
            if self._refusing:
                return Outcome()
            self._refusing = True
            detail.update(reason="inconsistent with the estimate", km_estimate_m=round(km_est, 3))
            return Outcome([Event(view.t, EventType.GNSS_REFUSED, km_est, detail=detail)])
        self._refusing = False
        new = Fix(
            view.t,
            view.s,
            view.d,
            km_gnss,
            km_gnss + (fix.km_equipment_m - fix.km_m),
            fix.line_code,
            fix.track,
            fix.k,
            FixSource.GNSS,
            u,
            t_ref=view.t,
        )
        if fix.state == PositionState.UNCERTAIN:
            new = replace(new, state=PositionState.UNCERTAIN, uncertain_since_d=view.d)
        ev = Event(view.t, EventType.GNSS_CORRECTION, km_gnss, km_est - km_gnss, detail=detail)
        return Outcome([ev], new)

    def _initial(self, epoch: int, view: EngineView) -> Outcome:
        if not self.unit.cfg.allow_initial:
            return Outcome()
        dec = self._gps_track(view)
        if dec is None:
            return Outcome()
        line_code, track = dec
        ref = self._solutions(line_code, track, 1, view)
        if not isinstance(ref, TrackSolutions):
            return ref
        row = ref.at(epoch)
        if row is None or float(row["uncertainty_m"]) > self.unit.cfg.initial_max_uncertainty_m:
            return Outcome()
        k = self._direction(ref, str(row["receiver"]), view)
        if k is None:
            return Outcome()
        sols = self._solutions(line_code, track, k, view)
        if not isinstance(sols, TrackSolutions) or (row := sols.at(epoch)) is None:
            return Outcome() if isinstance(sols, TrackSolutions) else sols
        other = self.unit.other_track_better(sols, view.t)
        if other is not None:
            return self._disagrees(track, other, view)
        u, km = float(row["uncertainty_m"]), float(row["km_m"])
        new = Fix(view.t, view.s, view.d, km, km, line_code, track, k, FixSource.GNSS, u, t_ref=view.t)
        detail = {"line_code": line_code, "track": track, "k": k, **_detail(row, None)}
        return Outcome([Event(view.t, EventType.INITIAL_POSITION_GNSS, km, detail=detail)], new)

    def _gps_track(self, view: EngineView) -> tuple[str, str] | None:
        """(line, track) of the latest GPS decision of the current on-track period."""
        if self.gps is None or not self.gps.decisions:
            return None
        travel = view.travel
        off = np.flatnonzero(~np.asarray(travel.on_track[: view.i + 1], dtype=bool))
        since = float(travel.t[off[-1]]) if off.size else -np.inf
        decided = [d for d in self.gps.decisions if since < d.t <= view.t]
        return (decided[-1].line_code, decided[-1].track) if decided else None

    def _direction(self, sols: TrackSolutions, receiver: str, view: EngineView) -> int | None:
        """k from an earlier epoch of the same receiver (module docstring), or None."""
        tb = sols.table
        mine = tb[tb["ok"] & (tb["receiver"] == receiver) & (tb["t"] <= view.t)]
        if len(mine) < 2:
            return None
        t = mine["t"].to_numpy(dtype=float)
        km = mine["km_m"].to_numpy(dtype=float)
        u = mine["uncertainty_m"].to_numpy(dtype=float)
        travel = view.travel
        s = np.interp(t, travel.t, travel.s)
        ds, dkm, uu = s[-1] - s, km[-1] - km, u[-1] + u
        good = (np.abs(ds) >= self.unit.cfg.direction_min_travel_m) & (np.abs(dkm) > uu)
        good &= np.abs(np.abs(dkm) - np.abs(ds)) <= uu + 0.02 * np.abs(ds)
        if not good.any():
            return None
        j = int(np.flatnonzero(good)[-1])
        return 1 if dkm[j] * ds[j] > 0 else -1


def _detail(row: Any, margin: float | None) -> dict[str, Any]:
    out: dict[str, Any] = {
        "receiver": str(row["receiver"]),
        "uncertainty_m": round(float(row["uncertainty_m"]), 3),
        "n_used": int(row["n_used"]),
        "n_excluded": int(row["n_excluded"]),
        "residual_rms_m": None if not np.isfinite(row["residual_rms_m"]) else round(float(row["residual_rms_m"]), 3),
        "clock_aided": bool(row["clock_aided"]),
    }
    if margin is not None:
        out["margin_m"] = round(margin, 3)
    return out
