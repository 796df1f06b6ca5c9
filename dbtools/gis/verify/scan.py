"""GIS verification, step 8 (:mod:`dbtools.gis.verify`): the scan — neighbouring cells pooled
into windows of 100–500 m along each track, tested with the run as the unit.

**Contrast.** For a window W of w cells on one track and each replication unit u (a run;
for the along-track residual a run-epoch, see below) with values in W::

    c_u = mean over W's cells of u's cell means  −  ½·(mean over the left flank + mean over the right flank)

where the flanks are ``flank`` cells either side, ``gap`` cells away from W (one flank
alone at a track end or break). The D-GPS error is Gauss–Markov with a correlation time of
minutes (σ ≈ 0.75 m, τ ≈ 180 s): within a few seconds it is nearly one value per run, and
the difference removes it; the symmetric flank mean also removes its linear trend, so
what stays is the GIS error of W relative to its surroundings plus the increment of the
slow error over the seconds between them (≈ σ·√(Δt/τ)). The units are independent
(different runs), so the window's contrasts are k independent draws:
``m = mean_u c_u``, ``s² = var_u c_u`` (ddof 1).

**Moderated t** [Smyth 2004, Stat. Appl. Genet. Mol. Biol. 3(1) art. 3]. With 5 runs s² has 4
degrees of freedom and Student's t(4) needs |t| > 60 to survive a correction over thousands
of windows. The contrast's spread is a property of the receivers and of the window length,
so per window length the variances of non-overlapping windows are fitted by a scaled
inverse-χ² prior (s₀², d₀) — Smyth's moment estimator on log s² with the digamma /
trigamma corrections — and each window's variance is moderated::

    s̃² = (d₀·s₀² + d·s²) / (d₀ + d),   t = m / (s̃/√k),   p = 2·P(T_{d₀+d} > |t|)   (d = k − 1)

which under that model is exact. A window with a larger own spread (a multipath burst in
one run, a noisy stretch) keeps a larger s̃ — it is not tested on the pooled spread alone —
and d₀ is small when the windows' spreads really differ. d₀ → ∞ (the spreads vary no more
than sampling explains) gives the pooled z-test.

**Multiple testing.** Every testable window of every length on every track is one test
(``m_tests`` of them); the p-values are adjusted together — Bonferroni by default (the
family-wise error of the whole verification stays ≤ alpha, however correlated the
overlapping windows are: the expected number of false defects of one verification is at
most alpha) or Benjamini–Hochberg. A permutation calibration would be sharper under
dependence, but 5 runs have only 2⁵ = 32 sign patterns (smallest p 1/32): with the
run as the unit there is nothing to permute. Bonferroni costs little where it matters: the
targets sit at |t| of 10–20.

**Selection.** A window is *significant* when its adjusted p ≤ alpha and |m| ≥ the
smallest shift worth reporting. Significant windows overlap; they are taken greedily by
|t|, each dropping the windows whose core *or flanks* touch it (a window beside a defect
has the defect in its flank and a spurious half contrast of the opposite sign). A
displaced stretch longer than the longest window is reported as that window's length.

**Along-track residual.** The same scan on r = GIS km − pipeline km of the fixes with a
reference (:mod:`fieldlogs.gisverify.evidence`). The pipeline's km error is reset by every
absolute fix, so the unit is the run-epoch (run × the pipeline's absolute-fix count at the fix:
``km_ref_epoch``), and a contrast never mixes two epochs. Within an epoch the pipeline's km
error drifts linearly with the travel (a wheel-diameter error, the same for a vehicle's
runs), which a one-sided flank would take for a GIS error: here a unit needs both flanks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import FloatArray
from dbtools.gis.verify.cells import Cells, adjust_pvalues

IntArray = npt.NDArray[np.int64]
#: Cells skipped between a window and its flanks (the half-displaced cell at each end of a stretch).
SCAN_GAP_CELLS = 1
#: Largest (units × columns) block of a track held at once [entries]; about 25 arrays of
#: that size live while its windows are summed (≈ 100 MB).
BLOCK_ENTRIES = 500_000
#: Prior degrees of freedom above this count as infinite (the pooled z-test).
D0_MAX = 1e6
#: Columns of the tested windows (:func:`scan`).
WINDOW_COLUMNS = (
    "tid",
    "first",
    "cells",
    "units",
    "weight",
    "mean_m",
    "var_m2",
    "se_m",
    "df",
    "t_stat",
    "p_value",
    "q_value",
)
#: Smallest time factor h of a contrast [s]: the averaging and interpolation noise a
#: contrast keeps when window and flanks are passed within a second or two.
H_FLOOR_S = 2.0


@dataclass(frozen=True)
class Prior:
    """Scaled inverse-χ² prior of a window length's contrast variance: s₀² and d₀."""

    s0_sq: float
    d0: float
    windows: int
    """Non-overlapping windows it was fitted on."""


def trigamma_inverse(x: float) -> float:
    """y with trigamma(y) = x (x > 0), Newton's method on 1/trigamma [Smyth 2004, §6.2]."""
    from scipy.special import polygamma

    if x > 1e7:
        return float(1.0 / np.sqrt(x))
    if x < 1e-6:
        return 1.0 / x
    y = 0.5 + 1.0 / x
    for _ in range(50):
        tri = float(polygamma(1, y))
        step = tri * (1.0 - tri / x) / float(polygamma(2, y))
        y += step
        if -step / y < 1e-8:
            break
    return float(y)


def fit_prior(var: FloatArray, df: FloatArray) -> Prior:
    """Smyth's moment estimate of (s₀², d₀) from sample variances ``var`` with ``df``
    degrees of freedom each: e = log s² − ψ(d/2) + log(d/2); mean e = log s₀² − ψ(d₀/2) +
    log(d₀/2); var e − mean ψ′(d/2) = ψ′(d₀/2). Too few (< 3) positive variances: no prior
    (d₀ = 0, each window on its own)."""
    from scipy.special import digamma, polygamma

    ok = np.isfinite(var) & (var > 0) & (df > 0)
    v, d = var[ok], df[ok]
    if v.size < 3:
        return Prior(float("nan"), 0.0, int(v.size))
    e = np.log(v) - digamma(d / 2) + np.log(d / 2)
    e_mean = float(e.mean())
    e_var = float(((e - e_mean) ** 2).sum() / (e.size - 1) - np.mean(polygamma(1, d / 2)))
    if e_var <= 0:
        return Prior(float(np.exp(e_mean)), D0_MAX, int(v.size))
    d0 = min(2.0 * trigamma_inverse(e_var), D0_MAX)
    s0_sq = float(np.exp(e_mean + digamma(d0 / 2) - np.log(d0 / 2)))
    return Prior(s0_sq, d0, int(v.size))


def moderated_t(
    mean: FloatArray, var: FloatArray, k: FloatArray, weight: FloatArray, prior: Prior
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(se, df, t, two-sided p) of windows with weighted contrast ``mean``, unit variance
    ``var`` over ``k`` units of total weight ``weight`` (module docstring): the moderated
    variance, or the window's own where that is larger."""
    from scipy import stats

    d = k - 1.0
    own = np.where(np.isfinite(var), var, 0.0)
    if prior.d0 > 0 and np.isfinite(prior.s0_sq):
        s2 = np.maximum((prior.d0 * prior.s0_sq + d * own) / (prior.d0 + d), own)
        df = prior.d0 + d
    else:
        s2, df = var, d
    with np.errstate(invalid="ignore", divide="ignore"):
        se = np.sqrt(s2 / weight)
        t = mean / se
    p = 2.0 * stats.t.sf(np.abs(t), np.maximum(df, 1.0))
    bad = (k < 2) | ~np.isfinite(t)
    return se, df, np.where(bad, np.nan, t), np.where(bad, np.nan, p)


# ------------------------------------------------------------------------------ contrasts


@dataclass
class _Track:
    """One track's cells (local 0..n−1 = grid ids lo..lo+n−1) laid out for the window
    sums: ``pad`` empty columns at both ends and after every grid point without a cell (a
    track end, a kilometrage break or a hole), so that a flank never reaches across one."""

    lo: int
    n: int
    pad: int
    column: IntArray
    """Expanded column of each local cell."""
    cell_at: IntArray
    """Local cell of each expanded column (−1: padding or a point without a cell)."""

    @classmethod
    def of(cls, grid: Cells, lo: int, hi: int, pad: int) -> _Track:
        has = grid.has_next[lo : hi + 1]
        n = has.size
        holes_before = np.concatenate([[0], np.cumsum(~has)[:-1]]).astype(np.int64)
        column = pad + np.arange(n) + pad * holes_before
        width = int(column[-1]) + 1 + pad if n else 2 * pad
        cell_at = np.full(width, -1, dtype=np.int64)
        cell_at[column[has]] = np.flatnonzero(has)
        return cls(lo, n, pad, column.astype(np.int64), cell_at)

    @property
    def width(self) -> int:
        return int(self.cell_at.size)


def _window_sums(
    ps: FloatArray, pt: FloatArray, pc: FloatArray, trk: _Track, w: int, gap: int, flank: int, both_sides: bool
) -> tuple[IntArray, FloatArray, FloatArray]:
    """The local starts of the windows of w cells that hold cells only, and per unit (rows)
    and window (columns) the contrast c and its weight 1/h (0 where the unit has no
    contrast). ``ps``, ``pt``, ``pc``: prefix sums over the expanded columns of the units'
    cell means, cell mean times and cell counts (units × (width + 1)); every sum is a slice
    difference. ``both_sides``: a unit needs both flanks (a trend cancels)."""
    e0, e1 = trk.pad, trk.width - trk.pad - w  # window starts (expanded), flanks stay inside
    if e1 < e0:
        return np.zeros(0, np.int64), np.zeros((ps.shape[0], 0)), np.zeros((ps.shape[0], 0))
    m = e1 - e0 + 1

    def span(p: FloatArray, lo: int, hi: int) -> FloatArray:
        """Sum over expanded columns e+lo .. e+hi−1 for every window start e."""
        return np.asarray(p[:, e0 + hi : e0 + hi + m] - p[:, e0 + lo : e0 + lo + m], dtype=np.float64)

    sides = ((0, w), (-gap - flank, -gap), (w + gap, w + gap + flank))
    n_core, n_l, n_r = (span(pc, lo, hi) for lo, hi in sides)
    with np.errstate(invalid="ignore", divide="ignore"):
        core, left, right = (span(ps, lo, hi) / n for (lo, hi), n in zip(sides, (n_core, n_l, n_r), strict=True))
        t_c, t_l, t_r = (span(pt, lo, hi) / n for (lo, hi), n in zip(sides, (n_core, n_l, n_r), strict=True))
    has_l, has_r = n_l > 0, n_r > 0
    both = has_l & has_r
    flank_mean = np.where(has_l, np.where(has_r, 0.5 * (left + right), left), right)
    # Brownian increments of the slow error: var ∝ (|Δt_l| + |Δt_r|)/4 for both flanks, |Δt| for one
    h = np.where(
        both,
        0.25 * (np.abs(t_c - t_l) + np.abs(t_r - t_c)),
        np.where(has_l, np.abs(t_c - t_l), np.abs(t_r - t_c)),
    )
    ok = (n_core > 0) & (both if both_sides else has_l | has_r) & np.isfinite(h)
    weight = np.where(ok, 1.0 / np.maximum(np.where(ok, h, 0.0), H_FLOOR_S), 0.0)
    c = np.where(ok, core - flank_mean, 0.0)
    # windows made of real cells only: w consecutive columns that are cells of the track
    real = np.concatenate([[0], np.cumsum(trk.cell_at >= 0)])
    starts = np.arange(e0, e1 + 1)
    valid = (real[starts + w] - real[starts]) == w
    return trk.cell_at[starts[valid]], c[:, valid], weight[:, valid]


def _track_windows(
    values: pd.DataFrame, trk: _Track, widths: Sequence[int], gap: int, flank: int, both_sides: bool
) -> list[pd.DataFrame]:
    """Tested windows of one track: per width, units k, Σw, and the weighted contrasts' mean
    and variance (accumulated over blocks of units so that memory stays bounded)."""
    unit_code, _ = pd.factorize(values["unit"], sort=True)
    n_units = int(unit_code.max()) + 1 if unit_code.size else 0
    col = trk.column[values["cell"].to_numpy(dtype=np.int64) - trk.lo]
    v = values["v"].to_numpy(dtype=float)
    tv = values["t"].to_numpy(dtype=float)
    block = max(1, BLOCK_ENTRIES // max(trk.width, 1))
    acc: dict[int, list[FloatArray]] = {}
    starts: dict[int, IntArray] = {}
    for u0 in range(0, n_units, block):
        rows = (unit_code >= u0) & (unit_code < u0 + block)
        m = min(block, n_units - u0)
        prefix = []
        for quantity in (v, tv, np.ones_like(v)):
            dense = np.zeros((m, trk.width))
            dense[unit_code[rows] - u0, col[rows]] = quantity[rows]
            prefix.append(np.concatenate([np.zeros((m, 1)), np.cumsum(dense, axis=1)], axis=1))
        for w in widths:
            a, c, wt = _window_sums(prefix[0], prefix[1], prefix[2], trk, w, gap, flank, both_sides)
            if not a.size:
                continue
            sums = [(wt > 0).sum(axis=0).astype(float), wt.sum(axis=0), (wt * c).sum(axis=0), (wt * c * c).sum(axis=0)]
            starts[w] = a
            acc[w] = sums if w not in acc else [x + y for x, y in zip(acc[w], sums, strict=True)]
    out = []
    for w, (k, sw, s1, s2) in acc.items():
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = s1 / sw
            var = np.where(k > 1, (s2 - s1 * mean) / (k - 1), np.nan)
        out.append(
            pd.DataFrame(
                {
                    "first": starts[w] + trk.lo,
                    "cells": w,
                    "units": k,
                    "weight": sw,
                    "mean_m": mean,
                    "var_m2": np.maximum(var, 0.0),
                }
            )
        )
    return out


def contrasts(
    values: pd.DataFrame, grid: Cells, widths: Sequence[int], gap: int, flank: int, *, both_sides: bool = False
) -> pd.DataFrame:
    """Every window of every track with at least one unit: ``tid``, ``first`` (grid id),
    ``cells``, ``units``, ``weight``, ``mean_m``, ``var_m2``. ``values``: one row per (cell,
    unit) with the unit's mean value ``v`` and mean time ``t`` in that cell. ``both_sides``:
    only units with values in both flanks (module docstring, along-track)."""
    frames = []
    if len(values):
        tid = grid.tid[values["cell"].to_numpy(dtype=np.int64)]
        for t, sub in values.groupby(tid, sort=True):
            pts = np.flatnonzero(grid.tid == int(t))
            trk = _Track.of(grid, int(pts[0]), int(pts[-1]), gap + flank)
            frames += [f.assign(tid=int(t)) for f in _track_windows(sub, trk, widths, gap, flank, both_sides)]
    frames = [f[f["units"] > 0] for f in frames]
    if not frames:
        return pd.DataFrame({c: pd.Series([], dtype=float) for c in WINDOW_COLUMNS[:7]})
    return pd.concat(frames, ignore_index=True)[list(WINDOW_COLUMNS[:7])]


# ------------------------------------------------------------------------------ tests


def window_tests(windows: pd.DataFrame, min_units: int, correction: str) -> tuple[pd.DataFrame, dict[int, Prior]]:
    """Moderated t of every window with ≥ ``min_units`` units, adjusted over all of them
    (``q_value``); the prior of each window length (fitted on the non-overlapping windows
    ``first ≡ 0 mod cells`` of each track)."""
    w = windows[windows["units"] >= min_units].reset_index(drop=True)
    priors: dict[int, Prior] = {}
    cols = {c: np.full(len(w), np.nan) for c in ("se_m", "df", "t_stat", "p_value")}
    for key, idx in w.groupby("cells").indices.items():
        cells = int(key)  # type: ignore[call-overload]
        sub = w.iloc[idx]
        disjoint = (sub["first"].to_numpy() % cells) == 0
        k = sub["units"].to_numpy(dtype=float)
        var = sub["var_m2"].to_numpy(dtype=float)
        prior = fit_prior(var[disjoint], k[disjoint] - 1.0)
        priors[cells] = prior
        weight = sub["weight"].to_numpy(dtype=float)
        se, df, t, p = moderated_t(sub["mean_m"].to_numpy(dtype=float), var, k, weight, prior)
        for name, val in zip(("se_m", "df", "t_stat", "p_value"), (se, df, t, p), strict=True):
            cols[name][idx] = val
    for name, val in cols.items():
        w[name] = val
    w["q_value"] = adjust_pvalues(w["p_value"].to_numpy(dtype=float), correction)
    return w[list(WINDOW_COLUMNS)], priors


def select_windows(tested: pd.DataFrame, alpha: float, min_shift_m: float, reach: int) -> pd.DataFrame:
    """The displaced stretches among the significant windows (module docstring): the most
    significant window left (largest |t|) marks one; of the significant windows of the same
    sign that overlap it, the one with the largest |mean| is the stretch (a window inside a
    displaced stretch has part of it in a flank, a window around it dilutes it: the one that
    fits has the largest contrast). Every window whose core or flanks (``reach`` cells either
    side) touch a stretch taken is dropped."""
    sig = tested[(tested["q_value"] <= alpha) & (tested["mean_m"].abs() >= min_shift_m)]
    if sig.empty:
        return sig.assign(last=pd.Series([], dtype=np.int64))
    sig = sig.assign(order=-sig["t_stat"].abs()).sort_values(["order", "p_value"], kind="stable")
    tid = sig["tid"].to_numpy()
    lo = sig["first"].to_numpy(dtype=np.int64)
    hi = lo + sig["cells"].to_numpy(dtype=np.int64)
    sign = np.sign(sig["mean_m"].to_numpy(dtype=float))
    size = np.abs(sig["mean_m"].to_numpy(dtype=float))
    alive = np.ones(len(sig), dtype=bool)
    keep = []
    while alive.any():
        top = int(np.argmax(alive))  # sorted by |t|: the first one alive
        near = alive & (tid == tid[top]) & (sign == sign[top]) & (lo < hi[top]) & (hi > lo[top])
        best = int(np.flatnonzero(near)[np.argmax(size[near])])
        keep.append(sig.index[best])
        alive &= ~((tid == tid[best]) & (lo - reach < hi[best]) & (hi + reach > lo[best]))
    out = sig.loc[keep].drop(columns="order").sort_values(["tid", "first"]).reset_index(drop=True)
    out["last"] = (out["first"] + out["cells"] - 1).astype(np.int64)
    return out


@dataclass
class ScanResult:
    """What the scan of one quantity found: the selected windows (``WINDOW_COLUMNS`` + ``last``),
    how many windows were tested and the prior per window length (cells)."""

    selected: pd.DataFrame
    tested: int
    priors: dict[int, Prior]


def scan(
    values: pd.DataFrame,
    grid: Cells,
    widths: Sequence[int],
    flank: int,
    *,
    min_units: int,
    alpha: float,
    correction: str,
    min_shift_m: float,
    both_sides: bool = False,
) -> ScanResult:
    """Contrasts, moderated tests, correction and greedy selection (module docstring)."""
    if not widths:
        return ScanResult(select_windows(pd.DataFrame(columns=list(WINDOW_COLUMNS)), alpha, 0.0, 0), 0, {})
    windows = contrasts(values, grid, widths, SCAN_GAP_CELLS, flank, both_sides=both_sides)
    tested, priors = window_tests(windows, min_units, correction)
    selected = select_windows(tested, alpha, min_shift_m, SCAN_GAP_CELLS + flank)
    return ScanResult(selected, len(tested), priors)


def scan_summary(result: ScanResult, spacing_m: float) -> dict[str, object]:
    """The scan as JSON data: windows tested and selected, and per window length the prior
    (s₀ in metres, d₀; null where it could not be fitted)."""

    def num(x: float) -> float | None:
        return round(float(x), 6) if np.isfinite(x) else None

    return {
        "windows_tested": result.tested,
        "windows_selected": len(result.selected),
        "priors": [
            {
                "window_m": round(cells * spacing_m, 3),
                "s0_m": num(np.sqrt(p.s0_sq)) if np.isfinite(p.s0_sq) else None,
                "d0": num(p.d0),
                "fitted_on": p.windows,
            }
            for cells, p in sorted(result.priors.items())
        ],
    }
