"""GIS grid verification from traversed trajectories [S001 §9(a), SPEC §6].

Input: GPS fixes whose track is *known* (from balises or the GPS up/down decision, never
guessed — :mod:`fieldlogs.gisverify.evidence` selects them), one row per fix with the columns of
:data:`FIX_COLUMNS`. Everything below is vectorised over fixes (no Python loop per fix or
per cell; one small loop per *defect*).

**1. Map-matching.** Each fix is matched exactly to the nearest segment of its known
track (:meth:`~dbtools.gis.matching.TrackIndex.match_xy`, within ``max_offset_m``): km
``k_i`` and signed lateral offset ``o_i`` (positive left of increasing km). Its *cell* is
the grid segment [km_j, km_j+1) that holds k_i (20 m). The along-track residual
``r_i = k_i − km_ref_i`` compares the GPS km with the pipeline's balise/feature-corrected
km where that is known well enough (``km_ref_m``; NaN otherwise).

**2. The run is the unit.** D-GPS error is Gauss–Markov with a correlation time of
minutes: over one cell (about one second at line speed), and over a few hundred metres,
it is a single draw per run. Fixes of one run in one cell are therefore not independent
evidence; they are averaged first. For cell c with runs r = 1..k_c::

    ō_rc = mean of run r's offsets in c
    m_c  = mean_r ō_rc,   s_c = sd_r ō_rc (ddof 1, the between-run spread),   se_c = s_c / √k_c

**3. Test.** H0: the cell's GIS centreline is right (μ_c = 0). The between-run spread
is a property of the receivers, not of the cell, so it is also pooled over the track
(``s_pool² = Σ(k_c − 1)s_c² / Σ(k_c − 1)``); the test uses ``s = max(s_c, s_pool)`` —
a cell's own spread only where it is larger (local multipath) — because with a handful
of runs ``s_c`` alone is often small by chance, and a small spread times a moderate mean
would then pass for a defect. ``t_c = m_c / (s/√k_c)`` against Student's t with k_c − 1
degrees of freedom for the own spread, (runs on the track − 1) for the pooled one (a
conservative count: neighbouring cells share the same runs' errors); ``p_c`` two-sided.
Over all *testable* cells the p-values are corrected for multiple testing —
Benjamini–Hochberg (false-discovery rate, default; valid under the positive dependence of
neighbouring cells) or Bonferroni (family-wise) — giving ``q_c``. A cell is a **defect
cell** when ``q_c ≤ alpha`` *and* ``|m_c| ≥ min_shift_m`` (significance alone is not
enough: with hundreds of runs a few centimetres become significant but are not worth a
DB change; the simulator's spline-vs-chord difference on 300 m curves is ~0.1 m).

**4. Status.** A cell is *unverified* — never "good" — when it has fewer than
``min_runs`` runs or ``min_fixes`` fixes ("evidence"), or when it is not a defect but its
95 % confidence interval ``|m_c| + t₀.₉₇₅·se_c`` reaches beyond ``tolerance_m``
("inconclusive": too noisy to say the centreline is right to within the tolerance — the
cells either side of a displaced stretch, which see half of it, usually land here).
Otherwise it is *verified*. Cells of the grid without any fix are unverified too; they
appear in the coverage only.

**5. Defects.** Defect cells of one track with the same sign of shift are merged when at
most ``merge_gap_cells`` cells lie between them (never across a kilometrage break). Per
defect the runs are again the unit: the per-run mean over the defect's (run, cell) means
gives a t-test p-value as in 3. The **shift** is estimated differently: each run's mean
inside the defect minus its *own* mean offset over ``background_m`` either side (the cell
next to the defect and other defects skipped). The D-GPS error of a run barely changes
over the seconds between the two (σ·√(2(1 − e^(−Δt/τ))) ≈ 0.3 m for 15 s at τ = 180 s
against 0.75 m), so the difference removes most of it: the shift's error drops from
σ/√runs to about 0.3 m/√runs (``background_m`` column: what was removed).

**6. Proposed correction.** The lateral error of the grid is taken as piecewise linear
between grid points (that is how the DB interpolates the track): a fix at fraction u of
segment j sees ``(1 − u)·e_j + u·e_{j+1}``. Per defect the point shifts e_j of the
defect's points are the weighted least-squares solution over the background-corrected
offsets (as in 5) of the fixes of its cells and of the one cell on each side (points
outside fixed at 0; each (run, cell) has total weight 1, as in 2), with a tiny ridge and
a total-variation penalty ``smooth``·Σ|Δe| (iteratively reweighted least squares on the
tridiagonal system), which flattens noise while keeping the ends of a displaced stretch
sharp; the levels of the resulting segments are then refitted without the penalty (no
shrinkage). Three Huber re-weightings (residuals beyond 2 robust sd) keep a multipath
burst that passed the trust filter from bending the fit. Points whose estimate reaches ``min_move_m`` are moved that far
perpendicular to the track (tangent from the grid points two either side, in the plane
zone of :class:`Projector`), to the left for a positive shift — where the fixes say the
track really is.

**7. Along-track residual.** Per cell the run-level mean and spread of ``r_i`` are
reported (not tested: the pipeline km carries its own error, up to its margin, correlated
within a run — only cycles with a small margin should provide ``km_ref_m``).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from typing import Any, Literal

import numpy as np
import numpy.typing as npt
import pandas as pd
from scipy import stats
from scipy.linalg import solve_banded

from dbtools.gis.geometry import FloatArray, Projector
from dbtools.gis.matching import TrackIndex, track_index_for
from dbtools.network import Network, canonical
from schemas.errors import InputError
from schemas.tables import GIS, GIS_SPACING_M

IntArray = npt.NDArray[np.int64]

#: Columns of the fixes given to :func:`verify_fixes` (``km_ref_m`` may be NaN).
FIX_COLUMNS = ("run_id", "t", "lat", "lon", "line_code", "track", "km_ref_m")
#: Cell status values.
VERIFIED, UNVERIFIED, DEFECT = "verified", "unverified", "defect"
#: Columns of :attr:`GisVerification.cells` (one row per cell with at least one fix).
CELL_COLUMNS = (
    "line_code",
    "track",
    "km_from_m",
    "km_to_m",
    "runs",
    "fixes",
    "offset_mean_m",
    "offset_spread_m",
    "offset_fix_sd_m",
    "se_m",
    "t_stat",
    "p_value",
    "q_value",
    "km_residual_mean_m",
    "km_residual_spread_m",
    "km_residual_runs",
    "status",
    "reason",
)
#: Columns of :attr:`GisVerification.defects`.
DEFECT_COLUMNS = (
    "defect_id",
    "line_code",
    "track",
    "km_from_m",
    "km_to_m",
    "length_m",
    "cells",
    "runs",
    "fixes",
    "shift_m",
    "spread_m",
    "background_m",
    "p_value",
    "q_min",
    "km_residual_mean_m",
    "points_moved",
    "max_move_m",
)
#: Columns of :attr:`GisVerification.coverage` (one row per line/track of the DB).
COVERAGE_COLUMNS = (
    "line_code",
    "track",
    "cells",
    "length_km",
    "verified_km",
    "unverified_km",
    "defect_km",
    "verified_share",
    "unverified_share",
    "defect_share",
    "defects",
    "runs",
    "fixes",
)
#: Columns of :attr:`GisVerification.proposal` (one row per GIS point moved).
PROPOSAL_COLUMNS = ("defect_id", "line_code", "track", "km_m", "shift_m", "lat", "lon", "lat_new", "lon_new")
#: Cells next to a defect that may still be displaced (half-displaced, or short of evidence):
#: left out of the background, and their points part of the proposal's fit.
EDGE_CELLS = 2
#: Iterations and |Δe| floor [m] of the total-variation smoothing of proposed shifts.
TV_ITERATIONS, TV_EPS_M = 50, 1e-3
#: Huber re-weighting of the proposal's fixes: iterations and threshold (× robust sd).
HUBER_ITERATIONS, HUBER_K = 3, 2.0
#: Neighbouring point shifts closer than this after the total variation are one segment [m].
TV_SEGMENT_TOL_M = 0.02
#: Longest grid segment counted as a cell in the coverage [m] (longer = a hole or a break).
MAX_CELL_M = 200.0


@dataclass(frozen=True)
class VerifyConfig:
    """Thresholds of the verification (module docstring, steps 3–6)."""

    alpha: float = 0.01
    """Significance level after the multiple-testing correction (FDR for BH)."""
    correction: Literal["bh", "bonferroni"] = "bh"
    """Multiple-testing correction over all testable cells."""
    min_shift_m: float = 0.5
    """Smallest mean lateral offset worth correcting [m]."""
    min_runs: int = 3
    """Fewer runs through a cell → unverified (the run is the independent unit)."""
    min_fixes: int = 5
    """Fewer fixes in a cell → unverified."""
    tolerance_m: float = 1.5
    """A cell is verified only if its 95 % CI of the mean offset lies within ±this [m]."""
    max_offset_m: float = 10.0
    """Fixes farther than this from their known track are not evidence [m]."""
    merge_gap_cells: int = 1
    """Defect cells with at most this many cells between them form one defect."""
    background_m: float = 200.0
    """Each run's own offset within this distance either side of a defect is its local
    GPS error, subtracted when estimating the shift (0 = off) [m]."""
    min_move_m: float = 0.25
    """Proposed point shifts smaller than this are not applied [m]."""
    ridge: float = 1e-3
    """Ridge of the least-squares point shifts, relative to the mean data weight per point."""
    smooth: float = 1.0
    """Total-variation penalty on neighbouring point shifts [m × mean data weight per
    point]: flattens noise inside a displaced stretch but keeps its ends sharp (the levels
    are then refitted without the penalty)."""

    def __post_init__(self) -> None:
        if not 0 < self.alpha < 1:
            raise ValueError("alpha must be in (0, 1)")
        if self.correction not in ("bh", "bonferroni"):
            raise ValueError("correction must be 'bh' or 'bonferroni'")
        if self.min_runs < 2:
            raise ValueError("min_runs must be at least 2 (a spread needs two runs)")
        if min(self.tolerance_m, self.max_offset_m) <= 0 or self.min_shift_m < 0 or self.min_fixes < 1:
            raise ValueError("thresholds must be positive")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass
class GisVerification:
    """Result of :func:`verify_fixes` (frames with the ``*_COLUMNS`` above)."""

    config: VerifyConfig
    cells: pd.DataFrame
    defects: pd.DataFrame
    coverage: pd.DataFrame
    proposal: pd.DataFrame
    counts: dict[str, int] = field(default_factory=dict)
    """fixes_in, fixes_unknown_track, fixes_far (beyond max_offset_m), fixes_off_grid,
    fixes_matched, runs."""
    km_residual: dict[str, float | int | None] = field(default_factory=dict)
    """Spread of the along-track residual over all eligible fixes (the pipeline km's own
    error plus GPS along-track error): n, median, mean, sd, p95_abs [m]."""

    @property
    def has_defects(self) -> bool:
        return len(self.defects) > 0

    def to_dict(self) -> dict[str, Any]:
        """The documented JSON shape (see ``trainpos gis verify --help``)."""
        return {
            "config": self.config.to_dict(),
            "counts": dict(self.counts),
            "km_residual": dict(self.km_residual),
            "coverage": _records(self.coverage),
            "defects": _records(self.defects),
            "proposal": _records(self.proposal),
            "cells": _records(self.cells),
        }


def _records(frame: pd.DataFrame) -> list[dict[str, Any]]:
    rows = frame.astype(object).where(frame.notna(), None).to_dict("records")
    out: list[dict[str, Any]] = [{str(k): v for k, v in r.items()} for r in rows]
    for row in out:
        for k, v in row.items():
            if isinstance(v, float):
                row[k] = round(v, 6) if np.isfinite(v) else None
            elif isinstance(v, np.integer):
                row[k] = int(v)
            elif isinstance(v, np.floating):
                row[k] = round(float(v), 6) if np.isfinite(v) else None
            elif isinstance(v, np.bool_):
                row[k] = bool(v)
    return out


# ------------------------------------------------------------------------------ the grid


@dataclass
class _Grid:
    """The DB's grid points sorted by (line, track, km), with the TrackIndex track ids."""

    frame: pd.DataFrame
    tid: IntArray
    km: FloatArray
    x: FloatArray
    y: FloatArray
    key: FloatArray
    """km + a per-track offset: one sorted array for all tracks (searchsorted)."""
    shift: FloatArray
    """Per track id: the offset added to km in ``key``."""
    has_next: npt.NDArray[np.bool_]
    """Point i starts a cell (the next point is on the same track, 0 < Δkm ≤ MAX_CELL_M)."""
    keys: list[tuple[str, str]]
    """(line_code, track) of each track id."""

    @classmethod
    def build(cls, network: Network, index: TrackIndex) -> _Grid:
        g = network.gis
        num = g[["km_m", "lat", "lon"]].to_numpy(dtype=float, na_value=np.nan)
        g = g[np.isfinite(num).all(axis=1) & g["line_code"].notna().to_numpy() & g["track"].notna().to_numpy()]
        g = g.assign(line_code=g["line_code"].astype(str), track=g["track"].astype(str))
        g = g.sort_values(["line_code", "track", "km_m"], kind="stable").reset_index(drop=True)
        known = pd.MultiIndex.from_tuples(index.keys) if index.keys else pd.MultiIndex.from_arrays([[], []])
        tid = known.get_indexer(pd.MultiIndex.from_frame(g[["line_code", "track"]])).astype(np.int64)
        km = g["km_m"].to_numpy(dtype=float)
        x, y = index.to_xy(g["lat"].to_numpy(dtype=float), g["lon"].to_numpy(dtype=float))
        n_t = len(index.keys)
        lo = np.full(n_t, np.inf)
        hi = np.full(n_t, -np.inf)
        np.minimum.at(lo, tid, km)
        np.maximum.at(hi, tid, km)
        span = np.where(np.isfinite(lo), hi - lo, 0.0) + 1000.0
        shift = np.concatenate([[0.0], np.cumsum(span)[:-1]]) - np.where(np.isfinite(lo), lo, 0.0)
        key = km + shift[tid]
        has_next = np.zeros(km.size, dtype=bool)
        if km.size > 1:
            dkm = np.diff(km)
            has_next[:-1] = (tid[1:] == tid[:-1]) & (dkm > 0) & (dkm <= MAX_CELL_M)
        return cls(g, tid, km, x, y, key, shift, has_next, list(index.keys))

    def cell_of(self, tid: IntArray, km: FloatArray) -> IntArray:
        """Grid point starting the cell that holds (track, km); −1 outside every cell."""
        k = km + self.shift[tid]
        j = np.searchsorted(self.key, k, side="right") - 1
        ok = (j >= 0) & (j < self.km.size)
        jj = np.clip(j, 0, max(self.km.size - 1, 0))
        ok &= self.tid[jj] == tid
        ok &= self.has_next[jj]
        return np.where(ok, jj, -1)


# ------------------------------------------------------------------------------ matching


def known_track_ids(line_code: pd.Series, track: pd.Series, index: TrackIndex) -> IntArray:
    """TrackIndex track id per row (−1: missing, or not a track of the grid); strings are
    factorized once, the few distinct pairs looked up."""
    lc_codes, lc_uniq = pd.factorize(line_code.astype(object), use_na_sentinel=True)
    tr_codes, tr_uniq = pd.factorize(track.astype(object), use_na_sentinel=True)
    table = np.full((len(lc_uniq) + 1, len(tr_uniq) + 1), -1, dtype=np.int64)
    ids = {key: i for i, key in enumerate(index.keys)}
    for i, lc in enumerate(lc_uniq):
        for j, tr in enumerate(tr_uniq):
            table[i, j] = ids.get((str(lc), str(tr)), -1)
    return table[lc_codes, tr_codes]  # the sentinel −1 indexes the last row/column (−1 ids)


def match_fixes(fixes: pd.DataFrame, index: TrackIndex, grid: _Grid, max_offset_m: float) -> tuple[pd.DataFrame, dict]:
    """Fixes on their known track: ``run``, ``cell``, ``km_m``, ``offset_m``, ``u`` (position
    in the cell, 0..1), ``km_residual_m``; and counts of the fixes left out."""
    n = len(fixes)
    tid_known = known_track_ids(fixes["line_code"], fixes["track"], index)
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
    out = pd.DataFrame(
        {
            "run": run_code[f].astype(np.int64),
            "cell": cell.astype(np.int64),
            "km_m": km,
            "offset_m": off,
            "u": u,
            "km_residual_m": km - km_ref,
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
    """One row per (cell, run), sorted: fixes, mean offset, km-residual mean and its count."""
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
    )
    key = out.index.to_numpy()
    out.insert(0, "run", key % n_runs)
    out.insert(0, "cell", key // n_runs)
    return out.reset_index(drop=True)


_RC_DTYPES = {"cell": np.int64, "run": np.int64, "n": np.int64, "off": float, "res": float, "n_res": np.int64}


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


# ------------------------------------------------------------------------------ defects


def merge_defects(
    cells: pd.DataFrame, grid_tid: IntArray, max_gap_cells: int, has_next: npt.NDArray[np.bool_] | None = None
) -> pd.Series:
    """Defect number (0, 1, …) per defect cell (index = grid point id, same order); cells of
    one track with the same sign and ≤ ``max_gap_cells`` cells between them share one —
    never across a kilometrage break or hole (``has_next`` false: no cell there)."""
    d = cells[cells["status"] == DEFECT]
    if d.empty:
        return pd.Series([], dtype=np.int64)
    j = d.index.to_numpy(dtype=np.int64)
    sign = np.sign(d["offset_mean_m"].to_numpy())
    tid = grid_tid[j]
    new = np.ones(j.size, dtype=bool)
    new[1:] = (tid[1:] != tid[:-1]) | (sign[1:] != sign[:-1]) | (np.diff(j) - 1 > max_gap_cells)
    if has_next is not None:
        holes = np.concatenate([[0], np.cumsum(~has_next)])
        new[1:] |= holes[j[1:]] - holes[j[:-1]] > 0
    return pd.Series(np.cumsum(new) - 1, index=d.index)


def defect_spans(labels: pd.Series) -> tuple[IntArray, IntArray]:
    """First and last cell (grid point ids) of each defect of :func:`merge_defects`."""
    if labels.empty:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    cell_ids = pd.Series(labels.index.to_numpy(dtype=np.int64))
    lab = labels.to_numpy()
    g = cell_ids.groupby(lab)
    return np.asarray(g.min(), dtype=np.int64), np.asarray(g.max(), dtype=np.int64)


def run_backgrounds(
    rc: pd.DataFrame, first: IntArray, last: IntArray, grid: _Grid, window_cells: int, skip_cells: int = EDGE_CELLS
) -> list[pd.Series]:
    """Per defect, each run's median offset (run → m) over its cells within
    ``window_cells`` either side of the defect — skipping the ``skip_cells`` next to it
    (partly displaced, or displaced but short of evidence) and every defect's cells (and
    theirs). Empty when there is no such evidence.

    The D-GPS error is correlated over minutes: a run's error beside the defect is nearly
    its error inside, so the difference removes it from the shift estimate; the median
    keeps a displaced cell that slipped into the window from biasing it."""
    out: list[pd.Series] = []
    if window_cells <= 0 or not len(first):
        return [pd.Series(dtype=float) for _ in first]
    blocked = np.zeros(grid.km.size + 1, dtype=np.int64)
    np.add.at(blocked, np.maximum(first - skip_cells, 0), 1)
    np.add.at(blocked, np.minimum(last + 1 + skip_cells, grid.km.size), -1)
    in_defect = np.cumsum(blocked)[:-1] > 0
    ref_ok = grid.has_next & ~in_defect
    cells = rc["cell"].to_numpy()  # sorted (run_cell_means)
    for a, b in zip(first, last, strict=True):
        lo, hi = max(a - skip_cells - window_cells, 0), min(b + skip_cells + window_cells, grid.km.size - 1)
        i, j = np.searchsorted(cells, [lo, hi + 1])
        c = cells[i:j]
        sel = rc.iloc[i:j][ref_ok[c] & (grid.tid[c] == grid.tid[a])]
        out.append(sel.groupby("run")["off"].median() if len(sel) else pd.Series(dtype=float))
    return out


def _defect_table(
    labels: pd.Series,
    cells: pd.DataFrame,
    rc: pd.DataFrame,
    grid: _Grid,
    pooled: pd.Series,
    track_runs: pd.Series,
    backgrounds: list[pd.Series],
) -> tuple[pd.DataFrame, IntArray, IntArray]:
    """Defect rows (without the proposal columns) and each defect's first/last cell.
    ``pooled`` / ``track_runs``: per track id, the pooled between-run sd and the runs;
    ``backgrounds``: per defect, :func:`run_backgrounds`."""
    if labels.empty:
        return pd.DataFrame(columns=list(DEFECT_COLUMNS)), np.zeros(0, np.int64), np.zeros(0, np.int64)
    lab = labels.to_numpy()
    cell_ids = labels.index.to_numpy(dtype=np.int64)
    first, last = defect_spans(labels)
    n_def = first.size
    # every cell from first to last (gap cells included) belongs to the defect
    span_cells = np.concatenate([np.arange(a, b + 1) for a, b in zip(first, last, strict=True)])
    span_lab = np.repeat(np.arange(n_def), last - first + 1)
    owner = pd.Series(span_lab, index=span_cells)
    sub = rc[rc["cell"].isin(owner.index)]
    sub = sub.assign(defect=owner.reindex(sub["cell"]).to_numpy())
    per_run = sub.groupby(["defect", "run"], sort=True)["off"].mean()
    run_means = per_run.groupby(level="defect")
    raw = np.asarray(run_means.mean().reindex(range(n_def)), dtype=np.float64)
    raw_spread = np.asarray(run_means.std(ddof=1).reindex(range(n_def)), dtype=np.float64)
    runs = run_means.size().reindex(range(n_def), fill_value=0).to_numpy()
    tid = grid.tid[first]
    sd, df = effective_spread(
        raw_spread,
        runs.astype(float),
        pooled.reindex(tid).to_numpy(dtype=float),
        track_runs.reindex(tid).to_numpy(dtype=float),
    )
    _, p = t_test(raw, sd, runs.astype(float), df)
    # the shift itself: each run's mean over the defect minus its own background nearby
    shift, spread, back = raw.copy(), raw_spread.copy(), np.zeros(n_def)
    for i, b in enumerate(backgrounds):
        if b.empty:
            continue
        diff = (per_run.loc[i] - b).dropna()
        if diff.empty:
            continue
        shift[i] = float(diff.mean())
        spread[i] = float(diff.std(ddof=1)) if diff.size > 1 else np.nan
        back[i] = float(raw[i] - shift[i])
    res = sub[sub["n_res"] > 0].groupby(["defect", "run"])["res"].mean().groupby(level="defect").mean()
    fixes = sub.groupby("defect")["n"].sum().reindex(range(n_def), fill_value=0).to_numpy()
    q_min = cells.loc[cell_ids, "q_value"].groupby(lab).min().reindex(range(n_def)).to_numpy()
    g = grid.frame
    table = pd.DataFrame(
        {
            "defect_id": np.arange(1, n_def + 1),
            "line_code": g["line_code"].to_numpy()[first],
            "track": g["track"].to_numpy()[first],
            "km_from_m": grid.km[first],
            "km_to_m": grid.km[last + 1],
            "length_m": grid.km[last + 1] - grid.km[first],
            "cells": last - first + 1,
            "runs": runs,
            "fixes": fixes,
            "shift_m": shift,
            "spread_m": spread,
            "background_m": back,
            "p_value": p,
            "q_min": q_min,
            "km_residual_mean_m": res.reindex(range(n_def)).to_numpy(dtype=float),
        }
    )
    return table, first, last


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
        diag = np.bincount(lc, wt * pl**2, minlength=n_pts) + np.bincount(rc_, wt * pr**2, minlength=n_pts)
        upper = np.bincount(left[both], wt[both] * phi_l[both] * phi_r[both], minlength=n_pts)
        rhs = np.bincount(lc, wt * pl * off, minlength=n_pts) + np.bincount(rc_, wt * pr * off, minlength=n_pts)
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
    return s_mat @ c


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
    ``shift_m`` (positive = left of increasing km) in the plane zone of ``projector``.

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
    proj = projector or Projector.for_points(lat, lon)
    x, y = proj.to_xy(lon, lat)
    nx, ny = lateral_shift(x, y, pos.astype(np.int64), s)
    new_lon, new_lat = proj.to_lonlat(nx, ny)
    rows = order[pos]
    out.loc[rows, "lat"] = np.round(new_lat, 9)
    out.loc[rows, "lon"] = np.round(new_lon, 9)
    return out


# ------------------------------------------------------------------------------ the driver


def verify_fixes(network: Network, fixes: pd.DataFrame, cfg: VerifyConfig | None = None) -> GisVerification:
    """Map-match, test every cell, merge defects and propose corrections (module docstring)."""
    cfg = cfg or VerifyConfig()
    missing = [c for c in FIX_COLUMNS if c not in fixes.columns]
    if missing:
        raise ValueError(f"fixes lack columns {missing}")
    if not len(network.gis):
        raise InputError("the DB has no GIS grid to verify", path=network.origin or None)
    index = track_index_for(network)
    grid = network.cached(("gis_verify_grid", id(index)), lambda: _Grid.build(network, index))
    matched, counts = match_fixes(fixes, index, grid, cfg.max_offset_m)
    matched = matched.sort_values("cell", kind="stable", ignore_index=True)
    rc = run_cell_means(matched)
    # per track: runs on it and the pooled between-run spread of its cells
    track_runs = pd.Series(rc["run"].to_numpy()).groupby(grid.tid[rc["cell"].to_numpy()]).nunique()
    pooled = pd.Series(dtype=float)
    if len(rc):
        cells = cell_statistics(rc, matched)
        tid_c = grid.tid[cells.index.to_numpy(dtype=np.int64)]
        runs_c = cells["runs"].to_numpy(dtype=float)
        pooled_c = pooled_spread(cells["offset_spread_m"].to_numpy(dtype=float), runs_c, tid_c)
        pooled = pd.Series(pooled_c, index=tid_c).groupby(level=0).first()
        runs_on_track = np.asarray(track_runs.reindex(tid_c).to_numpy(), dtype=np.float64)
        cells = classify(cells, pooled_c, runs_on_track, cfg)
    else:
        cells = _empty_cells()
    labels = merge_defects(cells, grid.tid, cfg.merge_gap_cells, grid.has_next)
    first, last = defect_spans(labels)
    backgrounds = run_backgrounds(rc, first, last, grid, round(cfg.background_m / GIS_SPACING_M))
    defects, first, last = _defect_table(labels, cells, rc, grid, pooled, track_runs, backgrounds)
    proposal = _proposal(defects, first, last, matched, grid, index.projector, cfg, backgrounds)
    if len(defects):
        moved = proposal.groupby("defect_id")["shift_m"]
        defects["points_moved"] = moved.size().reindex(defects["defect_id"], fill_value=0).to_numpy()
        defects["max_move_m"] = moved.apply(lambda s: float(s.abs().max())).reindex(defects["defect_id"]).to_numpy()
    else:
        defects = pd.DataFrame(columns=list(DEFECT_COLUMNS))
    cell_frame = _cell_frame(cells, grid)
    coverage = _coverage(cells, grid, defects, rc)
    return GisVerification(cfg, cell_frame, defects, coverage, proposal, counts, _residual_summary(matched))


def _empty_cells() -> pd.DataFrame:
    cols = [c for c in CELL_COLUMNS if c not in ("line_code", "track", "km_from_m", "km_to_m")]
    return pd.DataFrame({c: pd.Series([], dtype=object if c in ("status", "reason") else float) for c in cols})


def _cell_frame(cells: pd.DataFrame, grid: _Grid) -> pd.DataFrame:
    j = cells.index.to_numpy(dtype=np.int64)
    out = cells.reset_index(drop=True)
    out.insert(0, "km_to_m", grid.km[j + 1] if j.size else np.zeros(0))
    out.insert(0, "km_from_m", grid.km[j])
    out.insert(0, "track", grid.frame["track"].to_numpy()[j])
    out.insert(0, "line_code", grid.frame["line_code"].to_numpy()[j])
    for c in ("runs", "fixes", "km_residual_runs"):
        out[c] = out[c].astype(np.int64)
    return out[list(CELL_COLUMNS)]


def _proposal(
    defects: pd.DataFrame,
    first: IntArray,
    last: IntArray,
    matched: pd.DataFrame,
    grid: _Grid,
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
    return pd.concat(rows, ignore_index=True)[list(PROPOSAL_COLUMNS)]


def _coverage(cells: pd.DataFrame, grid: _Grid, defects: pd.DataFrame, rc: pd.DataFrame) -> pd.DataFrame:
    """Per line/track of the DB: cells and km verified / unverified / defect."""
    n = grid.km.size
    starts = np.flatnonzero(grid.has_next)
    length = np.zeros(n)
    length[starts] = grid.km[starts + 1] - grid.km[starts]
    status = np.full(n, UNVERIFIED, dtype=object)
    if len(cells):
        status[cells.index.to_numpy(dtype=np.int64)] = cells["status"].to_numpy()
    frame = pd.DataFrame(
        {
            "line_code": grid.frame["line_code"].to_numpy()[starts],
            "track": grid.frame["track"].to_numpy()[starts],
            "len": length[starts] / 1000.0,
            "status": status[starts],
        }
    )
    cov = frame.pivot_table(
        index=["line_code", "track"], columns="status", values="len", aggfunc="sum", fill_value=0.0
    ).reindex(columns=[VERIFIED, UNVERIFIED, DEFECT], fill_value=0.0)
    keys = grid.frame[["line_code", "track"]].drop_duplicates()
    cov = cov.reindex(pd.MultiIndex.from_frame(keys), fill_value=0.0)
    total = cov.sum(axis=1).to_numpy()
    ncell = frame.groupby(["line_code", "track"]).size().reindex(cov.index, fill_value=0)
    out = pd.DataFrame(
        {
            "line_code": cov.index.get_level_values(0),
            "track": cov.index.get_level_values(1),
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
    nd = defects.groupby(["line_code", "track"]).size() if len(defects) else pd.Series(dtype=np.int64)
    out["defects"] = [int(nd.get((lc, tr), 0)) for lc, tr in zip(out["line_code"], out["track"], strict=True)]
    tid_rc = grid.tid[rc["cell"].to_numpy()]
    runs = pd.Series(rc["run"].to_numpy()).groupby(tid_rc).nunique()
    fixes = pd.Series(rc["n"].to_numpy()).groupby(tid_rc).sum()
    ids = {key: i for i, key in enumerate(grid.keys)}
    t_out = [ids[(lc, tr)] for lc, tr in zip(out["line_code"], out["track"], strict=True)]
    out["runs"] = runs.reindex(t_out, fill_value=0).to_numpy(dtype=np.int64)
    out["fixes"] = fixes.reindex(t_out, fill_value=0).to_numpy(dtype=np.int64)
    return out[list(COVERAGE_COLUMNS)].reset_index(drop=True)


def _residual_summary(matched: pd.DataFrame) -> dict[str, float | int | None]:
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


# ------------------------------------------------------------------------------ proposal


def proposed_network(network: Network, result: GisVerification) -> Network:
    """``network`` with the GIS points of the proposal moved (every other table unchanged)."""
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
    return Network(tables, origin=f"{network.origin} + gis verify proposal", meta={})
