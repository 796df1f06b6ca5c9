"""Balise positions from the runs' dead reckoning [S003 §4.5, §5.5]; wheel scales per run.

**One pass, one estimate.** For a read j of balise b in a chain (:mod:`fieldlogs.survey.trajectory`)
the nearest reads outside b's cluster before (a) and after (c) it are its anchors, at
their current positions c_a, c_c (the DB's, or the surveyed one of a balise found moved).
Dead reckoning from each side gives

    forward  ĉ_f = c_a + σ·λ·(d_j − d_a),        backward ĉ_b = c_c − σ·λ·(d_c − d_j),

each with variance s₀² + (q·L)² (L the travel from its anchor, s₀ = ``interval_sigma_m``,
q = ``interval_sigma_pct``); a side whose slip-correction budget grew by more than
``max_slip_allowance_m`` is not used (a slip correction is good to a few per cent of
itself, too coarse here). Their inverse-variance mean ĉ_j gives the pass's residual
δ = (c_DB − ĉ_j)·dkm/dc, DB km minus where the runs put it. The pipeline's correction
amount at a balise [S003 §4.5] is −δ from the forward side alone with λ = 1: the survey
adds the other side and the wheel's scale, and leaves out the balise's own cluster (the
I1 of a pair would otherwise vouch for its I2 five metres away).

**Across passes.** The passes are independent (each run its own odometry): per balise the
mean δ̄ of its n pass residuals, its spread s, and the standard error
se = max(s, s_pool)/√n with s_pool² = v̂·mean(var) from the track's pooled variance factor
v̂ = Σ(δ − δ̄)²/var ÷ Σ(n − 1) (with few passes s alone is often small by chance); the 95 %
interval is δ̄ ± t₀.₉₇₅,ₙ₋₁·se.

**Adjustment.** A balise off by e drags the residuals of its neighbours (whose anchor it
is) by e times the weight of that side (about e/2, nearly e where the other side is long
or missing). The survey therefore iterates: the balises that qualify as moved and whose
culprit score (:func:`culprit_score`: both sides must see the balise off by the same
amount; a neighbour of a displaced balise is off from one side only) is the largest among
the qualifying balises of the clusters they anchor or are anchored by in some chain
(:func:`anchor_pairs`; not the neighbouring clusters in the DB: a balise that is never
read, unpowered or gone, anchors nobody, and the balises on either side of it are each
other's anchors) are *flagged*, their anchor position is replaced by the surveyed one
(c_DB − δ̄/(dkm/dc)), the wheel scales and every residual are estimated again; flags that
no longer qualify are dropped; until the flags and anchors no longer change
(``max_iterations``). A balise whose flag or anchor still changed in the last round did
not settle: it is reported *unverified*, never *ok* or *moved* on one phase of a cycle.

**Wheel scale.** Within one chain a read i of balise b measures y_i = σ·c_b = a_p + λ·d_i + ε_i:
the reader's true place is the balise's track length, the travel d_i counts it in the
wheel's scale, a_p is the odometry's offset on the *stretch* p (the chain split wherever the
correction allowance grew between two reads: a slip or slide correction's distance is the
radar's or the integrated acceleration's, already in the ground's scale, so a corrected
stretch would pull λ towards 1 by its share — 0.45 % worn, 100 m of correction in 1 km:
0.045 % — whatever its small allowance; split there, the correction's own error enters no
stretch). The errors of a wheel scale are then those of its reads' *places*, not of the
intervals' lengths: ε_i = the DB position's error of b (its survey tolerance) + where along
the track the telegram was taken (the antenna's reception window, the telegram's time
stamp × speed) + the pulse quantisation of d_i, independent between reads — an interval's
constant part s₀ = ``interval_sigma_m`` is two of them, so var ε = s₀²/2, plus the
variance of a surveyed anchor (a balise found moved, (se/(dkm/dc))²). Between two reads
every one of them telescopes: the interval of i−1, i and that of i, i+1 share ε_i with
opposite signs, so the intervals' errors are not independent and do not grow with their
length (the share ``interval_sigma_pct`` of a balise residual, which also holds the error
of λ itself, is not one of them). λ̂ is therefore the weighted least-squares slope of y on
d with one offset per stretch (weights 1/var ε; only stretches of two or more reads), over
at least ``wheel_min_distance_m`` of stretch travel. The scale of var ε is measured: with
χ²_r = Σ wᵢrᵢ² over the run's n_r reads in P_r stretches, ν_r = n_r − P_r − 1, the factor
f_r = max(χ²_r/ν_r, Σχ²/Σν) (the run's own Birge ratio, at least the one pooled over every
run of the survey — with a dozen degrees of freedom a run's own is often small by chance),
and se(λ̂) = √(f_r/Σ wᵢ(dᵢ − d̄_p)²) · t₀.₉₇₅,ν_r/1.96 (the interval ±1.96·se of
:mod:`fieldlogs.survey.wheels` then a Student-t one). The GIS grid's length error, which
every balise and GNSS scale on that grid shares, is added there, not here.

Status: *missed* (never read on ≥ ``min_missed_passes`` passes), *moved* (|δ̄| ≥
``moved_min_m`` and the interval excludes 0), *ok* (the interval within
±``ok_tolerance_m``), otherwise *unverified* (not passed, too few passes, or inconclusive).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.survey.config import CONFIDENCE, SurveyConfig
from fieldlogs.survey.trajectory import BaliseTable, Reads

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]
OK, MOVED, MISSED, UNVERIFIED = "ok", "moved", "missed", "unverified"
#: A wheel-scale interval is clean only if the correction allowance did not grow in it [m].
ALLOWANCE_EPS_M = 1e-9
#: Two-sided 95 % normal quantile (the wheel intervals are ±Z95·se, :mod:`fieldlogs.survey.wheels`).
Z95 = 1.96


def t_quantile(df: FloatArray | float) -> FloatArray:
    """Two-sided 95 % Student-t quantile (NaN for df < 1)."""
    from scipy import stats

    dfa = np.asarray(df, dtype=float)
    with np.errstate(invalid="ignore"):
        q = stats.t.ppf(0.5 + CONFIDENCE / 2.0, np.where(dfa >= 1, dfa, np.nan))
    return np.asarray(q, dtype=float)


@dataclass(frozen=True)
class Neighbours:
    """For every read: its anchor read on each side (−1: none) and the travel to it."""

    prev: IntArray
    next: IntArray

    @classmethod
    def of(cls, reads: Reads, cluster: IntArray) -> Neighbours:
        n = reads.n
        if n == 0:
            z = np.zeros(0, dtype=np.int64)
            return cls(z, z)
        cl = cluster[reads.balise]
        new = np.r_[True, (reads.chain[1:] != reads.chain[:-1]) | (cl[1:] != cl[:-1])]
        grp = np.cumsum(new) - 1
        first = np.flatnonzero(new)
        last = np.r_[first[1:], n] - 1
        prev = first[grp] - 1
        nxt = last[grp] + 1
        prev = np.where((prev >= 0) & (reads.chain[np.maximum(prev, 0)] == reads.chain), prev, -1)
        nxt = np.where((nxt < n) & (reads.chain[np.minimum(nxt, n - 1)] == reads.chain), nxt, -1)
        return cls(prev.astype(np.int64), nxt.astype(np.int64))


def _variance(length: FloatArray, cfg: SurveyConfig) -> FloatArray:
    return np.asarray(cfg.interval_sigma_m**2 + (cfg.interval_sigma_pct / 100.0 * length) ** 2, dtype=float)


def read_variance(cfg: SurveyConfig) -> float:
    """Prior variance of one read's σ·c − λ·d about its stretch's line [m²] (module
    docstring, "Wheel scale"): half the constant part of an interval, s₀²/2."""
    return float(cfg.interval_sigma_m**2 / 2.0)


def wheel_scales(
    reads: Reads, c_anchor: FloatArray, n_runs: int, cfg: SurveyConfig, anchor_var: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Per run: λ (NaN when unknown), its standard error and the clean travel used [m]
    (module docstring, "Wheel scale"); ``anchor_var`` the variance of each balise's anchor
    position [m²] (a surveyed one; None: 0)."""
    lam, se, used = np.full(n_runs, np.nan), np.full(n_runs, np.nan), np.zeros(n_runs)
    n = reads.n
    if n == 0:
        return lam, se, used
    step = np.r_[False, reads.chain[1:] == reads.chain[:-1]]
    step[1:] &= (np.diff(reads.allowance) <= ALLOWANCE_EPS_M) & (np.diff(reads.d) > 0)
    piece = np.cumsum(~step) - 1
    n_p = int(piece[-1]) + 1
    y = reads.motion * c_anchor[reads.balise]
    v = read_variance(cfg) + (np.zeros(n) if anchor_var is None else anchor_var[reads.balise])
    ok_pt = np.isfinite(y) & np.isfinite(reads.d) & (v > 0)
    w = np.where(ok_pt, 1.0 / np.where(v > 0, v, 1.0), 0.0)
    y, x = np.where(ok_pt, y, 0.0), reads.d
    wp = np.bincount(piece, w, n_p)
    cnt = np.bincount(piece, ok_pt.astype(float), n_p)
    with np.errstate(invalid="ignore", divide="ignore"):
        xbar = np.bincount(piece, w * x, n_p) / wp
        ybar = np.bincount(piece, w * y, n_p) / wp
    lo = np.full(n_p, np.inf)
    hi = np.full(n_p, -np.inf)
    np.minimum.at(lo, piece[ok_pt], x[ok_pt])
    np.maximum.at(hi, piece[ok_pt], x[ok_pt])
    run_p = np.zeros(n_p, dtype=np.int64)
    run_p[piece] = reads.run
    real = cnt >= 2
    used = np.asarray(np.bincount(run_p[real], (hi - lo)[real], n_runs), dtype=float)
    dx = np.where(ok_pt & real[piece], x - np.nan_to_num(xbar[piece]), 0.0)
    dy = np.where(ok_pt & real[piece], y - np.nan_to_num(ybar[piece]), 0.0)
    sxx = np.bincount(reads.run, w * dx * dx, n_runs)
    sxy = np.bincount(reads.run, w * dx * dy, n_runs)
    ok = (used >= cfg.wheel_min_distance_m) & (sxx > 0)
    lam[ok] = sxy[ok] / sxx[ok]
    r = dy - np.nan_to_num(lam[reads.run]) * dx
    chi2 = np.bincount(reads.run, w * r * r, n_runs)
    dof = np.bincount(run_p[real], cnt[real] - 1.0, n_runs) - 1.0
    fit = ok & (dof >= 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        pooled = float(chi2[fit].sum() / dof[fit].sum()) if fit.any() else 1.0
        factor = np.fmax(np.where(fit, chi2 / np.maximum(dof, 1.0), pooled), pooled)
        widen = np.where(dof >= 1, t_quantile(np.maximum(dof, 1.0)) / Z95, 1.0)
        se[ok] = (np.sqrt(factor / sxx) * widen)[ok]
    return lam, se, used


@dataclass(frozen=True)
class PassEstimates:
    """One residual per read that has at least one usable side."""

    read: IntArray
    residual_m: FloatArray
    """DB km − surveyed km [m]."""
    var_m2: FloatArray
    forward_m: FloatArray
    """Residual from the forward side alone (NaN: side not used)."""
    backward_m: FloatArray


def _side(
    reads: Reads, j: IntArray, anchor: IntArray, c_anchor: FloatArray, lam: FloatArray, cfg: SurveyConfig
) -> tuple[FloatArray, FloatArray]:
    """(ĉ, variance) from the anchors ``anchor`` of reads ``j`` (NaN where unusable)."""
    ok = anchor >= 0
    a = np.where(ok, anchor, 0)
    length = np.abs(reads.d[j] - reads.d[a])
    allow = np.abs(reads.allowance[j] - reads.allowance[a])
    ok &= allow <= cfg.max_slip_allowance_m
    est = c_anchor[reads.balise[a]] + reads.motion[j] * lam[reads.run[j]] * (reads.d[j] - reads.d[a])
    ok &= np.isfinite(est)
    return np.where(ok, est, np.nan), np.where(ok, _variance(length, cfg), np.nan)


def pass_estimates(
    reads: Reads, nb: Neighbours, table: BaliseTable, c_anchor: FloatArray, lam: FloatArray, cfg: SurveyConfig
) -> PassEstimates:
    """Each pass's residual (module docstring, "One pass, one estimate")."""
    j = np.arange(reads.n)
    cf, vf = _side(reads, j, nb.prev, c_anchor, lam, cfg)
    cb, vb = _side(reads, j, nb.next, c_anchor, lam, cfg)
    wf = np.where(np.isfinite(cf), 1.0 / vf, 0.0)
    wb = np.where(np.isfinite(cb), 1.0 / vb, 0.0)
    wsum = wf + wb
    use = wsum > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        c_hat = (np.nan_to_num(cf) * wf + np.nan_to_num(cb) * wb) / wsum
    b = reads.balise
    c_db, slope = table.c[b], table.slope[b]
    return PassEstimates(
        j[use],
        ((c_db - c_hat) * slope)[use],
        (1.0 / wsum[use]) * slope[use] ** 2,
        ((c_db - cf) * slope)[use],
        ((c_db - cb) * slope)[use],
    )


def balise_statistics(est: PassEstimates, reads: Reads, table: BaliseTable) -> pd.DataFrame:
    """Per balise (every row of ``table``): n, mean, spread, se, 95 % half-width, z."""
    nb_rows = len(table.frame)
    b = reads.balise[est.read]
    n = np.bincount(b, None, nb_rows)
    s1 = np.bincount(b, est.residual_m, nb_rows)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s1 / n
        dev = est.residual_m - mean[b]
        ss = np.bincount(b, dev * dev, nb_rows)
        sd = np.sqrt(ss / (n - 1))
        std = np.bincount(b, dev * dev / est.var_m2, nb_rows)
        mvar = np.bincount(b, est.var_m2, nb_rows) / n
    track = table.frame["line_code"] + "/" + table.frame["track"]
    dof = pd.Series(np.maximum(n - 1, 0)).groupby(track.to_numpy()).transform("sum").to_numpy(dtype=float)
    vhat = pd.Series(std).groupby(track.to_numpy()).transform("sum").to_numpy(dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        vhat = np.where(dof > 0, vhat / dof, np.nan)
        pooled = np.sqrt(vhat * mvar)
        spread = np.fmax(np.where(n > 1, sd, np.nan), pooled)
        se = spread / np.sqrt(n)
        half = t_quantile((n - 1).astype(float)) * se
        z = mean / se
    forward = _side_mean(b, est.forward_m, nb_rows)
    backward = _side_mean(b, est.backward_m, nb_rows)
    return pd.DataFrame(
        {
            "n_estimates": n,
            "residual_m": mean,
            "spread_m": sd,
            "se_m": se,
            "ci95_m": half,
            "z": z,
            "forward_m": forward,
            "backward_m": backward,
        }
    )


def _side_mean(b: IntArray, side: FloatArray, n_rows: int) -> FloatArray:
    ok = np.isfinite(side)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.asarray(np.bincount(b[ok], side[ok], n_rows) / np.bincount(b[ok], None, n_rows), dtype=float)


def culprit_score(stats: pd.DataFrame) -> FloatArray:
    """How surely a balise, rather than the anchor of one of its sides, is off: a displaced
    balise is seen off by the same amount from both sides, the neighbour of one only from
    the side that balise anchors. min(|f̄|, |b̄|) when the side means f̄, b̄ agree in sign,
    0 when they disagree, half the one side's |mean| at the end of a chain (one side can
    not tell the balise from its anchor)."""
    f = stats["forward_m"].to_numpy(dtype=float)
    b = stats["backward_m"].to_numpy(dtype=float)
    both = np.isfinite(f) & np.isfinite(b)
    two = np.where(np.sign(f) == np.sign(b), np.fmin(np.abs(f), np.abs(b)), 0.0)
    one = 0.5 * np.abs(np.where(np.isfinite(f), f, b))
    return np.asarray(np.nan_to_num(np.where(both, two, one)), dtype=float)


def qualifies(stats: pd.DataFrame, cfg: SurveyConfig) -> BoolArray:
    """Moved by the status rule of the module docstring."""
    mean = stats["residual_m"].to_numpy(dtype=float)
    half = stats["ci95_m"].to_numpy(dtype=float)
    n = stats["n_estimates"].to_numpy(dtype=float)
    with np.errstate(invalid="ignore"):
        return np.asarray((n >= cfg.min_passes) & (np.abs(mean) >= cfg.moved_min_m) & (np.abs(mean) > half))


def anchor_pairs(reads: Reads, nb: Neighbours, cluster: IntArray) -> IntArray:
    """Every (cluster, anchor cluster) pair of the reads, both ways round, once each: the
    clusters whose errors enter each other's residuals (module docstring, "Adjustment")."""
    j = np.arange(reads.n)
    parts = [np.c_[cluster[reads.balise[j[a >= 0]]], cluster[reads.balise[a[a >= 0]]]] for a in (nb.prev, nb.next)]
    pairs = np.concatenate([*parts, *(p[:, ::-1] for p in parts)]).astype(np.int64).reshape(-1, 2)
    return np.unique(pairs, axis=0) if len(pairs) else pairs


def local_maxima(cand: BoolArray, score_in: FloatArray, cluster: IntArray, pairs: IntArray) -> BoolArray:
    """Candidates whose score (:func:`culprit_score`) is at least that of every candidate
    in the clusters they anchor or are anchored by (``pairs``, :func:`anchor_pairs`)."""
    n_cl = int(cluster.max()) + 1 if cluster.size else 0
    score = np.where(cand, score_in, -1.0)
    best = np.full(n_cl, -1.0)
    np.maximum.at(best, cluster, score)
    rival = np.full(n_cl, -1.0)
    if len(pairs):
        np.maximum.at(rival, pairs[:, 0], best[pairs[:, 1]])
    return np.asarray(cand & (score >= rival[cluster]))


@dataclass
class Adjustment:
    """Result of the iteration of the module docstring."""

    stats: pd.DataFrame
    flagged: BoolArray
    c_anchor: FloatArray
    scale: FloatArray
    scale_se: FloatArray
    scale_distance_m: FloatArray
    estimates: PassEstimates
    iterations: int
    unsettled: BoolArray
    """Balises whose flag or anchor still changed in the last round: the iteration stopped at
    ``max_iterations`` without settling (a cycle of flags), so their residual is one phase of
    it, not an estimate — :mod:`fieldlogs.survey.inspection` calls them *unverified*."""


def adjust(reads: Reads, table: BaliseTable, n_runs: int, cfg: SurveyConfig) -> Adjustment:
    """Flag, correct and re-estimate until stable (module docstring, "Adjustment")."""
    cluster = table.frame["cluster"].to_numpy(dtype=np.int64)
    nb = Neighbours.of(reads, cluster)
    pairs = anchor_pairs(reads, nb, cluster)
    c_db = table.c
    c_anchor = c_db.copy()
    flagged = np.zeros(len(table.frame), dtype=bool)
    anchor_var = np.zeros(len(table.frame))
    it = 0
    while True:
        it += 1
        lam, lam_se, used = wheel_scales(reads, c_anchor, n_runs, cfg, anchor_var)
        est = pass_estimates(reads, nb, table, c_anchor, lam, cfg)
        stats = balise_statistics(est, reads, table)
        cand = qualifies(stats, cfg)
        new = (flagged & cand) | local_maxima(cand, culprit_score(stats), cluster, pairs)
        shift = np.where(new, np.nan_to_num(stats["residual_m"].to_numpy(dtype=float)) / table.slope, 0.0)
        c_new = c_db - shift
        anchor_var = np.where(new, np.nan_to_num(stats["se_m"].to_numpy(dtype=float) / table.slope) ** 2, 0.0)
        changed = (new != flagged) | ~np.isclose(c_new, c_anchor, rtol=0.0, atol=1e-4, equal_nan=True)
        stable = not bool(changed.any())
        flagged, c_anchor = new, c_new
        if stable or it >= cfg.max_iterations:
            return Adjustment(stats, flagged, c_anchor, lam, lam_se, used, est, it, changed)
