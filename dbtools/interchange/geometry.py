"""railML coordinates → lon/lat, and track geometry → ``gis grid`` inputs and a grid.

Every georeferenced point of a track with a km (railML 2.x ``geoCoord`` on placed elements,
railML 3 ``intrinsicCoordinate`` with a linear and a geometric coordinate) is a centreline
vertex *and* a kilometre post of its line; shape vertices without a km (a gml LineString)
are vertices only. With at least two posts on a line the grid is built by
:func:`dbtools.gis.grid.build_grid` — the same code as ``gis grid`` — so an imported
network gets exactly the grid a survey with those points would give.

Coordinate order: a geographic CRS in EPSG axis order (lat, lon), as railML 2.x ``geoCoord``
and GML ``pos`` write it; a projected CRS (easting, northing). railML 3
``geometricCoordinate`` is read as (x = lon, y = lat) in a geographic CRS.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from typing import Any

import pandas as pd

from dbtools.interchange.model import RTrack

WGS84 = 4326
_EPSG_RE = re.compile(r"(?:EPSG\D*)(\d{4,6})\s*$", re.IGNORECASE)


def epsg_of(text: str | None) -> int:
    """The EPSG code in ``EPSG:3067``, ``urn:ogc:def:crs:EPSG::4326``, ``…/EPSG/0/4258`` or
    ``4326``; WGS 84 when ``text`` is None. ValueError for anything else."""
    if text is None:
        return WGS84
    t = text.strip()
    if t.isdigit():
        return int(t)
    m = _EPSG_RE.search(t)
    if not m:
        raise ValueError(f"CRS '{text}' is not an EPSG code")
    return int(m.group(1))


def _crs(epsg: int) -> Any:
    from dbtools.gis.geometry import crs_of  # pyproj: only once a coordinate is converted

    return crs_of(epsg)


def geodetic_epsg(metric_epsg: int) -> int:
    """EPSG code of the geodetic CRS (the lat/lon datum) of a projected CRS; WGS 84 when PROJ
    has no code for it."""
    geo = _crs(metric_epsg).geodetic_crs
    code = geo.to_epsg() if geo is not None else None
    return int(code) if code else WGS84


def to_lonlat(values: Sequence[float], crs: str | None, *, xy: bool = False) -> tuple[float, float, float | None]:
    """(lon, lat, height) of one coordinate tuple in ``crs`` (module doc for the order);
    ``xy``: (x = lon, y = lat) for a geographic CRS. Lat/lon stay in the CRS's own datum
    (no datum shift, as everywhere in the suite)."""
    if len(values) < 2:
        raise ValueError("needs at least two coordinates")
    epsg = epsg_of(crs)
    c = _crs(epsg)
    h = float(values[2]) if len(values) > 2 else None
    if c.is_geographic:
        lat, lon = (values[1], values[0]) if xy else (values[0], values[1])
    elif c.is_projected:
        from dbtools.gis.geometry import geodetic_transformer

        lon, lat = geodetic_transformer(epsg).transform(values[0], values[1], direction="INVERSE")
    else:
        raise ValueError(f"EPSG:{epsg} is neither geographic nor projected")
    if not (-90 <= lat <= 90 and -180 <= lon <= 180):
        raise ValueError(f"({lat}, {lon}) is not a latitude/longitude")
    return float(lon), float(lat), h


def survey_frames(tracks: Sequence[tuple[RTrack, str, str]]) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(centreline vertices, km posts) in the ``gis grid`` formats from the georeferenced
    points of (railML track, line_code, track) triples; vertices in km order per track."""
    vertices: list[dict[str, Any]] = []
    posts: dict[tuple[str, float], dict[str, Any]] = {}
    chains: dict[tuple[str, str], list[Any]] = {}
    for rt, line, track in tracks:
        chains.setdefault((line, track), []).extend(rt.geo)
    for (line, track), pts in sorted(chains.items()):
        pts = sorted(pts, key=lambda p: (p.km if p.km == p.km else float("inf"), p.pos))
        seq = 0
        last: tuple[float, float] | None = None
        for p in pts:
            if last == (p.lon, p.lat):
                continue
            seq += 1
            last = (p.lon, p.lat)
            vertices.append(
                {"line_code": line, "track": track, "seq": seq, "lon": p.lon, "lat": p.lat, "height_m": p.height}
            )
            if not p.vertex_only:
                posts.setdefault(
                    (line, round(p.km, 3)),
                    {"line_code": line, "km_m": p.km, "lon": p.lon, "lat": p.lat, "km_after_m": p.km_after},
                )
    cl = pd.DataFrame(vertices, columns=["line_code", "track", "seq", "lon", "lat", "height_m"])
    kp = pd.DataFrame(list(posts.values()), columns=["line_code", "km_m", "lon", "lat", "km_after_m"])
    return cl, kp.sort_values(["line_code", "km_m"]).reset_index(drop=True)


def grid_from_survey(cl: pd.DataFrame, kp: pd.DataFrame) -> Any:
    """The 20 m grid of :func:`dbtools.gis.grid.build_grid` from survey frames (typed as the
    ``gis grid`` readers type them)."""
    from dbtools.gis.grid import build_grid
    from schemas.frames import read_and_check
    from schemas.gisinput import CENTRELINE_VERTICES, KM_POSTS

    cl_t = read_and_check(CENTRELINE_VERTICES, cl.astype(str).replace({"None": "", "nan": ""}), file="railml").frame
    kp_t = read_and_check(KM_POSTS, kp.astype(str).replace({"None": "", "nan": ""}), file="railml").frame
    return build_grid(cl_t, kp_t, centrelines_file="railml centrelines", posts_file="railml km posts")
