"""Geometry of every track at once, for the topology rules: the coordinates and outward
azimuth of both ends and the length of the centreline (SPEC §8.1), vectorised over the whole
network (no per-track Python loop: a national network has ≥ 50,000 tracks).

* A track with ``track_points`` (crossovers, connecting curves, station tracks…): its
  first/last point; the azimuth of the first/last chord, pointing out of the track; its
  length the sum of the ellipsoidal (GRS80) distances between consecutive points.
* A track along a line's ``gis`` grid (declared with line, track and both end km, or
  implied): the grid of its line and track is linearly interpolated at the end km — an end
  km between two grid points (a switch toe off the 20 m grid) is placed on the chord
  between them; its length is the difference of the cumulative chord length of the grid at
  the two end km; the outward azimuth at an end is that of the chord from the grid point
  ``GIS_SPACING_M`` inside the track to the end.

Interpolation runs over all grid tracks in one call: each (line, track) grid is shifted to
its own band of a single increasing key (band index × span + km), and end km are clamped
into their own grid's range before the look-up, so no interpolation crosses from one
grid into the next.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import GEOD
from dbtools.gis.index import grid_index
from dbtools.network import Network, sorted_by
from dbtools.rules.common import column, texts
from dbtools.topology import first_rows, grid_extents
from schemas.tables import GIS_SPACING_M

F64 = npt.NDArray[np.float64]


def _inv(lat0: F64, lon0: F64, lat1: F64, lon1: F64) -> tuple[F64, F64]:
    """Forward azimuth [deg from north] and ellipsoidal distance [m] from point 0 to 1."""
    if lat0.size == 0:
        return np.empty(0), np.empty(0)
    az, _, dist = GEOD.inv(lon0, lat0, lon1, lat1)
    return np.asarray(az, dtype=float), np.asarray(dist, dtype=float)


def _nan(n: int) -> F64:
    return np.full(n, np.nan)


def track_geometry(net: Network, tracks: pd.DataFrame) -> pd.DataFrame:
    """Per row of ``tracks`` (:func:`dbtools.topology.all_tracks`): ``lat_begin, lon_begin,
    az_begin, lat_end, lon_end, az_end`` (azimuths outward, degrees from north) and
    ``geo_length_m`` — NaN where the track has no centreline."""
    n = len(tracks)
    out = {k: _nan(n) for k in ("lat_begin", "lon_begin", "az_begin", "lat_end", "lon_end", "az_end", "geo_length_m")}
    tid = texts(tracks["track_id"])
    own = _from_track_points(net.track_points)
    at = own.index.get_indexer(pd.Index(tid)) if len(own) else np.full(n, -1)
    has_points = at >= 0
    if has_points.any():
        sel = own.iloc[at[has_points]]
        for k in out:
            out[k][has_points] = sel[k].to_numpy(dtype=float)
    _from_gis(net, tracks, ~has_points, out)
    return pd.DataFrame(out, index=tracks.index)


def _from_track_points(tp: pd.DataFrame) -> pd.DataFrame:
    """End points, outward end azimuths and polyline length of every track in track_points."""
    if tp.empty:
        return pd.DataFrame()
    if not sorted_by(tp, ("track_id", "pos_m")):
        tp = tp.sort_values(["track_id", "pos_m"], kind="stable")
    ids, _ = pd.factorize(tp["track_id"], use_na_sentinel=False)  # equal ids, equal codes
    lat, lon = tp["lat"].to_numpy(float), tp["lon"].to_numpy(float)
    first = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    last = np.r_[first[1:] - 1, len(ids) - 1]
    az, dist = _inv(lat[:-1], lon[:-1], lat[1:], lon[1:])
    same = ids[1:] == ids[:-1]
    seg_len = np.where(same, dist, 0.0)
    cum = np.r_[0.0, np.cumsum(seg_len)]
    single = first == last
    nxt, prv = np.minimum(first, len(az) - 1), np.maximum(last - 1, 0)
    az_b = np.where(single, np.nan, (az[nxt] + 180.0) % 360.0 if len(az) else np.nan)
    az_e = np.where(single, np.nan, az[prv] if len(az) else np.nan)
    return pd.DataFrame(
        {
            "lat_begin": lat[first],
            "lon_begin": lon[first],
            "az_begin": az_b,
            "lat_end": lat[last],
            "lon_end": lon[last],
            "az_end": az_e,
            "geo_length_m": cum[last] - cum[first],
        },
        index=pd.Index(texts(tp["track_id"].iloc[first]), dtype=object),
    )


def _steps(net: Network, g: pd.DataFrame) -> F64:
    """Ellipsoidal distance between consecutive rows of ``g`` (the grid sorted by line,
    track and km): the grid index's (:attr:`GridIndex.dist`, computed once per network) when
    it holds the same points in the same order, as it does for a valid grid."""
    if g is net.gis:
        grid = grid_index(net)
        n = len(g)
        if grid.pos.size == n and (n == 0 or (grid.pos[0] == 0 and bool(np.all(np.diff(grid.pos) == 1)))):
            return grid.dist
    lat, lon = g["lat"].to_numpy(float), g["lon"].to_numpy(float)
    return _inv(lat[:-1], lon[:-1], lat[1:], lon[1:])[1]


def _from_gis(net: Network, tracks: pd.DataFrame, todo: npt.NDArray[np.bool_], out: dict[str, F64]) -> None:
    """Fill ``out`` for the tracks along a line grid (module doc)."""
    gis = net.gis
    if gis.empty or not todo.any():
        return
    if sorted_by(gis, ("line_code", "track", "km_m")):  # as read from a DB: the grid's runs, no group-by
        g, ext = gis, grid_extents(net)
        codes: npt.NDArray[np.int64] = np.repeat(np.arange(len(ext)), np.diff(np.r_[ext["start"].to_numpy(), len(g)]))
        uniq = pd.MultiIndex.from_arrays([texts(ext["line_code"]), texts(ext["track"])])
        lo, hi = ext["km_lo"].to_numpy(float), ext["km_hi"].to_numpy(float)
    else:
        g = gis.sort_values(["line_code", "track", "km_m"])
        codes = g.groupby(["line_code", "track"], sort=False, observed=True).ngroup().to_numpy().astype(np.int64)
        first = g.iloc[np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])]
        uniq = pd.MultiIndex.from_arrays([column(first, "line_code"), column(first, "track")])
        lo = pd.Series(g["km_m"].to_numpy(float)).groupby(codes).min().to_numpy()
        hi = pd.Series(g["km_m"].to_numpy(float)).groupby(codes).max().to_numpy()
    km = g["km_m"].to_numpy(float)
    lat, lon = g["lat"].to_numpy(float), g["lon"].to_numpy(float)
    span = float(np.nanmax(km) - np.nanmin(km)) + 10.0 * GIS_SPACING_M
    base = float(np.nanmin(km))
    key = codes * span + (km - base)
    dist = _steps(net, g)
    cum = np.r_[0.0, np.cumsum(np.where(codes[1:] == codes[:-1], dist, 0.0))]

    t = tracks[todo]
    idx = np.flatnonzero(todo)
    q = pd.MultiIndex.from_arrays([texts(t["line_code"]), texts(t["track"])])
    gid = uniq.get_indexer(q)
    k0 = t["km_begin_m"].to_numpy(dtype=float, na_value=np.nan)
    k1 = t["km_end_m"].to_numpy(dtype=float, na_value=np.nan)
    ok = (gid >= 0) & np.isfinite(k0) & np.isfinite(k1)
    idx, gid, k0, k1 = idx[ok], gid[ok], k0[ok], k1[ok]
    if idx.size == 0:
        return

    def at(k: F64) -> tuple[F64, F64, F64]:
        kk = gid * span + (np.clip(k, lo[gid], hi[gid]) - base)
        return np.interp(kk, key, lat), np.interp(kk, key, lon), np.interp(kk, key, cum)

    la0, lo0, c0 = at(k0)
    la1, lo1, c1 = at(k1)
    inward = np.sign(k1 - k0) * GIS_SPACING_M
    li0, loi0, _ = at(k0 + inward)
    li1, loi1, _ = at(k1 - inward)
    az_b, _ = _inv(li0, loi0, la0, lo0)
    az_e, _ = _inv(li1, loi1, la1, lo1)
    for name, v in (
        ("lat_begin", la0),
        ("lon_begin", lo0),
        ("az_begin", az_b),
        ("lat_end", la1),
        ("lon_end", lo1),
        ("az_end", az_e),
        ("geo_length_m", np.abs(c1 - c0)),
    ):
        out[name][idx] = v


def end_coordinates(
    geo: pd.DataFrame, rows: npt.NDArray[np.int64], ends: npt.NDArray[np.object_]
) -> tuple[F64, F64, F64]:
    """(lat, lon, outward azimuth) of the given track rows at the given ends."""
    is_begin = ends == "begin"
    pick = {c: geo[f"{c}_begin"].to_numpy(float)[rows] for c in ("lat", "lon", "az")}
    alt = {c: geo[f"{c}_end"].to_numpy(float)[rows] for c in ("lat", "lon", "az")}
    return tuple(np.where(is_begin, pick[c], alt[c]) for c in ("lat", "lon", "az"))  # type: ignore[return-value]


def distance_m(lat0: F64, lon0: F64, lat1: F64, lon1: F64) -> F64:
    """Ellipsoidal distance [m], NaN where a coordinate is missing; 0 where the points are
    the same (as the geodesic gives it; most joined track ends coincide, so the geodesic is
    solved only for the others)."""
    out = _nan(len(lat0))
    ok = np.isfinite(lat0) & np.isfinite(lon0) & np.isfinite(lat1) & np.isfinite(lon1)
    same = ok & (lat0 == lat1) & (lon0 == lon1)
    out[same] = 0.0
    ok &= ~same
    if ok.any():
        out[ok] = _inv(lat0[ok], lon0[ok], lat1[ok], lon1[ok])[1]
    return out


def chord_azimuths(tp: pd.DataFrame, track_ids: set[str]) -> pd.DataFrame:
    """Azimuth [deg] of every chord between consecutive track_points of the given tracks:
    columns ``track_id``, ``az``."""
    sel = tp[first_rows(pd.Series(sorted(track_ids), dtype=object), tp["track_id"]) >= 0]
    if not sorted_by(sel, ("track_id", "pos_m")):
        sel = sel.sort_values(["track_id", "pos_m"], kind="stable")
    ids = texts(sel["track_id"])
    lat, lon = sel["lat"].to_numpy(float), sel["lon"].to_numpy(float)
    az, _ = _inv(lat[:-1], lon[:-1], lat[1:], lon[1:])
    same = ids[1:] == ids[:-1] if len(ids) else np.zeros(0, dtype=bool)
    return pd.DataFrame({"track_id": ids[1:][same] if len(ids) else ids, "az": az[same]})
