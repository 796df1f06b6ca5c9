"""Hand-made networks for the track-match tests, drawn in a local metric frame (x east, y
north, metres) around lat 60.2°, lon 24.9° and turned into lat/lon by the azimuthal
equidistant projection on GRS80 (scale error below 10⁻⁸ within 2 km of the centre, so the
drawn lengths and offsets are true on the ground)."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
import pandas as pd
from pyproj import Proj

from dbtools.network import Network, canonical, empty_frame
from schemas.network import CONNECTIONS, NETWORK_TRACKS, TRACK_POINTS
from schemas.tables import DB_TABLES

PROJ = Proj(proj="aeqd", lat_0=60.2, lon_0=24.9, ellps="GRS80", units="m")


def lonlat(x: object, y: object) -> tuple[np.ndarray, np.ndarray]:
    lon, lat = PROJ(np.asarray(x, dtype=float), np.asarray(y, dtype=float), inverse=True)
    return np.asarray(lon), np.asarray(lat)


def _densify(pts: list[tuple[float, float]], step: float = 20.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    xs, ys = [pts[0][0]], [pts[0][1]]
    for (x0, y0), (x1, y1) in pairwise(pts):
        n = max(1, int(np.ceil(np.hypot(x1 - x0, y1 - y0) / step)))
        f = np.arange(1, n + 1) / n
        xs += list(x0 + f * (x1 - x0))
        ys += list(y0 + f * (y1 - y0))
    x, y = np.array(xs), np.array(ys)
    pos = np.r_[0.0, np.cumsum(np.hypot(np.diff(x), np.diff(y)))]
    return x, y, pos


def make_network(
    tracks: dict[str, list[tuple[float, float]]], connections: list[tuple[str, str, str, str, str]] = ()
) -> Network:
    """Tracks as polylines (begin → end) and connections (track_a, end_a, track_b, end_b,
    navigability); every track's centreline in ``track_points``."""
    rows, pts = [], []
    for tid, poly in tracks.items():
        x, y, pos = _densify(poly)
        lon, lat = lonlat(x, y)
        rows.append({"track_id": tid, "line_code": None, "track": None, "kind": "siding", "km_begin_m": None,
                     "km_end_m": None, "length_m": float(pos[-1]), "name": None})  # fmt: skip
        pts.append(pd.DataFrame({"track_id": tid, "pos_m": pos, "km_m": np.nan, "lat": lat, "lon": lon}))
    conn = pd.DataFrame(
        [dict(zip(("track_a", "end_a", "track_b", "end_b", "navigability"), c, strict=True)) for c in connections],
        columns=["track_a", "end_a", "track_b", "end_b", "navigability"],
    ).assign(switch_id=None)
    tables = {t.name: empty_frame(t) for t in DB_TABLES}
    tables["tracks"] = canonical(NETWORK_TRACKS, pd.DataFrame(rows))
    tables["connections"] = canonical(CONNECTIONS, conn)
    tables["track_points"] = canonical(TRACK_POINTS, pd.concat(pts, ignore_index=True))
    return Network(tables, origin="hand-made")


def fixes(xy: list[tuple[float, float]] | np.ndarray, dt: float = 1.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, lat, lon) of fixes at plane points, ``dt`` seconds apart (NaN point: no position)."""
    a = np.asarray(xy, dtype=float).reshape(-1, 2)
    lon, lat = lonlat(a[:, 0], a[:, 1])
    return np.arange(len(a)) * dt, lat, lon
