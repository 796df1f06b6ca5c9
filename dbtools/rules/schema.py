"""Value rules the declarative schema cannot express (SPEC §3 "schema").

Types, required fields, enumerations, lat/lon inside the operating area and key uniqueness
are declared in :mod:`schemas.tables` and checked by :func:`schemas.frames.check_frame`.
Here:

* ``schema.radius`` (error) — a ``left``/``right`` feature row needs radius_m > 0; every
  other row radius_m = 0.
* ``schema.not_finite`` (error) — ±inf in a numeric column (a DB can store it; source
  readers already reject it as ``schema.type``).
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
from schemas.tables import DB_TABLES, FEATURE_POINTS

F64 = npt.NDArray[np.float64]

CURVE = (Attribute.LEFT.value, Attribute.RIGHT.value)


def check_values(tables: dict[str, pd.DataFrame], config: ValidationConfig, loc: Locator) -> list[Finding]:
    out: list[Finding] = []
    cap = config.max_findings_per_rule
    fp = tables.get(FEATURE_POINTS.name)
    if fp is not None and not fp.empty:
        T = FEATURE_POINTS.name
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
                keys={k: py(fp[k].iat[i]) for k in FEATURE_POINTS.primary_key},
                value=py(radius[i]),
                limit="> 0" if curve else 0,
                column="radius_m",
                **loc.at(T, i),
            )

        out += capped("schema.radius", Severity.ERROR, T, bad, build, cap, loc.file(T))
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
