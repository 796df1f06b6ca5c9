"""GIS verification, step 6 (:mod:`dbtools.gis.verify`): least-squares lateral point
shifts of a defect (total variation, Huber), lateral moves of grid points in the network's
plane, the proposal table and the network with the proposal applied."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import FloatArray, Projector
from dbtools.gis.index import GridIndex
from dbtools.gis.verify.cells import Cells
from dbtools.gis.verify.config import (
    EDGE_CELLS,
    HUBER_ITERATIONS,
    HUBER_K,
    PROPOSAL_COLUMNS,
    TV_EPS_M,
    TV_ITERATIONS,
    TV_SEGMENT_TOL_M,
    VerifyConfig,
)
from dbtools.gis.verify.result import GisVerification
from dbtools.network import Network, canonical
from schemas.network import TRACK_POINTS
from schemas.tables import GIS

IntArray = npt.NDArray[np.int64]


def point_shifts(
    matched: pd.DataFrame,
    first: int,
    last: int,
    same_track: IntArray,
    *,
    background: pd.Series | None = None,
    ridge: float = 1e-3,
    smooth: float = 0.0,
) -> FloatArray:
    """Least-squares lateral shifts of the grid points first..last (grid point ids; step 6).

    Uses the fixes of the cells that touch them (first−1 .. last) on the same track
    (``same_track``: the grid point ids of that track; the points beyond are fixed at 0);
    each fix weighs 1 / (fixes of its run in its cell). With ``background`` (run → its mean offset beside
    the defect, :func:`run_backgrounds`) only those runs are used, each offset minus its
    run's background. Penalties, relative to the mean data weight per point: ``ridge``·Σe²
    and the total variation ``smooth``·Σ|Δe| over neighbouring points, including the steps
    to the fixed points either side (piecewise-constant errors keep their steps; noise is
    flattened)."""
    from scipy.linalg import solve_banded

    n_pts = last - first + 1
    lo, hi = max(first - 1, int(same_track[0])), min(last, int(same_track[-1]))
    a, b = np.searchsorted(matched["cell"].to_numpy(), [lo, hi + 1])  # ``matched`` is sorted by cell
    sel = matched.iloc[a:b]
    off = sel["offset_m"].to_numpy()
    if background is not None and not background.empty:
        keep = sel["run"].isin(background.index).to_numpy()
        sel = sel[keep]
        off = off[keep] - background.reindex(sel["run"]).to_numpy(dtype=float)
    cell = sel["cell"].to_numpy()
    u = sel["u"].to_numpy()
    run = sel["run"].to_numpy()
    _, inv, cnt = np.unique(cell * (int(run.max(initial=0)) + 1) + run, return_inverse=True, return_counts=True)
    w = 1.0 / cnt[inv]
    left = cell - first  # local index of the cell's start point (−1 … n_pts − 1)
    right = left + 1
    phi_l, phi_r = 1.0 - u, u
    ok_l = (left >= 0) & (left < n_pts)
    ok_r = (right >= 0) & (right < n_pts)
    both = ok_l & ok_r
    lc, rc_ = np.where(ok_l, left, 0), np.where(ok_r, right, 0)
    pl, pr = np.where(ok_l, phi_l, 0.0), np.where(ok_r, phi_r, 0.0)

    def fit(wt: FloatArray) -> FloatArray:
        """The penalised least squares for fix weights ``wt``."""
        diag = _weighted_count(lc, wt * pl**2, n_pts) + _weighted_count(rc_, wt * pr**2, n_pts)
        upper = _weighted_count(left[both], wt[both] * phi_l[both] * phi_r[both], n_pts)
        rhs = _weighted_count(lc, wt * pl * off, n_pts) + _weighted_count(rc_, wt * pr * off, n_pts)
        scale = max(float(diag.mean()), 1e-9)
        diag = diag + ridge * scale

        def solve(v: FloatArray) -> FloatArray:
            """(A + ridge + Dᵀ·diag(v)·D) e = b, D the first difference over 0, e, 0."""
            ab = np.zeros((3, n_pts))
            ab[0, 1:] = upper[:-1] - v[1:-1]
            ab[1] = diag + v[:-1] + v[1:]
            ab[2, :-1] = upper[:-1] - v[1:-1]
            return np.asarray(solve_banded((1, 1), ab, rhs), dtype=float)

        e = solve(np.zeros(n_pts + 1))
        if smooth <= 0:
            return e
        # total variation λ·Σ|Δe| by iteratively reweighted least squares: the quadratic
        # weight λ / (2·|Δe|) has the same gradient at the current estimate
        lam = smooth * scale
        for _ in range(TV_ITERATIONS):
            v = lam / (2.0 * np.maximum(np.abs(np.diff(np.concatenate([[0.0], e, [0.0]]))), TV_EPS_M))
            e_new = solve(v)
            converged = np.max(np.abs(e_new - e)) < 1e-4
            e = e_new
            if converged:
                break
        return _refit_segments(e, diag, upper, rhs)

    e = fit(w)
    # Huber re-weighting: a multipath burst that passed the trust filter must not bend the fit
    for _ in range(HUBER_ITERATIONS):
        resid = off - (pl * e[lc] + pr * e[rc_])
        mad = 1.4826 * float(np.median(np.abs(resid))) if resid.size else 0.0
        if mad <= 0:
            break
        h = np.minimum(1.0, HUBER_K * mad / np.maximum(np.abs(resid), 1e-12))
        e = fit(w * h)
    return e


def _weighted_count(index: IntArray, weights: FloatArray, n: int) -> FloatArray:
    """Sum of ``weights`` per index 0..n−1 (``np.bincount`` with weights, typed)."""
    return np.asarray(np.bincount(index, weights, minlength=n), dtype=np.float64)


def _refit_segments(e: FloatArray, diag: FloatArray, upper: FloatArray, rhs: FloatArray) -> FloatArray:
    """Least squares again with e constant on each run of equal values that total
    variation produced (it shrinks every step by about λ / data weight; the refit keeps
    its segmentation, not its shrinkage). Segments at 0 stay at 0."""
    n = e.size
    padded = np.concatenate([[0.0], e])
    seg = np.cumsum(np.abs(np.diff(padded)) > TV_SEGMENT_TOL_M)  # 0 = the level of the fixed points
    free = np.unique(seg[seg > 0])
    if not free.size:
        return np.zeros(n)
    s_mat = (seg[:, None] == free[None, :]).astype(float)
    a = np.diag(diag)
    if n > 1:
        a += np.diag(upper[:-1], 1) + np.diag(upper[:-1], -1)
    c = np.linalg.lstsq(s_mat.T @ a @ s_mat, s_mat.T @ rhs, rcond=None)[0]
    return np.asarray(s_mat @ c, dtype=np.float64)


# ------------------------------------------------------------------------------ geometry


def lateral_shift(x: FloatArray, y: FloatArray, moved: IntArray, shift_m: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Points ``moved`` of one track polyline (x, y in km order) moved by ``shift_m``
    perpendicular to the track, positive to the left of increasing km. The tangent at a
    point is the chord between the points two either side (one-sided at the ends), taken
    from the *unmoved* polyline."""
    n = x.size
    a = np.clip(moved - 2, 0, n - 1)
    b = np.clip(moved + 2, 0, n - 1)
    tx, ty = x[b] - x[a], y[b] - y[a]
    norm = np.hypot(tx, ty)
    norm = np.where(norm > 0, norm, 1.0)
    nx, ny = -ty / norm, tx / norm  # left normal
    return x[moved] + shift_m * nx, y[moved] + shift_m * ny


def shift_grid_points(
    gis: pd.DataFrame,
    line_code: str,
    track: str,
    km_m: npt.ArrayLike,
    shift_m: npt.ArrayLike,
    projector: Projector | None = None,
) -> pd.DataFrame:
    """A copy of a GIS grid frame with the points (line_code, track, km_m) moved laterally by
    ``shift_m`` (positive = left of increasing km) in the plane zone of ``projector`` (by
    default the grid's one projection, :mod:`dbtools.gis.index`).

    Used for proposed corrections and to make surveyed-with-error grids for tests and
    benchmarks. Unknown km are an error (ValueError)."""
    out = gis.copy()
    on = ((out["line_code"].astype(str) == str(line_code)) & (out["track"].astype(str) == str(track))).to_numpy()
    idx = np.flatnonzero(on)
    trk = out.iloc[idx].sort_values("km_m", kind="stable")
    order = trk.index.to_numpy()
    kms = trk["km_m"].to_numpy(dtype=float)
    want = np.atleast_1d(np.asarray(km_m, dtype=float))
    s = np.broadcast_to(np.asarray(shift_m, dtype=float), want.shape)
    pos = np.searchsorted(kms, want)
    if want.size and ((pos >= kms.size).any() or not np.allclose(kms[np.minimum(pos, kms.size - 1)], want)):
        raise ValueError(f"km not on the grid of {line_code} {track}")
    lat = trk["lat"].to_numpy(dtype=float)
    lon = trk["lon"].to_numpy(dtype=float)
    proj = projector or GridIndex(gis).projector
    if proj is None:
        raise ValueError("the GIS grid has no valid point to project")
    x, y = proj.to_xy(lon, lat)
    nx, ny = lateral_shift(x, y, pos.astype(np.int64), s)
    new_lon, new_lat = proj.to_lonlat(nx, ny)
    rows = order[pos]
    out.loc[rows, "lat"] = np.round(new_lat, 9)
    out.loc[rows, "lon"] = np.round(new_lon, 9)
    return out


def build_proposal(
    defects: pd.DataFrame,
    first: IntArray,
    last: IntArray,
    matched: pd.DataFrame,
    grid: Cells,
    projector: Projector,
    cfg: VerifyConfig,
    backgrounds: list[pd.Series],
) -> pd.DataFrame:
    rows = []
    for d, a, b, back in zip(defects["defect_id"], first, last, backgrounds, strict=True):
        on = np.flatnonzero(grid.tid == grid.tid[a])  # the track's points (contiguous)
        # the defect's points and EDGE_CELLS more either side: where the displacement really
        # ends is decided by the fit (total variation keeps undisplaced points at 0)
        p_lo, p_hi = max(int(a) - EDGE_CELLS, int(on[0])), min(int(b) + 1 + EDGE_CELLS, int(on[-1]))
        e = point_shifts(matched, p_lo, p_hi, on, background=back, ridge=cfg.ridge, smooth=cfg.smooth)
        pts = np.arange(p_lo, p_hi + 1)
        keep = np.abs(e) >= cfg.min_move_m
        if not keep.any():
            continue
        pts, e = pts[keep], e[keep]
        local = pts - on[0]
        nx, ny = lateral_shift(grid.x[on], grid.y[on], local, e)
        lon_new, lat_new = projector.to_lonlat(nx, ny)
        g = grid.frame.iloc[pts]
        rows.append(
            pd.DataFrame(
                {
                    "defect_id": int(d),
                    "track_id": g["track_id"].to_numpy(),
                    "line_code": g["line_code"].to_numpy(),
                    "track": g["track"].to_numpy(),
                    "km_m": grid.km[pts],
                    "shift_m": e,
                    "lat": g["lat"].to_numpy(dtype=float),
                    "lon": g["lon"].to_numpy(dtype=float),
                    "lat_new": np.round(lat_new, 9),
                    "lon_new": np.round(lon_new, 9),
                }
            )
        )
    if not rows:
        return pd.DataFrame({c: pd.Series([], dtype=float) for c in PROPOSAL_COLUMNS})
    out = pd.concat(rows, ignore_index=True)[list(PROPOSAL_COLUMNS)]
    # two defects close together may both move a point between them: the larger move stands
    order = out.assign(size=-out["shift_m"].abs()).sort_values("size", kind="stable").index
    keep = ~out.loc[order].duplicated(["line_code", "track", "km_m"]).reindex(out.index).to_numpy()
    return out[keep].reset_index(drop=True)


def proposed_network(network: Network, result: GisVerification, track_points: GisVerification | None = None) -> Network:
    """``network`` with the GIS points of the proposal moved, and the track points of
    ``track_points``' proposal (:func:`dbtools.gis.verify.track_points.verify_track_points`,
    keyed by ``track_id`` and ``pos_m``); every other table unchanged."""
    tables = dict(network.tables)
    gis = network.gis.copy()
    p = result.proposal
    if len(p):
        key = pd.MultiIndex.from_frame(gis[["line_code", "track", "km_m"]].astype({"line_code": str, "track": str}))
        pkey = pd.MultiIndex.from_arrays([p["line_code"].astype(str), p["track"].astype(str), p["km_m"].astype(float)])
        pos = key.get_indexer(pkey)
        if (pos < 0).any():
            raise ValueError("a proposed point is not on the grid")
        gis.loc[pos, "lat"] = p["lat_new"].to_numpy(dtype=float)
        gis.loc[pos, "lon"] = p["lon_new"].to_numpy(dtype=float)
    tables[GIS.name] = canonical(GIS, gis)
    if track_points is not None and len(track_points.proposal):
        tables[TRACK_POINTS.name] = _moved_track_points(network.track_points, track_points.proposal)
    return Network(tables, origin=f"{network.origin} + gis verify proposal", meta={})


def _moved_track_points(tp: pd.DataFrame, proposal: pd.DataFrame) -> pd.DataFrame:
    """``track_points`` with the proposed points (``track_id``, ``pos_m`` → ``lat_new``, ``lon_new``) moved."""
    out = tp.reset_index(drop=True)
    key = pd.MultiIndex.from_arrays([out["track_id"].astype(str), out["pos_m"].astype(float)])
    pkey = pd.MultiIndex.from_arrays([proposal["track_id"].astype(str), proposal["pos_m"].astype(float)])
    pos = key.get_indexer(pkey)
    if (pos < 0).any():
        raise ValueError("a proposed point is not a track point")
    out.loc[pos, "lat"] = proposal["lat_new"].to_numpy(dtype=float)
    out.loc[pos, "lon"] = proposal["lon_new"].to_numpy(dtype=float)
    return canonical(TRACK_POINTS, out)
