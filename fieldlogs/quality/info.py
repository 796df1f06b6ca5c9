"""``logs info``: what a run holds, at a glance (never fails on a damaged stream).

Distance by pulses = total pulses · π·D / teeth (:func:`schemas.units.metres_per_pulse`),
with the total taken in time order and counter resets bridged as ``logs repair`` does
(:func:`fieldlogs.quality.tacho.cumulative_again`). Measured
rates are 1 / median Δt over the distinct time stamps. GPS availability is the share of
rows with ``fix ≥ 1`` (any fix) and with ``fix = 2`` (D-GPS).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from fieldlogs.quality.tacho import cumulative_again, time_order
from fieldlogs.runs.handle import Run
from schemas.enums import GpsFix, Severity
from schemas.units import metres_per_pulse


@dataclass
class StreamInfo:
    name: str
    file: str
    format: str
    rows: int | None
    """None when the file cannot be read."""
    t_start_s: float | None = None
    t_end_s: float | None = None
    declared_rate_hz: float | None = None
    measured_rate_hz: float | None = None
    """1 / median Δt (sampled streams only; None for event streams)."""


@dataclass
class GpsInfo:
    rows: int
    fix_share: float
    """Share of rows with fix ≥ 1 (GPS or D-GPS)."""
    dgps_share: float
    """Share of rows with fix = 2 (D-GPS)."""


@dataclass
class RunInfo:
    run: str
    run_id: str
    vehicle_id: str | None
    vehicle_kind: str | None
    start_time: str | None
    db_version: str | None
    duration_s: float | None
    distance_m: float | None
    """Pulse distance; None without a tacho stream or wheel data."""
    streams: list[StreamInfo] = field(default_factory=list)
    gps: GpsInfo | None = None
    errors_reading: int = 0
    """Errors met while reading run.json and the streams (``logs check`` lists them)."""

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("duration_s", "distance_m"):
            if d[k] is not None:
                d[k] = round(d[k], 3)
        for s in d["streams"]:
            for k in ("t_start_s", "t_end_s", "measured_rate_hz"):
                if s[k] is not None:
                    s[k] = round(s[k], 6)
        if d["gps"] is not None:
            d["gps"] = {k: round(v, 6) if isinstance(v, float) else v for k, v in d["gps"].items()}
        return d


def _stream_info(run: Run, name: str) -> StreamInfo:
    frame = run.stream(name)
    info = StreamInfo(
        name,
        str(run.stream_file(name)),
        run.stream_format(name) or "",
        None if frame is None else len(frame),
        declared_rate_hz=run.stream_rate_hz(name),
    )
    if frame is None or not len(frame) or "t" not in frame.columns:
        return info
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    if np.isnan(t).all():
        return info
    info.t_start_s, info.t_end_s = float(np.nanmin(t)), float(np.nanmax(t))
    _, ts = time_order(t)
    if info.declared_rate_hz is not None and len(ts) >= 2:
        med = float(np.median(np.diff(ts)))
        info.measured_rate_hz = 1.0 / med if med > 0 else None
    return info


def _distance_m(run: Run) -> float | None:
    frame = run.stream("tacho")
    diameter, teeth = run.field("wheel_diameter_m"), run.field("teeth")
    if frame is None or diameter is None or teeth is None:
        return None
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    p = frame["pulses"].to_numpy(dtype=float, na_value=np.nan)
    pos, _ = time_order(np.where(np.isnan(p), np.nan, t))
    if len(pos) < 2:
        return 0.0 if len(pos) else None
    fixed, _ = cumulative_again(p[pos])
    return float(fixed[-1] - fixed[0]) * metres_per_pulse(diameter, teeth)


def _gps_info(run: Run) -> GpsInfo | None:
    frame = run.stream("gps")
    if frame is None:
        return None
    fix = frame["fix"].to_numpy(dtype=float, na_value=0.0)
    n = len(fix)
    if n == 0:
        return GpsInfo(0, 0.0, 0.0)
    return GpsInfo(n, float((fix >= GpsFix.GPS).mean()), float((fix == GpsFix.DGPS).mean()))


def run_info(folder: Path | str) -> RunInfo:
    """Summarise one run. Raises InputError only when the run cannot be read at all."""
    run = Run(Path(folder))
    streams = [_stream_info(run, n) for n in run.streams_present()]
    starts = [s.t_start_s for s in streams if s.t_start_s is not None]
    ends = [s.t_end_s for s in streams if s.t_end_s is not None]
    return RunInfo(
        run=str(run.folder),
        run_id=run.run_id,
        vehicle_id=run.field("vehicle_id"),
        vehicle_kind=run.vehicle_kind,
        start_time=run.field("start_time"),
        db_version=run.field("db_version"),
        duration_s=(max(ends) - min(starts)) if starts else None,
        distance_m=_distance_m(run),
        streams=streams,
        gps=_gps_info(run),
        errors_reading=sum(f.severity == Severity.ERROR for f in run.findings),
    )
