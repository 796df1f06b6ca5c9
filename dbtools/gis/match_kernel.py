"""The compiled loop of :meth:`dbtools.gis.matching.TrackIndex.match_xy` (numba) for many
fixes (the method: :mod:`dbtools.gis.matching`; its numpy twin and the cell keys:
:mod:`dbtools.gis.match_numpy`).

A module of its own so that numba is imported only when many fixes are matched (or the
kernel was loaded ahead, :mod:`fieldlogs.pipeline.warm`), not by every command that reads a
DB nor by a run's few thousand fixes. The kernels are cached on disk (``cache=True``): numba compiles
them once per installation, later processes load the machine code.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from dbtools.gis.geometry import FloatArray
from dbtools.gis.match_numpy import CELL_OFFSET as _CELL_OFFSET
from dbtools.gis.match_numpy import CELL_STRIDE as _CELL_STRIDE
from dbtools.gis.match_numpy import cell_keys

IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]

__all__ = ["cell_keys", "match_kernel", "warm"]


@njit(cache=True, nogil=True)
def _consider(
    v: int, qx: float, qy: float, x: FloatArray, y: FloatArray, dx: FloatArray, dy: FloatArray,
    inv_len2: FloatArray, segment_ok: BoolArray, vertex_track: IntArray, ok_track: BoolArray, max_d2: float,
    nt: int, bt: IntArray, bs: IntArray, bd: FloatArray, bu: FloatArray,
) -> int:  # fmt: skip
    """Both segments adjacent to vertex ``v``: keep per track the nearest (first segment
    index on exact ties, like an argmin over the track). Returns the number of tracks."""
    for s in (v - 1, v):
        if s < 0 or not segment_ok[s] or not ok_track[vertex_track[s]]:
            continue
        t = vertex_track[s]
        ax = x[s]
        ay = y[s]
        u = min(max(((qx - ax) * dx[s] + (qy - ay) * dy[s]) * inv_len2[s], 0.0), 1.0)
        ex = ax + u * dx[s] - qx
        ey = ay + u * dy[s] - qy
        d2 = ex * ex + ey * ey
        if d2 > max_d2:
            continue
        j = 0
        while j < nt and bt[j] != t:
            j += 1
        if j == nt:
            bt[j] = t
            nt += 1
        elif not (d2 < bd[j] or (d2 == bd[j] and s < bs[j])):
            continue
        bs[j] = s
        bd[j] = d2
        bu[j] = u
    return nt


@njit(cache=True, nogil=True)
def _sort_nearest_first(nt: int, bt: IntArray, bs: IntArray, bd: FloatArray, bu: FloatArray) -> None:
    """Insertion sort of the first ``nt`` entries by distance, then segment index (a
    deterministic order for tracks at exactly the same distance)."""
    for i in range(1, nt):
        j = i
        while j > 0 and (bd[j] < bd[j - 1] or (bd[j] == bd[j - 1] and bs[j] < bs[j - 1])):
            bt[j], bt[j - 1] = bt[j - 1], bt[j]
            bs[j], bs[j - 1] = bs[j - 1], bs[j]
            bd[j], bd[j - 1] = bd[j - 1], bd[j]
            bu[j], bu[j - 1] = bu[j - 1], bu[j]
            j -= 1


@njit(cache=True, nogil=True)
def match_kernel(
    px: FloatArray, py: FloatArray, fixes: IntArray, first: int, side: float, keys: IntArray, start: IntArray,
    order: IntArray, x: FloatArray, y: FloatArray, dx: FloatArray, dy: FloatArray, inv_len2: FloatArray,
    segment_ok: BoolArray, vertex_track: IntArray, ok_track: BoolArray, max_d2: float,
) -> tuple[IntArray, IntArray, IntArray, FloatArray, FloatArray, int]:  # fmt: skip
    """For fixes ``fixes[first:]``: every vertex of the 3 × 3 cells around the fix (all the
    vertices within the cell side, and more), both segments adjacent to each, per track the
    nearest; tracks emitted nearest first. Returns (fix, pass, segment, u, squared
    distance, index of the first fix not done): the same arithmetic as
    :class:`PolylineIndex` / brute force (the signed offset is taken from them by
    :meth:`TrackIndex.match_xy`). Stops early when the output buffer is full."""
    m = fixes.size
    n_tracks = ok_track.size
    cap = max(4 * (m - first), n_tracks) + n_tracks
    out_f = np.empty(cap, dtype=np.int64)
    out_p = np.empty(cap, dtype=np.int64)
    out_s = np.empty(cap, dtype=np.int64)
    out_u = np.empty(cap)
    out_d2 = np.empty(cap)
    bt = np.empty(n_tracks, dtype=np.int64)
    bs = np.empty(n_tracks, dtype=np.int64)
    bd = np.empty(n_tracks)
    bu = np.empty(n_tracks)
    lo_cell = 1
    hi_cell = _CELL_STRIDE - 2
    n_out = 0
    r = first
    while r < m and n_out + n_tracks <= cap:
        f = fixes[r]
        qx = px[f]
        qy = py[f]
        cx = min(max(np.floor(qx / side), -_CELL_OFFSET + 1), hi_cell - _CELL_OFFSET) + _CELL_OFFSET
        cy = min(max(np.floor(qy / side), -_CELL_OFFSET + 1), hi_cell - _CELL_OFFSET) + _CELL_OFFSET
        nt = 0
        for gx in range(max(int(cx) - 1, lo_cell), min(int(cx) + 1, hi_cell) + 1):
            # cells (gx, cy − 1 … cy + 1) have consecutive keys: one search, then a walk
            lo_key = gx * _CELL_STRIDE + max(int(cy) - 1, lo_cell)
            hi_key = gx * _CELL_STRIDE + min(int(cy) + 1, hi_cell)
            c = np.searchsorted(keys, lo_key)
            while c < keys.size and keys[c] <= hi_key:
                for i in range(start[c], start[c + 1]):
                    nt = _consider(
                        order[i], qx, qy, x, y, dx, dy, inv_len2, segment_ok, vertex_track, ok_track, max_d2,
                        nt, bt, bs, bd, bu,
                    )  # fmt: skip
                c += 1
        _sort_nearest_first(nt, bt, bs, bd, bu)
        for j in range(nt):
            out_f[n_out + j] = f
            out_p[n_out + j] = j
            out_s[n_out + j] = bs[j]
            out_u[n_out + j] = bu[j]
            out_d2[n_out + j] = bd[j]
        n_out += nt
        r += 1
    return out_f[:n_out], out_p[:n_out], out_s[:n_out], out_u[:n_out], out_d2[:n_out], r


def warm() -> None:
    """Compile the kernel (or load it from the disk cache) for the argument types
    :meth:`~dbtools.gis.matching.TrackIndex.match_xy` passes, on a two-vertex track: done
    ahead by ``make`` (the install step), so that no command — nor every worker of an
    audit pool at once — compiles it on its first match."""
    f = np.zeros(2)
    i = np.zeros(2, dtype=np.int64)
    ok = np.ones(2, dtype=np.bool_)
    match_kernel(f, f, i[:1], 0, 1.0, i[:1], np.array([0, 2], dtype=np.int64), i, f, f, f, f, f, ok, i, ok[:1], 1.0)
