"""Track-constrained positioning [S002]: unknowns s (along the track) and one clock per receiver.

Per epoch the rows r are pseudoranges of K receivers (receiver k_r, antenna A_k on the
vehicle, see ``track``), corrected as in ``observables``: ρ_c,r = |r_s,r − A_k(s)| + sagnac + b_k + ε_r.
The unknowns drop from (x, y, z, b) to (s, b_1..b_K) [S002 fig. 1], so one receiver needs
**two satellites** (two receivers three). Gauss–Newton on the piecewise-linear track:

* residual v_r = ρ_c,r − |r_s − A(s)| − sagnac − b_k; Jacobian H_r = [g_r, e_k] with the
  along-track geometry g_r = ∂ρ/∂s = −û_r·t (û receiver→satellite, t the tangent);
* weighted normal equations (HᵀWH)δ = HᵀWv, W = diag(1/σ_r²) from ``errormodel``;
  iterate from a given start, the prior s, or a coarse search along the whole track (every
  ``coarse_step_m``, the best fit of the clocks eliminated) to |δ| < 1 mm;
* 1σ along the track σ_s = √[(HᵀWH)⁻¹]_ss and the along-track DOP ADOP = √[(HᵀH)⁻¹]_ss.
  Two satellites ahead of and behind the train at low elevation give g ≈ ±cos E and
  σ_s ≈ σ/(√2 cos E) — the paper's best case.

Integrity, with redundancy (dof = rows − unknowns ≥ 1) [S002]:

* *no on-track solution*: an epoch whose solution leaves the track (or the window
  |s − s_prior| ≤ ``prior_window_sigmas``·√(σ_prior² + σ_s²) around the prior), or does not
  converge, is solved again without each row in turn; the row whose removal gives a converged
  on-track solution with the smallest test statistic is rejected. The final satellites-only
  solution must lie in the same window (two satellites can fit a second, distant point of a
  winding track);
* *exclusion*: while the global test T = Σ v_r²/σ_r² exceeds the χ²(dof) quantile at
  ``p_false_alarm`` or a normalised residual w_r = |v_r|/(σ_r√q_r) exceeds ``k_w``
  (q_r = 1 − h_r/σ_r², h_r the hat-matrix diagonal: Baarda's w-test, which sees a bias on a
  low-redundancy row that the global test dilutes), the satellite row with the largest w_r
  is excluded; with dof = 1 a failing epoch cannot be resolved and is refused;
* an optional prior (s_prior, σ_prior) — the pipeline's own estimate, e.g. from the
  tachometer — enters the *tests* as one more observation: with it, three satellites on one
  receiver can identify a faulty one (without it the three normalised residuals of a
  one-dof problem are equal). The prior is never the one excluded (a fault that hides in
  the satellites' own fit shows as a large prior residual; blaming the prior would accept
  it): when only the prior disagrees the epoch fails. The reported s uses the satellites only;
* a predicted receiver clock (``Rows.clock_prior_m``, from ``coasting``) is one more
  observation of b_k, kept in the solution and the tests and never excluded: with it one
  satellite fixes s. In the ADOP it counts as a row of weight σ_rms²/σ_clock².

Stated uncertainty U = max(k_ff·σ_s, PL): k_ff = 3.29 is the 10⁻³ two-sided bound of
fault-free Gaussian errors, and PL the protection level against one satellite fault the
w-test misses, PL = max_r |K_sr|·σ_r/√q_r·(k_w + k_md) with K = (HᵀWH)⁻¹HᵀW of the
satellites-only estimate and q_r the redundancy numbers of the detector (with the prior
when one is given): the largest error a bias just below the detectable size on one row can
cause (the RAIM slope of Brown & Chin 1997, in w-test form). With dof = 0 nothing is
monitored: PL is NaN and U the fault-free term.
Measured figures: bench/NOTES.md (GNSS).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from typing import Final

import numpy as np

from fieldlogs.gnss.constants import C_MPS, BoolArray, FloatArray, IntArray
from fieldlogs.gnss.linalg import inv_safe, singular, solve_safe
from fieldlogs.gnss.track import Antenna, TrackLine

STATUS_OK: Final = 0
STATUS_TOO_FEW: Final = 1
STATUS_NOT_CONVERGED: Final = 2
STATUS_OFF_TRACK: Final = 3
STATUS_FAULT: Final = 4
STATUS_GEOMETRY: Final = 5
STATUS_NAMES: Final = {
    STATUS_OK: "ok",
    STATUS_TOO_FEW: "too_few_satellites",
    STATUS_NOT_CONVERGED: "not_converged",
    STATUS_OFF_TRACK: "no_on_track_solution",
    STATUS_FAULT: "fault_not_excluded",
    STATUS_GEOMETRY: "poor_geometry",
}


@dataclass(frozen=True)
class ConstrainedConfig:
    """Solver and integrity parameters (module docstring)."""

    max_iter: int = 15
    tol_m: float = 1e-3
    p_false_alarm: float = 1e-3
    max_exclusions: int = 3
    k_w: float = 3.29
    """Critical value of the normalised residuals (Baarda's w-test, 10⁻³ two-sided per row)."""
    k_fault_free: float = 3.29
    k_missed_detection: float = 3.09
    max_adop: float = 10.0
    prior_window_sigmas: float = 5.0
    coarse_step_m: float = 100.0


@dataclass(frozen=True)
class Rows:
    """One batch of epochs: rows (E, S) of K receivers' corrected pseudoranges."""

    sat_pos: FloatArray
    pr_m: FloatArray
    sigma_m: FloatArray
    usable: BoolArray
    omega_e: FloatArray
    receiver: IntArray
    """Receiver index k_r of each row (0..K−1)."""
    direction: FloatArray
    """+1 where the vehicle faces increasing s, −1 otherwise (E,)."""
    clock_prior_m: FloatArray | None = None
    """Predicted receiver clocks (E, K) for clock coasting, or None."""
    clock_prior_sigma_m: FloatArray | None = None
    """Their 1σ (E, K); +inf where there is no prediction."""

    def take(self, sel: IntArray) -> Rows:
        """The epochs ``sel``."""
        return self._map(lambda v: v[sel])

    def repeat(self, n: int) -> Rows:
        """Every epoch repeated ``n`` times in place (for candidate searches)."""
        return self._map(lambda v: np.repeat(v, n, axis=0))

    def _map(self, fn: Callable[[np.ndarray], np.ndarray]) -> Rows:
        cp, cs = self.clock_prior_m, self.clock_prior_sigma_m
        return Rows(
            fn(self.sat_pos),
            fn(self.pr_m),
            fn(self.sigma_m),
            fn(self.usable),
            fn(self.omega_e),
            fn(self.receiver),
            fn(self.direction),
            None if cp is None else fn(cp),
            None if cs is None else fn(cs),
        )

    def clock_weight(self) -> FloatArray:
        """1/σ² of the clock predictions (E, K); 0 where none."""
        if self.clock_prior_sigma_m is None:
            return np.zeros((self.pr_m.shape[0], int(self.receiver.max(initial=0)) + 1))
        sig = self.clock_prior_sigma_m
        return np.where(np.isfinite(sig), 1.0 / np.where(np.isfinite(sig), sig, 1.0) ** 2, 0.0)


@dataclass
class ConstrainedSolution:
    """Per-epoch result (E,) and per-row flags (E, S)."""

    s: FloatArray
    clock_m: FloatArray
    sigma_clock_m: FloatArray
    sigma_s: FloatArray
    adop: FloatArray
    uncertainty_m: FloatArray
    protection_m: FloatArray
    test: FloatArray
    dof: IntArray
    n_used: IntArray
    used: BoolArray
    excluded: BoolArray
    no_track: BoolArray
    residual_m: FloatArray
    mdb_m: FloatArray
    """Minimal detectable bias of each used row (k_w + k_md)·σ_r/√q_r; NaN unused or unmonitored."""
    status: IntArray


@lru_cache(maxsize=8)
def chi2_thresholds(p_false_alarm: float, max_dof: int = 128) -> FloatArray:
    """χ²(dof) quantiles at 1 − p_false_alarm for dof = 0..max_dof (dof 0: +inf)."""
    from scipy.stats import chi2  # lazy: scipy.stats is heavy

    out = np.full(max_dof + 1, np.inf)
    out[1:] = chi2.ppf(1.0 - p_false_alarm, np.arange(1, max_dof + 1))
    return out


@dataclass
class _Fit:
    s: FloatArray
    b: FloatArray
    h: FloatArray
    v: FloatArray
    n_inv: FloatArray
    converged: BoolArray


def _geometry(track: TrackLine, rows: Rows, ant: FloatArray, s: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Modelled range (without clock) and g = ∂ρ/∂s of every row at reference-point s (E,)."""
    d = rows.direction[:, None]
    along, lateral, height = ant[rows.receiver, 0], ant[rows.receiver, 1], ant[rows.receiver, 2]
    sa = s[:, None] + d * along
    j = track.segment(sa)
    pos = (
        track.xyz[j]
        + (sa - track.s[j])[..., None] * track.tangent[j]
        + (d * lateral)[..., None] * track.left[j]
        + height[..., None] * track.up[j]
    )
    diff = rows.sat_pos - pos
    rng = np.linalg.norm(diff, axis=-1)
    sag = (rows.omega_e / C_MPS) * (rows.sat_pos[..., 0] * pos[..., 1] - rows.sat_pos[..., 1] * pos[..., 0])
    u = diff / np.where(rng > 0, rng, 1.0)[..., None]
    g = -np.sum(u * track.tangent[j], axis=-1)
    return rng + sag, g


def _normal(
    h: FloatArray,
    w: FloatArray,
    v: FloatArray,
    prior_w: FloatArray,
    prior_v: FloatArray,
    cw: FloatArray,
    cv: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    n = np.einsum("esi,es,esj->eij", h, w, h)
    rhs = np.einsum("esi,es,es->ei", h, w, v)
    n[:, 0, 0] += prior_w
    rhs[:, 0] += prior_w * prior_v
    kk = np.arange(1, n.shape[1])
    n[:, kk, kk] += cw
    rhs[:, 1:] += cw * cv
    # receivers without rows nor a clock prediction: pin their clock (regularise the empty column)
    empty = (np.einsum("esi,es->ei", h[..., 1:] ** 2, w) <= 0) & (cw <= 0)
    idx = np.arange(1, n.shape[1])
    n[:, idx, idx] += empty
    return n, rhs


def gauss_newton(
    track: TrackLine,
    rows: Rows,
    antennas: FloatArray,
    used: BoolArray,
    s0: FloatArray,
    prior: tuple[FloatArray, FloatArray] | None,
    cfg: ConstrainedConfig,
) -> _Fit:
    """Batched Gauss–Newton from s0 (module docstring); unknowns (s, b_0..b_{K−1})."""
    k = int(antennas.shape[0])
    e, n_s = rows.pr_m.shape
    w = np.where(used, 1.0 / np.where(used, rows.sigma_m, 1.0) ** 2, 0.0)
    onehot = np.zeros((e, n_s, k))
    onehot[np.arange(e)[:, None], np.arange(n_s)[None, :], rows.receiver] = 1.0
    s = np.asarray(s0, dtype=float).copy()
    rho, g = _geometry(track, rows, antennas, s)
    resid0 = np.where(used, rows.pr_m - rho, 0.0)
    b = np.einsum("es,es,esk->ek", resid0, w, onehot) / np.maximum(np.einsum("es,esk->ek", w, onehot), 1e-30)
    cw = rows.clock_weight()[:, :k] if rows.clock_prior_m is not None else np.zeros((e, k))
    cb = np.zeros((e, k)) if rows.clock_prior_m is None else np.nan_to_num(rows.clock_prior_m[:, :k])
    b = np.where((cw > 0) & (np.einsum("es,esk->ek", w, onehot) <= 0), cb, b)
    p_w = np.zeros(e) if prior is None else 1.0 / prior[1] ** 2
    p_s = np.zeros(e) if prior is None else prior[0]
    converged = np.zeros(e, dtype=bool)
    for _ in range(cfg.max_iter):
        rho, g = _geometry(track, rows, antennas, s)
        v = np.where(used, rows.pr_m - rho - np.einsum("esk,ek->es", onehot, b), 0.0)
        h = np.concatenate([g[..., None], onehot], axis=-1)
        n, rhs = _normal(h, w, v, p_w, p_s - s, cw, cb - b)
        delta, bad = solve_safe(n, rhs)
        delta[:, 0] = np.clip(delta[:, 0], -5_000.0, 5_000.0)
        s = s + delta[:, 0]
        b = b + delta[:, 1:]
        converged = (np.max(np.abs(delta), axis=1) < cfg.tol_m) & ~bad
        if converged.all():
            break
    rho, g = _geometry(track, rows, antennas, s)
    v = np.where(used, rows.pr_m - rho - np.einsum("esk,ek->es", onehot, b), 0.0)
    h = np.concatenate([g[..., None], onehot], axis=-1)
    n, _ = _normal(h, w, v, p_w, p_s - s, cw, cb - b)
    return _Fit(s, b, h, v, inv_safe(n), converged & ~singular(n))


def coarse_start(track: TrackLine, rows: Rows, antennas: FloatArray, used: BoolArray, step_m: float) -> FloatArray:
    """Start s per epoch: the best of candidates every ``step_m`` along the whole track, the
    clocks eliminated as weighted means per receiver (chunks of epochs to bound memory)."""
    cand = np.arange(0.0, track.length_m + step_m, step_m)
    e = rows.pr_m.shape[0]
    best = np.zeros(e)
    w = np.where(used, 1.0 / np.where(used, rows.sigma_m, 1.0) ** 2, 0.0)
    k = int(antennas.shape[0])
    for a in range(0, e, 32):
        sl = slice(a, a + 32)
        m = min(32, e - a)
        sub = rows.take(np.arange(a, a + m))
        rep = sub.repeat(cand.size)
        rho, _ = _geometry(track, rep, antennas, np.tile(cand, m))
        ww = np.repeat(w[sl], cand.size, axis=0)
        res = np.where(ww > 0, rep.pr_m - rho, 0.0)
        cost = np.zeros(res.shape[0])
        for kk in range(k):
            wk = ww * (rep.receiver == kk)
            mean = np.sum(wk * res, axis=1) / np.maximum(np.sum(wk, axis=1), 1e-30)
            cost += np.sum(wk * (res - mean[:, None]) ** 2, axis=1)
        best[sl] = cand[np.argmin(cost.reshape(m, cand.size), axis=1)]
    return best


def _statistics(
    fit: _Fit, rows: Rows, used: BoolArray, prior: tuple[FloatArray, FloatArray] | None, prior_on: BoolArray
) -> tuple[FloatArray, FloatArray, IntArray, FloatArray]:
    """Global test T, normalised residuals (E, S+1: last column the prior), dof and q (redundancy)."""
    w = np.where(used, 1.0 / np.where(used, rows.sigma_m, 1.0) ** 2, 0.0)
    hnh = np.einsum("esi,eij,esj->es", fit.h, fit.n_inv, fit.h)
    q = np.clip(1.0 - w * hnh, 1e-12, 1.0)
    wres = np.where(used, fit.v * np.sqrt(w) / np.sqrt(q), 0.0)
    t = np.sum(w * fit.v**2, axis=1)
    k = fit.b.shape[1]
    cw = rows.clock_weight()[:, :k] if rows.clock_prior_m is not None else np.zeros((used.shape[0], k))
    observed = cw > 0
    for kk in range(k):
        observed[:, kk] |= np.any(used & (rows.receiver == kk), axis=1)
    dof = used.sum(axis=1) + (cw > 0).sum(axis=1) - 1 - observed.sum(axis=1)
    if rows.clock_prior_m is not None:
        cv = np.nan_to_num(rows.clock_prior_m[:, :k]) - fit.b
        t = t + np.sum(cw * cv**2, axis=1)
    prior_w = np.zeros_like(t)
    if prior is not None:
        pw = np.where(prior_on, 1.0 / prior[1] ** 2, 0.0)
        pv = prior[0] - fit.s
        pq = np.clip(1.0 - pw * fit.n_inv[:, 0, 0], 1e-12, 1.0)
        t = t + pw * pv**2
        dof = dof + prior_on
        prior_w = np.where(prior_on, pv * np.sqrt(pw) / np.sqrt(pq), 0.0)
    return t, np.concatenate([wres, prior_w[:, None]], axis=1), dof.astype(np.int64), q


def _merge(fit: _Fit, part: _Fit, sel: IntArray) -> None:
    for name in ("s", "b", "h", "v", "n_inv", "converged"):
        getattr(fit, name)[sel] = getattr(part, name)


def _on_track(
    track: TrackLine, fit: _Fit, prior: tuple[FloatArray, FloatArray] | None, cfg: ConstrainedConfig
) -> BoolArray:
    ok = fit.converged & (fit.s >= 0.0) & (fit.s <= track.length_m)
    if prior is not None:
        sig = np.sqrt(prior[1] ** 2 + np.abs(fit.n_inv[:, 0, 0]))
        ok &= np.abs(fit.s - prior[0]) <= cfg.prior_window_sigmas * sig
    return ok


def _n_unknowns(rows: Rows, used: BoolArray, k: int) -> IntArray:
    """1 + the receivers with rows or a clock prediction."""
    cw = rows.clock_weight()
    n = np.ones(used.shape[0], dtype=np.int64)
    for kk in range(k):
        prior_k = cw[:, kk] > 0 if kk < cw.shape[1] else np.zeros(used.shape[0], dtype=bool)
        n += np.any(used & (rows.receiver == kk), axis=1) | prior_k
    return n


def _n_observations(rows: Rows, used: BoolArray) -> IntArray:
    """Satellite rows plus clock predictions."""
    return np.asarray(used.sum(axis=1) + (rows.clock_weight() > 0).sum(axis=1), dtype=np.int64)


def _reject_off_track(
    track: TrackLine,
    rows: Rows,
    ant: FloatArray,
    used: BoolArray,
    fit: _Fit,
    prior: tuple[FloatArray, FloatArray] | None,
    cfg: ConstrainedConfig,
) -> BoolArray:
    """Leave-one-out search for epochs without an on-track solution (module docstring)."""
    k = int(ant.shape[0])
    no_track = np.zeros_like(used)
    bad = np.flatnonzero(
        ~_on_track(track, fit, prior, cfg) & (_n_observations(rows, used) > _n_unknowns(rows, used, k))
    )
    if bad.size == 0:
        return no_track
    best_score = np.full(bad.size, np.inf)
    best_slot = np.full(bad.size, -1)
    best_fit: _Fit | None = None
    thr = chi2_thresholds(cfg.p_false_alarm)
    for j in range(used.shape[1]):
        cand = bad[used[bad, j]]
        if cand.size == 0:
            continue
        u = used[cand].copy()
        u[:, j] = False
        part = gauss_newton(
            track,
            rows.take(cand),
            ant,
            u,
            fit.s[cand],
            None if prior is None else (prior[0][cand], prior[1][cand]),
            cfg,
        )
        t, _, dof, _ = _statistics(part, rows.take(cand), u, None, np.zeros(cand.size, dtype=bool))
        ok = _on_track(track, part, None if prior is None else (prior[0][cand], prior[1][cand]), cfg)
        score = np.where(ok, np.where(dof >= 1, t / thr[np.clip(dof, 1, thr.size - 1)], 0.0), np.inf)
        pos = np.searchsorted(bad, cand)
        better = score < best_score[pos]
        best_score[pos[better]] = score[better]
        best_slot[pos[better]] = j
        if best_fit is None:
            best_fit = _Fit(
                fit.s.copy(), fit.b.copy(), fit.h.copy(), fit.v.copy(), fit.n_inv.copy(), fit.converged.copy()
            )
        _merge(
            best_fit,
            _Fit(*(getattr(part, n)[better] for n in ("s", "b", "h", "v", "n_inv", "converged"))),
            cand[better],
        )
    hit = best_slot >= 0
    if best_fit is not None and hit.any():
        e_hit = bad[hit]
        no_track[e_hit, best_slot[hit]] = True
        used[e_hit, best_slot[hit]] = False
        _merge(fit, _Fit(*(getattr(best_fit, n)[e_hit] for n in ("s", "b", "h", "v", "n_inv", "converged"))), e_hit)
    return no_track


def _exclude_faults(
    track: TrackLine,
    rows: Rows,
    ant: FloatArray,
    used: BoolArray,
    fit: _Fit,
    prior: tuple[FloatArray, FloatArray] | None,
    prior_on: BoolArray,
    cfg: ConstrainedConfig,
) -> tuple[BoolArray, BoolArray]:
    """Exclusion loop (module docstring); returns (excluded rows, epochs still failing)."""
    thr = chi2_thresholds(cfg.p_false_alarm)
    excluded = np.zeros_like(used)
    n_s = used.shape[1]
    fail = np.zeros(used.shape[0], dtype=bool)
    for _ in range(cfg.max_exclusions + 1):
        t, wres, dof, _ = _statistics(fit, rows, used, prior, prior_on)
        fail = (dof >= 1) & ((t > thr[np.clip(dof, 0, thr.size - 1)]) | (np.max(np.abs(wres), axis=1) > cfg.k_w))
        sel = np.flatnonzero(fail & (dof >= 2))
        if sel.size == 0:
            break
        worst = np.argmax(np.abs(wres[sel, :n_s]), axis=1)  # satellites only: the prior is the reference
        used[sel, worst] = False
        excluded[sel, worst] = True
        pr = None if prior is None else (prior[0][sel], prior[1][sel])
        _merge(fit, gauss_newton(track, rows.take(sel), ant, used[sel], fit.s[sel], pr, cfg), sel)
    return excluded, fail


def _uncertainty(
    fit: _Fit, rows: Rows, used: BoolArray, dof_det: IntArray, q_det: FloatArray, cfg: ConstrainedConfig
) -> tuple[FloatArray, FloatArray, FloatArray]:
    """σ_s, ADOP and the protection level PL of the satellites-only estimate ``fit`` against
    one fault missed by the detector whose redundancy numbers are ``q_det`` (module docstring)."""
    w = np.where(used, 1.0 / np.where(used, rows.sigma_m, 1.0) ** 2, 0.0)
    sigma_s = np.sqrt(np.abs(fit.n_inv[:, 0, 0]))
    hh = np.einsum("esi,es,esj->eij", fit.h, used.astype(float), fit.h)
    idx = np.arange(1, hh.shape[1])
    # a clock prediction counts as one more row, weighted relative to the rms satellite σ
    cw = rows.clock_weight()[:, : idx.size] if rows.clock_prior_m is not None else np.zeros((used.shape[0], idx.size))
    sig2 = np.sum(np.where(used, rows.sigma_m**2, 0.0), axis=1) / np.maximum(used.sum(axis=1), 1)
    hh[:, idx, idx] += cw * sig2[:, None]
    empty = (np.einsum("esi,es->ei", fit.h[..., 1:] ** 2, used.astype(float)) <= 0) & (cw <= 0)
    hh[:, idx, idx] += empty
    adop = np.sqrt(np.abs(inv_safe(hh)[:, 0, 0]))
    adop = np.where(np.isfinite(adop), adop, np.inf)
    k_s = np.einsum("ei,esi,es->es", fit.n_inv[:, 0, :], fit.h, w)
    slope = np.where(used, np.abs(k_s) * np.where(used, rows.sigma_m, 0.0) / np.sqrt(q_det), 0.0)
    pl = np.where(dof_det >= 1, slope.max(axis=1, initial=0.0) * (cfg.k_w + cfg.k_missed_detection), np.nan)
    return sigma_s, adop, pl


def solve_constrained(
    track: TrackLine,
    rows: Rows,
    antennas: list[Antenna],
    cfg: ConstrainedConfig | None = None,
    *,
    s_init: FloatArray | None = None,
    prior: tuple[FloatArray, FloatArray] | None = None,
) -> ConstrainedSolution:
    """Track-constrained solution of every epoch of ``rows`` (module docstring)."""
    cfg = cfg or ConstrainedConfig()
    ant = np.array([[a.along_m, a.lateral_m, a.height_m] for a in antennas], dtype=float)
    k = len(antennas)
    e = rows.pr_m.shape[0]
    used = rows.usable & np.isfinite(rows.pr_m) & np.isfinite(rows.sigma_m) & np.all(np.isfinite(rows.sat_pos), axis=-1)
    if s_init is not None:
        s0 = np.asarray(s_init, dtype=float).copy()
        miss = np.flatnonzero(~np.isfinite(s0))
        if miss.size:  # no start given: the coarse search for those epochs
            s0[miss] = coarse_start(track, rows.take(miss), ant, used[miss], cfg.coarse_step_m)
    elif prior is not None:
        s0 = np.asarray(prior[0], dtype=float)
    else:
        s0 = coarse_start(track, rows, ant, used, cfg.coarse_step_m)
    prior_on = np.ones(e, dtype=bool) if prior is not None else np.zeros(e, dtype=bool)
    fit = gauss_newton(track, rows, ant, used, s0, prior, cfg)
    no_track = _reject_off_track(track, rows, ant, used, fit, prior, cfg)
    excluded, fail = _exclude_faults(track, rows, ant, used, fit, prior, prior_on, cfg)
    _, _, dof_det, q_det = _statistics(fit, rows, used, prior, prior_on)
    if prior is not None:
        fit = gauss_newton(track, rows, ant, used, fit.s, None, cfg)
    t, _, dof, _ = _statistics(fit, rows, used, None, np.zeros(e, dtype=bool))
    sigma_s, adop, pl = _uncertainty(fit, rows, used, dof_det, q_det, cfg)
    n_used = used.sum(axis=1)
    status = np.full(e, STATUS_OK, dtype=np.int64)
    status[adop > cfg.max_adop] = STATUS_GEOMETRY
    status[fail] = STATUS_FAULT
    status[~_on_track(track, fit, prior, cfg)] = STATUS_OFF_TRACK
    status[~fit.converged] = STATUS_NOT_CONVERGED
    status[_n_observations(rows, used) < _n_unknowns(rows, used, k)] = STATUS_TOO_FEW
    for kk in range(k):
        status[(~np.any(used & (rows.receiver == kk), axis=1)) & (k > 1) & (status == STATUS_OK)] = STATUS_TOO_FEW
    return ConstrainedSolution(
        s=fit.s,
        clock_m=fit.b,
        sigma_clock_m=np.sqrt(np.abs(np.diagonal(fit.n_inv, axis1=1, axis2=2)[:, 1:])),
        sigma_s=sigma_s,
        adop=adop,
        uncertainty_m=np.fmax(cfg.k_fault_free * sigma_s, pl),
        protection_m=pl,
        test=t,
        dof=dof,
        n_used=n_used.astype(np.int64),
        used=used,
        excluded=excluded,
        no_track=no_track,
        residual_m=np.where(used, fit.v, np.nan),
        mdb_m=np.where(
            used & (dof_det >= 1)[:, None], (cfg.k_w + cfg.k_missed_detection) * rows.sigma_m / np.sqrt(q_det), np.nan
        ),
        status=status,
    )
