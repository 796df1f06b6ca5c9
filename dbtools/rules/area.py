"""Operating-area rules: every GIS point inside the network's area (:mod:`dbtools.gis.georef`).

* ``schema.range`` (error) — a point more than ``AREA_TOLERANCE_M`` (2 km) outside the
  declared or derived operating area (a wrong sign, swapped lat/lon, a lost decimal
  point); the point is left out of the grid index. Fix: correct the value (sign, swapped
  lat/lon, decimal point), or the declared limits (the operating area in the DB meta).
* ``gis.outside_area`` (warning) — a point outside the area but within the tolerance (an
  area drawn slightly tight); the point is used. Fix: widen the declared operating area, or
  correct the point.

Points off the globe (|lat| > 90°, |lon| > 180°) are the schema's own range findings.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from dbtools.gis import index as grid_blocks
from dbtools.gis.georef import AREA_TOLERANCE_M, Georef
from dbtools.gis.index import network_georef
from dbtools.network import Network
from dbtools.rules.common import Locator, capped, column, py
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.tables import GIS, LAT_RANGE, LON_RANGE

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


def check_area(network: Network, loc: Locator, max_findings: int = 1000) -> list[Finding]:
    """``schema.range`` / ``gis.outside_area`` for the GIS points (module docstring)."""
    georef = network_georef(network)
    gis = network.gis
    if georef is None or gis.empty:
        return []
    lat, lon = column(gis, "lat"), column(gis, "lon")
    rows, dist = _outside(georef, lat, lon)
    far, near = np.flatnonzero(dist > AREA_TOLERANCE_M), np.flatnonzero(dist <= AREA_TOLERANCE_M)
    file = loc.file(GIS.name)

    def build(j: int, severity: Severity) -> Finding:
        i = int(rows[j])
        a = georef.area
        col = "lat" if not a.lat_min <= lat[i] <= a.lat_max else "lon"
        what = "an error" if severity == Severity.ERROR else "within the tolerance: used"
        return Finding(
            "schema.range" if severity == Severity.ERROR else "gis.outside_area",
            severity,
            GIS.name,
            f"point {lat[i]:.6f}, {lon[i]:.6f} lies {_km(dist[j])} outside the {_area_text(georef)} "
            f"({what}; more than {AREA_TOLERANCE_M / 1000:g} km outside is an error)",
            keys={
                "line_code": py(gis["line_code"].iat[i]),
                "track": py(gis["track"].iat[i]),
                "km_m": py(column(gis, "km_m")[i]),
            },
            value=[py(lat[i]), py(lon[i])],
            limit=[a.lat_min, a.lat_max, a.lon_min, a.lon_max],
            column=col,
            **loc.at(GIS.name, i),
        )

    return capped(
        "schema.range", Severity.ERROR, GIS.name, far, lambda i: build(i, Severity.ERROR), max_findings, file
    ) + capped(
        "gis.outside_area", Severity.WARNING, GIS.name, near, lambda i: build(i, Severity.WARNING), max_findings, file
    )


def _outside(georef: Georef, lat: F64, lon: F64) -> tuple[I64, F64]:
    """The rows of the points outside the area (on the globe, coordinates present) and their
    distance to it [m], ``BLOCK`` points at a time: bounded temporaries."""
    rows: list[I64] = []
    dist: list[F64] = []
    for a in range(0, lat.size, grid_blocks.BLOCK):
        la, lo = lat[a : a + grid_blocks.BLOCK], lon[a : a + grid_blocks.BLOCK]
        with np.errstate(invalid="ignore"):
            on_globe = np.flatnonzero((np.abs(la) <= LAT_RANGE[1]) & (np.abs(lo) <= LON_RANGE[1]))
        d = georef.area.distance_m(la[on_globe], lo[on_globe])
        with np.errstate(invalid="ignore"):
            out = d > 0
        rows.append(a + on_globe[out])
        dist.append(d[out])
    if not rows:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    return np.concatenate(rows).astype(np.int64), np.concatenate(dist)


def _km(d: float) -> str:
    return f"{d / 1000:.1f} km" if d >= 1000 else f"{d:.0f} m"


def _area_text(georef: Georef) -> str:
    return f"{georef.area_source} operating area ({georef.area.describe()})"


__all__ = ["check_area"]
