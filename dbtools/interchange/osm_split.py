"""Rail ways → tracks: splitting at switches and junctions, lengths, end directions and the
20 m centreline grid (SPEC §8.1: a track runs between two switches or ends).

**Splitting.** A way (each run of located nodes, :class:`~dbtools.interchange.osm_read.RailWay`)
is cut at every inner node that another rail way also holds (a junction, the end of another
way meeting it, a crossing) or that is tagged ``railway=switch|railway_crossing``. Pieces
keep the way's direction (begin = the earlier node). Ids are traceable: ``w<way id>`` for a
way that stays whole, else ``w<way id>_<k>`` for its k-th piece (k = 1, 2, … in the way's
node order). Two ways meeting end to end without a switch are *not* merged: each stays a
track and a ``both`` connection joins them (the OSM way stays findable by its id).

**Lengths** are geodesic (GRS80, :data:`dbtools.gis.geometry.GEOD`) summed over the way's
segments. **Directions** at a track end, for the switch geometry, are taken in the network's
UTM plane (:func:`dbtools.gis.georef.utm_epsg` of the median node): the unit vector from the
end node to the point :data:`DIR_M` along the track (or its other end when shorter) —
far enough that a short first segment does not decide the angle, near enough to stay on the
turnout (a 1:9 turnout's lead is ≈ 30 m).

**Grid.** Every track gets points at pos 0, 20, 40 … m and at its end (``track_points``),
lat/lon interpolated linearly in degrees within the OSM segment holding that pos (segments
are metres to a few hundred metres long: the chord–arc difference is far below OSM's
accuracy). All of it is done on the concatenated vertices of all pieces at once (numpy).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.interchange.osm_read import OsmData

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Distance along a track at which its end direction is taken [m] (module doc).
DIR_M = 15.0
#: Grid step of track_points [m] (schemas.network TRACK_POINTS).
STEP_M = 20.0
#: Split at inner nodes tagged railway=<one of these>.
SPLIT_KINDS = ("switch", "railway_crossing")


@dataclass
class Pieces:
    """All tracks cut from the ways, their vertices concatenated (piece i: ``start[i]:stop[i]``)."""

    track_id: list[str]
    way_index: I64
    start: I64
    stop: I64
    node: I64
    lat: F64
    lon: F64
    x: F64
    y: F64
    s: F64
    """Geodesic distance of each vertex from its piece's begin [m]."""
    epsg: int

    @property
    def length(self) -> F64:
        return self.s[self.stop - 1]

    @property
    def begin_node(self) -> I64:
        return self.node[self.start]

    @property
    def end_node(self) -> I64:
        return self.node[self.stop - 1]

    def __len__(self) -> int:
        return len(self.track_id)


def _cuts(data: OsmData) -> set[int]:
    """Nodes where ways are cut: held by more than one way position, or switch/crossing."""
    ids = [w.nodes[a:b] for w in data.ways for a, b in w.runs]
    if not ids:
        return set()
    allids = np.concatenate(ids)
    uniq, counts = np.unique(allids, return_counts=True)
    shared = set(uniq[counts >= 2].tolist())
    tagged = {n for n, node in data.nodes.items() if node.kind in SPLIT_KINDS}
    return shared | tagged


def split_ways(data: OsmData) -> Pieces:
    """Cut every way into tracks (module doc)."""
    from pyproj import Transformer

    from dbtools.gis.geometry import GEOD
    from dbtools.gis.georef import utm_epsg

    cuts = _cuts(data)
    cut_arr = np.fromiter(cuts, dtype=np.int64, count=len(cuts))
    sizes_all = np.array([len(w.nodes) for w in data.ways], dtype=np.int64)
    offsets = np.concatenate(([0], np.cumsum(sizes_all)))
    flat = np.concatenate([w.nodes for w in data.ways]) if data.ways else np.empty(0, np.int64)
    is_cut = np.isin(flat, cut_arr)  # one look-up for all nodes of all ways
    tid: list[str] = []
    way_index: list[int] = []
    chunks: list[tuple[int, int, int]] = []  # (way index, first, last) inclusive node indices
    for wi, way in enumerate(data.ways):
        runs = way.runs
        parts: list[tuple[int, int]] = []
        cut_here = is_cut[offsets[wi] : offsets[wi + 1]]
        for a, b in runs:
            inner = np.flatnonzero(cut_here[a + 1 : b - 1]) + a + 1
            bounds = [a, *inner.tolist(), b - 1]
            parts += list(itertools.pairwise(bounds))
        for k, (i, j) in enumerate(parts, start=1):
            tid.append(f"w{way.way_id}" if len(parts) == 1 else f"w{way.way_id}_{k}")
            way_index.append(wi)
            chunks.append((wi, i, j))
    sizes = np.array([j - i + 1 for _, i, j in chunks], dtype=np.int64)
    stop = np.cumsum(sizes)
    start = stop - sizes
    node = np.concatenate([data.ways[w].nodes[i : j + 1] for w, i, j in chunks]) if chunks else np.empty(0, np.int64)
    lat = np.concatenate([data.ways[w].lat[i : j + 1] for w, i, j in chunks]) if chunks else np.empty(0)
    lon = np.concatenate([data.ways[w].lon[i : j + 1] for w, i, j in chunks]) if chunks else np.empty(0)
    epsg = utm_epsg(float(np.median(lat)), float(np.median(lon))) if len(lat) else 32632
    x, y = Transformer.from_crs(4326, epsg, always_xy=True).transform(lon, lat)
    seg = np.zeros(len(lat))
    if len(lat) > 1:
        _, _, d = GEOD.inv(lon[:-1], lat[:-1], lon[1:], lat[1:])
        seg[1:] = d
    seg[start] = 0.0  # no segment across two pieces
    s = np.cumsum(seg)
    s -= np.repeat(s[start], sizes)
    return Pieces(
        tid, np.asarray(way_index, np.int64), start, stop, node, lat, lon, np.asarray(x), np.asarray(y), s, epsg
    )


def _global(p: Pieces) -> tuple[F64, F64]:
    """Vertex distances made increasing over all pieces (piece i offset by the lengths
    before it plus 1 m each), and the offsets."""
    base = np.concatenate(([0.0], np.cumsum(p.length + 1.0)[:-1]))
    sizes = p.stop - p.start
    return p.s + np.repeat(base, sizes), base


def at_pos(p: Pieces, piece: I64, pos: F64, what: str) -> F64:
    """Interpolate vertex values (``what``: lat, lon, x or y) at ``pos`` along ``piece``."""
    xp, base = _global(p)
    values = getattr(p, what)
    return np.asarray(np.interp(base[piece] + np.clip(pos, 0.0, p.length[piece]), xp, values), dtype=float)


def end_frame(p: Pieces) -> pd.DataFrame:
    """One row per track end: node, piece, end (begin/end) and the outward unit direction
    (dx, dy) in the UTM plane (module doc)."""
    n = len(p)
    idx = np.arange(n, dtype=np.int64)
    reach = np.minimum(DIR_M, p.length)
    piece = np.concatenate([idx, idx])
    at_node = np.concatenate([np.zeros(n), p.length])
    ahead = np.concatenate([reach, p.length - reach])
    x0, y0 = at_pos(p, piece, at_node, "x"), at_pos(p, piece, at_node, "y")
    x1, y1 = at_pos(p, piece, ahead, "x"), at_pos(p, piece, ahead, "y")
    dx, dy = x1 - x0, y1 - y0
    norm = np.hypot(dx, dy)
    norm[norm == 0] = 1.0
    return pd.DataFrame(
        {
            "node": np.concatenate([p.begin_node, p.end_node]),
            "piece": piece,
            "end": np.repeat(np.array(["begin", "end"], dtype=object), n),
            "dx": dx / norm,
            "dy": dy / norm,
        }
    )


def grid(p: Pieces) -> tuple[I64, F64]:
    """The grid of every piece (module doc): (piece index, pos) of each point."""
    length = p.length
    n_full = np.floor(length / STEP_M).astype(np.int64) + 1
    tail = (length - (n_full - 1) * STEP_M) > 1e-6
    counts = n_full + tail
    piece = np.repeat(np.arange(len(p), dtype=np.int64), counts)
    first = np.repeat(np.cumsum(counts) - counts, counts)
    pos = (np.arange(len(piece)) - first) * STEP_M
    last = np.cumsum(counts) - 1
    pos[last[tail]] = length[tail]
    return piece, pos.astype(float)
