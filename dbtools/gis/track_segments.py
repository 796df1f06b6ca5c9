"""Every track's centreline as short plane segments, for candidate search and projection.

Tracks are :func:`dbtools.topology.all_tracks` (declared and implied); a track's centreline
is :func:`dbtools.topology.centreline` (its ``track_points``, else its line's ``gis`` grid
between its end km), read here in one pass per table. Distance along a track (``pos``, from
its begin) and line km are the centreline's own (geodesic) values, interpolated linearly on
a segment; only directions and perpendicular offsets are taken in the plane — the
network's one metric CRS (:func:`dbtools.gis.index.network_georef`, else derived from the
points: :func:`dbtools.gis.index.projection_for`). Segments longer than ``max_segment_m``
are split (same line, interpolated pos/km) so that a search radius around segment midpoints
stays tight (:mod:`dbtools.gis.track_candidates`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import Projector
from dbtools.network import Network

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Longest plane segment kept; longer ones are split [m].
MAX_SEGMENT_M = 25.0


@dataclass(frozen=True)
class TrackGeometry:
    """Segments of all tracks (arrays of one length, one row per segment) and the tracks."""

    track_ids: list[str]
    length_m: F64
    """Per track: its length from begin to end [m] (``tracks.length_m``, else its centreline's)."""
    projector: Projector
    seg_track: I64
    x0: F64
    y0: F64
    dx: F64
    dy: F64
    s0: F64
    """Distance along the track at the segment's start [m]; ``ds`` its increment."""
    ds: F64
    km0: F64
    """Line km at the segment's start (NaN where the track has none); ``dkm`` its increment."""
    dkm: F64

    @property
    def index_of(self) -> dict[str, int]:
        return {t: i for i, t in enumerate(self.track_ids)}


def _polylines(net: Network) -> tuple[pd.DataFrame, list[str], F64]:
    """Centreline vertices (track, pos_m, km_m, lat, lon) of every track, begin to end."""
    from dbtools.topology import all_tracks

    tracks = all_tracks(net)
    ids = [str(t) for t in tracks["track_id"]]
    tp = net.track_points
    own = tp[["track_id", "pos_m", "km_m", "lat", "lon"]].astype(
        {"track_id": object, "pos_m": float, "km_m": float, "lat": float, "lon": float}
    )
    rest = tracks[~tracks["track_id"].astype(str).isin(set(own["track_id"].astype(str)))]
    pts = pd.concat([own, _on_lines(net, rest)], ignore_index=True)
    pts = pts[np.isfinite(pts["lat"].to_numpy(float)) & np.isfinite(pts["lon"].to_numpy(float))]
    pts = pts.sort_values(["track_id", "pos_m"], kind="stable").reset_index(drop=True)
    length = tracks["length_m"].to_numpy(dtype=float, na_value=np.nan)
    return pts, ids, length


def _on_lines(net: Network, tracks: pd.DataFrame) -> pd.DataFrame:
    """The ``gis`` grid points of each track along a line between its end km, ``pos`` =
    |km − km at begin| (:func:`dbtools.topology.centreline`, for all tracks at once)."""
    cols = ["track_id", "pos_m", "km_m", "lat", "lon"]
    t = tracks[tracks["line_code"].notna() & tracks["km_begin_m"].notna() & tracks["km_end_m"].notna()]
    if t.empty or net.gis.empty:
        return pd.DataFrame({c: [] for c in cols})
    t = pd.DataFrame(
        {
            "track_id": t["track_id"].astype(str).to_numpy(),
            "line_code": t["line_code"].astype(str).to_numpy(),
            "track": t["track"].astype(str).to_numpy(),
            "k0": t["km_begin_m"].to_numpy(float),
            "k1": t["km_end_m"].to_numpy(float),
        }
    )
    g = net.gis[["line_code", "track", "km_m", "lat", "lon"]]
    g = pd.DataFrame(
        {
            "line_code": g["line_code"].astype(str).to_numpy(),
            "track": g["track"].astype(str).to_numpy(),
            "km_m": g["km_m"].to_numpy(float),
            "lat": g["lat"].to_numpy(float),
            "lon": g["lon"].to_numpy(float),
        }
    )
    m = g.merge(t, on=["line_code", "track"], how="inner")
    km = m["km_m"].to_numpy(float)
    k0, k1 = m["k0"].to_numpy(float), m["k1"].to_numpy(float)
    lo, hi = np.minimum(k0, k1), np.maximum(k0, k1)
    m = m[(km >= lo - 1e-6) & (km <= hi + 1e-6)]
    out: pd.DataFrame = m.assign(pos_m=np.abs(m["km_m"].to_numpy(float) - m["k0"].to_numpy(float)))[cols]
    return out


def _projector(net: Network, lat: F64, lon: F64) -> Projector:
    from dbtools.gis.index import network_georef, projection_for

    g = network_georef(net)
    p = Projector.from_epsg(g.crs_epsg) if g is not None else projection_for(lat, lon)
    if p is None:
        raise ValueError("the network has no centreline points to match to")
    return p


def build_geometry(net: Network, *, max_segment_m: float = MAX_SEGMENT_M) -> TrackGeometry:
    """The segments of ``net`` (built once per loaded network through ``Network.cached``)."""

    def build() -> TrackGeometry:
        pts, ids, length = _polylines(net)
        index = {t: i for i, t in enumerate(ids)}
        tid = pts["track_id"].map(index).to_numpy(dtype=np.int64)
        lat, lon = pts["lat"].to_numpy(float), pts["lon"].to_numpy(float)
        proj = _projector(net, lat, lon)
        x, y = proj.to_xy(lon, lat)
        pos, km = pts["pos_m"].to_numpy(float), pts["km_m"].to_numpy(float)
        ok = tid[1:] == tid[:-1]
        a = np.flatnonzero(ok)
        seg_len = np.hypot(x[a + 1] - x[a], y[a + 1] - y[a])
        pieces = np.maximum(1, np.ceil(seg_len / max_segment_m)).astype(np.int64)
        rep = np.repeat(a, pieces)
        frac0 = (np.arange(len(rep)) - np.repeat(np.cumsum(pieces) - pieces, pieces)) / np.repeat(pieces, pieces)
        step = 1.0 / np.repeat(pieces, pieces)

        def lerp(v: F64, f: F64) -> F64:
            return v[rep] + f * (v[rep + 1] - v[rep])

        x0, y0, s0, k0 = lerp(x, frac0), lerp(y, frac0), lerp(pos, frac0), lerp(km, frac0)
        f1 = frac0 + step
        cl_len = np.zeros(len(ids))
        last = np.flatnonzero(np.r_[~ok, True])
        cl_len[tid[last]] = pos[last]
        length = np.where(np.isfinite(length) & (length > 0), length, cl_len)
        return TrackGeometry(
            ids, length, proj, tid[rep].astype(np.int64), x0, y0, lerp(x, f1) - x0, lerp(y, f1) - y0, s0,
            lerp(pos, f1) - s0, k0, lerp(km, f1) - k0,
        )  # fmt: skip

    return net.cached(("track_segments", max_segment_m), build)
