"""Geodesic lengths and resampling of lon/lat polylines on the WGS 84 ellipsoid.

A polyline's length is the sum of the geodesic distances between its consecutive vertices
(Karney's algorithm through ``pyproj.Geod``, accurate to nanometres); the distance of a
point along it is the length up to its segment plus the geodesic distance within it. A
point at distance ``s`` along a segment lies on the segment's geodesic: from the segment's
first vertex at the forward azimuth of the segment, ``s − S_i`` metres on (the direct
geodesic problem, ``Geod.fwd``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from pyproj import Geod

F64 = npt.NDArray[np.float64]
GEOD = Geod(ellps="WGS84")
#: Spacing of a track's centreline points (the ``track_points`` grid) [m].
STEP_M = 20.0


@dataclass(frozen=True)
class Polyline:
    """Vertices (lon, lat) [deg] and the distance of each from the first [m]."""

    lon: F64
    lat: F64
    cum: F64

    @property
    def length(self) -> float:
        return float(self.cum[-1]) if len(self.cum) else 0.0


def polyline(lon: npt.ArrayLike, lat: npt.ArrayLike) -> Polyline:
    """The polyline with its cumulative geodesic distances."""
    lo, la = np.asarray(lon, dtype=float), np.asarray(lat, dtype=float)
    if len(lo) < 2:
        return Polyline(lo, la, np.zeros(len(lo)))
    _, _, d = GEOD.inv(lo[:-1], la[:-1], lo[1:], la[1:])
    return Polyline(lo, la, np.concatenate([[0.0], np.cumsum(np.asarray(d, dtype=float))]))


def length_m(lon: npt.ArrayLike, lat: npt.ArrayLike) -> float:
    """Geodesic length of a lon/lat polyline [m]."""
    return polyline(lon, lat).length


def points_at(line: Polyline, pos: npt.ArrayLike) -> tuple[F64, F64]:
    """(lon, lat) of the points at distances ``pos`` along the line (clipped to it)."""
    s = np.clip(np.asarray(pos, dtype=float), 0.0, line.length)
    seg = np.clip(np.searchsorted(line.cum, s, side="right") - 1, 0, len(line.cum) - 2)
    az, _, _ = GEOD.inv(line.lon[seg], line.lat[seg], line.lon[seg + 1], line.lat[seg + 1])
    lon, lat, _ = GEOD.fwd(line.lon[seg], line.lat[seg], az, s - line.cum[seg])
    return np.asarray(lon, dtype=float), np.asarray(lat, dtype=float)


def grid_positions(length: float, step: float = STEP_M) -> F64:
    """0, step, 2·step … below ``length``, and ``length`` itself (the end is always a point)."""
    n = int(np.floor(length / step + 1e-9))
    pos = np.arange(n + 1, dtype=float) * step
    if length - pos[-1] > 1e-6:
        pos = np.append(pos, length)
    return pos


def resample(line: Polyline, step: float = STEP_M) -> tuple[F64, F64, F64]:
    """(pos, lon, lat) every ``step`` metres along the line from its first vertex, plus its
    last vertex (:func:`grid_positions`)."""
    pos = grid_positions(line.length, step)
    lon, lat = points_at(line, pos)
    lon[-1], lat[-1] = line.lon[-1], line.lat[-1]
    return pos, lon, lat


def azimuth_away(line: Polyline, from_end: bool, reach: float) -> float:
    """Forward azimuth [deg] from an end of the line towards the point ``reach`` metres
    into it (the direction a train leaving the node onto this line takes)."""
    r = min(reach, line.length)
    if from_end:
        lo, la = points_at(line, [line.length - r])
        az, _, _ = GEOD.inv(line.lon[-1], line.lat[-1], lo[0], la[0])
    else:
        lo, la = points_at(line, [r])
        az, _, _ = GEOD.inv(line.lon[0], line.lat[0], lo[0], la[0])
    return float(az)
