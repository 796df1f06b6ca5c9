"""One surveyed centreline of ``gis grid`` (pure): finding locations in the input files, who a
track is, and the cleaned polyline (step 1 of :mod:`dbtools.gis.grid`) shared by the line
grid and the per-track grid (:mod:`dbtools.gis.track_grid`).

The polyline's chainage ``s`` is measured on the ground (geodesic length of each segment),
not in the plane, so lengths are not off by the projection's scale factor (0.9999–1.0001 in
a JGD2011 zone); positions are interpolated in the plane.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import Projector, geodesic_step
from schemas.enums import Severity
from schemas.findings import Finding

FloatArray = npt.NDArray[np.float64]

#: Consecutive vertices closer than this are duplicates [m].
DUPLICATE_VERTEX_M = 1e-3

#: Extra frame columns the readers may add: file line of the row, and a label prefix for
#: inputs without lines (GeoJSON: "feature 3, vertex 12").
ROW_COL = "_row"
LABEL_COL = "_label"


class Where:
    """Finding locations: file and line of an input row (or a label when there are no lines)."""

    def __init__(self, frame: pd.DataFrame, table: str, file: str | None) -> None:
        self.table, self.file = table, file
        self.rows = frame[ROW_COL] if ROW_COL in frame.columns else None
        self.labels = frame[LABEL_COL] if LABEL_COL in frame.columns else None

    def finding(
        self,
        rule: str,
        severity: Severity,
        message: str,
        idx: Any = None,
        *,
        keys: Mapping[str, object] | None = None,
        value: object = None,
        limit: object = None,
        column: str | None = None,
    ) -> Finding:
        row = None
        if idx is not None and self.rows is not None:
            v = self.rows.loc[idx]
            row = None if pd.isna(v) else int(v)
        if idx is not None and self.labels is not None:
            label = self.labels.loc[idx]
            if isinstance(label, str) and label:
                message = f"{label}: {message}"
        return Finding(
            rule,
            severity,
            self.table,
            message,
            keys=dict(keys or {}),
            value=value,
            limit=limit,
            file=self.file,
            row=row,
            column=column,
        )


@dataclass
class Polyline:
    """One track's cleaned centreline: plane vertices, heights (or None), ground chainage."""

    x: FloatArray
    y: FloatArray
    heights: FloatArray | None
    s: FloatArray


@dataclass(frozen=True)
class TrackCtx:
    """Who a track is, for findings: a line's track (line_code, track), or a track of its
    own (``track_id``; line_code then the line whose posts give it km, if any)."""

    line_code: str
    track: str
    first_idx: Any
    cw: Where
    pw: Where
    track_id: str | None = None

    @property
    def keys(self) -> dict[str, object]:
        if self.track_id is not None:
            return {"track_id": self.track_id}
        return {"line_code": self.line_code, "track": self.track}

    @property
    def name(self) -> str:
        """The track in a message: "track X1" or "track D of line '0420'"."""
        if self.track_id is not None:
            return f"track {self.track_id}"
        return f"track {self.track} of line '{self.line_code}'"


def polyline(vertices: pd.DataFrame, projector: Projector, ctx: TrackCtx, findings: list[Finding]) -> Polyline | None:
    """Step 1: plane vertices without repeats, heights if given on every vertex, chainage
    on the ground (geodesic, not in the plane: scale factor 0.9999–1.0001); None (and a
    finding) when fewer than two distinct vertices remain."""
    lon = vertices["lon"].to_numpy(dtype=float)
    lat = vertices["lat"].to_numpy(dtype=float)
    x, y = projector.to_xy(lon, lat)
    h = vertices["height_m"].to_numpy(dtype=float, na_value=np.nan)
    step = geodesic_step(lon, lat)
    dup = np.flatnonzero(step < DUPLICATE_VERTEX_M) + 1
    if dup.size:
        findings.append(
            ctx.cw.finding(
                "gisinput.duplicate_vertex",
                Severity.WARNING,
                f"{dup.size} vertex(es) repeat the previous one and were dropped",
                vertices.index[dup[0]],
                keys=ctx.keys,
                value=int(dup.size),
            )
        )
        keep = np.ones(x.size, dtype=bool)
        keep[dup] = False
        x, y, h, step = x[keep], y[keep], h[keep], geodesic_step(lon[keep], lat[keep])
    if x.size < 2:
        findings.append(
            ctx.cw.finding(
                "gisinput.short_track",
                Severity.ERROR,
                f"{ctx.name} has fewer than two distinct vertices",
                ctx.first_idx,
                keys=ctx.keys,
                value=int(x.size),
                limit=2,
            )
        )
        return None
    has_h = ~np.isnan(h)
    if has_h.any() and not has_h.all():
        findings.append(
            ctx.cw.finding(
                "gisinput.partial_height",
                Severity.WARNING,
                f"height_m is given on {int(has_h.sum())} of {h.size} vertices of the track; heights ignored",
                ctx.first_idx,
                keys=ctx.keys,
                column="height_m",
            )
        )
    return Polyline(x, y, h if has_h.all() else None, np.concatenate([[0.0], np.cumsum(step)]))
