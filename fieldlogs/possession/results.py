"""What a possession check returns: alarms and notices, the per-period timeline, the run's
result and its documented JSON shape (``{"runs": [...]}``, docs/guide/possessions.md)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from typing import Any

import numpy as np
import numpy.typing as npt

from fieldlogs.pipeline.types import Event, GpsAnalysis, TrackDecision
from schemas.enums import AlarmType, NoticeType
from schemas.jsonable import jsonable

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
#: Decimals of the alarms' evidence in JSON (mm, ms).
EVIDENCE_DIGITS = 3


def wall(start: datetime, t: float) -> str:
    """Wall-clock time of run time t (ISO 8601 with the run's offset, ms)."""
    return (start + timedelta(seconds=float(t))).isoformat(timespec="milliseconds")


def _r(v: float | None, nd: int) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), nd)


@dataclass
class Alarm:
    """An alarm (:class:`~schemas.enums.AlarmType`) or a notice (:class:`~schemas.enums.NoticeType`)."""

    type: AlarmType | NoticeType
    t: float
    time: str
    km_m: float | None
    track: str | None
    work_no: str | None
    evidence: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "type": self.type.value,
            "t": round(self.t, 2),
            "time": self.time,
            "km_m": _r(self.km_m, 2),
            "track": self.track,
            "work_no": self.work_no,
            "evidence": jsonable(self.evidence, EVIDENCE_DIGITS),
        }


@dataclass
class Timeline:
    """What the plot of one on-rail period needs."""

    t: FloatArray
    km: FloatArray
    u: FloatArray
    fix_t: FloatArray
    fix_km: FloatArray
    fix_trusted: BoolArray
    sections: list[tuple[float, float, str, float, float]]
    """(t from, t to, work_no, km_from, km_to) of the governing possession."""


@dataclass
class PeriodResult:
    """One on-rail period: its line, governing work, decisions, crossovers and timeline."""

    t_on: float
    t_off: float
    line_code: str | None
    work_no: str | None
    decisions: list[TrackDecision]
    crossovers: list[Event]
    timeline: Timeline
    gps: GpsAnalysis | None = field(default=None, repr=False)

    def decision_json(self, start: datetime) -> dict[str, Any] | None:
        if not self.decisions:
            return None
        d = self.decisions[0]
        return {
            "t": round(d.t, 2),
            "time": wall(start, d.t),
            "line_code": d.line_code,
            "track": d.track,
            "after_on_rail_s": round(d.t - self.t_on, 2),
            "evidence": jsonable(d.evidence, EVIDENCE_DIGITS),
        }


@dataclass
class RunCheck:
    """Result of checking one run against the plan."""

    run: str
    run_id: str
    start_time: datetime
    possessions: list[str]
    periods: list[PeriodResult]
    alarms: list[Alarm]
    notices: list[Alarm]
    tacho: dict[str, Any] = field(default_factory=lambda: {"used": False, "note": "no tacho stream"})
    """Whether the km filter used a tacho, and why not (``{"used", "note"}``)."""

    @property
    def track_decision(self) -> dict[str, Any] | None:
        """The first up/down decision after going on rail (first on-rail period that has one)."""
        for p in self.periods:
            d = p.decision_json(self.start_time)
            if d is not None:
                return d
        return None

    def to_json(self) -> dict[str, Any]:
        return {
            "run": self.run,
            "run_id": self.run_id,
            "possessions": self.possessions,
            "track_decision": self.track_decision,
            "alarms": [a.to_json() for a in self.alarms],
            "notices": [n.to_json() for n in self.notices],
            "tacho": dict(self.tacho),
            "on_rail": [
                {
                    "t_on": round(p.t_on, 2),
                    "t_off": round(p.t_off, 2),
                    "time_on": wall(self.start_time, p.t_on),
                    "time_off": wall(self.start_time, p.t_off),
                    "line_code": p.line_code,
                    "work_no": p.work_no,
                    "track_decision": p.decision_json(self.start_time),
                }
                for p in self.periods
            ],
        }


def checks_json(checks: list[RunCheck]) -> dict[str, Any]:
    """The documented JSON shape ``{"runs": [...]}``."""
    return {"runs": [c.to_json() for c in checks]}
