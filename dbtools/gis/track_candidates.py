"""Candidate tracks of each fix: the nearest segment of every track within the search radius.

A fix (plane x, y) and a segment from P0 with direction D: the foot of the perpendicular at
u = clamp(((X − P0)·D) / |D|², 0, 1), distance d = |X − (P0 + u·D)|, signed offset positive
left of the track's direction (begin → end): sign of D × (X − P0). A segment within radius r
of a fix has its midpoint within r + ½·longest segment, so a k-d tree over the midpoints
(scipy ``cKDTree``: the ``k`` nearest within that bound, ``k`` raised for the fixes where
all ``k`` are within it) gives every segment in reach; per (fix, track) the nearest of them
is kept, and per fix at most ``max_tracks`` tracks, nearest first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from dbtools.gis.track_segments import TrackGeometry

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: Midpoints looked at per fix at first (more where these do not reach the bound).
K_FIRST = 16


@dataclass(frozen=True)
class Candidates:
    """Candidates of the fixes, grouped by fix in fix order (``offsets``: fix k's candidates
    are ``offsets[k]:offsets[k+1]``), nearest first within a fix."""

    offsets: I64
    track: I64
    dist_m: F64
    """Perpendicular distance [m] (≥ 0)."""
    offset_m: F64
    """Signed offset, positive left of the track's begin → end direction [m]."""
    pos_m: F64
    """Distance along the track from its begin at the foot [m]."""
    km_m: F64
    ux: F64
    """Unit direction of the segment (begin → end), plane east/north components."""
    uy: F64


def segment_tree(geo: TrackGeometry) -> object:
    from scipy.spatial import cKDTree

    mx, my = geo.x0 + 0.5 * geo.dx, geo.y0 + 0.5 * geo.dy
    return cKDTree(np.column_stack([mx, my]))


def _near_segments(tree: object, xy: F64, bound: float, n_seg: int) -> tuple[I64, I64]:
    """(fix, segment) of every segment midpoint within ``bound`` of each fix: the ``K_FIRST``
    nearest first; the fixes whose last one is still within the bound (there may be more)
    asked again with four times as many, until none is cut short."""
    fixes, segs = [], []
    todo = np.arange(len(xy), dtype=np.int64)
    k = min(K_FIRST, n_seg)
    while len(todo):
        dist, idx = tree.query(xy[todo], k=k, distance_upper_bound=bound)  # type: ignore[attr-defined]
        idx = np.asarray(idx, dtype=np.int64).reshape(len(todo), k)
        full = np.isfinite(np.asarray(dist).reshape(len(todo), k)[:, -1]) & (k < n_seg)
        done = todo[~full]
        fixes.append(np.repeat(done, k))
        segs.append(idx[~full].ravel())
        todo, k = todo[full], min(4 * k, n_seg)
    fix, seg = np.concatenate(fixes), np.concatenate(segs)
    keep = seg < n_seg
    return fix[keep], seg[keep]


def find_candidates(geo: TrackGeometry, tree: object, x: F64, y: F64, radius_m: float, max_tracks: int) -> Candidates:
    """Candidates of fixes at plane (x, y) within ``radius_m`` (see the module docstring)."""
    n = len(x)
    half = 0.5 * float(np.max(np.hypot(geo.dx, geo.dy))) if len(geo.dx) else 0.0
    if n == 0 or len(geo.dx) == 0:
        e = np.empty(0)
        return Candidates(np.zeros(n + 1, dtype=np.int64), e.astype(np.int64), e, e, e, e, e, e)
    fix, seg = _near_segments(tree, np.column_stack([x, y]), radius_m + half, len(geo.dx))
    px, py = x[fix] - geo.x0[seg], y[fix] - geo.y0[seg]
    dx, dy = geo.dx[seg], geo.dy[seg]
    l2 = np.maximum(dx * dx + dy * dy, 1e-12)
    u = np.clip((px * dx + py * dy) / l2, 0.0, 1.0)
    ex, ey = px - u * dx, py - u * dy
    d = np.hypot(ex, ey)
    near = d <= radius_m
    fix, seg, u, d = fix[near], seg[near], u[near], d[near]
    trk = geo.seg_track[seg]
    # nearest segment per (fix, track), then tracks by distance within each fix
    order = np.lexsort((seg, d, trk, fix))
    fix, seg, u, d, trk = fix[order], seg[order], u[order], d[order], trk[order]
    first = np.ones(len(fix), dtype=bool)
    first[1:] = (fix[1:] != fix[:-1]) | (trk[1:] != trk[:-1])
    fix, seg, u, d, trk = fix[first], seg[first], u[first], d[first], trk[first]
    order = np.lexsort((trk, d, fix))
    fix, seg, u, d, trk = fix[order], seg[order], u[order], d[order], trk[order]
    start = np.searchsorted(fix, fix, side="left")
    rank = np.arange(len(fix)) - start
    keep = rank < max_tracks
    fix, seg, u, d, trk = fix[keep], seg[keep], u[keep], d[keep], trk[keep]
    dx, dy = geo.dx[seg], geo.dy[seg]
    norm = np.maximum(np.hypot(dx, dy), 1e-12)
    cross = dx * (y[fix] - geo.y0[seg]) - dy * (x[fix] - geo.x0[seg])
    offsets = np.searchsorted(fix, np.arange(n + 1), side="left").astype(np.int64)
    return Candidates(
        offsets,
        trk,
        d,
        np.where(cross >= 0, d, -d),
        geo.s0[seg] + u * geo.ds[seg],
        geo.km0[seg] + u * geo.dkm[seg],
        dx / norm,
        dy / norm,
    )
