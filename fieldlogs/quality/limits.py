"""Physical limits of the log streams, applied before the pipeline (issue 32, fail-safe).

Every numeric column of a stream declares the range a working sensor can report
(``schemas/logs.py``: e.g. specific force within ±30 m/s², rates within ±3 rad/s, GPS
latitude within ±90°, radar speed 0–150 m/s). A sample outside it — or infinite — is no
measurement: 20 rows of ``ax = 45 m/s²`` integrated by the slide correction moved a
"determined" km by 81 m, one ``ax = 1e308`` by 5e304 m. Such a row is masked (dropped from the
stream, as a missing sample: the IMU-gap and usability rules then account for it, and
the margin grows as for any gap), never used. A missing value (NaN) in a nullable column
is not out of range. ``t`` is left to the cleaning of the time base.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from schemas.logs import LOG_STREAMS
from schemas.model import Table

#: Streams whose limits are applied: the sensors the pipeline reads. The truth is the
#: simulator's, and raw radar IF samples are scaled by the radar module (ADC counts over
#: run.json's ``radar.full_scale``, the I/Q sign of ``radar.iq_convention``: ``radar.framing``).
LIMITED_STREAMS = ("tacho", "imu", "gps", "cab", "radar")


@dataclass(frozen=True)
class OutOfRange:
    """Rows of one stream with a value outside its column's declared range."""

    stream: str
    rows: np.ndarray
    """Positions in the frame as read (0-based) of the rows masked."""
    columns: dict[str, int]
    """Column → how many of its values were outside (a row may count in several)."""
    worst: dict[str, float]
    """Column → the value farthest outside, for the message."""


def out_of_range(name: str, frame: pd.DataFrame, table: Table | None = None) -> OutOfRange | None:
    """The rows of ``frame`` (stream ``name``) whose value in a declared numeric column is
    infinite or outside [min, max]; None when every value is within its range."""
    table = table or LOG_STREAMS.get(name)
    if table is None or name not in LIMITED_STREAMS or frame.empty:
        return None
    bad_any = np.zeros(len(frame), dtype=bool)
    counts: dict[str, int] = {}
    worst: dict[str, float] = {}
    for c in table.columns:
        if c.name == "t" or c.dtype not in ("float", "int") or c.name not in frame.columns:
            continue
        if c.min is None and c.max is None:
            continue
        v = pd.to_numeric(frame[c.name], errors="coerce").to_numpy(dtype=float, na_value=np.nan)
        lo = -np.inf if c.min is None else c.min
        hi = np.inf if c.max is None else c.max
        with np.errstate(invalid="ignore"):
            bad = ~np.isnan(v) & ((v < lo) | (v > hi) | ~np.isfinite(v))
        n = int(bad.sum())
        if n:
            counts[c.name] = n
            excess = np.where(v[bad] > hi, v[bad] - hi, lo - v[bad])
            worst[c.name] = float(v[bad][int(np.argmax(excess))])
            bad_any |= bad
    if not counts:
        return None
    return OutOfRange(name, np.flatnonzero(bad_any), counts, worst)


def masked(name: str, frame: pd.DataFrame) -> tuple[pd.DataFrame, OutOfRange | None]:
    """``frame`` without its rows outside the limits (the same frame when none is), and
    which were masked: what the pipeline and ``logs check``'s clock check both read."""
    bad = out_of_range(name, frame)
    if bad is None:
        return frame, None
    keep = np.ones(len(frame), dtype=bool)
    keep[bad.rows] = False
    return frame[keep].reset_index(drop=True), bad
