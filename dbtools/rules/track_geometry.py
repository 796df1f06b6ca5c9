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

**Lengths without a geodesic a step** (:func:`dbtools.gis.index.step_bounds`): every step's
geodesic length lies in [low, high] from its straight chord, so each length is bracketed by
the same sums over the lower and the upper bounds (a length is a sum of steps with weights in
[0, 1], the interpolated part steps included). ``track_geometry(…, doubtful)`` asks the caller
which brackets decide nothing (the track-length rule: a bracket that straddles its limit);
only the steps of those tracks are solved exactly (``Geod.inv``). Without ``doubtful`` every
length is exact.

Interpolation runs over all grid tracks in one call: each (line, track) grid is shifted to
its own band of a single increasing key (band index × span + km), and end km are clamped
into their own grid's range before the look-up, so no interpolation crosses from one
grid into the next.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import GEOD
from dbtools.gis.index import exact_steps, grid_index, step_bounds
from dbtools.network import Network, sorted_by
from dbtools.rules.common import column, texts
from dbtools.topology import all_tracks, first_rows, grid_extents, track_codes
from schemas.enums import TrackEnd
from schemas.network import TRACK_POINTS
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


#: Per step (length n − 1): the geodesic length's lower and upper bounds, 0 across groups.
Bounds = tuple[F64, F64]


class _Lengths:
    """Lengths of some rows of the track table, each a function of the step lengths ``d`` of
    one point sequence (``lon``, ``lat``; ``same[i]``: step i joins two points of one group);
    ``steps(rows)`` the steps the lengths of those rows depend on."""

    def __init__(
        self,
        rows: npt.NDArray[np.int64],
        lon: F64,
        lat: F64,
        same: npt.NDArray[np.bool_],
        of: Callable[[F64], F64],
        steps: Callable[[npt.NDArray[np.bool_]], npt.NDArray[np.bool_]],
        exact: F64 | None = None,
        bounds: Bounds | None = None,
    ) -> None:
        self.rows, self.lon, self.lat, self.same, self.of, self.steps = rows, lon, lat, same, of, steps
        if exact is not None:
            self.low = self.high = np.where(same, exact, 0.0)
        else:
            low, high = bounds if bounds is not None else step_bounds(lon, lat)
            far = np.flatnonzero(same & ~(np.isfinite(low) & np.isfinite(high)))
            if far.size:
                low, high = low.copy(), high.copy()  # ``bounds`` may be the grid index's own
                low[far] = high[far] = exact_steps(lon, lat, far)  # the chord bounds nothing: solved
            self.low, self.high = np.where(same, low, 0.0), np.where(same, high, 0.0)

    def bounds(self) -> Bounds:
        return self.of(self.low), self.of(self.high)

    def exact(self, which: npt.NDArray[np.bool_]) -> F64:
        """Exact lengths of the rows ``which`` (a mask over ``rows``); others from the lower bounds."""
        if self.low is self.high:
            return self.of(self.low)
        need = np.flatnonzero(self.steps(which) & self.same)
        d = self.low.copy()
        d[need] = exact_steps(self.lon, self.lat, need)
        return self.of(d)


def track_geometry(
    net: Network,
    tracks: pd.DataFrame,
    doubtful: Callable[[F64, F64], npt.NDArray[np.bool_]] | None = None,
    azimuths: npt.NDArray[np.bool_] | None = None,
) -> pd.DataFrame:
    """Per row of ``tracks`` (:func:`dbtools.topology.all_tracks`): ``lat_begin, lon_begin,
    az_begin, lat_end, lon_end, az_end`` (azimuths outward, degrees from north),
    ``geo_length_low_m`` ≤ ``geo_length_high_m`` bounding the centreline's length and
    ``geo_length_m`` — exact where ``doubtful(low, high)`` (all rows at once) is true or
    ``doubtful`` is not given, else NaN; NaN everywhere where the track has no centreline.
    ``azimuths`` (a mask over the rows): the only rows whose azimuths are wanted (the others'
    are NaN: two ``Geod.inv`` a track saved); all rows when not given."""
    n = len(tracks)
    out = {k: _nan(n) for k in ("lat_begin", "lon_begin", "az_begin", "lat_end", "lon_end", "az_end")}
    want_az = np.ones(n, dtype=bool) if azimuths is None else np.asarray(azimuths, dtype=bool)
    own, own_len, at = _own_points(net, tracks)
    has_points = at >= 0
    parts = []
    if has_points.any():
        sel = own.iloc[at[has_points]]
        for k in ("lat_begin", "lon_begin", "lat_end", "lon_end"):
            out[k][has_points] = sel[k].to_numpy(dtype=float)
        assert own_len is not None
        az_rows = np.flatnonzero(has_points & want_az)
        out["az_begin"][az_rows], out["az_end"][az_rows] = own_len.azimuths(at[az_rows])
        parts.append(own_len.select(np.flatnonzero(has_points), at[has_points]))
    grid_len = _from_gis(net, tracks, ~has_points, out, want_az)
    if grid_len is not None:
        parts.append(grid_len)
    low, high, exact = _nan(n), _nan(n), _nan(n)
    for part in parts:
        low[part.rows], high[part.rows] = part.bounds()
    want = np.ones(n, dtype=bool) if doubtful is None else np.asarray(doubtful(low, high), dtype=bool)
    for part in parts:
        which = want[part.rows]
        if which.any():
            exact[part.rows[which]] = part.exact(which)[which]
    return pd.DataFrame(
        {**out, "geo_length_low_m": low, "geo_length_high_m": high, "geo_length_m": exact}, index=tracks.index
    )


class _OwnLengths:
    """Polyline lengths of the tracks of track_points (one group of points per track)."""

    def __init__(self, lon: F64, lat: F64, ids: npt.NDArray[np.intp], first: npt.NDArray[np.intp]) -> None:
        self.lon, self.lat, self.ids, self.first = lon, lat, ids, first
        self.last = np.r_[first[1:] - 1, len(ids) - 1]
        self.same = ids[1:] == ids[:-1]

    def azimuths(self, groups: npt.NDArray[np.intp]) -> tuple[F64, F64]:
        """Outward azimuths [deg] at the begin and the end of the track groups ``groups``: the
        first chord's reversed, the last chord's (NaN for a track of a single point)."""
        first, last = self.first[groups], self.last[groups]
        single = first == last
        nxt, prv = first[~single], last[~single] - 1
        lat, lon = self.lat, self.lon
        az_b, az_e = _nan(len(groups)), _nan(len(groups))
        az_b[~single] = (_inv(lat[nxt], lon[nxt], lat[nxt + 1], lon[nxt + 1])[0] + 180.0) % 360.0
        az_e[~single] = _inv(lat[prv], lon[prv], lat[prv + 1], lon[prv + 1])[0]
        return az_b, az_e

    def select(self, rows: npt.NDArray[np.int64], groups: npt.NDArray[np.intp]) -> _Lengths:
        """The lengths of the track groups ``groups``, for the track-table rows ``rows``."""
        first, last, ids = self.first[groups], self.last[groups], self.ids

        def of(d: F64) -> F64:
            cum = np.r_[0.0, np.cumsum(d)]
            return np.asarray(cum[last] - cum[first], dtype=float)

        def steps(which: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
            return np.isin(ids[:-1], ids[first[which]])

        return _Lengths(rows, self.lon, self.lat, self.same, of, steps)


def _own_points(net: Network, tracks: pd.DataFrame) -> tuple[pd.DataFrame, _OwnLengths | None, npt.NDArray[np.int64]]:
    """:func:`_from_track_points` of the network's track_points and the group of each row of
    ``tracks`` in it (−1: none). For :func:`dbtools.topology.all_tracks` and track_points as
    read from a DB (sorted by track and pos) the points are grouped by the network's track
    codes (:func:`dbtools.topology.track_codes`: no text hashed again); else by their ids."""
    tp, n = net.track_points, len(tracks)
    if not tp.empty and tracks is all_tracks(net) and sorted_by(tp, ("track_id", "pos_m")):
        codes = track_codes(net)
        own, own_len = _from_track_points(tp, codes.of[(TRACK_POINTS.name, "track_id")])
        group = np.full(len(codes.uniques), -1, dtype=np.int64)
        group[own.index.to_numpy()] = np.arange(len(own))
        return own, own_len, group[codes.of[("all_tracks", "track_id")]]
    own, own_len = _from_track_points(tp)
    at = own.index.get_indexer(pd.Index(texts(tracks["track_id"]))) if len(own) else np.full(n, -1)
    return own, own_len, np.asarray(at, dtype=np.int64)


def _from_track_points(
    tp: pd.DataFrame, codes: npt.NDArray[np.int64] | None = None
) -> tuple[pd.DataFrame, _OwnLengths | None]:
    """End points of every track in track_points, and their polyline lengths and outward end
    azimuths (:meth:`_OwnLengths.azimuths`: the first and last chord's ``Geod.inv`` only).
    Indexed by the track id, or by the code of ``codes`` (one per row of ``tp``, equal for
    equal ids; ``tp`` then sorted by track and pos)."""
    if tp.empty:
        return pd.DataFrame(), None
    if codes is not None:
        ids = codes
    else:
        if not sorted_by(tp, ("track_id", "pos_m")):
            tp = tp.sort_values(["track_id", "pos_m"], kind="stable")
        ids, _ = pd.factorize(tp["track_id"], use_na_sentinel=False)  # equal ids, equal codes
    lat, lon = tp["lat"].to_numpy(float), tp["lon"].to_numpy(float)
    first = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    last = np.r_[first[1:] - 1, len(ids) - 1]
    ends = pd.DataFrame(
        {
            "lat_begin": lat[first],
            "lon_begin": lon[first],
            "lat_end": lat[last],
            "lon_end": lon[last],
        },
        index=pd.Index(texts(tp["track_id"].iloc[first]), dtype=object) if codes is None else pd.Index(ids[first]),
    )
    return ends, _OwnLengths(lon, lat, ids, first)


def _cached_steps(net: Network, g: pd.DataFrame) -> tuple[F64 | None, Bounds | None]:
    """The grid index's exact steps (:attr:`GridIndex.dist`) or else its step bounds
    (:attr:`GridIndex.bounds`), when already computed and it holds the points of ``g`` (the
    grid sorted by line, track and km) in the same order; (None, None) otherwise."""
    if g is net.gis:
        grid = grid_index(net)
        if grid.whole_frame:
            if "dist" in grid.__dict__:
                return grid.dist, None
            if "bounds" in grid.__dict__:
                return None, grid.bounds
    return None, None


def _from_gis(
    net: Network, tracks: pd.DataFrame, todo: npt.NDArray[np.bool_], out: dict[str, F64], want_az: npt.NDArray[np.bool_]
) -> _Lengths | None:
    """Fill ``out`` for the tracks along a line grid (module doc; azimuths only where
    ``want_az``); their lengths."""
    gis = net.gis
    if gis.empty or not todo.any():
        return None
    ext = grid_extents(net)
    uniq: pd.MultiIndex | None
    if "start" in ext.columns:  # sorted by line, track and km, as read from a DB: the grid's runs, no group-by
        g = gis
        codes: npt.NDArray[np.int64] = np.repeat(np.arange(len(ext)), np.diff(np.r_[ext["start"].to_numpy(), len(g)]))
        uniq = None  # the rows of ``ext``: the network's line/track codes (all_tracks) or a MultiIndex
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

    idx = np.flatnonzero(todo)
    gid = _grid_rows(net, tracks, idx, uniq if uniq is not None else ext)
    k0 = tracks["km_begin_m"].to_numpy(dtype=float, na_value=np.nan)[idx]
    k1 = tracks["km_end_m"].to_numpy(dtype=float, na_value=np.nan)[idx]
    ok = (gid >= 0) & np.isfinite(k0) & np.isfinite(k1)
    idx, gid, k0, k1 = idx[ok], gid[ok], k0[ok], k1[ok]
    if idx.size == 0:
        return None

    def key_at(k: F64, some: npt.NDArray[np.intp] | None = None) -> F64:
        g_ = gid if some is None else gid[some]
        return np.asarray(g_ * span + (np.clip(k, lo[g_], hi[g_]) - base), dtype=float)

    def at(k: F64, some: npt.NDArray[np.intp]) -> tuple[F64, F64]:
        """Lat and lon at km ``k`` of the tracks ``gid[some]``."""
        kk = key_at(k, some)
        return np.interp(kk, key, lat), np.interp(kk, key, lon)

    at0, at1 = Interpolation(key_at(k0), key), Interpolation(key_at(k1), key)  # each end's bracket searched once
    la0, lo0, la1, lo1 = at0(lat), at0(lon), at1(lat), at1(lon)
    for name, v in (("lat_begin", la0), ("lon_begin", lo0), ("lat_end", la1), ("lon_end", lo1)):
        out[name][idx] = v
    az = np.flatnonzero(want_az[idx])
    inward = np.sign(k1[az] - k0[az]) * GIS_SPACING_M
    li0, loi0 = at(k0[az] + inward, az)
    li1, loi1 = at(k1[az] - inward, az)
    out["az_begin"][idx[az]] = _inv(li0, loi0, la0[az], lo0[az])[0]
    out["az_end"][idx[az]] = _inv(li1, loi1, la1[az], lo1[az])[0]

    def of(d: F64) -> F64:
        cum = np.concatenate([[0.0], np.cumsum(d)])
        return np.abs(at1(cum) - at0(cum))

    def steps(which: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_]:
        return np.isin(codes[:-1], gid[which])  # the whole grid of each track's line and track

    return _Lengths(idx, lon, lat, codes[1:] == codes[:-1], of, steps, *_cached_steps(net, g))


class Interpolation:
    """``np.interp(x, xp, fp)`` for many ``fp`` over the same ``x`` and ``xp`` (``xp``
    increasing): the bracket xp[j] ≤ x < xp[j+1] of each x is searched once, and each call
    does numpy's own arithmetic — slope (fp[j+1] − fp[j]) / (xp[j+1] − xp[j]), value
    slope·(x − xp[j]) + fp[j] (from the right end of the bracket when that is NaN); fp[j] where
    x = xp[j]; fp[0] left of xp, fp[−1] from xp[−1] on; NaN where x is NaN — so every value is
    ``np.interp``'s to the bit. An ``xp`` of fewer than two points, or holding NaN or not
    increasing: ``np.interp`` itself."""

    def __init__(self, x: F64, xp: F64) -> None:
        self.x, self.xp = x, xp
        self.plain = len(xp) < 2 or not bool(np.all(xp[1:] >= xp[:-1]))  # False as well where xp holds NaN
        if self.plain:
            return
        n = len(xp)
        j = np.searchsorted(xp, x, side="right") - 1
        self.j = np.clip(j, 0, n - 2)
        self.lower = xp[self.j]
        self.upper = xp[self.j + 1]
        self.first = np.flatnonzero(j < 0)
        self.last = np.flatnonzero(j >= n - 1)
        self.hit = np.flatnonzero((j >= 0) & (j < n - 1) & (self.lower == x))
        self.nan = np.flatnonzero(np.isnan(x))

    def __call__(self, fp: F64) -> F64:
        if self.plain:
            return np.asarray(np.interp(self.x, self.xp, fp), dtype=float)
        y0, y1 = fp[self.j], fp[self.j + 1]
        with np.errstate(all="ignore"):  # as np.interp: inf and NaN pass through, no warning
            slope = (y1 - y0) / (self.upper - self.lower)
            r = slope * (self.x - self.lower) + y0
            again = np.flatnonzero(np.isnan(r))
            if again.size:
                r[again] = slope[again] * (self.x[again] - self.upper[again]) + y1[again]
                still = again[np.isnan(r[again]) & (y0[again] == y1[again])]
                r[still] = y0[still]
        r[self.hit] = y0[self.hit]
        r[self.last] = fp[-1]
        r[self.first] = fp[0]
        r[self.nan] = self.x[self.nan]
        return np.asarray(r, dtype=float)


def _grid_rows(
    net: Network, tracks: pd.DataFrame, idx: npt.NDArray[np.intp], grids: pd.MultiIndex | pd.DataFrame
) -> npt.NDArray[np.int64]:
    """The grid (row of ``grids``: its (line_code, track) pairs) of the tracks ``idx`` (−1:
    none): for :func:`dbtools.topology.all_tracks` and the rows of :func:`grid_extents`, the
    network's shared codes (:attr:`dbtools.topology.TrackCodes.line_tracks`), else a look-up."""
    if isinstance(grids, pd.DataFrame):
        if tracks is all_tracks(net) and grids is grid_extents(net):
            return track_codes(net).line_tracks.grid_rows("all_tracks")[idx]
        grids = pd.MultiIndex.from_arrays([texts(grids["line_code"]), texts(grids["track"])])
    t = tracks.iloc[idx]
    return np.asarray(grids.get_indexer(pd.MultiIndex.from_arrays([texts(t["line_code"]), texts(t["track"])])))


def is_begin(ends: pd.Series) -> npt.NDArray[np.bool_]:
    """Which of the ends (``begin``/``end`` text, as held) are ``begin`` (False where missing):
    one comparison of the column as held, no Python string per value."""
    return np.asarray((ends == TrackEnd.BEGIN.value).to_numpy(dtype=bool, na_value=False), dtype=bool)


def end_coordinates(
    geo: pd.DataFrame, rows: npt.NDArray[np.int64], at_begin: npt.NDArray[np.bool_]
) -> tuple[F64, F64, F64]:
    """(lat, lon, outward azimuth) of the given track rows at their begin where ``at_begin``,
    else at their end."""
    pick = {c: geo[f"{c}_begin"].to_numpy(float)[rows] for c in ("lat", "lon", "az")}
    alt = {c: geo[f"{c}_end"].to_numpy(float)[rows] for c in ("lat", "lon", "az")}
    return tuple(np.where(at_begin, pick[c], alt[c]) for c in ("lat", "lon", "az"))  # type: ignore[return-value]


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


def coded_chord_azimuths(net: Network, tracks: npt.NDArray[np.int64]) -> tuple[npt.NDArray[np.int64], F64]:
    """:func:`chord_azimuths` of the network's track_points as read from a DB (sorted by track
    and pos) for the tracks of the track codes ``tracks`` (:func:`dbtools.topology.track_codes`:
    equal ids, equal codes), by those codes: (the track code of each chord, its azimuth)."""
    codes = track_codes(net)
    own = codes.of[(TRACK_POINTS.name, "track_id")]
    wanted = np.zeros(len(codes.uniques), dtype=bool)
    wanted[tracks] = True
    sel = np.flatnonzero(wanted[own])
    ids = own[sel]
    tp = net.track_points
    return _chords(ids, tp["lat"].to_numpy(float)[sel], tp["lon"].to_numpy(float)[sel])


def chord_azimuths(tp: pd.DataFrame, track_ids: set[str]) -> pd.DataFrame:
    """Azimuth [deg] of every chord between consecutive track_points of the given tracks:
    columns ``track_id``, ``az``."""
    held = tp["track_id"]
    wanted = pd.Series(sorted(track_ids), dtype=held.dtype if isinstance(held.dtype, pd.StringDtype) else object)
    sel = tp[first_rows(wanted, held) >= 0]  # as Arrow text when tp holds it: Arrow's hash look-up
    if not sorted_by(sel, ("track_id", "pos_m")):
        sel = sel.sort_values(["track_id", "pos_m"], kind="stable")
    cid, az = _chords(texts(sel["track_id"]), sel["lat"].to_numpy(float), sel["lon"].to_numpy(float))
    return pd.DataFrame({"track_id": cid, "az": az})


def _chords(ids: npt.NDArray[Any], lat: F64, lon: F64) -> tuple[npt.NDArray[Any], F64]:
    """(the track of each chord, its azimuth [deg]) between consecutive points of one track:
    ``ids`` the points' tracks, in track and pos order."""
    az, _ = _inv(lat[:-1], lon[:-1], lat[1:], lon[1:])
    same = ids[1:] == ids[:-1] if len(ids) else np.zeros(0, dtype=bool)
    return (ids[1:][same] if len(ids) else ids), az[same]
