"""GIS verification, steps 1–4 and 7 (:mod:`dbtools.gis.verify`): the cells of the grid
index, fixes matched onto their known track, run-level cell statistics, the t-test with
multiple-testing correction, the cell status and the coverage per track (``track_id``)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import FloatArray
from dbtools.gis.index import GridIndex
from dbtools.gis.matching import TrackIndex
from dbtools.gis.verify.config import (
    CELL_COLUMNS,
    COVERAGE_COLUMNS,
    DEFECT,
    KM_EPOCH_COLUMN,
    MAX_CELL_M,
    UNVERIFIED,
    VERIFIED,
    VerifyConfig,
)
from dbtools.network import Network
from dbtools.topology import grid_track_ids

IntArray = npt.NDArray[np.int64]


# ------------------------------------------------------------------------------ the cells


@dataclass
class Cells:
    """The grid index's points as cells: point i starts the cell [km_i, km_i+1) when the
    next point is on the same track, 0 < Δkm ≤ :data:`MAX_CELL_M`."""

    grid: GridIndex
    frame: pd.DataFrame
    """The valid GIS rows in index order (``line_code`` and ``track`` as strings)."""
    has_next: npt.NDArray[np.bool_]

    @classmethod
    def build(cls, grid: GridIndex, network: Network | None = None) -> Cells:
        """The cells of ``grid``; each point's ``track_id`` is the network's track that holds
        it (:func:`dbtools.topology.grid_track_ids`; the implied ``LINE:TRACK`` without a network)."""
        g = grid.gis.iloc[grid.pos]
        frame = g.assign(line_code=g["line_code"].astype(str), track=g["track"].astype(str)).reset_index(drop=True)
        if network is not None:
            ids = grid_track_ids(network, frame["line_code"], frame["track"], frame["km_m"])
        else:
            ids = (frame["line_code"] + ":" + frame["track"]).to_numpy(dtype=object)
        frame["track_id"] = ids
        has_next = np.zeros(grid.n, dtype=bool)
        if grid.n > 1:
            dkm = np.diff(grid.km)
            has_next[:-1] = (grid.tid[1:] == grid.tid[:-1]) & (dkm > 0) & (dkm <= MAX_CELL_M)
        return cls(grid, frame, has_next)

    @property
    def tid(self) -> IntArray:
        return self.grid.tid

    @property
    def km(self) -> FloatArray:
        return self.grid.km

    @property
    def x(self) -> FloatArray:
        return self.grid.x

    @property
    def y(self) -> FloatArray:
        return self.grid.y

    @property
    def keys(self) -> list[tuple[str, str]]:
        return self.grid.keys

    def cell_of(self, tid: IntArray, km: FloatArray) -> IntArray:
        """Grid point starting the cell that holds (track, km); −1 outside every cell."""
        g = self.grid
        j = np.searchsorted(g.key, km + g.shift[tid], side="right") - 1
        ok = (j >= 0) & (j < g.n)
        jj = np.clip(j, 0, max(g.n - 1, 0))
        ok &= g.tid[jj] == tid
        ok &= self.has_next[jj]
        return np.asarray(np.where(ok, jj, -1), dtype=np.int64)


# ------------------------------------------------------------------------------ matching


def match_fixes(
    fixes: pd.DataFrame, index: TrackIndex, grid: Cells, max_offset_m: float
) -> tuple[pd.DataFrame, dict[str, int]]:
    """Fixes on their known track: ``run``, ``cell``, ``km_m``, ``offset_m``, ``u`` (position
    in the cell, 0..1), ``km_residual_m``; and counts of the fixes left out."""
    n = len(fixes)
    tid_known = index.grid.track_ids(fixes["line_code"].to_numpy(dtype=object), fixes["track"].to_numpy(dtype=object))
    has_track = tid_known >= 0
    x, y = index.to_xy(fixes["lat"].to_numpy(dtype=float), fixes["lon"].to_numpy(dtype=float))
    x = np.where(has_track, x, np.nan)
    m = index.match_xy(x, y, max_offset_m=max_offset_m)
    f = m["fix"].to_numpy()
    on_known = m["track_id"].to_numpy() == tid_known[f]
    f = f[on_known]
    km = m["km_m"].to_numpy()[on_known]
    off = m["offset_m"].to_numpy()[on_known]
    cell = grid.cell_of(tid_known[f], km)
    inside = cell >= 0
    f, km, off, cell = f[inside], km[inside], off[inside], cell[inside]
    u = (km - grid.km[cell]) / (grid.km[cell + 1] - grid.km[cell])
    run_code, runs = pd.factorize(fixes["run_id"].astype(str), sort=True)
    km_ref = fixes["km_ref_m"].to_numpy(dtype=float, na_value=np.nan)[f]
    epoch = (
        fixes[KM_EPOCH_COLUMN].to_numpy(dtype=float, na_value=0.0)[f]
        if KM_EPOCH_COLUMN in fixes.columns
        else np.zeros(f.size)
    )
    out = pd.DataFrame(
        {
            "run": run_code[f].astype(np.int64),
            "cell": cell.astype(np.int64),
            "km_m": km,
            "offset_m": off,
            "u": u,
            "km_residual_m": km - km_ref,
            "epoch": epoch.astype(np.int64),
            "t": fixes["t"].to_numpy(dtype=float, na_value=np.nan)[f],
        }
    )
    counts = {
        "fixes_in": int(n),
        "fixes_unknown_track": int((~has_track).sum()),
        "fixes_far": int(has_track.sum() - on_known.sum()),
        "fixes_off_grid": int((~inside).sum()),
        "fixes_matched": len(out),
        "runs": len(runs),
    }
    return out, counts


# ------------------------------------------------------------------------------ statistics


def run_cell_means(matched: pd.DataFrame) -> pd.DataFrame:
    """One row per (cell, run), sorted: fixes, mean offset, km-residual mean and its count,
    mean fix time."""
    if not len(matched):
        return pd.DataFrame({c: pd.Series([], dtype=t) for c, t in _RC_DTYPES.items()})
    cell = matched["cell"].to_numpy()
    run = matched["run"].to_numpy()
    n_runs = int(run.max()) + 1
    g = matched.groupby(cell * n_runs + run, sort=True)  # one integer key: faster than two
    out = g.agg(
        n=("offset_m", "size"),
        off=("offset_m", "mean"),
        res=("km_residual_m", "mean"),
        n_res=("km_residual_m", "count"),
        t=("t", "mean"),
    )
    key = out.index.to_numpy()
    out.insert(0, "run", key % n_runs)
    out.insert(0, "cell", key // n_runs)
    return out.reset_index(drop=True)


_RC_DTYPES = {
    "cell": np.int64,
    "run": np.int64,
    "n": np.int64,
    "off": float,
    "res": float,
    "n_res": np.int64,
    "t": float,
}


def cell_statistics(rc: pd.DataFrame, matched: pd.DataFrame) -> pd.DataFrame:
    """Per cell (index = grid point id): runs, fixes, run-level mean and spread (step 2),
    fix-level sd and the along-track residual (step 7)."""
    g = rc.groupby("cell", sort=True)
    cells = pd.DataFrame(
        {
            "runs": g.size(),
            "fixes": g["n"].sum(),
            "offset_mean_m": g["off"].mean(),
            "offset_spread_m": g["off"].std(ddof=1),
        }
    )
    cells["offset_fix_sd_m"] = matched.groupby("cell", sort=True)["offset_m"].std(ddof=1)
    has_res = rc[rc["n_res"] > 0].groupby("cell", sort=True)
    cells["km_residual_mean_m"] = has_res["res"].mean()
    cells["km_residual_spread_m"] = has_res["res"].std(ddof=1)
    cells["km_residual_runs"] = has_res.size().reindex(cells.index, fill_value=0).astype(np.int64)
    return cells


def pooled_spread(spread: FloatArray, runs: FloatArray, group: IntArray) -> FloatArray:
    """Per row, the between-run sd pooled over its group (track):
    sqrt(Σ (k−1)·s² / Σ (k−1)) over the group's rows with k ≥ 2 (NaN if none)."""
    ok = np.isfinite(spread) & (runs >= 2)
    n_g = int(group.max()) + 1 if group.size else 0
    num = np.bincount(group[ok], (runs[ok] - 1) * spread[ok] ** 2, minlength=n_g)
    den = np.bincount(group[ok], runs[ok] - 1, minlength=n_g)
    with np.errstate(invalid="ignore", divide="ignore"):
        pooled = np.sqrt(num / den)
    return pooled[group] if group.size else np.zeros(0)


def t_test(
    mean: npt.ArrayLike, sd: npt.ArrayLike, k: npt.ArrayLike, df: npt.ArrayLike | None = None
) -> tuple[FloatArray, FloatArray]:
    """One-sample two-sided t-test of H0: μ = 0 from k run means with this mean and sd.

    ``df`` defaults to k − 1. k < 2 → NaN. A zero sd gives p = 0 for a non-zero mean and
    p = 1 for a zero mean."""
    m = np.asarray(mean, dtype=float)
    s = np.asarray(sd, dtype=float)
    ka = np.asarray(k, dtype=float)
    dfa = ka - 1 if df is None else np.asarray(df, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        se = s / np.sqrt(ka)
        t = np.where(se > 0, m / se, np.where(m == 0, 0.0, np.sign(m) * np.inf))
    from scipy import stats

    p = 2.0 * stats.t.sf(np.abs(t), np.maximum(dfa, 1))
    bad = (ka < 2) | ~np.isfinite(m) | ~np.isfinite(s)
    return np.where(bad, np.nan, t), np.where(bad, np.nan, p)


def adjust_pvalues(p: npt.ArrayLike, method: str = "bh") -> FloatArray:
    """Multiple-testing adjusted p-values (q-values); NaN stays NaN and is not counted.

    ``bh``: Benjamini–Hochberg step-up, q_(i) = min_{j ≥ i} p_(j)·m/j;
    ``bonferroni``: min(1, p·m)."""
    pa = np.asarray(p, dtype=float)
    out = np.full(pa.shape, np.nan)
    ok = np.isfinite(pa)
    m = int(ok.sum())
    if m == 0:
        return out
    pv = pa[ok]
    if method == "bonferroni":
        out[ok] = np.minimum(1.0, pv * m)
        return out
    order = np.argsort(pv, kind="stable")
    ranked = pv[order] * m / np.arange(1, m + 1)
    q = np.minimum.accumulate(ranked[::-1])[::-1]
    res = np.empty(m)
    res[order] = np.minimum(q, 1.0)
    out[ok] = res
    return out


def effective_spread(
    spread: FloatArray, runs: FloatArray, pooled: FloatArray, track_runs: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(sd, degrees of freedom) of the test: the larger of the cell's own between-run sd
    (df k − 1) and the track's pooled one (df = runs on the track − 1, a conservative count:
    neighbouring cells share the same runs' errors)."""
    own = np.where(np.isfinite(spread), spread, 0.0)
    use_pool = np.isfinite(pooled) & (pooled > own)
    sd = np.where(use_pool, pooled, spread)
    df = np.where(use_pool, np.maximum(track_runs - 1, runs - 1), runs - 1)
    return sd, df


def classify(cells: pd.DataFrame, pooled: FloatArray, track_runs: FloatArray, cfg: VerifyConfig) -> pd.DataFrame:
    """Test every cell and add ``se_m``, ``t_stat``, ``p_value``, ``q_value``, ``status`` and
    ``reason`` (steps 3–4). Per cell: ``pooled`` between-run sd of its track
    (:func:`pooled_spread`) and ``track_runs``, the number of runs on its track."""
    from scipy import stats

    runs = cells["runs"].to_numpy(dtype=float)
    fixes = cells["fixes"].to_numpy()
    mean = cells["offset_mean_m"].to_numpy(dtype=float)
    spread = cells["offset_spread_m"].to_numpy(dtype=float)
    sd, df = effective_spread(spread, runs, np.asarray(pooled, dtype=float), np.asarray(track_runs, dtype=float))
    tstat, p = t_test(mean, sd, runs, df)
    testable = (runs >= cfg.min_runs) & (fixes >= cfg.min_fixes) & np.isfinite(p)
    q = adjust_pvalues(np.where(testable, p, np.nan), cfg.correction)
    defect = testable & (q <= cfg.alpha) & (np.abs(mean) >= cfg.min_shift_m)
    with np.errstate(invalid="ignore", divide="ignore"):
        se = sd / np.sqrt(runs)
        half = stats.t.ppf(0.975, np.maximum(df, 1)) * se
        conclusive = np.abs(mean) + half <= cfg.tolerance_m
    status = np.where(defect, DEFECT, np.where(testable & conclusive, VERIFIED, UNVERIFIED))
    reason = np.select(
        [defect, ~testable & (runs < cfg.min_runs), ~testable, ~conclusive],
        [
            "significant offset",
            f"fewer than {cfg.min_runs} runs",
            f"fewer than {cfg.min_fixes} fixes",
            f"95 % CI beyond ±{cfg.tolerance_m:g} m",
        ],
        default="",
    )
    out = cells.copy()
    out["se_m"] = se
    out["t_stat"] = tstat
    out["p_value"] = p
    out["q_value"] = q
    out["status"] = status
    out["reason"] = reason
    return out


def empty_cells() -> pd.DataFrame:
    cols = [c for c in CELL_COLUMNS if c not in ("track_id", "line_code", "track", "km_from_m", "km_to_m")]
    return pd.DataFrame({c: pd.Series([], dtype=object if c in ("status", "reason") else float) for c in cols})


def cell_frame(cells: pd.DataFrame, grid: Cells) -> pd.DataFrame:
    j = cells.index.to_numpy(dtype=np.int64)
    out = cells.reset_index(drop=True)
    out.insert(0, "km_to_m", grid.km[j + 1] if j.size else np.zeros(0))
    out.insert(0, "km_from_m", grid.km[j])
    out.insert(0, "track", grid.frame["track"].to_numpy()[j])
    out.insert(0, "line_code", grid.frame["line_code"].to_numpy()[j])
    out.insert(0, "track_id", grid.frame["track_id"].to_numpy()[j])
    for c in ("runs", "fixes", "km_residual_runs"):
        out[c] = out[c].astype(np.int64)
    return out[list(CELL_COLUMNS)]


def coverage(cells: pd.DataFrame, grid: Cells, defects: pd.DataFrame, rc: pd.DataFrame) -> pd.DataFrame:
    """Per track of the DB (``track_id``, with its line and track names): cells and km
    verified / unverified / defect, defects (counted on the track where they begin), runs
    and fixes."""
    n = grid.km.size
    starts = np.flatnonzero(grid.has_next)
    length = np.zeros(n)
    length[starts] = grid.km[starts + 1] - grid.km[starts]
    status = np.full(n, UNVERIFIED, dtype=object)
    if len(cells):
        status[cells.index.to_numpy(dtype=np.int64)] = cells["status"].to_numpy()
    g = grid.frame
    frame = pd.DataFrame(
        {
            "track_id": g["track_id"].to_numpy()[starts],
            "len": length[starts] / 1000.0,
            "status": status[starts],
        }
    )
    cov = frame.pivot_table(index="track_id", columns="status", values="len", aggfunc="sum", fill_value=0.0).reindex(
        columns=[VERIFIED, UNVERIFIED, DEFECT], fill_value=0.0
    )
    keys = g.drop_duplicates("track_id")  # every track of the grid, in grid order
    cov = cov.reindex(pd.Index(keys["track_id"]), fill_value=0.0)
    total = cov.sum(axis=1).to_numpy()
    ncell = frame.groupby("track_id").size().reindex(cov.index, fill_value=0)
    out = pd.DataFrame(
        {
            "track_id": keys["track_id"].to_numpy(),
            "line_code": keys["line_code"].to_numpy(),
            "track": keys["track"].to_numpy(),
            "cells": ncell.to_numpy(dtype=np.int64),
            "length_km": total,
            "verified_km": cov[VERIFIED].to_numpy(),
            "unverified_km": cov[UNVERIFIED].to_numpy(),
            "defect_km": cov[DEFECT].to_numpy(),
        }
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        for s in (VERIFIED, UNVERIFIED, DEFECT):
            out[f"{s}_share"] = np.where(total > 0, out[f"{s}_km"] / total, np.nan)
    nd = defects.groupby("track_id").size() if len(defects) else pd.Series(dtype=np.int64)
    out["defects"] = nd.reindex(out["track_id"], fill_value=0).to_numpy(dtype=np.int64)
    tid_rc = g["track_id"].to_numpy()[rc["cell"].to_numpy()]
    runs = pd.Series(rc["run"].to_numpy()).groupby(tid_rc).nunique()
    fixes = pd.Series(rc["n"].to_numpy()).groupby(tid_rc).sum()
    out["runs"] = runs.reindex(out["track_id"], fill_value=0).to_numpy(dtype=np.int64)
    out["fixes"] = fixes.reindex(out["track_id"], fill_value=0).to_numpy(dtype=np.int64)
    return out[list(COVERAGE_COLUMNS)].reset_index(drop=True)


def residual_summary(matched: pd.DataFrame) -> dict[str, float | int | None]:
    r = matched["km_residual_m"].to_numpy()
    r = r[np.isfinite(r)]
    if not r.size:
        return {"n": 0, "median_m": None, "mean_m": None, "sd_m": None, "p95_abs_m": None}
    return {
        "n": int(r.size),
        "median_m": round(float(np.median(r)), 3),
        "mean_m": round(float(r.mean()), 3),
        "sd_m": round(float(r.std(ddof=1)), 3) if r.size > 1 else None,
        "p95_abs_m": round(float(np.percentile(np.abs(r), 95)), 3),
    }
