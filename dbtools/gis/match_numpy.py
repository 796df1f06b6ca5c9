"""The candidate search of :meth:`dbtools.gis.matching.TrackIndex.match_xy` in numpy, and the
cell keys of its candidate index (the method: :mod:`dbtools.gis.matching`).

The same answer as the compiled loop of :mod:`dbtools.gis.match_kernel`, bit for bit (the
same float operations in the same order, the same tie rules; a hypothesis test compares
the two): per fix every vertex of the 3 × 3 cells of side R around it, both segments
adjacent to each, per track the nearest within ``max_d2`` (lowest segment index on exact
ties), tracks nearest first. The pairs (fix, candidate segment) are materialised, a block
of fixes at a time: for the few thousand fixes of a run this costs milliseconds, where
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
#: this path takes ≈ 0.3 s and ≈ 60 MB of peak (blocks of BLOCK_FIXES), where importing numba
#: and loading the kernel takes ≈ 0.5 s and ≈ 190 MB of RSS before it matches them in 0.03 s
#: (bench/NOTES.md, "Day-long runs without numba"); beyond ≈ 180,000 fixes the kernel is faster.
NUMPY_MAX_FIXES = 100_000
#: Fixes per block of materialised candidate pairs (bounds the memory: ~ 20–60 pairs a fix).
BLOCK_FIXES = 8192


def cell_keys(x: FloatArray, y: FloatArray, side: float) -> IntArray:
    """Cell key ``cx · stride + cy`` of points in cells of ``side`` metres; the cell
    coordinates are offset and clipped into the key range (a point beyond it shares a
    border cell, and distances decide)."""
    hi = CELL_STRIDE - 2

    def cell(v: FloatArray) -> IntArray:
        return np.clip(np.floor(v / side), -CELL_OFFSET + 1, hi - CELL_OFFSET).astype(np.int64) + CELL_OFFSET

    return cell(x) * CELL_STRIDE + cell(y)


def _candidates(
    qx: FloatArray, qy: FloatArray, side: float, keys: IntArray, start: IntArray
) -> tuple[IntArray, IntArray]:
    """(row of the fix in ``qx``, position in the vertex order) of every vertex of the 3 × 3
    cells around each fix: per column of cells gx one contiguous run of the order, as the
    kernel's walk over consecutive keys."""
    lo_cell, hi_cell = 1, CELL_STRIDE - 2
    cx = (np.clip(np.floor(qx / side), -CELL_OFFSET + 1, hi_cell - CELL_OFFSET) + CELL_OFFSET).astype(np.int64)
    cy = (np.clip(np.floor(qy / side), -CELL_OFFSET + 1, hi_cell - CELL_OFFSET) + CELL_OFFSET).astype(np.int64)
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
    return fix_row, pos


def _nearest_per_track(fix: IntArray, track: IntArray, seg: IntArray, d2: FloatArray) -> tuple[IntArray, IntArray]:
    """(kept candidates, their pass) — per (fix, track) the lexicographic minimum of
    (distance², segment), then each fix's tracks ordered by (distance², segment)."""
    order = np.lexsort((seg, d2, track, fix))
    f, t = fix[order], track[order]
    first = np.ones(order.size, dtype=bool)
    first[1:] = (f[1:] != f[:-1]) | (t[1:] != t[:-1])
    kept = order[first]
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
        row, pos = _candidates(qx, qy, side, keys, start)
        v = order[pos]
        row = np.concatenate([row, row])
        s = np.concatenate([v - 1, v])  # both segments adjacent to each vertex
        keep = s >= 0
        row, s = row[keep], s[keep]
        keep = segment_ok[s] & ok_track[vertex_track[s]]
        row, s = row[keep], s[keep]
        ax, ay, sx, sy, qxr, qyr = x[s], y[s], dx[s], dy[s], qx[row], qy[row]
        t = ((qxr - ax) * sx + (qyr - ay) * sy) * inv_len2[s]
        m = np.where(0.0 > t, 0.0, t)  # min(max(t, 0), 1) as the kernel (and Python) evaluate it
        u = np.where(1.0 < m, 1.0, m)
        ex = ax + u * sx - qxr
        ey = ay + u * sy - qyr
        d2 = ex * ex + ey * ey
        near = d2 <= max_d2
        row, s, u, d2 = row[near], s[near], u[near], d2[near]
        kept, passes = _nearest_per_track(row, vertex_track[s], s, d2)
        out.append((block[row[kept]], passes, s[kept], u[kept], d2[kept]))
    if not out:
        z = np.zeros(0, dtype=np.int64)
        return z, z, z, np.zeros(0), np.zeros(0)
    f, p, sg, uu, dd = (np.concatenate(a) for a in zip(*out, strict=True))
    return f, p, sg, uu, dd
