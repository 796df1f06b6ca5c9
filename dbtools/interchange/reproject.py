"""``db export --crs EPSG:XXXX``: the GIS layers in another CRS (pyproj).

The layers are built in the network's geodetic datum (lon, lat: :func:`geodetic_epsg`);
:func:`reproject` transforms every position of every geometry (Point, LineString and the
other GeoJSON types) to the target CRS in (x, y) order — longitude/easting first, whatever
the CRS's official axis order, as GeoJSON, GeoPackage and GeoParquet store them. A height
(the third value) is kept as it is: the transformation is horizontal. A position the
transformation cannot express (outside the CRS's area of use, pyproj's ``inf``) is a
UsageError: nothing is written.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from dbtools.interchange.geometry import epsg_of
from schemas.errors import UsageError


def parse_crs(text: str) -> int:
    """The EPSG code of ``EPSG:XXXX`` (or ``urn:ogc:def:crs:EPSG::XXXX``, or the bare number),
    checked against PROJ's database; UsageError when it is not a known EPSG CRS."""
    from pyproj import CRS
    from pyproj.exceptions import CRSError

    try:
        code = epsg_of(text)
        CRS.from_epsg(code)
    except (ValueError, CRSError) as exc:
        raise UsageError(f"--crs '{text}': not an EPSG CRS PROJ knows (give EPSG:XXXX, e.g. EPSG:3067)") from exc
    return code


def _positions(coords: Any, out: list[list[float]]) -> None:
    """Collect the positions (lists of numbers) of nested GeoJSON coordinates in order."""
    if coords and isinstance(coords[0], int | float):
        out.append(coords)
    else:
        for c in coords:
            _positions(c, out)


def _rebuild(coords: Any, it: Any) -> Any:
    if coords and isinstance(coords[0], int | float):
        return next(it)
    return [_rebuild(c, it) for c in coords]


def reproject(features: Sequence[dict[str, Any]], source_epsg: int, target_epsg: int) -> list[dict[str, Any]]:
    """Copies of ``features`` with every geometry in ``target_epsg`` (module doc); the same
    features when the CRSs are equal."""
    if source_epsg == target_epsg:
        return list(features)
    from pyproj import Transformer

    positions: list[list[float]] = []
    for f in features:
        if f["geometry"] is not None:
            _positions(f["geometry"]["coordinates"], positions)
    if not positions:
        return list(features)
    t = Transformer.from_crs(source_epsg, target_epsg, always_xy=True)
    xs, ys = t.transform([p[0] for p in positions], [p[1] for p in positions], errcheck=False)
    moved = []
    for p, x, y in zip(positions, xs, ys, strict=True):
        if not (math.isfinite(x) and math.isfinite(y)):
            raise UsageError(f"--crs EPSG:{target_epsg}: the point ({p[0]}, {p[1]}) lies outside what that CRS covers")
        moved.append([float(x), float(y), *p[2:]])
    it = iter(moved)
    out = []
    for f in features:
        g = f["geometry"]
        geometry = None if g is None else {**g, "coordinates": _rebuild(g["coordinates"], it)}
        out.append({**f, "geometry": geometry})
    return out
