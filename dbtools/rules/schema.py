"""Value rules the declarative schema cannot express (SPEC §3 "schema").

Types, required fields, enumerations, lat/lon inside the operating area and key uniqueness
are declared in :mod:`schemas.tables` and checked by :func:`schemas.frames.check_frame`.
Here:

* ``schema.radius`` (error) — a ``left``/``right`` feature row needs radius_m > 0; every
  other row radius_m = 0. Fix: set ``radius_m`` of left/right rows to the curve radius, of
  every other row to 0.
* ``schema.not_finite`` (error) — ±inf in a numeric column (a DB can store it; source
  readers already reject it as ``schema.type``). Fix: replace the infinite value by the real
  one.
* ``schema.empty_table`` — a header-only source file (or a DB table without rows): an error
  for ``gis`` (no km can be placed, matched or checked without the grid), a warning for
  ``balises`` (a train never gets an initial position [S003 §4]; only what needs no balise
  works, e.g. the GPS-based possession check of road-rail vehicles [S001 §6]). An empty
  ``feature_points`` is no finding: a network without curves is possible. Fix: add the rows
  (build the grid with ``gis grid``; list the balises).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.rules.common import Locator, capped, column, py
from dbtools.rules.config import ValidationConfig
from schemas.enums import Attribute, Severity
from schemas.findings import Finding
from schemas.model import Table
from schemas.network import TRACK_POINTS
from schemas.tables import BALISES, DB_TABLES, FEATURE_POINTS, GIS, TRACK_FEATURE_POINTS

F64 = npt.NDArray[np.float64]

CURVE = (Attribute.LEFT.value, Attribute.RIGHT.value)


def check_values(tables: dict[str, pd.DataFrame], config: ValidationConfig, loc: Locator) -> list[Finding]:
    out: list[Finding] = []
    cap = config.max_findings_per_rule
    for feat in (FEATURE_POINTS, TRACK_FEATURE_POINTS):
        fp = tables.get(feat.name)
        if fp is not None and not fp.empty:
            out += _radius(feat, fp, cap, loc)
    for table in DB_TABLES:
        frame = tables.get(table.name)
        if frame is None or frame.empty:
            continue
        for col in table.columns:
            if col.dtype != "float" or col.name not in frame.columns:
                continue
            vals = column(frame, col.name)
            bad = np.flatnonzero(np.isinf(vals))

            def inf(i: int, t: Table = table, c: str = col.name, v: F64 = vals, f: pd.DataFrame = frame) -> Finding:
                return Finding(
                    "schema.not_finite",
                    Severity.ERROR,
                    t.name,
                    f"{v[i]} is not a finite number",
                    keys={k: py(f[k].iat[i]) for k in t.primary_key if k in f.columns},
                    value=str(v[i]),
                    limit="finite",
                    column=c,
                    **loc.at(t.name, i),
                )

            out += capped("schema.not_finite", Severity.ERROR, table.name, bad, inf, cap, loc.file(table.name))
    return out


#: An empty grid where the tracks have their own centrelines (a network without kilometrage,
#: e.g. imported from RailTopoModel GeoJSON): positions along the tracks, no line km.
GIS_BESIDE_TRACK_POINTS = "no line grid: the tracks have only their own centrelines (track_points), no line km"
#: Tables that must not be empty: severity and what an empty one means on board.
EMPTY_TABLES = {
    GIS.name: (Severity.ERROR, "no GIS grid: no km can be placed on the map, matched to GPS or checked"),
    BALISES.name: (
        Severity.WARNING,
        "no balises: a train never gets an initial position [S003 §4] (only GPS-based checks can use this DB)",
    ),
}


def check_empty_tables(
    tables: dict[str, pd.DataFrame], loc: Locator, *, tables_read: set[str] | None = None
) -> list[Finding]:
    """``schema.empty_table`` for each table of :data:`EMPTY_TABLES` without rows
    (``tables_read``: only these — in a source set, a missing file is its own finding).
    An empty ``gis`` is only a warning where ``track_points`` has rows: every track's
    centreline is there (a network imported from OSM or RailTopoModel, SPEC §8.1), but the
    line-based positioning has no line grid to run on."""
    out = []
    points = tables.get(TRACK_POINTS.name)
    for name, (severity, meaning) in EMPTY_TABLES.items():
        frame = tables.get(name)
        if (tables_read is not None and name not in tables_read) or (frame is not None and len(frame)):
            continue
        if name == GIS.name and points is not None and len(points):
            severity, meaning = Severity.WARNING, GIS_BESIDE_TRACK_POINTS
        file = loc.file(name)
        where = f"{file} has a header but no rows" if file else f"table '{name}' has no rows"
        out.append(
            Finding(
                "schema.empty_table",
                severity,
                name,
                f"{where}: {meaning}",
                file=file,
                row=2 if file else None,
                value=0,
                limit="≥ 1 row",
            )
        )
    return out


def _radius(feat: Table, fp: pd.DataFrame, cap: int, loc: Locator) -> list[Finding]:
    """``schema.radius`` of the rows of a feature-point table (``feature_points`` or
    ``track_feature_points``)."""
    T = feat.name
    attr, radius = column(fp, "attribute"), column(fp, "radius_m")
    is_curve = np.isin(attr, CURVE)
    known = pd.notna(attr) & np.isfinite(radius)
    bad = np.flatnonzero(known & ((is_curve & (radius <= 0)) | (~is_curve & (radius != 0))))

    def build(i: int) -> Finding:
        curve = bool(is_curve[i])
        return Finding(
            "schema.radius",
            Severity.ERROR,
            T,
            f"a '{attr[i]}' row needs radius_m {'> 0' if curve else '= 0 (0 means straight)'}, found {radius[i]:g}",
            keys={k: py(fp[k].iat[i]) for k in feat.primary_key},
            value=py(radius[i]),
            limit="> 0" if curve else 0,
            column="radius_m",
            **loc.at(T, i),
        )

    return capped("schema.radius", Severity.ERROR, T, bad, build, cap, loc.file(T))
