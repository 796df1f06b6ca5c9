"""What ``trainpos survey`` reports, and its documented JSON shape."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dbtools.gis.verify.result import GisVerification
from dbtools.network import Network
from fieldlogs.survey.balises import MISSED, MOVED
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.features import MOVED as F_MOVED
from fieldlogs.survey.features import NEW, NOT_SEEN, TrackCurves
from fieldlogs.survey.wheels import ALERT


def records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    """Rows as JSON-ready dicts: NaN → None, numpy scalars → Python, floats rounded."""
    out: list[dict[str, Any]] = []
    for rec in frame.astype(object).where(frame.notna(), None).to_dict("records"):
        row: dict[str, Any] = {}
        for k, v in rec.items():
            if isinstance(v, np.bool_):
                v = bool(v)
            elif isinstance(v, np.integer):
                v = int(v)
            elif isinstance(v, float | np.floating):
                v = round(float(v), 6) if np.isfinite(v) else None
            row[str(k)] = v
        out.append(row)
    return out


@dataclass
class SurveyReport:
    """The survey of one DB against many runs (every frame's columns are in its module)."""

    db: str
    db_version: str | None
    network: Network = field(repr=False)
    config: SurveyConfig
    runs: pd.DataFrame
    """run_id, folder, vehicle_id, start_time, duration_s, distance_m, telegrams, identified, unknown, …"""
    failed_runs: pd.DataFrame
    """run, error."""
    balises: pd.DataFrame
    missed: pd.DataFrame
    candidates: pd.DataFrame
    features: pd.DataFrame
    curves: dict[tuple[str, str], TrackCurves] = field(repr=False)
    wheel_runs: pd.DataFrame
    wheels: pd.DataFrame
    gis: GisVerification | None
    gis_note: str = ""
    gis_tracks: GisVerification | None = None
    """The GIS verification of the tracks off a line (``track_points``, per track_id;
    :mod:`dbtools.gis.verify.track_points`); None on a DB without track points."""
    changes: pd.DataFrame = field(default_factory=pd.DataFrame)
    """What ``--propose`` changes (:mod:`fieldlogs.survey.propose`)."""
    proposed: Network | None = field(default=None, repr=False)
    """The DB with the applied changes (what ``--propose`` writes as a source set)."""
    iterations: int = 0

    def summary(self) -> dict[str, Any]:
        """Counts per status, and the flags that make the command exit 1."""
        b = self.balises["status"].value_counts().to_dict()
        f = self.features["status"].value_counts().to_dict() if len(self.features) else {}
        w = self.wheels["status"].value_counts().to_dict() if len(self.wheels) else {}
        cand = int(self.candidates["confirmed"].sum()) if len(self.candidates) else 0
        return {
            "runs": len(self.runs),
            "failed_runs": len(self.failed_runs),
            "run_hours": round(float(self.runs["duration_s"].sum()) / 3600.0, 3) if len(self.runs) else 0.0,
            "balises": {str(k): int(v) for k, v in sorted(b.items())},
            "candidates_confirmed": cand,
            "features": {str(k): int(v) for k, v in sorted(f.items())},
            "wheels": {str(k): int(v) for k, v in sorted(w.items())},
            "wheels_inconsistent": int((self.wheels["consistent"] == False).sum()) if len(self.wheels) else 0,  # noqa: E712
            "gis_defects": (
                len(self.gis.defects) + (len(self.gis_tracks.defects) if self.gis_tracks is not None else 0)
                if self.gis is not None
                else None
            ),
            "changes": len(self.changes),
        }

    @property
    def flagged(self) -> bool:
        """Anything a maintainer must act on (exit 1): moved or missed balises, confirmed
        candidates, moved / new / not seen feature points, wheel alerts, vehicles whose wheel
        sources disagree, GIS defects, or runs that could not be used."""
        s = self.summary()
        return bool(
            s["balises"].get(MOVED, 0)
            or s["balises"].get(MISSED, 0)
            or s["candidates_confirmed"]
            or sum(s["features"].get(k, 0) for k in (F_MOVED, NEW, NOT_SEEN))
            or s["wheels"].get(ALERT, 0)
            or s["wheels_inconsistent"]
            or s["gis_defects"]
            or s["failed_runs"]
        )

    def to_dict(self) -> dict[str, Any]:
        """The documented JSON shape (docs/guide/survey.md, ``trainpos survey --help``)."""
        gis = None
        if self.gis is not None:
            gis = {k: v for k, v in self.gis.to_dict().items() if k != "cells"}
            if self.gis_tracks is not None:  # only a network DB has them: line-only output unchanged
                gis["track_points"] = {k: v for k, v in self.gis_tracks.to_dict().items() if k != "cells"}
        return {
            "db": self.db,
            "db_version": self.db_version,
            "config": asdict(self.config),
            "summary": self.summary(),
            "runs": records(self.runs),
            "failed_runs": records(self.failed_runs),
            "balises": records(self.balises),
            "missed_passes": records(self.missed),
            "candidates": records(self.candidates),
            "features": records(self.features),
            "wheels": {"vehicles": records(self.wheels), "runs": records(self.wheel_runs)},
            "gis": gis,
            "gis_note": self.gis_note,
            "changes": records(self.changes),
        }
