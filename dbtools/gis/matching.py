"""Map-matching of position fixes to the 20 m GIS grid [S001 §4.2.3, SPEC §5.4].

For a fix and a candidate track, the fix's kilometrage is the foot of the perpendicular
dropped onto the *nearest segment* of that track's grid polyline and its lateral offset the
signed length of that perpendicular (positive left of increasing km). On double track the
two nearest grid points of a fix are often on different tracks, so segments are only ever
formed between consecutive grid points of one track: tracks are never mixed.

Structure of a :class:`TrackIndex` (built once per network on its
:class:`~dbtools.gis.index.GridIndex`, reused by the GPS unit, GIS verification and the
possession audit):

* the grid index's points, track ids, plane projection (its one projection policy) and
  **pieces**: per (line_code, track) the grid points in km order, cut wherever a segment
  cannot be interpolated (:meth:`~dbtools.gis.index.GridIndex.cuts`: a listed kilometrage
  break, km not increasing, an unlisted km jump, a hole longer than ``max_segment_m``).
  Segments longer than ``densify_m`` get extra vertices on the segment with linearly
  interpolated km — the geometry and every projection stay the same, but all segments are
  short, which keeps the search radius below small;
* the vertices **bucketed in square cells** of side R (the candidate index, built once per
  search radius R, see below) and, per piece, an exact
  :class:`~dbtools.gis.geometry.PolylineIndex` (built on demand, for unbounded projection
  onto one known track: :meth:`TrackIndex.project_onto`).

Exactness of :meth:`TrackIndex.match_xy`. If a track has a segment within ``max_offset_m``
of a fix, the nearer end of that segment is within ``R = max_offset_m + ½·longest
segment``. Every vertex within R of a fix lies in the 3 × 3 cells of side R around the
fix's cell; all their vertices are taken (a superset), and both segments adjacent to each
are evaluated exactly. Hence, per track, the nearest candidate segment is the nearest
segment of the whole track whenever that is within ``max_offset_m`` — the same answer as
brute force over every segment of the track (segment index breaking exact ties, as an
argmin over the track would). Per fix, tracks are then taken in order of distance (exact
ties: lower segment index first), in one compiled loop over the fixes
(:mod:`dbtools.gis.match_kernel`) or, for the few thousand fixes of a run, the same
arithmetic in numpy (:mod:`dbtools.gis.match_numpy`), which spares the process numba.

Fixes are processed in the order of their own cells of side R (x-major cell keys), so that
consecutive fixes read the same and the neighbouring cells' vertices from memory (on the
bench's 100,000 fixes the kernel takes 22 % less time than in the order of 1 km cells it
had); each fix is matched on its own, so the order changes no result, and results come back
in input order. Throughput:
``bench/bench_matching.py``; why cells rather than the k-d tree this used before:
bench/NOTES.md (Performance).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import FloatArray, PolylineIndex, Projection, Projector
from dbtools.gis.index import GridIndex, PieceRule, grid_index
from dbtools.gis.match_numpy import NUMPY_MAX_FIXES, cell_keys, match_numpy
from dbtools.network import Network
from schemas.tables import GIS_SPACING_M

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Columns of :meth:`TrackIndex.match` (one row per fix and candidate track).
MATCH_COLUMNS = (
    "fix",
    "line_code",
    "track",
    "track_id",
    "km_m",
    "offset_m",
    "distance_m",
    "best",
    "dir_e",
    "dir_n",
)
#: Default search radius: a fix farther than this from a track is not matched to it [m].
DEFAULT_MAX_OFFSET_M = 15.0


@dataclass(frozen=True)
class Piece:
    """A contiguous run of one track's vertices that can be interpolated (module doc)."""

    track_id: int
    start: int
    """First vertex (index into :attr:`TrackIndex.x` etc.)."""
    stop: int
    """One past the last vertex."""


class TrackIndex:
    """Nearest-segment map-matching onto every track of a GIS grid (see module docstring).

    ``grid`` needs ``line_code``, ``track``, ``km_m``, ``lat``, ``lon`` (rows with a
    missing value are ignored); ``km_breaks`` (optional) ``line_code``, ``track``,
    ``km_from_m``. Attributes ``x``, ``y``, ``km``, ``vertex_track`` are the vertices in
    (line, track, km) order, densified; ``segment_ok[i]`` says vertices i and i+1 form a
    segment (same piece).
    """

    def __init__(
        self,
        grid: pd.DataFrame | GridIndex,
        projector: Projector | None = None,
        km_breaks: pd.DataFrame | None = None,
        *,
        km_tolerance_m: float = 1.0,
        km_tolerance_rel: float = 0.02,
        max_segment_m: float = 200.0,
        densify_m: float = 1.25 * GIS_SPACING_M,
    ) -> None:
        gi = grid if isinstance(grid, GridIndex) else GridIndex(grid, km_breaks, projector)
        if gi.projector is None:
            raise ValueError("an empty GIS grid needs an explicit projector")
        self.grid = gi
        self.projector: Projector = gi.projector
        self.keys: list[tuple[str, str]] = list(gi.keys)
        self.line_categories = sorted({lc for lc, _ in self.keys})
        self.track_categories = sorted({tr for _, tr in self.keys})
        self._line_dtype = pd.CategoricalDtype(self.line_categories)
        self._track_dtype = pd.CategoricalDtype(self.track_categories)
        self._key_line = np.array([self.line_categories.index(lc) for lc, _ in self.keys], dtype=np.int64)
        self._key_track = np.array([self.track_categories.index(tr) for _, tr in self.keys], dtype=np.int64)
        cut = gi.cuts(PieceRule(km_tolerance_m, km_tolerance_rel, max_segment_m))
        self._densify(gi, cut, densify_m)
        self._segment_constants()
        self._poly: dict[int, PolylineIndex] = {}

    def _densify(self, gi: GridIndex, cut: BoolArray, densify_m: float) -> None:
        """Vertices: point i contributes itself and, unless the step i → i+1 is cut, the
        extra vertices of that segment (longer than ``densify_m``: split into ~20 m parts
        with linearly interpolated km); an isolated point is doubled (a zero-length segment)."""
        x0, y0, km0, tid0 = gi.x, gi.y, gi.km, gi.tid
        n = km0.size
        parts = np.where(cut | (gi.seg <= densify_m), 1, np.ceil(gi.seg / GIS_SPACING_M)).astype(np.int64)
        piece0 = np.concatenate([[0], np.cumsum(cut)]) if n else np.zeros(0, dtype=np.int64)
        size = np.bincount(piece0) if n else np.zeros(0, dtype=np.int64)
        single = size[piece0] == 1 if n else np.zeros(0, dtype=bool)
        counts = np.ones(n, dtype=np.int64)
        if n > 1:
            counts[:-1] += np.where(cut, 0, parts - 1)
        counts += single
        base = np.repeat(np.arange(n), counts)
        first = np.repeat(np.cumsum(counts) - counts, counts)
        step = np.arange(base.size) - first
        nxt = np.minimum(base + 1, max(n - 1, 0))
        with np.errstate(invalid="ignore", divide="ignore"):
            frac = np.where(single[base] | (step == 0), 0.0, step / np.concatenate([parts, [1]])[base] if n else 0.0)
        self.x = np.ascontiguousarray(x0[base] + frac * (x0[nxt] - x0[base]))
        self.y = np.ascontiguousarray(y0[base] + frac * (y0[nxt] - y0[base]))
        self.km = np.ascontiguousarray(km0[base] + frac * (km0[nxt] - km0[base]))
        self.vertex_track = tid0[base]
        vpiece = piece0[base]
        nv = self.x.size
        self.segment_ok = np.zeros(nv, dtype=bool)  # padded: the last vertex starts no segment
        if nv > 1:
            self.segment_ok[:-1] = vpiece[1:] == vpiece[:-1]
        starts = np.flatnonzero(np.concatenate([[True], vpiece[1:] != vpiece[:-1]])) if nv else np.zeros(0, int)
        stops = np.concatenate([starts[1:], [nv]]) if nv else np.zeros(0, int)
        self.pieces = [Piece(int(self.vertex_track[a]), int(a), int(b)) for a, b in zip(starts, stops, strict=True)]
        self._track_pieces: dict[int, list[int]] = {}
        for i, p in enumerate(self.pieces):
            self._track_pieces.setdefault(p.track_id, []).append(i)

    def _segment_constants(self) -> None:
        """Per segment (index = first vertex): direction, 1/length², unit vector, Δkm."""
        nv = self.x.size
        self._dx = np.zeros(nv)
        self._dy = np.zeros(nv)
        if nv > 1:
            self._dx[:-1] = np.diff(self.x)
            self._dy[:-1] = np.diff(self.y)
        self._dx[~self.segment_ok] = 0.0
        self._dy[~self.segment_ok] = 0.0
        len2 = self._dx**2 + self._dy**2
        with np.errstate(divide="ignore"):
            self._inv_len2 = np.where(len2 > 0, 1.0 / len2, 0.0)
        # unit vector of increasing km per segment (km increases within a piece)
        self._ux = self._dx * np.sqrt(self._inv_len2)
        self._uy = self._dy * np.sqrt(self._inv_len2)
        self._dkm = np.zeros(nv)
        if nv > 1:
            self._dkm[:-1] = np.where(self.segment_ok[:-1], np.diff(self.km), 0.0)
        self.half_max_segment_m = 0.5 * float(np.sqrt(len2.max())) if nv else 0.0
        self._cell_cache: dict[float, tuple[float, IntArray, IntArray, IntArray]] = {}

    @classmethod
    def from_network(cls, network: Network, projector: Projector | None = None, **kwargs: float) -> TrackIndex:
        """Index of every track of ``network`` (kilometrage breaks respected), on the
        network's grid index unless another ``projector`` is asked for."""
        if projector is None:
            return cls(grid_index(network), **kwargs)  # type: ignore[arg-type]
        return cls(network.gis, projector, network.tables.get("km_breaks"), **kwargs)

    # ------------------------------------------------------------------------------ access
    @property
    def n_vertices(self) -> int:
        return int(self.x.size)

    def track_id(self, line_code: str, track: str) -> int | None:
        return self.grid.track_id(line_code, track)

    def pieces_of(self, track_id: int) -> list[int]:
        """Indices into :attr:`pieces` of one track's pieces, in km order."""
        return list(self._track_pieces.get(track_id, []))

    def piece_index(self, piece: int) -> PolylineIndex:
        """The exact projector of one piece (built on first use)."""
        poly = self._poly.get(piece)
        if poly is None:
            p = self.pieces[piece]
            sl = slice(p.start, p.stop)
            poly = PolylineIndex(self.x[sl], self.y[sl], self.km[sl])
            self._poly[piece] = poly
        return poly

    def to_xy(self, lat: npt.ArrayLike, lon: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        return self.projector.to_xy(lon, lat)

    def project_onto(self, x: npt.ArrayLike, y: npt.ArrayLike, line_code: str, track: str) -> Projection:
        """Exact projection onto one known track, however far the points are (nearest over
        the track's pieces; ``segment`` is the vertex index in :attr:`x`). For points known
        to be on that track: GIS verification, a vehicle's declared track."""
        px = np.atleast_1d(np.asarray(x, dtype=float))
        py = np.atleast_1d(np.asarray(y, dtype=float))
        t = self.track_id(line_code, track)
        out = Projection(
            np.full(px.size, np.nan), np.full(px.size, np.nan), np.full(px.size, -1, np.int64), np.full(px.size, np.inf)
        )
        ok = np.isfinite(px) & np.isfinite(py)
        if t is None or not ok.any():
            return out
        for pi in self._track_pieces[t]:
            pr = self.piece_index(pi).project(px[ok], py[ok])
            better = pr.distance_m < out.distance_m[ok]
            idx = np.flatnonzero(ok)[better]
            out.km_m[idx] = pr.km_m[better]
            out.offset_m[idx] = pr.offset_m[better]
            out.segment[idx] = pr.segment[better] + self.pieces[pi].start
            out.distance_m[idx] = pr.distance_m[better]
        out.distance_m[~np.isfinite(out.km_m)] = np.nan
        return out

    # ------------------------------------------------------------------------------ matching
    def match(
        self,
        lat: npt.ArrayLike,
        lon: npt.ArrayLike,
        line_code: str | None = None,
        track: str | None = None,
        max_offset_m: float = DEFAULT_MAX_OFFSET_M,
    ) -> pd.DataFrame:
        """Match fixes given as latitude/longitude (see :meth:`match_xy`)."""
        x, y = self.to_xy(lat, lon)
        return self.match_xy(x, y, line_code, track, max_offset_m)

    def match_xy(
        self,
        x: npt.ArrayLike,
        y: npt.ArrayLike,
        line_code: str | None = None,
        track: str | None = None,
        max_offset_m: float = DEFAULT_MAX_OFFSET_M,
    ) -> pd.DataFrame:
        """Every (fix, track) pair whose nearest segment is within ``max_offset_m``.

        Columns: ``fix`` (position in the input arrays), ``line_code``, ``track``
        (categoricals), ``track_id`` (index into :attr:`keys`), ``km_m`` (foot of the
        perpendicular on the track's nearest segment), ``offset_m`` (signed, positive left
        of increasing km), ``distance_m`` (= |offset_m|), ``best`` (the fix's nearest
        track), ``dir_e`` / ``dir_n`` (unit vector of increasing km of the matched segment in the
        plane, east/north: the track heading, which the GPS unit needs to tell a crossover from a
        slow GPS error seen through a curve). Sorted by fix, then distance; fixes with no track in reach, or with NaN
        coordinates, have no row. ``line_code`` / ``track`` restrict the candidates.
        """
        px = np.atleast_1d(np.asarray(x, dtype=float))
        py = np.atleast_1d(np.asarray(y, dtype=float))
        allowed = self._allowed(line_code, track)
        parts = []
        if self.n_vertices and px.size:
            finite = np.flatnonzero(np.isfinite(px) & np.isfinite(py))
            cells = self._cells(float(max_offset_m) + self.half_max_segment_m)
            # in the order of the fixes' own cells (module doc); any order gives the same rows
            pending = finite[np.argsort(cell_keys(px[finite], py[finite], cells[0]))]
            ok_track = np.ones(len(self.keys), dtype=np.bool_) if allowed is None else allowed
            for f, p, sg, u, d2 in self._candidate_matches(px, py, pending, cells, ok_track, float(max_offset_m) ** 2):
                cross = self._dx[sg] * (py[f] - self.y[sg]) - self._dy[sg] * (px[f] - self.x[sg])
                d = np.sqrt(d2)
                parts.append((f, p, sg, u, np.where(cross >= 0, d, -d)))
        return self._frame(px.size, parts)

    def _candidate_matches(
        self,
        px: FloatArray,
        py: FloatArray,
        pending: IntArray,
        cells: tuple[float, IntArray, IntArray, IntArray],
        ok_track: BoolArray,
        max_d2: float,
    ) -> list[tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]]:
        """(fix, pass, segment, u, squared distance) blocks: numpy for a few fixes (no numba
        import, no kernel load), the compiled kernel for many or once it is loaded — the same
        numbers either way (:mod:`dbtools.gis.match_numpy`)."""
        x, y, dx, dy, il2, seg_ok, vt = (
            self.x,
            self.y,
            self._dx,
            self._dy,
            self._inv_len2,
            self.segment_ok,
            self.vertex_track,
        )
        side, keys, start, order = cells
        if pending.size <= NUMPY_MAX_FIXES and "dbtools.gis.match_kernel" not in sys.modules:
            return [
                match_numpy(px, py, pending, side, keys, start, order, x, y, dx, dy, il2, seg_ok, vt, ok_track, max_d2)
            ]
        from dbtools.gis.match_kernel import match_kernel  # numba: only for many fixes

        out, done = [], 0
        while done < pending.size:  # a full output buffer returns early: go on from there
            f, p, sg, u, d2, done = match_kernel(
                px, py, pending, done, side, keys, start, order, x, y, dx, dy, il2, seg_ok, vt, ok_track, max_d2
            )
            out.append((f, p, sg, u, d2))
        return out

    def _cells(self, radius: float) -> tuple[float, IntArray, IntArray, IntArray]:
        """The vertices bucketed in square cells of side ``radius`` (built once per radius):
        (cell side, sorted cell keys, first position of each key's vertices in the order,
        vertex order by cell). A disk of radius ``radius`` lies in the 3 × 3 cells around
        its centre's cell."""
        cached = self._cell_cache.get(radius)
        if cached is None:
            key = cell_keys(self.x, self.y, radius)
            order = np.argsort(key, kind="stable")
            keys, start = np.unique(key[order], return_index=True)
            cached = (radius, keys, np.append(start, order.size).astype(np.int64), order.astype(np.int64))
            self._cell_cache[radius] = cached
        return cached

    def _allowed(self, line_code: str | None, track: str | None) -> BoolArray | None:
        if line_code is None and track is None:
            return None
        return np.array(
            [
                (line_code is None or lc == str(line_code)) and (track is None or tr == str(track))
                for lc, tr in self.keys
            ],
            dtype=bool,
        )

    def _frame(
        self, n_fixes: int, parts: list[tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]]
    ) -> pd.DataFrame:
        if parts:
            f, p, s, u, off = (np.concatenate(a) for a in zip(*parts, strict=True))
        else:
            f = p = s = np.zeros(0, dtype=np.int64)
            u = off = np.zeros(0)
        # input order without sorting: a fix's rows are its passes 0..c−1
        count = np.bincount(f, minlength=n_fixes)
        pos = (np.cumsum(count) - count)[f] + p
        order = np.empty(f.size, dtype=np.int64)
        order[pos] = np.arange(f.size)
        f, p, s, u, off = f[order], p[order], s[order], u[order], off[order]
        km = self.km[s] + u * self._dkm[s]
        tid = self.vertex_track[s]
        return pd.DataFrame(
            {
                "fix": f,
                "line_code": pd.Categorical.from_codes(self._key_line[tid], dtype=self._line_dtype),
                "track": pd.Categorical.from_codes(self._key_track[tid], dtype=self._track_dtype),
                "track_id": tid,
                "km_m": km,
                "offset_m": off,
                "distance_m": np.abs(off),
                "best": p == 0,
                "dir_e": self._ux[s],
                "dir_n": self._uy[s],
            }
        )


def track_index_for(network: Network) -> TrackIndex:
    """The :class:`TrackIndex` of ``network``, built once per loaded network on its
    :func:`~dbtools.gis.index.grid_index` (networks are not modified after loading)."""
    gi = grid_index(network)
    return network.cached(("track_index", id(gi)), lambda: TrackIndex(gi))
