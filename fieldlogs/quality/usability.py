"""One rule for whether a run can serve an application (issue 15), shared by ``logs check``,
``run``, ``audit``, ``gis verify``, ``survey``, ``db impact`` and ``possession check``.

What a run needs depends on what it is for and on the vehicle:

* **positioning** (the pipeline: ``run``, ``audit``, ``gis verify``, …) dead-reckons on the
  wheel: a ``tacho`` stream with a plausible wheel (diameter 0.5–1.3 m for a train, 0.2–1.3 m
  for a road-rail vehicle's rail wheels; teeth 1–1000) is needed whatever the vehicle — without
  it the position could not move and would be claimed at a stale km. A train also needs its
  ``imu``: without it slips and slides can neither be detected nor bounded [S000 §3.1], so no
  margin would hold. A road-rail vehicle needs its ``gps`` and ``cab`` (PTO).
* **possession** (``possession check``): ``gps`` and ``cab``; a tacho is used when usable.

Every needed stream must have at least two usable rows (every required column valid), and a
time base in seconds: a stream whose median step is ~1000 (or ~10⁶) times its declared
interval was logged in milliseconds (or microseconds) — said so, not guessed at.

A run that fails is refused (FindingsError, exit 1, each problem a finding naming the stream
and column); it is never positioned at a "determined" km it cannot support.
"""

from __future__ import annotations

from enum import StrEnum

import numpy as np
import pandas as pd

from fieldlogs.io import REQUIRED_STREAMS, Run
from schemas.enums import Severity, VehicleKind
from schemas.errors import FindingsError
from schemas.findings import Finding
from schemas.logs import LOG_STREAMS
from schemas.vehicle import TEETH_RANGE as TEETH
from schemas.vehicle import WHEEL_DIAMETER_M

#: Time units a stream's ``t`` may have been logged in by mistake: (name, factor to seconds).
WRONG_TIME_UNITS = (("microseconds", 1e6), ("milliseconds", 1e3))


class Purpose(StrEnum):
    POSITIONING = "positioning"
    POSSESSION = "possession"


def needed_streams(kind: str, purpose: Purpose) -> tuple[str, ...]:
    """The streams a run of vehicle ``kind`` needs for ``purpose`` (module docstring)."""
    if purpose == Purpose.POSSESSION:
        return REQUIRED_STREAMS[VehicleKind.ROAD_RAIL.value]
    base = REQUIRED_STREAMS.get(kind, ())
    return base if "tacho" in base else ("tacho", *base)


def usability_findings(run: Run, purpose: Purpose) -> list[Finding]:
    """Why ``run`` cannot serve ``purpose`` (empty: it can)."""
    if run.meta is None:
        errors = [f for f in run.findings if f.severity == Severity.ERROR]
        return errors or [_finding("run.json", "run.json is missing or invalid")]
    out: list[Finding] = []
    for name in needed_streams(run.meta.vehicle_kind, purpose):
        out += _stream_problems(run, name, purpose)
    if purpose == Purpose.POSITIONING:
        out += _wheel_problems(run)
    return out


def require_usable(run: Run, purpose: Purpose) -> None:
    """FindingsError (exit 1) naming every problem when ``run`` cannot serve ``purpose``."""
    problems = usability_findings(run, purpose)
    if problems:
        summary = "; ".join(f"{f.table}: {f.message}" for f in problems[:3])
        raise FindingsError(f"unusable run for {purpose} ({summary})", problems, path=run.folder)


def _finding(table: str, message: str, column: str | None = None, value: object = None) -> Finding:
    return Finding("run.unusable", Severity.ERROR, table, message, column=column, value=value)


def _stream_problems(run: Run, name: str, purpose: Purpose) -> list[Finding]:
    why = {
        "tacho": "the position is dead-reckoned on the wheel",
        "imu": "without it slips and slides can be neither detected nor bounded",
        "gps": "km and track come from the GPS",
        "cab": "on rail = PTO on",
    }.get(name, f"needed for {purpose}")
    if not run.has(name):
        return [_finding(name, f"no {name} stream ({why})")]
    frame = run.stream(name)
    table = LOG_STREAMS[name]
    cols = [c.name for c in table.columns if c.required and not c.nullable]
    usable = _usable_rows(frame, cols) if frame is not None and all(c in frame.columns for c in cols) else 0
    if usable < 2:
        first = next((f for f in run.stream_findings(name) if f.severity == Severity.ERROR), None)
        return [_finding(name, "no usable rows" + (f" ({first.message})" if first else ""))]
    assert frame is not None
    unit = time_unit_problem(frame["t"].to_numpy(dtype=float, na_value=np.nan), table.rate_hz)
    return [_finding(name, unit, column="t")] if unit else []


def _usable_rows(frame: pd.DataFrame, cols: list[str]) -> int:
    """Rows with every column of ``cols`` valid (column by column: no copy of the frame)."""
    ok = np.ones(len(frame), dtype=bool)
    for c in cols:
        ok &= frame[c].notna().to_numpy()
    return int(np.count_nonzero(ok))


def time_unit_problem(t: np.ndarray, rate_hz: float | None) -> str | None:
    """The message when a stream's median step says its ``t`` is not in seconds."""
    finite = np.isfinite(t)
    if not finite.all():
        t = t[finite]
    del finite
    if rate_hz is None or t.size < 3:
        return None
    if not bool((t[1:] >= t[:-1]).all()):  # sorted already (the usual case): no sorted copy
        t = np.sort(t)
    step = float(np.median(np.diff(t), overwrite_input=True))
    nominal = 1.0 / rate_hz
    for unit, factor in WRONG_TIME_UNITS:
        if 0.3 * factor * nominal <= step <= 3.0 * factor * nominal:
            return (
                f"t looks like {unit}: rows {step:g} apart for a {rate_hz:g} Hz stream "
                f"(t must be seconds since the run's start; divide by {factor:g})"
            )
    return None


def _wheel_problems(run: Run) -> list[Finding]:
    meta = run.meta
    assert meta is not None
    lo, hi = WHEEL_DIAMETER_M.get(meta.vehicle_kind, WHEEL_DIAMETER_M[VehicleKind.TRAIN.value])
    out: list[Finding] = []
    d, teeth = meta.wheel_diameter_m, meta.teeth
    if d is None or teeth is None:
        return out  # no tacho stream: said by the stream rule
    if not (np.isfinite(d) and lo <= d <= hi):
        out.append(
            _finding(
                "run.json",
                f"wheel_diameter_m {d:.6g} m is not a {meta.vehicle_kind}'s wheel ({lo:g}–{hi:g} m)",
                "wheel_diameter_m",
                d,
            )
        )
    if not TEETH[0] <= teeth <= TEETH[1]:
        out.append(_finding("run.json", f"teeth {teeth} is not {TEETH[0]}–{TEETH[1]}", "teeth", teeth))
    return out
