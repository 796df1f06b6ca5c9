"""The candidate search of :meth:`dbtools.gis.matching.TrackIndex.match_xy` in numpy, and the
cell keys of its candidate index (the method: :mod:`dbtools.gis.matching`).

The same answer as the compiled loop of :mod:`dbtools.gis.match_kernel`, bit for bit (the
same float operations in the same order, the same tie rules; a hypothesis test compares
the two): per fix every vertex of the 3 × 3 cells of side R around it, the segments
adjacent to each (each segment once, where the kernel meets some twice: the same set), per
track the nearest within ``max_d2`` (lowest segment index on exact ties: one integer sort by
(fix, track) and group minima), tracks nearest first. The pairs (fix, candidate segment)
are materialised, a block of fixes at a time: for the few thousand fixes of a run this
costs milliseconds, where
importing numba and loading the kernel from its disk cache costs a few tenths of a second
(bench/NOTES.md, "Whole-process run (issue 21, third pass)"); for many fixes the kernel is
faster (:data:`NUMPY_MAX_FIXES`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

#: Cell coordinates are offset by this and keyed as ``cx · stride + cy`` (int64, no overlap).
CELL_OFFSET = 1 << 24
CELL_STRIDE = 1 << 26
#: Up to this many fixes a match is done here unless the compiled kernel is already loaded: a
#: day of GPS at 1 Hz (86,400 fixes), so a 24 h run's one match needs no numba. At 100,000 fixes
#: on the demo line this path takes ≈ 0.2 s CPU (0.37 s before the grouping by one sort) and
#: ≈ 60 MB of peak (blocks of BLOCK_FIXES), where importing numba and loading the kernel takes
#: ≈ 0.5 s and ≈ 190 MB of RSS before it matches them in 0.03 s (bench/NOTES.md, "Day-long runs
#: without numba" and "Map matching: which path the bench timed"); the kernel is faster in a
#: fresh process beyond ≈ 300,000 fixes, and at any size once loaded.
NUMPY_MAX_FIXES = 100_000
#: Fixes per block of materialised candidate pairs (bounds the memory: ~ 20–60 pairs a fix).
BLOCK_FIXES = 8192


def _cell(v: FloatArray, side: float) -> IntArray:
    """Offset cell coordinate of coordinates ``v`` in cells of ``side`` metres, clipped into
    the key range (a point beyond it shares a border cell, and distances decide)."""
    return np.clip(np.floor(v / side), -CELL_OFFSET + 1, CELL_STRIDE - 2 - CELL_OFFSET).astype(np.int64) + CELL_OFFSET


def cell_keys(x: FloatArray, y: FloatArray, side: float) -> IntArray:
    """Cell key ``cx · stride + cy`` of points in cells of ``side`` metres (:func:`_cell`)."""
    return _cell(x, side) * CELL_STRIDE + _cell(y, side)


def _candidates(
    qx: FloatArray, qy: FloatArray, side: float, keys: IntArray, start: IntArray
) -> tuple[IntArray, IntArray, IntArray, IntArray]:
    """(row of the fix in ``qx``, position in the vertex order) of every vertex of the 3 × 3
    cells around each fix: per column of cells gx one contiguous run of the order, as the
    kernel's walk over consecutive keys; and the fixes' own cells (cx, cy)."""
    lo_cell, hi_cell = 1, CELL_STRIDE - 2
    cx, cy = _cell(qx, side), _cell(qy, side)
    lo_y = np.maximum(cy - 1, lo_cell)
    hi_y = np.minimum(cy + 1, hi_cell)
    rows, firsts, counts = [], [], []
    for k in (-1, 0, 1):
        gx = cx + k
        ok = np.flatnonzero((gx >= lo_cell) & (gx <= hi_cell))
        c0 = np.searchsorted(keys, gx[ok] * CELL_STRIDE + lo_y[ok], side="left")
        c1 = np.searchsorted(keys, gx[ok] * CELL_STRIDE + hi_y[ok], side="right")
        rows.append(ok)
        firsts.append(start[c0])
        counts.append(start[c1] - start[c0])
    row, first, count = np.concatenate(rows), np.concatenate(firsts), np.concatenate(counts)
    fix_row = np.repeat(row, count)
    pos = np.arange(fix_row.size) - np.repeat(np.cumsum(count) - count, count) + np.repeat(first, count)
    return fix_row, pos, cx, cy


def _segments(
    row: IntArray, v: IntArray, cx: IntArray, cy: IntArray, side: float, x: FloatArray, y: FloatArray,
    segment_ok: BoolArray, vertex_track: IntArray, ok_track: BoolArray,
) -> tuple[IntArray, IntArray]:  # fmt: skip
    """(row, segment) of the segments adjacent to the candidate vertices ``v`` of fixes
    ``row``, each once: segment v, and segment v − 1 unless vertex v − 1 lies in the fix's
    3 × 3 cells too (then it is a candidate and brings that segment as its own). The kernel
    evaluates such a segment twice, with the same result; the set is the same."""
    keep = segment_ok[v] & ok_track[vertex_track[v]]
    w = v - 1
    has = w >= 0
    wr, w = row[has], w[has]
    prev = segment_ok[w] & ok_track[vertex_track[w]]
    wr, w = wr[prev], w[prev]
    outside = (np.abs(_cell(x[w], side) - cx[wr]) > 1) | (np.abs(_cell(y[w], side) - cy[wr]) > 1)
    return np.concatenate([row[keep], wr[outside]]), np.concatenate([v[keep], w[outside]])


def _nearest_per_track(
    fix: IntArray, track: IntArray, seg: IntArray, d2: FloatArray, n_tracks: int
) -> tuple[IntArray, IntArray]:
    """(kept candidates, their pass) — per (fix, track) the lexicographic minimum of
    (distance², segment), then each fix's tracks ordered by (distance², segment).

    One integer sort groups the candidates by (fix, track); each group's minimum distance²
    and, among the candidates at that distance, its lowest segment are group reductions
    (``np.minimum.reduceat``), which a lexicographic sort on all four keys would give
    too at about three times the cost. Candidates of one segment reached from both of
    its vertices are identical (same segment, same fix: same u and distance²): any one
    of them is kept."""
    if fix.size == 0:
        return fix, fix
    key = fix * n_tracks + track
    o = np.argsort(key)
    k, dd, ss = key[o], d2[o], seg[o]
    new = np.empty(k.size, dtype=bool)
    new[0] = True
    new[1:] = k[1:] != k[:-1]
    starts = np.flatnonzero(new)
    size = np.diff(np.append(starts, k.size))
    at_min = dd == np.repeat(np.minimum.reduceat(dd, starts), size)
    lowest = np.minimum.reduceat(np.where(at_min, ss, np.iinfo(np.int64).max), starts)
    pos = np.flatnonzero(at_min & (ss == np.repeat(lowest, size)))
    group = np.cumsum(new)[pos]
    first = np.empty(pos.size, dtype=bool)
    first[0] = True
    first[1:] = group[1:] != group[:-1]
    kept = o[pos[first]]
    kept = kept[np.lexsort((seg[kept], d2[kept], fix[kept]))]
    fk = fix[kept]
    new = np.ones(kept.size, dtype=bool)
    new[1:] = fk[1:] != fk[:-1]
    starts = np.flatnonzero(new)
    passes = np.arange(kept.size) - np.repeat(starts, np.diff(np.append(starts, kept.size)))
    return kept, passes.astype(np.int64)


def match_numpy(
    px: FloatArray, py: FloatArray, fixes: IntArray, side: float, keys: IntArray, start: IntArray,
    order: IntArray, x: FloatArray, y: FloatArray, dx: FloatArray, dy: FloatArray, inv_len2: FloatArray,
    segment_ok: BoolArray, vertex_track: IntArray, ok_track: BoolArray, max_d2: float,
) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]:  # fmt: skip
    """(fix, pass, segment, u, squared distance) for the fixes ``fixes``: what
    :func:`dbtools.gis.match_kernel.match_kernel` returns for them (rows in another order,
    the same set; :meth:`TrackIndex.match_xy` orders them by fix and pass)."""
    out: list[tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray]] = []
    for b in range(0, fixes.size, BLOCK_FIXES):
        block = fixes[b : b + BLOCK_FIXES]
        qx, qy = px[block], py[block]
        row, pos, cx, cy = _candidates(qx, qy, side, keys, start)
        row, s = _segments(row, order[pos], cx, cy, side, x, y, segment_ok, vertex_track, ok_track)
        ax, ay, sx, sy, qxr, qyr = x[s], y[s], dx[s], dy[s], qx[row], qy[row]
        t = ((qxr - ax) * sx + (qyr - ay) * sy) * inv_len2[s]
        m = np.where(0.0 > t, 0.0, t)  # min(max(t, 0), 1) as the kernel (and Python) evaluate it
        u = np.where(1.0 < m, 1.0, m)
        ex = ax + u * sx - qxr
        ey = ay + u * sy - qyr
        d2 = ex * ex + ey * ey
        near = d2 <= max_d2
        row, s, u, d2 = row[near], s[near], u[near], d2[near]
        kept, passes = _nearest_per_track(row, vertex_track[s], s, d2, ok_track.size)
        out.append((block[row[kept]], passes, s[kept], u[kept], d2[kept]))
    if not out:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z, np.zeros(0), np.zeros(0)
    f, p, sg, uu, dd = (np.concatenate(a) for a in zip(*out, strict=True))
    return f, p, sg, uu, dd
