"""What a track match returns (:mod:`fieldlogs.trackmatch.match` defines the quantities;
:mod:`fieldlogs.trackmatch.path` assembles them)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Status of a fix in the result.
MATCHED, NO_CANDIDATE, OUTLIER, NO_POSITION = "matched", "no_candidate", "outlier", "no_position"
FIX_COLUMNS = ("t", "lat", "lon", "status", "track_id", "offset_m", "distance_m", "km_m", "probability")
PATH_COLUMNS = ("chain", "track_id", "probability", "t_from", "t_to", "fixes")


@dataclass
class TrackMatch:
    """The matched path, every fix's projection and a summary."""

    path: pd.DataFrame
    fixes: pd.DataFrame
    summary: dict[str, Any]

    def to_json(self) -> dict[str, Any]:
        def rows(frame: pd.DataFrame) -> list[dict[str, Any]]:
            clean = frame.astype(object).where(frame.notna(), None)
            return [dict(zip(clean.columns, r, strict=True)) for r in clean.itertuples(index=False)]

        return {"summary": self.summary, "path": rows(self.path), "fixes": rows(self.fixes)}


@dataclass
class Hmm:
    """The problem decoded (layout: :mod:`fieldlogs.trackmatch.hmm`); ``ends`` per pair: the
    exit/entry ends its route takes (:func:`fieldlogs.trackmatch.routes.route_distances`)."""

    steps: I64
    """Fix index of each step."""
    coff: I64
    cand: I64
    """Candidate (index into the Candidates arrays) of each step's entries."""
    loge: F64
    poff: I64
    logt: F64
    ends: npt.NDArray[np.int8]
