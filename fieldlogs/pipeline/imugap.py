"""IMU gaps: while the IMU is silent a slip or slide can be neither detected nor bounded.

Slip/slide detection compares the accelerometer with the pulses [S000 eq. 1]; where the IMU
has no samples the pulses are taken as they are. A gap longer than ``margin.imu_gap_s`` on
moving cycles (pulse speed above the odometry's ``min_speed_kmh``) is therefore an integrity
loss, handled fail-safe like a correction that ran out of time:

* the odometry's error allowance grows on the gap's cycles by ``margin.imu_gap_share`` of the
  travel (the wheel may be slipping or sliding by that share of the speed unseen — the
  simulator's and the papers' slips are 10–40 %), so the margin keeps holding;
* the position becomes *uncertain* at the gap's start (:class:`ImuGapAid`), until the next
  absolute fix, with an ``imu_lost`` event (and ``imu_back`` when the samples return).

Short gaps (a dropped packet) stay bridged by the odometry's NaN policy.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from dbtools.masks import true_runs
from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority, StaticAid
from fieldlogs.pipeline.cycles import IMU_COLUMNS, Cycles
from fieldlogs.pipeline.types import Event, Odometry
from schemas.enums import EventType, PositionState


@dataclass(frozen=True)
class ImuGap:
    i0: int
    """First cycle without IMU samples."""
    i1: int
    """One past the last."""
    t0: float
    t1: float


def imu_gaps(cycles: Cycles, min_gap_s: float, min_speed_mps: float) -> list[ImuGap]:
    """Runs of cycles without IMU samples, longer than ``min_gap_s``, on which the vehicle
    moved (pulse speed above ``min_speed_mps`` somewhere in the run)."""
    if not cycles.has_imu or cycles.n == 0:
        return []
    missing = np.zeros(cycles.n, dtype=bool)
    for c in IMU_COLUMNS:
        missing |= ~np.isfinite(cycles.imu[c])
    starts, ends = true_runs(missing)
    t, v = cycles.t, np.nan_to_num(cycles.v_pulse, nan=0.0)
    out = []
    for a, b in zip(starts, ends, strict=True):
        t_end = float(t[b]) if b < cycles.n else float(t[-1])
        if t_end - float(t[a]) >= min_gap_s and (v[a:b] > min_speed_mps).any():
            out.append(ImuGap(int(a), int(b), float(t[a]), t_end))
    return out


def with_gap_allowance(odo: Odometry, gaps: list[ImuGap], share: float) -> Odometry:
    """``odo`` with its allowance grown by ``share`` of the travel over each gap (cumulative,
    never decreasing)."""
    if not gaps or share <= 0.0:
        return odo
    grow = np.zeros(odo.d.size)
    dd = np.diff(odo.d, prepend=odo.d[0] if odo.d.size else 0.0)
    for g in gaps:
        grow[g.i0 : g.i1] = share * dd[g.i0 : g.i1]
    return replace(odo, allowance=odo.allowance + np.cumsum(grow))


@dataclass(eq=False)
class ImuGapAid(StaticAid):
    """The position becomes uncertain where slips stop being detectable."""

    gaps: list[ImuGap]
    share: float
    name = "imu_gap"
    priority = Priority.INTEGRITY

    def observations(self) -> Iterator[Observation]:
        for g in self.gaps:
            yield Observation(g.t0, (True, g))
            yield Observation(g.t1, (False, g))

    def next_observation(self, view: EngineView) -> Observation | None:
        """A fix taken inside a gap (a balise read while the IMU is silent) is uncertain too."""
        fix = view.estimate
        if fix is None or fix.state != PositionState.DETERMINED:
            return None
        inside = [g for g in self.gaps if g.t0 < view.t < g.t1]
        return Observation(view.t, (None, inside[0])) if inside else None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        lost, g = obs.payload
        if lost is None:  # still silent: the new fix is not trusted either
            fix = view.estimate
            if fix is None or fix.state != PositionState.DETERMINED:
                return Outcome()
            return Outcome(estimate=replace(fix, state=PositionState.UNCERTAIN, uncertain_since_d=view.d))
        detail = {"t_from": g.t0, "t_to": g.t1, "allowance_share": self.share}
        if not lost:
            return Outcome([Event(view.t, EventType.IMU_BACK, view.km, detail=detail)])
        ev = Event(view.t, EventType.IMU_LOST, view.km, detail=detail)
        fix = view.estimate
        if fix is None or fix.state == PositionState.UNCERTAIN:
            return Outcome([ev])
        return Outcome([ev], replace(fix, t_effective=view.t, state=PositionState.UNCERTAIN, uncertain_since_d=view.d))
