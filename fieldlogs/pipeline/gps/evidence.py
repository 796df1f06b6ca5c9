"""Statistics of the up/down test over a window of trusted fixes [S001 §4.2; SPEC §5.4].

**Up/down decision.** At each trusted, matched fix k, the evidence is the trusted fixes of
the last ``decide_window_s`` (and after the last crossover). For each candidate track j:
n_j fixes matched, mean offset m_j, share_j of fixes whose nearest track is j. The slow
GPS error makes consecutive fixes dependent, so the standard error of m_j follows the
Gauss-Markov model (ρ = exp(−1 s/τ), ``noise_*``)::

    SE_j² = σ²·g(n_j) + σ_w²/n_j,   g(n) = [n(1+ρ)/(1−ρ) − 2ρ(1−ρⁿ)/(1−ρ)²] / n²

(1/g(n) is the effective sample size: 120 fixes are worth ~1.8 independent ones at
τ = 60 s, ~1.2 at τ = 180 s), inflated by the ratio of the window's own scatter to the model's
expectation when the data are noisier than the model. Under "on track j" m_j ~ N(0, SE²);
under "on track b" m_j ~ N(c, SE²) with c the offset of b's centreline, i.e. m_b ~ N(0, SE²).
The log-likelihood ratio is therefore ``LLR_jb = (m_b² − m_j²) / (2·SE_j²)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.matching import TrackIndex
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.types import BoolArray, FloatArray, IntArray


@dataclass
class Evidence:
    """Trusted, matched fixes (rows e) × candidate tracks (columns j), with prefix sums."""

    fix: IntArray
    """Row in the fixes table of each evidence row."""
    t: FloatArray
    tracks: IntArray
    """Track id (TrackIndex.keys) of each column."""
    r: FloatArray
    """(E, J) offsets, NaN where the track is not a candidate."""
    km: FloatArray
    near: IntArray
    """Column of each row's nearest track."""
    cn: FloatArray
    cs: FloatArray
    cq: FloatArray
    cnear: FloatArray
    s_ne: FloatArray
    """Prefix sums of the left normal (east, north components) of each candidate track at the
    fix, and of the products the crossover's rotating-bias fit needs (see :func:`crossing`)."""
    s_nn: FloatArray
    s_ee: FloatArray
    s_en: FloatArray
    s_nn2: FloatArray
    s_re: FloatArray
    s_rn: FloatArray

    @classmethod
    def build(cls, t: FloatArray, evidence: BoolArray, matches: pd.DataFrame, index: TrackIndex) -> Evidence:
        rows = np.flatnonzero(evidence)
        m = matches[evidence[matches["fix"].to_numpy()]] if len(matches) else matches
        tracks = np.unique(m["track_id"].to_numpy()) if len(m) else np.zeros(0, dtype=np.int64)
        e_of = np.full(t.size, -1, dtype=np.int64)
        e_of[rows] = np.arange(rows.size)
        r = np.full((rows.size, tracks.size), np.nan)
        km = np.full((rows.size, tracks.size), np.nan)
        near = np.zeros(rows.size, dtype=np.int64)
        ne = np.zeros((rows.size, tracks.size))
        nn = np.zeros((rows.size, tracks.size))
        if len(m):
            e = e_of[m["fix"].to_numpy()]
            j = np.searchsorted(tracks, m["track_id"].to_numpy())
            r[e, j] = m["offset_m"].to_numpy()
            km[e, j] = m["km_m"].to_numpy()
            b = m["best"].to_numpy()
            near[e[b]] = j[b]
            # left normal of increasing km = heading turned +90°: offsets are positive to the left
            ne[e, j] = -m["dir_n"].to_numpy()
            nn[e, j] = m["dir_e"].to_numpy()
        has = np.isfinite(r)
        zero = np.zeros((1, tracks.size))
        onehot = (near[:, None] == np.arange(tracks.size)[None, :]).astype(float)
        r0 = np.where(has, r, 0.0)

        def csum(a: FloatArray) -> FloatArray:
            return np.concatenate([zero, np.cumsum(a, axis=0)])

        return cls(
            rows,
            t[rows],
            tracks,
            r,
            km,
            near,
            csum(has),
            csum(r0),
            csum(r0 * r0),
            csum(onehot),
            csum(ne),
            csum(nn),
            csum(ne * ne),
            csum(ne * nn),
            csum(nn * nn),
            csum(r0 * ne),
            csum(r0 * nn),
        )

    @property
    def size(self) -> int:
        return int(self.t.size)


def mean_variance_factor(n: npt.ArrayLike, rho: float) -> FloatArray:
    """g(n): variance of the mean of n consecutive unit-variance AR(1) samples (lag-1
    correlation ρ); 1/g(n) is the effective sample size."""
    na = np.maximum(np.asarray(n, dtype=float), 1.0)
    if rho <= 0.0:
        return np.asarray(1.0 / na, dtype=float)
    g = (na * (1 + rho) / (1 - rho) - 2 * rho * (1 - rho**na) / (1 - rho) ** 2) / (na * na)
    return np.asarray(g, dtype=float)


@dataclass
class Window:
    """Decision statistics of the windows ending at evidence rows ``i`` (vectorised)."""

    i: IntArray
    lo: IntArray
    n: FloatArray
    """(rows, J) fixes matched per track."""
    mean: FloatArray
    share: FloatArray
    se2: FloatArray
    llr: FloatArray
    """(rows, J) min over the other candidates of (m_b² − m_j²)/(2 SE_j²)."""
    ok: BoolArray
    """(rows, J) all conditions except the LLR threshold."""


def windows(ev: Evidence, i: IntArray, reset_lo: int, cfg: GpsConfig, length_s: float) -> Window:
    lo = np.maximum(np.searchsorted(ev.t, ev.t[i] - length_s, side="right"), reset_lo)
    hi = i + 1
    total = (hi - lo).astype(float)[:, None]
    n = ev.cn[hi] - ev.cn[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (ev.cs[hi] - ev.cs[lo]) / n
        msq = (ev.cq[hi] - ev.cq[lo]) / n
        share = (ev.cnear[hi] - ev.cnear[lo]) / total
    rho = float(np.exp(-1.0 / cfg.noise_tau_s)) if cfg.noise_tau_s > 0 else 0.0
    g = mean_variance_factor(n, rho)
    sig2, w2 = cfg.noise_sigma_m**2, cfg.noise_white_m**2
    nn = np.maximum(n, 1.0)
    se2 = sig2 * g + w2 / nn
    expected_scatter = sig2 * (1.0 - g) + w2 * (1.0 - 1.0 / nn)
    with np.errstate(invalid="ignore", divide="ignore"):
        inflate = np.where(n >= 5, np.maximum(1.0, (msq - mean * mean) / expected_scatter), 1.0)
    se2 = se2 * np.nan_to_num(inflate, nan=1.0, posinf=1e9)
    m2 = np.where(n > 0, mean * mean, np.inf)
    llr = np.full(n.shape, np.inf)
    for j in range(n.shape[1]):
        others = np.delete(m2, j, axis=1)
        if others.shape[1]:
            llr[:, j] = (others.min(axis=1) - m2[:, j]) / (2.0 * se2[:, j])
    duration = ev.t[i] - ev.t[np.minimum(lo, i)]
    ok = (
        (n >= cfg.decide_min_fixes)
        & (duration >= cfg.decide_min_duration_s - 1e-9)[:, None]
        & (share >= cfg.decide_min_share)
        & (np.abs(mean) <= np.minimum(cfg.decide_max_mean_m, cfg.decide_fit_z * np.sqrt(se2)))
    )
    return Window(i, lo, n, mean, share, se2, llr, ok)


def merge_windows(w: Window, wr: Window, use_r: BoolArray) -> Window:
    """Per (row, track), the recent window's statistics where ``use_r``, else the full one's."""
    row_r = use_r.any(axis=1)
    return Window(
        w.i,
        np.where(row_r, wr.lo, w.lo),
        np.where(use_r, wr.n, w.n),
        np.where(use_r, wr.mean, w.mean),
        np.where(use_r, wr.share, w.share),
        np.where(use_r, wr.se2, w.se2),
        np.where(use_r, wr.llr, w.llr),
        np.where(use_r, wr.ok, w.ok),
    )
