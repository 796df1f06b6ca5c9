"""GIS verification: the result (:class:`GisVerification`) and its documented JSON shape."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dbtools.gis.verify.config import KM_DEFECT_COLUMNS, VerifyConfig


@dataclass
class GisVerification:
    """Result of :func:`verify_fixes` (frames with the ``*_COLUMNS`` above)."""

    config: VerifyConfig
    cells: pd.DataFrame
    defects: pd.DataFrame
    coverage: pd.DataFrame
    proposal: pd.DataFrame
    counts: dict[str, int] = field(default_factory=dict)
    """fixes_in, fixes_unknown_track, fixes_far (beyond max_offset_m), fixes_off_grid,
    fixes_matched, runs."""
    km_residual: dict[str, float | int | None] = field(default_factory=dict)
    """Spread of the along-track residual over all eligible fixes (the pipeline km's own
    error plus GPS along-track error): n, median, mean, sd, p95_abs [m]."""
    km_defects: pd.DataFrame = field(default_factory=lambda: pd.DataFrame(columns=list(KM_DEFECT_COLUMNS)))
    """Stretches whose along-track residual (GIS km − pipeline km) stands out of its
    surroundings (the along-track scan, ``KM_DEFECT_COLUMNS``)."""
    scan: dict[str, Any] = field(default_factory=dict)
    """Per scan (``lateral``, ``along_track``): windows tested and selected, and the fitted
    prior of each window length."""

    @property
    def has_defects(self) -> bool:
        return len(self.defects) > 0 or len(self.km_defects) > 0

    def to_dict(self) -> dict[str, Any]:
        """The documented JSON shape (see ``trainpos gis verify --help``)."""
        return {
            "config": {k: list(v) if isinstance(v, tuple) else v for k, v in self.config.to_dict().items()},
            "counts": dict(self.counts),
            "km_residual": dict(self.km_residual),
            "coverage": _records(self.coverage),
            "defects": _records(self.defects),
            "proposal": _records(self.proposal),
            "km_defects": _records(self.km_defects),
            "scan": self.scan,
            "cells": _records(self.cells),
        }


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    rows = frame.astype(object).where(frame.notna(), None).to_dict("records")
    out: list[dict[str, Any]] = [{str(k): v for k, v in r.items()} for r in rows]
    for row in out:
        for k, v in row.items():
            if isinstance(v, float):
                row[k] = round(v, 6) if np.isfinite(v) else None
            elif isinstance(v, np.integer):
                row[k] = int(v)
            elif isinstance(v, np.floating):
                row[k] = round(float(v), 6) if np.isfinite(v) else None
            elif isinstance(v, np.bool_):
                row[k] = bool(v)
    return out
