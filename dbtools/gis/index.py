"""The grid index: the one structure over a network's GIS points, shared by the validation
rules (:mod:`dbtools.rules`), map-matching (:mod:`dbtools.gis.matching`), GIS verification
(:mod:`dbtools.gis.verify`) and the dead-reckoning metric (:mod:`fieldlogs.pipeline.metric`).
Built once per loaded network (:func:`grid_index`, through ``Network.cached``).

**Points.** The *valid* GIS points — ``line_code``, ``track``, ``km_m``, ``lat``, ``lon``
all present and finite, lat/lon not *far* outside the network's operating area
(:mod:`dbtools.gis.georef`: more than 2 km outside is an error) — sorted by (line_code, track,
km_m) (stable: a duplicate key keeps its file order). Each (line_code, track) is one
*track*, with track ids 0, 1, … in that order; its points are ``start[t]:end[t]``. Rows
left out are reported by the schema rules, never silently used.

**Projection policy** (every module, one plane per network): all plane work — headings,
curvature, track spacing, nearest segments, lateral offsets, lateral shifts — is done in
ONE conformal plane projection, :attr:`GridIndex.projector`: the network's metric CRS
(:func:`network_georef`), as declared in the DB meta or the source set's ``network.toml``,
else derived from the median (lat, lon) of the points — the JGD2011 plane rectangular
zone whose origin is nearest inside Japan, the UTM zone elsewhere
(:func:`dbtools.gis.georef.derive`). Lengths along the track are never taken from the
plane: steps are geodesic (GRS80), so km and track length carry no scale factor of the
projection (0.9999–1.0001 inside a JGD2011 zone, 0.9996–1.001 inside a UTM zone).

**Per step** (i → i + 1, arrays of length n − 1): ``dkm`` the km step within a track (NaN
across tracks), ``dist`` the geodesic distance, ``seg`` the plane distance.

**Track length** (the dead-reckoning metric): ``c[start] = km[start]``, ``c[i+1] = c[i] +
Δc[i]`` within each track — the length the wheels roll on that track's 3-D rail, which
differs from its km on the inner/outer track of a curve and on gradients:

    Δc = √((dist·(1 + h̄/R_E)·(1 + κ̄²·dist²/24))² + Δh²),

h̄ the two points' mean rail height (``height_m``, gaps interpolated; none: 0) above the
ellipsoid the geodesic lies on (R_E = 6 371 km: +0.0016 % at 100 m), κ̄² the mean squared
Menger curvature of the two vertices from the geodesic sides a, b, c of the triangle of a
vertex and its neighbours (κ² = 16·A²/(a²b²c²), A by Heron's rule in its stable order, so
no plane enters the length) — a curve's arc is longer than its chord by
dist²/(24R²), 0.01 % for 20 m at R = 400 m — and Δh the height step (a gradient g adds
≈ g²/2: 0.005 % at 10 ‰).

**km search.** One sorted key ``km + shift[t]`` for all tracks (``shift`` puts the tracks
1 km apart, in track-id order): :meth:`GridIndex.searchsorted` finds a km on a track with
one ``np.searchsorted`` for any number of queries.

**Shape** (:meth:`GridIndex.shape`, for spacing h and tolerance ε): a step is *regular*
when it is one spacing within a track (|Δkm − h| ≤ ε); at a vertex whose two steps are
regular, the turn angle between the segments, the Menger curvature
κ = 2·((b − a) × (c − b)) / (|b − a|·|c − b|·|c − a|) (positive turning left in increasing
km) and the heading of increasing km (chord of the neighbours; at a vertex with one regular
step, that step's direction).

**Pieces** (:meth:`GridIndex.cuts`): a step is *cut* — the two points are not joined by
an interpolable segment — across tracks, at a kilometrage break listed in ``km_breaks``
(km_from_m and km_to_m both matching consecutive points within ε), where km does not
increase, where the plane step is longer than ``max_segment_m`` (a hole) or differs from Δkm
by more than ``km_tolerance_m + km_tolerance_rel·Δkm`` (an unlisted km jump). A missing grid
point (Δkm = 40 m over 40 m) is not a cut.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.frame_columns import frame_column, lex_sorted, text_codes
from dbtools.gis.geometry import GEOD, Projector, geodesic_step
from dbtools.gis.georef import AREA_TOLERANCE_M, Georef, derive, georef_of
from dbtools.network import Network
from schemas.tables import LAT_RANGE, LON_RANGE

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
ObjArray = npt.NDArray[np.object_]

#: Mean Earth radius for the rail height's length factor 1 + h/R_E [m].
EARTH_RADIUS_M = 6_371_000.0
#: GRS80 semi-major axis [m] and first eccentricity squared (the ellipsoid of ``GEOD``).
GRS80_A: float = GEOD.a
GRS80_E2: float = GEOD.es
#: Largest normal curvature of the GRS80 ellipsoid: 1 / (meridian radius at the equator) [1/m].
KAPPA_MAX = 1.0 / (GRS80_A * (1.0 - GRS80_E2))
#: Points per block of the element-wise geometry of a whole network (bounds its temporaries).
BLOCK = 1 << 16
#: Rounding allowance of :func:`chord_bounds` on either side [m].
CHORD_ROUNDING_M = 1e-6
#: Gap between consecutive tracks in the sorted km key [m].
KEY_GAP_M = 1000.0
#: A listed kilometrage break matches consecutive points whose km agree within this [m].
BREAK_EPSILON_M = 1e-3


@dataclass(frozen=True)
class PieceRule:
    """When consecutive points of a track are not one interpolable segment (module doc)."""

    km_tolerance_m: float = 1.0
    km_tolerance_rel: float = 0.02
    max_segment_m: float = 200.0


@dataclass(frozen=True)
class GridShape:
    """Spacing-dependent geometry of the points (module doc, "Shape")."""

    regular: BoolArray
    """The step to the next point is one grid spacing within the same track (length n − 1)."""
    turn: F64
    """Signed angle between the segments before and after a vertex [rad] (NaN unless both
    steps are regular)."""
    kappa: F64
    """Signed Menger curvature at a vertex [1/m], positive left of increasing km (NaN unless
    both steps are regular)."""
    heading: F64
    """Direction of increasing km at a vertex [rad] (chord of the neighbouring points)."""


def projection_for(lat: F64, lon: F64) -> Projector | None:
    """The one plane projection of a set of points with nothing declared (module doc,
    "Projection policy"); None when there are no points."""
    g = derive(lat, lon)
    return None if g is None else Projector.from_epsg(g.crs_epsg)


def _menger_squared(lon: F64, lat: F64, step: F64) -> F64:
    """κ² at each point of one track from geodesic sides (module doc, "Track length"; an end
    point takes its neighbour's)."""
    out = np.zeros(lon.size)
    if lon.size < 3:
        return out
    _, _, far = GEOD.inv(lon[:-2], lat[:-2], lon[2:], lat[2:])
    sides = np.sort(np.column_stack([step[:-1], step[1:], np.asarray(far, dtype=float)]), axis=1)
    c, b, a = sides[:, 0], sides[:, 1], sides[:, 2]
    # Heron in Kahan's order (a ≥ b ≥ c): 16·A² without cancellation
    a16 = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c))
    with np.errstate(invalid="ignore", divide="ignore"):
        k2 = np.maximum(a16, 0.0) / (a * a * b * b * c * c)
    out[1:-1] = np.where(np.isfinite(k2), k2, 0.0)
    out[0], out[-1] = out[1], out[-2]
    return out


def chord_bounds(lon: F64, lat: F64) -> tuple[F64, F64]:
    """Bounds [low, high] of the geodesic (GRS80) length of each step i → i + 1 from its
    straight chord c between the two points on the ellipsoid (height 0, where the geodesic
    lies): 4 trigonometric functions a point instead of an inverse geodesic problem a step.

    A geodesic of the ellipsoid has no geodesic curvature, so its curvature is its normal
    curvature, at most κ = 1/M_min = 1/(a(1 − e²)) (the meridian radius at the equator,
    6 335 439 m). A curve of length s ≤ π/κ with curvature ≤ κ has a chord
    c ≥ (2/κ)·sin(κs/2) (Schur's comparison with the circle), and no curve is shorter than
    its chord, so c ≤ s ≤ (2/κ)·arcsin(κc/2) = c + κ²c³/24 + …: the gap is 8·10⁻¹² m at
    20 m and 1·10⁻⁶ m at 1 km. s ≤ π/κ (19 903 km) holds where |Δlat| and |Δlon| ≤ 1°: a
    path along a meridian and a parallel is then shorter than 2·(π/180)·a/√(1 − e²) ≈
    224 km; steps farther apart get NaN bounds (the caller solves them exactly). Both bounds
    are widened by ``CHORD_ROUNDING_M`` for rounding (the coordinates, ≈ 6.4·10⁶ m, carry
    ≈ 10⁻⁹ m each; ``Geod.inv`` is accurate to 15 nm)."""
    phi, lam = np.radians(lat), np.radians(lon)
    cos_phi = np.cos(phi)
    sin_phi = np.sin(phi)
    n = GRS80_A / np.sqrt(1.0 - GRS80_E2 * sin_phi * sin_phi)
    xyz = (n * cos_phi * np.cos(lam), n * cos_phi * np.sin(lam), n * (1.0 - GRS80_E2) * sin_phi)
    c = np.sqrt(sum(np.diff(v) ** 2 for v in xyz))
    with np.errstate(invalid="ignore"):
        near = (np.abs(np.diff(lat)) <= 1.0) & (np.abs(np.diff(lon)) <= 1.0)
        c = np.where(near, c, np.nan)
        high = (2.0 / KAPPA_MAX) * np.arcsin(np.minimum(0.5 * KAPPA_MAX * (c + CHORD_ROUNDING_M), 1.0))
    return c - CHORD_ROUNDING_M, high + CHORD_ROUNDING_M


def step_bounds(lon: F64, lat: F64) -> tuple[F64, F64]:
    """:func:`chord_bounds` of every step i → i + 1 of a whole network's points, ``BLOCK``
    points at a time (bounded temporaries, the same values); NaN where the chord cannot bound
    the step (far apart or a coordinate missing: solve it with :func:`exact_steps`)."""
    n = max(lon.size - 1, 0)
    low, high = np.empty(n), np.empty(n)
    for a in range(0, n, BLOCK):
        low[a : a + BLOCK], high[a : a + BLOCK] = chord_bounds(lon[a : a + BLOCK + 1], lat[a : a + BLOCK + 1])
    return low, high


def exact_steps(lon: F64, lat: F64, steps: I64) -> F64:
    """Geodesic (GRS80 ``Geod.inv``) length [m] of the given steps i → i + 1 only."""
    if steps.size == 0:
        return np.empty(0)
    _, _, d = GEOD.inv(lon[steps], lat[steps], lon[steps + 1], lat[steps + 1])
    return np.asarray(d, dtype=float)


def _shape_block(x: F64, y: F64, reg: BoolArray, a: int, b: int, out: tuple[F64, F64, F64]) -> None:
    """Turn, curvature and heading (module doc, "Shape") of the vertices a:b, written into
    ``out`` (turn, kappa, heading); ``reg[i]``: the step i − 1 → i is regular. Element by
    element the same operations for every block, so the values do not depend on the blocks."""
    n = x.size
    turn, kappa, heading = (o[a:b] for o in out)
    lo, hi = max(a - 1, 0), min(b + 1, n)  # the points the block's vertices use
    dx, dy = np.diff(x[lo:hi]), np.diff(y[lo:hi])  # the steps lo … hi − 2
    seg_h = np.arctan2(dy, dx)
    back, fwd = reg[a:b], reg[a + 1 : b + 1]
    not_both = ~(back & fwd)
    i0, i1 = max(a, 1), min(b, n - 1)  # interior vertices
    for o in (turn, kappa, heading):
        o[: i0 - a] = np.nan
        o[max(i1 - a, i0 - a) :] = np.nan
    if i1 > i0:
        s0, s1 = slice(i0 - 1 - lo, i1 - 1 - lo), slice(i0 - lo, i1 - lo)  # the steps before, after
        inner = turn[i0 - a : i1 - a]  # wrap_angle(seg_h[i] − seg_h[i − 1]) (dbtools.gis.geometry), in place
        np.subtract(seg_h[s1], seg_h[s0], out=inner)
        inner += np.pi
        np.remainder(inner, 2 * np.pi, out=inner)
        inner -= np.pi
        # signed_curvature (dbtools.gis.geometry), its sides' lengths shared by the two vertices of a step
        cx, cy = x[i0 + 1 : i1 + 1] - x[i0 - 1 : i1 - 1], y[i0 + 1 : i1 + 1] - y[i0 - 1 : i1 - 1]
        length = np.hypot(dx, dy)
        cross = dx[s0] * dy[s1] - dy[s0] * dx[s1]
        with np.errstate(invalid="ignore", divide="ignore"):
            kappa[i0 - a : i1 - a] = 2.0 * cross / (length[s0] * length[s1] * np.hypot(cx, cy))
        np.arctan2(cy, cx, out=heading[i0 - a : i1 - a])  # chord of the neighbours
    turn[not_both] = np.nan
    kappa[not_both] = np.nan
    heading[not_both] = np.nan  # … else the one regular step the vertex has
    use_fwd = np.flatnonzero(not_both & fwd)
    use_back = np.flatnonzero(not_both & ~fwd & back)
    heading[use_fwd] = seg_h[use_fwd + (a - lo)]
    heading[use_back] = seg_h[use_back + (a - 1 - lo)]


class GridIndex:
    """The grid index of one GIS frame (see module docstring).

    Attributes (length n = valid points, in (line, track, km) order): ``pos`` (row in the
    frame), ``tid`` (track id), ``km``, ``lat``, ``lon``, ``x``, ``y`` (plane, east/north),
    ``c`` (track length); per step: ``dkm``, ``dist``, ``seg``; per track id: ``start``,
    ``end``, ``lines``, ``tracks`` (object arrays), ``keys`` ((line, track) strings).
    """

    def __init__(
        self,
        gis: pd.DataFrame,
        km_breaks: pd.DataFrame | None = None,
        projector: Projector | None = None,
        georef: Georef | None = None,
        keep_bounds: bool = False,
    ) -> None:
        self.gis = gis
        self.km_breaks = km_breaks
        self.keep_bounds = keep_bounds
        """Keep the step bounds :meth:`steps_outside` computes (:attr:`bounds`: 16 bytes a
        point, for the topology rules' track lengths) instead of dropping them."""
        (lcode, luniq), (tcode, tuniq) = text_codes(gis, "line_code"), text_codes(gis, "track")
        km, lat, lon = (frame_column(gis, c, True) for c in ("km_m", "lat", "lon"))
        self.georef = georef if georef is not None else derive(lat, lon)
        with np.errstate(invalid="ignore"):
            ok = (lcode >= 0) & (tcode >= 0) & np.isfinite(km)
        ok &= self._inside(lat, lon)
        n = int(np.count_nonzero(ok))
        rows: I64 | None = None  # the frame's row of each point; None: every row, in order
        if n < ok.size:  # rows left out: the points are copies
            rows = np.flatnonzero(ok).astype(np.int64)
            lcode, tcode = lcode[rows], tcode[rows]
            km, lat, lon = km[rows], lat[rows], lon[rows]
        del ok
        if not lex_sorted(lcode, tcode, km, BLOCK):  # frames of a Network are: no sort
            order = np.lexsort((km, tcode, lcode))
            rows = order.astype(np.int64) if rows is None else rows[order]
            lcode, tcode = lcode[order], tcode[order]
            km, lat, lon = km[order], lat[order], lon[order]
            del order
        self._rows = rows
        self.km: F64 = km
        self.lat: F64 = lat
        self.lon: F64 = lon
        new = np.ones(n, dtype=bool)
        np.not_equal(lcode[1:], lcode[:-1], out=new[1:])
        new[1:] |= tcode[1:] != tcode[:-1]
        self.tid: I64 = np.cumsum(new, dtype=np.int64)
        self.tid -= 1
        self.start: I64 = np.flatnonzero(new).astype(np.int64)
        del new
        self.end: I64 = np.append(self.start[1:], n)[: self.start.size].astype(np.int64)
        self.lines: ObjArray = np.asarray(luniq, dtype=object)[lcode[self.start]]
        self.tracks: ObjArray = np.asarray(tuniq, dtype=object)[tcode[self.start]]
        del lcode, tcode
        self.keys: list[tuple[str, str]] = [(str(a), str(b)) for a, b in zip(self.lines, self.tracks, strict=True)]
        self._key_id = {key: i for i, key in enumerate(self.keys)}
        if projector is None and self.georef is not None:
            projector = Projector.from_epsg(self.georef.crs_epsg)
        self.projector = projector
        if self.projector is not None and n:
            self.x, self.y = self.projector.to_xy(self.lon, self.lat)
        else:
            self.x, self.y = np.zeros(n), np.zeros(n)
        self.dkm: F64 = np.diff(self.km)
        self.dkm[self.tid[1:] != self.tid[:-1]] = np.nan
        self._build_key()
        self._shapes: dict[tuple[float, float], GridShape] = {}
        self._cuts: dict[PieceRule, BoolArray] = {}
        self._breaks: dict[float, tuple[BoolArray, I64]] = {}

    def _inside(self, lat: F64, lon: F64) -> BoolArray:
        """Finite, on the globe and not far outside the operating area (``BLOCK`` points at a time)."""
        with np.errstate(invalid="ignore"):
            ok = (np.abs(lat) <= LAT_RANGE[1]) & (np.abs(lon) <= LON_RANGE[1])
        if self.georef is None or not ok.any():
            return np.asarray(ok, dtype=bool)
        area = self.georef.area
        for a in range(0, ok.size, BLOCK):
            part = ok[a : a + BLOCK]  # a view: written in place
            rows = slice(a, a + BLOCK) if part.all() else a + np.flatnonzero(part)
            part[part] = area.distance_m(lat[rows], lon[rows]) <= AREA_TOLERANCE_M
        return np.asarray(ok, dtype=bool)

    def _chords(self, a: int, b: int) -> tuple[F64, F64]:
        return chord_bounds(self.lon[a : b + 1], self.lat[a : b + 1])

    @cached_property
    def seg(self) -> F64:
        """Plane distance to the next point [m] (length n − 1; computed on first use)."""
        seg = np.diff(self.x)
        return np.hypot(seg, np.diff(self.y), out=seg)

    @cached_property
    def dist(self) -> F64:
        """Geodesic distance to the next point [m] (length n − 1; computed on first use)."""
        return geodesic_step(self.lon, self.lat) if self.n > 1 else np.zeros(0)

    @cached_property
    def whole_frame(self) -> bool:
        """Every row of the frame is a point, in the frame's order (``pos`` = 0 … n − 1): the
        frame is sorted by (line, track, km) and no key is missing — as read from a DB."""
        n = len(self.gis)
        return self._rows is None and self.n == n

    @cached_property
    def pos(self) -> I64:
        """The frame's row of each point (an ``arange`` for a whole frame: built on first use)."""
        return np.arange(self.n, dtype=np.int64) if self._rows is None else self._rows

    def row(self, i: int | np.integer[Any]) -> int:
        """The frame's row of point ``i`` (``pos[i]`` without building ``pos``)."""
        return int(i) if self._rows is None else int(self._rows[i])

    @cached_property
    def bounds(self) -> tuple[F64, F64]:
        """:func:`step_bounds` of every step (length n − 1; computed on first use, then shared
        by the GIS rules and the topology rules' track lengths). Read-only: do not modify."""
        return step_bounds(self.lon, self.lat)

    def steps_outside(
        self, where: BoolArray, limits: Callable[[int, int], tuple[F64, F64]]
    ) -> tuple[I64, F64, F64, F64]:
        """The steps i with ``where[i]`` whose geodesic length ``dist[i]`` is not finite or outside
        [lo[i], hi[i]] (``limits(a, b)``: lo, hi of steps a:b), with that length (``Geod.inv``), lo
        and hi; ``BLOCK`` steps at a time. Unless :attr:`dist` is known, a step is cleared by its
        3-D chord (:func:`chord_bounds`) and only the steps it cannot clear are solved exactly."""
        parts: list[tuple[I64, F64, F64, F64]] = []
        exact = "dist" in self.__dict__
        shared = self.keep_bounds or "bounds" in self.__dict__
        for a in range(0, max(self.n - 1, 0), BLOCK):
            b = min(a + BLOCK, self.n - 1)
            w = where[a:b]
            if not w.any():
                continue
            lo, hi = limits(a, b)
            if exact:
                doubt = np.flatnonzero(w)
                d = self.dist[a:b][doubt]
            else:
                low, high = (self.bounds[0][a:b], self.bounds[1][a:b]) if shared else self._chords(a, b)
                with np.errstate(invalid="ignore"):
                    doubt = np.flatnonzero(w & ~((low >= lo) & (high <= hi)))  # NaN: in doubt
                d = exact_steps(self.lon, self.lat, doubt + a)
            lo_d, hi_d = lo[doubt], hi[doubt]
            with np.errstate(invalid="ignore"):
                bad = (d < lo_d) | (d > hi_d) | ~np.isfinite(d)
            parts.append((doubt[bad] + a, d[bad], lo_d[bad], hi_d[bad]))
        if not parts:
            return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0), np.zeros(0)
        idx, dist, lo_b, hi_b = (np.concatenate(p) for p in zip(*parts, strict=True))
        return idx.astype(np.int64), dist, lo_b, hi_b

    @cached_property
    def c(self) -> F64:
        """Cumulative 3-D rail length at each point (module doc, "Track length"; on first use)."""
        c = np.empty(self.n)
        for s, e in zip(self.start, self.end, strict=True):
            c[s:e] = np.concatenate([[0.0], np.cumsum(self._rail_steps(s, e))]) + self.km[s]
        return c

    def _rail_steps(self, s: int, e: int) -> F64:
        """Δc of the steps of the track ``s:e`` (module doc, "Track length")."""
        step = self.dist[s : e - 1]
        h = self.height[s:e]
        k2 = _menger_squared(self.lon[s:e], self.lat[s:e], step)
        arc = 1.0 + 0.5 * (k2[1:] + k2[:-1]) * step * step / 24.0
        level = step * (1.0 + 0.5 * (h[1:] + h[:-1]) / EARTH_RADIUS_M) * arc
        return np.asarray(np.hypot(level, np.diff(h)), dtype=np.float64)

    @cached_property
    def height(self) -> F64:
        """Rail height of each point [m]: ``height_m``, gaps interpolated along the track
        (a track without any: 0)."""
        out = np.zeros(self.n)
        if "height_m" not in self.gis:
            return out
        h = frame_column(self.gis, "height_m", True)
        h = h if self._rows is None else h[self._rows]
        for s, e in zip(self.start, self.end, strict=True):
            ok = np.isfinite(h[s:e])
            if ok.any():
                out[s:e] = np.interp(self.km[s:e], self.km[s:e][ok], h[s:e][ok])
        return out

    def _build_key(self) -> None:
        n_t = len(self.keys)
        if n_t:
            lo, hi = self.km[self.start], self.km[self.end - 1]
            span = hi - lo + KEY_GAP_M
            self.shift: F64 = np.concatenate([[0.0], np.cumsum(span)[:-1]]) - lo
        else:
            self.shift = np.zeros(0)
        self.key: F64 = self.shift[self.tid] if self.n else np.zeros(0)
        self.key += self.km

    # ------------------------------------------------------------------------------ access
    @property
    def n(self) -> int:
        return int(self.km.size)

    @property
    def n_tracks(self) -> int:
        return len(self.keys)

    def track_id(self, line_code: object, track: object) -> int | None:
        """Track id of (line_code, track); None when the grid has no such track."""
        return self._key_id.get((str(line_code), str(track)))

    def track_ids(self, lines: npt.ArrayLike, tracks: npt.ArrayLike) -> I64:
        """Track id of each (line, track) pair (−1: missing, or not a track of the grid);
        strings are factorized once and the few distinct pairs looked up."""
        lc_codes, lc_uniq = pd.factorize(np.asarray(lines, dtype=object), use_na_sentinel=True)
        tr_codes, tr_uniq = pd.factorize(np.asarray(tracks, dtype=object), use_na_sentinel=True)
        table = np.full((len(lc_uniq) + 1, len(tr_uniq) + 1), -1, dtype=np.int64)
        tr_text = [str(tr) for tr in tr_uniq.tolist()]
        for i, lc in enumerate(lc_uniq.tolist()):
            for j, tr in enumerate(tr_text):
                table[i, j] = self._key_id.get((str(lc), tr), -1)
        return np.asarray(table[lc_codes, tr_codes], dtype=np.int64)  # sentinel −1: last row/col

    def km_range(self, tid: I64) -> tuple[F64, F64]:
        """(first km, last km) of each track id (NaN for −1)."""
        ok = tid >= 0
        lo = np.full(len(tid), np.nan)
        hi = np.full(len(tid), np.nan)
        lo[ok] = self.km[self.start[tid[ok]]]
        hi[ok] = self.km[self.end[tid[ok]] - 1]
        return lo, hi

    def searchsorted(self, tid: npt.ArrayLike, km: npt.ArrayLike, side: str = "left") -> I64:
        """Index of the first point of track ``tid`` with km ≥ ``km`` ('left') or > ('right').

        Queries before (after) a track's range get its first index (one past its last)."""
        t = np.asarray(tid, dtype=np.int64)
        k = np.asarray(km, dtype=float)
        lo_km, hi_km = self.km[self.start[t]], self.km[self.end[t] - 1]
        inside = (k >= lo_km) & (k <= hi_km)
        out = np.where(k < lo_km, self.start[t], self.end[t]).astype(np.int64)
        q = np.flatnonzero(inside)
        if len(q):
            out[q] = np.searchsorted(self.key, k[q] + self.shift[t[q]], side=side)  # type: ignore[call-overload]
        return out

    # ------------------------------------------------------------------------------ derived
    def shape(self, spacing_m: float, epsilon_m: float) -> GridShape:
        """Regular steps, turn, curvature and heading for grid spacing ``spacing_m`` (cached)."""
        key = (float(spacing_m), float(epsilon_m))
        if key not in self._shapes:
            self._shapes[key] = self._shape(*key)
        return self._shapes[key]

    def _shape(self, spacing_m: float, epsilon_m: float) -> GridShape:
        n = self.n
        # dkm is NaN across tracks, so a regular step is within one track
        regular = np.empty(max(n - 1, 0), dtype=bool)
        for a in range(0, n - 1, BLOCK):  # |dkm − spacing| ≤ ε, one temporary of a block
            d = self.dkm[a : a + BLOCK] - spacing_m
            np.less_equal(np.abs(d, out=d), epsilon_m, out=regular[a : a + BLOCK])
        reg = np.zeros(n + 1, dtype=bool)  # reg[i]: the step i − 1 → i is regular (False at both ends)
        reg[1:n] = regular
        turn, kappa, heading = np.empty(n), np.empty(n), np.empty(n)
        for a in range(0, n, BLOCK):
            _shape_block(self.x, self.y, reg, a, min(a + BLOCK, n), (turn, kappa, heading))
        return GridShape(regular, turn, kappa, heading)

    def break_steps(self, epsilon_m: float = BREAK_EPSILON_M) -> tuple[BoolArray, I64]:
        """(steps listed as km breaks, rows of ``km_breaks`` that match no step), cached."""
        if epsilon_m not in self._breaks:
            self._breaks[epsilon_m] = self._break_steps(epsilon_m)
        return self._breaks[epsilon_m]

    def _break_steps(self, eps: float) -> tuple[BoolArray, I64]:
        kb = self.km_breaks
        is_break = np.zeros(max(self.n - 1, 0), dtype=bool)
        if kb is None or kb.empty:
            return is_break, np.zeros(0, dtype=np.int64)
        if self.n < 2:
            return is_break, np.arange(len(kb), dtype=np.int64)
        lines, tracks = frame_column(kb, "line_code", False), frame_column(kb, "track", False)
        k_from, k_to = frame_column(kb, "km_from_m", True), frame_column(kb, "km_to_m", True)
        ok = pd.notna(lines) & pd.notna(tracks) & np.isfinite(k_from) & np.isfinite(k_to)
        tid = np.full(len(kb), -1, dtype=np.int64)
        tid[ok] = self.track_ids(lines[ok], tracks[ok])
        rows = np.flatnonzero(tid >= 0)
        i = np.minimum(self.searchsorted(tid[rows], k_from[rows] - eps), self.n - 2)
        hit = (
            (self.tid[i] == tid[rows])
            & (self.tid[i + 1] == tid[rows])
            & (np.abs(self.km[i] - k_from[rows]) <= eps)
            & (np.abs(self.km[i + 1] - k_to[rows]) <= eps)
        )
        is_break[i[hit]] = True
        used = np.zeros(len(kb), dtype=bool)
        used[rows[hit]] = True
        return is_break, np.flatnonzero(~used).astype(np.int64)

    def cuts(self, rule: PieceRule = PieceRule()) -> BoolArray:
        """Steps that do not form an interpolable segment (module doc, "Pieces"), cached."""
        if rule not in self._cuts:
            dkm = np.diff(self.km)
            seg = self.seg
            cut = (self.tid[1:] != self.tid[:-1]) | (dkm <= 0) | (seg > rule.max_segment_m)
            cut |= np.abs(seg - dkm) > rule.km_tolerance_m + rule.km_tolerance_rel * np.abs(dkm)
            cut |= self.break_steps()[0]
            self._cuts[rule] = cut
        return self._cuts[rule]


def network_georef(network: Network) -> Georef | None:
    """Area, metric CRS and height datum of ``network``: its meta (declared, or stored by
    ``db build``), the rest derived from its GIS points; None without any point."""
    gis = network.gis

    def build() -> tuple[pd.DataFrame, Georef | None]:
        lat, lon = frame_column(gis, "lat", True), frame_column(gis, "lon", True)
        return gis, georef_of(network.meta, lat, lon, network.origin)

    return network.cached(("georef", id(gis)), build)[1]


def grid_index(network: Network) -> GridIndex:
    """The :class:`GridIndex` of ``network``, built once per loaded network. The key holds
    the identity of the frames it was built from (and the index keeps them alive), so a
    table replaced after loading gets a new index."""
    gis, kb = network.gis, network.tables.get("km_breaks")
    georef = network_georef(network)
    keep = not network.tracks.empty  # a network with tracks: its topology rules reuse the step bounds
    return network.cached(_grid_key(network), lambda: GridIndex(gis, kb, georef=georef, keep_bounds=keep))


def _grid_key(network: Network) -> tuple[str, int, int]:
    return ("grid_index", id(network.gis), id(network.tables.get("km_breaks")))


def built_grid_index(network: Network) -> GridIndex | None:
    """The :func:`grid_index` of ``network`` if it was already built, else None (not built)."""
    grid = network.peek(_grid_key(network))
    return grid if isinstance(grid, GridIndex) else None
