"""The track's 3-D coordinate series from the onboard DB's GIS grid [S002 fig. 1].

The 20 m grid of one line/track (lat, lon and rail height per km, sorted by km) becomes the
solver's polyline (:class:`~fieldlogs.gnss.track.TrackLine`, ECEF from WGS-84 geodetic
coordinates) with the km of every vertex, so that a solution's s along the polyline maps to
km by linear interpolation between the vertices: km(s) = km_j + (s − s_j)·(km_{j+1} − km_j)
/ (s_{j+1} − s_j). Consecutive points at the same place (a kilometrage break surveyed twice)
are kept once.

Heights are required and must be ellipsoidal: a height error δh moves each satellite's range
by −sin E·δh, which the clock absorbs only in part, and an orthometric grid (the geoid is
~36–40 m above the ellipsoid in Japan) would put the track tens of metres below the antennas.
The DB meta key ``height_datum`` says which (``ellipsoidal`` or ``orthometric``, with
``geoid_model``); a DB without the key is taken as ellipsoidal, which is what the
``gis.height_m`` column declares. No geoid model is shipped, so an orthometric grid is
refused rather than converted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.gnss.constants import FloatArray
from fieldlogs.gnss.geodesy import geodetic_to_ecef
from fieldlogs.gnss.track import TrackLine
from schemas.errors import EXIT_FINDINGS, TrainposError

#: DB meta keys of the height datum (written by ``db build`` when declared or derived).
HEIGHT_DATUM_KEY = "height_datum"
GEOID_MODEL_KEY = "geoid_model"
ELLIPSOIDAL = "ellipsoidal"


class GnssTrackError(TrainposError):
    """The DB cannot carry track-constrained positioning on a line/track (no heights, …)."""

    exit_code = EXIT_FINDINGS

    def __init__(self, message: str, *, reason: str, path: str | None = None) -> None:
        super().__init__(message, path=path)
        self.reason = reason
        """Short machine name: unknown_track, no_heights, partial_heights, orthometric_heights."""


@dataclass(frozen=True)
class GisTrack:
    """One line/track of the GIS grid as the solver's 3-D polyline, with km at every vertex."""

    line_code: str
    track: str
    line: TrackLine
    km: FloatArray
    """km of every vertex of ``line`` (non-decreasing)."""

    def km_of_s(self, s: FloatArray | float) -> FloatArray:
        """km of polyline positions s (linear between vertices; slope 1 beyond the ends)."""
        sa = np.asarray(s, dtype=float)
        out = np.interp(sa, self.line.s, self.km)
        out = np.where(sa < self.line.s[0], self.km[0] + (sa - self.line.s[0]), out)
        return np.asarray(np.where(sa > self.line.s[-1], self.km[-1] + (sa - self.line.s[-1]), out), dtype=float)

    def s_of_km(self, km: FloatArray | float) -> FloatArray:
        """Inverse of :meth:`km_of_s`."""
        ka = np.asarray(km, dtype=float)
        out = np.interp(ka, self.km, self.line.s)
        out = np.where(ka < self.km[0], self.line.s[0] + (ka - self.km[0]), out)
        return np.asarray(np.where(ka > self.km[-1], self.line.s[-1] + (ka - self.km[-1]), out), dtype=float)


def height_datum(network: Network) -> tuple[str, str]:
    """(datum, geoid model) of the DB's heights; ellipsoidal when the meta does not say."""
    return str(network.meta.get(HEIGHT_DATUM_KEY) or ELLIPSOIDAL), str(network.meta.get(GEOID_MODEL_KEY) or "")


def gis_track(network: Network, line_code: str, track: str) -> GisTrack:
    """The 3-D polyline of ``line_code``/``track`` (module docstring); cached per network.

    Raises :class:`GnssTrackError` when the grid has no such track, fewer than 2 points, heights
    missing on any point, or orthometric heights.
    """
    return network.cached(("gnss_track", line_code, track), lambda: _build(network, line_code, track))


def _build(network: Network, line_code: str, track: str) -> GisTrack:
    _check_datum(network)
    g = network.gis
    g = g[(g["line_code"] == line_code) & (g["track"] == track)].sort_values("km_m", kind="stable")
    return _polyline(network, line_code, track, g, "km_m", "GIS")


def points_track(network: Network, track_id: str) -> GisTrack:
    """The 3-D polyline of a network track from its ``track_points`` (lat, lon, rail height by
    ``pos_m``: a station or crossover track off the line grid), with ``pos_m`` in place of km
    (``line_code`` empty, ``track`` the track id); cached per network. Raises
    :class:`GnssTrackError` as :func:`gis_track` does."""
    return network.cached(("gnss_points_track", track_id), lambda: _points_build(network, track_id))


def _points_build(network: Network, track_id: str) -> GisTrack:
    _check_datum(network)
    tp = network.track_points
    tp = tp[tp["track_id"].astype(str) == track_id].sort_values("pos_m", kind="stable")
    return _polyline(network, "", track_id, tp, "pos_m", "track_points")


def _check_datum(network: Network) -> None:
    datum, geoid = height_datum(network)
    if datum != ELLIPSOIDAL:
        raise GnssTrackError(
            f"GIS heights of the DB are {datum}{f' ({geoid})' if geoid else ''}: track-constrained GNSS needs "
            "ellipsoidal heights (no geoid model is shipped to convert them)",
            reason="orthometric_heights",
            path=network.origin or None,
        )


def _polyline(network: Network, line_code: str, track: str, g: pd.DataFrame, along: str, table: str) -> GisTrack:
    """The polyline of the rows ``g`` (lat, lon, height_m, sorted by ``along``) as a GisTrack."""
    where = f"{line_code}/{track}" if line_code else track
    if len(g) < 2:
        raise GnssTrackError(
            f"track {where} has {len(g)} {table} point(s): no 3-D track", reason="unknown_track", path=network.origin
        )
    h = g["height_m"].to_numpy(dtype=float, na_value=np.nan) if "height_m" in g else np.full(len(g), np.nan)
    missing = int((~np.isfinite(h)).sum())
    if missing:
        reason = "no_heights" if missing == len(g) else "partial_heights"
        raise GnssTrackError(
            f"track {where}: height_m is empty on {missing} of {len(g)} {table} points; track-constrained GNSS "
            "needs the rail height of every point",
            reason=reason,
            path=network.origin or None,
        )
    km = g[along].to_numpy(dtype=float)
    xyz = geodetic_to_ecef(np.radians(g["lat"].to_numpy(dtype=float)), np.radians(g["lon"].to_numpy(dtype=float)), h)
    keep = np.concatenate([[True], np.linalg.norm(np.diff(xyz, axis=0), axis=1) > 1e-6])
    return GisTrack(line_code, track, TrackLine.from_ecef(xyz[keep]), km[keep])
