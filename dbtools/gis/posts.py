"""Kilometre posts on one surveyed track (steps 2–5 of :mod:`dbtools.gis.grid`): the posts
of a line in the plane, their projection onto a track polyline, the reference chainage
``dr = ds − o·dθ``, the runs of continuous kilometrage and the 20 m grid kms of each run."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import PolylineIndex, turn_angle
from schemas.tables import GIS_SPACING_M

FloatArray = npt.NDArray[np.float64]

#: A post whose foot falls more than this beyond a track's end is not used on it [m].
BEYOND_END_TOL_M = 1.0
#: Grid kms may lie this far outside a run (float round-off at exact multiples) [m].
KM_EPS_M = 1e-6


@dataclass
class Posts:
    """The posts of one line, with their projected plane coordinates."""

    frame_index: pd.Index
    """Index labels of the posts in the input frame (for finding locations)."""
    km: FloatArray
    km_after: FloatArray
    x: FloatArray
    y: FloatArray
    used: npt.NDArray[np.bool_]
    nearest_m: FloatArray


def km_runs(
    r: FloatArray, rp: FloatArray, km_before: FloatArray, km_after: FloatArray
) -> list[tuple[list[float], list[float]]]:
    """Step 4: runs of continuous kilometrage, (reference chainage, km) knots of each, split
    at break posts; slope 1 before the first and after the last post."""
    runs: list[tuple[list[float], list[float]]] = []
    rk: list[float] = [float(r[0])]
    kk: list[float] = [float(km_before[0] - (rp[0] - r[0]))]
    for j in range(rp.size):
        if rp[j] > rk[-1]:
            rk.append(float(rp[j]))
            kk.append(float(km_before[j]))
        if km_after[j] != km_before[j]:
            runs.append((rk, kk))
            rk, kk = [float(rp[j])], [float(km_after[j])]
    if r[-1] > rk[-1]:
        kk.append(kk[-1] + float(r[-1] - rk[-1]))
        rk.append(float(r[-1]))
    runs.append((rk, kk))
    return runs


def grid_kms(
    runs: list[tuple[list[float], list[float]]], keys: dict[str, object]
) -> tuple[list[FloatArray], list[FloatArray], list[dict[str, object]]]:
    """Step 5: the multiples of 20 m of km inside each run, their reference chainage and
    one ``km_breaks`` row per break (last grid km before, first after)."""
    kms: list[FloatArray] = []
    refs: list[FloatArray] = []
    breaks: list[dict[str, object]] = []
    last_km: float | None = None
    for n_run, (rk_, kk_) in enumerate(runs):
        k_lo = math.ceil(kk_[0] / GIS_SPACING_M - KM_EPS_M / GIS_SPACING_M)
        k_hi = math.floor(kk_[-1] / GIS_SPACING_M + KM_EPS_M / GIS_SPACING_M)
        grid_km = np.arange(k_lo, k_hi + 1, dtype=float) * GIS_SPACING_M
        if not grid_km.size:
            continue
        if n_run > 0 and last_km is not None:
            breaks.append({**keys, "km_from_m": last_km, "km_to_m": float(grid_km[0])})
        last_km = float(grid_km[-1])
        kms.append(grid_km)
        refs.append(np.interp(grid_km, kk_, rk_) if len(rk_) > 1 else np.full(grid_km.size, rk_[0]))
    return kms, refs, breaks


@dataclass
class PostProjection:
    km_m: FloatArray
    offset_m: FloatArray
    distance_m: FloatArray
    beyond: npt.NDArray[np.bool_]


def project_posts(
    x: FloatArray, y: FloatArray, s: FloatArray, posts: Posts, max_offset: float
) -> tuple[PostProjection, npt.NDArray[np.bool_]]:
    """Chainage ``s`` of the foot, signed offset and distance of every post on one polyline
    (plane ``x``, ``y``; ground chainage ``s`` at the vertices); which posts are usable."""
    if posts.x.size == 0:
        empty = np.empty(0)
        return PostProjection(empty, empty, empty, np.empty(0, dtype=bool)), np.empty(0, dtype=bool)
    p = PolylineIndex(x, y, s).project(posts.x, posts.y)
    # along-track distance of the post from each end, positive inwards (negative = beyond)
    first = max(float(np.hypot(x[1] - x[0], y[1] - y[0])), 1e-12)
    last = max(float(np.hypot(x[-1] - x[-2], y[-1] - y[-2])), 1e-12)
    t0 = ((posts.x - x[0]) * (x[1] - x[0]) + (posts.y - y[0]) * (y[1] - y[0])) / first
    t1 = ((x[-1] - posts.x) * (x[-1] - x[-2]) + (y[-1] - posts.y) * (y[-1] - y[-2])) / last
    beyond = ((p.km_m <= 0.0) & (t0 < -BEYOND_END_TOL_M)) | ((p.km_m >= s[-1]) & (t1 < -BEYOND_END_TOL_M))
    usable = (p.distance_m <= max_offset) & ~beyond
    return PostProjection(p.km_m, p.offset_m, p.distance_m, beyond), usable


def reference_chainage(x: FloatArray, y: FloatArray, s: FloatArray, offset_m: float) -> FloatArray:
    """``r`` at the vertices: ``dr = ds − o·dθ``, each vertex's turn split over its two segments."""
    if offset_m == 0.0 or x.size < 3:
        return s.copy()
    turn = np.nan_to_num(turn_angle(x, y))
    seg_turn = 0.5 * (turn[:-1] + turn[1:])
    return np.concatenate([[0.0], np.cumsum(np.diff(s) - offset_m * seg_turn)])
