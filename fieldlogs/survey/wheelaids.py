"""Wheel scales of one run from its radar and its GNSS, beside the balise intervals.

Both are the run's wheel scale λ = D_true / D (D the configured diameter, run.json
``wheel_diameter_m``), the quantity :mod:`fieldlogs.survey.balises` estimates from balise
intervals, each with its own standard error; :mod:`fieldlogs.survey.wheels` adds the error
the GNSS and balise scales share (the GIS grid's track length, against which both are
measured) and combines them.

**Radar** [S004]. The odometry's own wheel calibration (:mod:`fieldlogs.pipeline.odometry.
ground_products`, summary ``wheel_calibration``) is taken as it is: r = Σ v_g·Δt / Σ Δd_p
over the adhering stretches, se = its 95 % half-width / 1.96 (independent frames, the radar's
systematic speed error b, the stretches' end pulses). It does not contain a scale error of
the radar's mounting (height, depression): that is what the consistency check of
:mod:`fieldlogs.survey.wheels` exposes.

**GNSS.** Along-track positions of the vehicle's reference point on the segment's line/track
(:mod:`fieldlogs.survey.extract`): the track-constrained solutions of the run's raw GNSS
[S002] (:class:`~fieldlogs.pipeline.aids.gnss.GnssUnit`, the best receiver per epoch, 1σ
``sigma_m``; for the facing k = motion·cab) when the run has them, else the trusted D-GPS
fixes matched to that track [S001 §4.2] (equal weights). Their km becomes the track's own
length c (:mod:`fieldlogs.pipeline.metric`) and y = σ·c (σ the segment's motion). Points are
split into *stretches*: one segment, no growth of the odometry's correction allowance between
consecutive points (a slip or slide correction starts a new stretch, so its distance error
never enters). Per stretch s and point i

    y_i = a_s + λ·d_i + e_i,

d the corrected odometry travel, a_s the stretch's offset (the odometry's distance error so far).
GNSS errors are correlated over minutes (multipath, atmosphere, a D-GPS correction's age), so
e is modelled as a Gauss–Markov process of correlation time τ = ``gnss_error_tau_s``
scaled by the point's σ_i, running on across a stretch's end (only the odometry's offset
changes there) and restarted at a segment's start. The generalised least-squares estimate
whitens each segment (z_i = (u_i − ρ_i·u_{i−1}) / √(1 − ρ_i²), u = ·/σ_i, ρ_i =
exp(−Δt_i/τ); z_0 = u_0) — the offsets' columns then reach one point into the next stretch,
so their normal equations are tridiagonal — eliminates the offsets through them and
regresses the whitened y on the whitened travel: λ̂ = (d̃ᵀỹ − cᵀA⁻¹c_y)/(d̃ᵀd̃ − cᵀA⁻¹c),
se² = s²/(d̃ᵀd̃ − cᵀA⁻¹c), s² the whitened residuals' variance (n − stretches − 1 degrees of
freedom) — the dense GLS with the full covariance, without forming it.

**Interval.** s²/sxx is λ̂'s variance only if the error is that Gauss–Markov process; the
real one is a sum (multipath of seconds, satellite orbit/clock and ionosphere of tens of
minutes, geometry changes), whose mix differs from run to run. λ̂ = hᵀy is linear in the
points (h = Wᵀg/sxx, g the whitened travel with the offsets projected out, W the whitening),
so Var(λ̂) = hᵀCh for the true covariance C, estimated from the fit's plain residuals u
(Newey–West): Σ_ℓ k_ℓ·γ̂(ℓ)·S(ℓ) over lags ℓ on the points' time grid within a segment,
γ̂(ℓ) the residuals' autocovariance, S(ℓ) = Σ hᵢhᵢ₊ℓ, Bartlett weights over a bandwidth of
``HAC_BANDWIDTH_TAUS``·τ (:func:`hac_variance`). The standard error is the larger of the two
(the residuals of one run see little of an error slower than the run: the model's stays the
floor).
Points whose whitened residual (a jump's edges) or plain residual y − â_s − λ̂·d (its
plateau) lies beyond ``gnss_outlier_z`` robust σ (1.4826·MAD) of its kind are dropped and
the fit repeated (a multipath jump the trust filter let through). Estimated only with at least
``wheel_min_distance_m`` of travel in stretches of three or more points. How the model was
checked (coverage of the interval, the dense GLS) is in ``bench/NOTES.md`` ("Wheels").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from dbtools.network import Network
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.pipeline.odometry.ground_products import Z95
from fieldlogs.pipeline.run import PipelineResult
from fieldlogs.pipeline.types import Odometry
from fieldlogs.survey.config import SurveyConfig

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
#: Sources of a GNSS wheel scale.
GNSS, DGPS = "gnss", "dgps"
#: Rounds of outlier rejection of the GNSS fit.
MAX_ROUNDS = 5
#: Fewest points a stretch needs to be used.
MIN_STRETCH_POINTS = 3
#: Bandwidth of the residuals' autocovariance in the sandwich variance, in τ (there the
#: model's correlation has fallen to e⁻³ = 5 %).
HAC_BANDWIDTH_TAUS = 3.0


@dataclass(frozen=True)
class AidScale:
    """One source's wheel scale of a run."""

    source: str
    """``radar`` / ``radar_if`` (the ground-speed stream), ``gnss`` or ``dgps``."""
    scale: float
    """λ = D_true / D_configured [–]."""
    se: float
    """Standard error of λ [–]."""
    distance_m: float
    """Travel the estimate rests on [m]."""
    points: int = 0
    """GNSS points used (0 for the radar)."""


@dataclass(frozen=True)
class SegmentSpan:
    """What the GNSS scale needs of a segment (:mod:`fieldlogs.survey.extract`)."""

    t0: float
    t1: float
    line_code: str
    track: str
    motion: int
    cab: int


@dataclass(frozen=True)
class AlongTrack:
    """GNSS points of a run on its segments' tracks, sorted by (stretch, t)."""

    t: FloatArray
    d: FloatArray
    """Corrected odometry travel [m]."""
    y: FloatArray
    """σ·c: track length in the direction of motion [m]."""
    sigma: FloatArray
    """Relative 1σ of each point [m]."""
    segment: IntArray
    stretch: IntArray
    """Stretch id, unique over the run (a segment holds one or more)."""

    @property
    def n(self) -> int:
        return int(self.t.size)

    def subset(self, keep: npt.NDArray[np.bool_]) -> AlongTrack:
        return AlongTrack(
            self.t[keep], self.d[keep], self.y[keep], self.sigma[keep], self.segment[keep], self.stretch[keep]
        )


def radar_scale(odo: Odometry, cfg: SurveyConfig) -> AidScale | None:
    """The odometry's radar wheel calibration as a scale (module docstring), if it rests on
    ``wheel_min_distance_m`` of travel."""
    cal = odo.ground.calibration if odo.ground is not None else None
    if cal is None or not cal.distance_m >= cfg.wheel_min_distance_m or not np.isfinite(cal.half_width):
        return None
    assert odo.ground is not None
    return AidScale(odo.ground.source, float(cal.ratio), float(cal.half_width) / Z95, float(cal.distance_m))


def _raw_points(result: PipelineResult, g: SegmentSpan) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """(t, km, σ) of the track-constrained solutions in a segment, or None without them."""
    from fieldlogs.gnss.ontrack import TrackSolutions

    unit = result.gnss
    if unit is None or unit.inputs is None:
        return None
    sols = unit.solutions(g.line_code, g.track, 1 if g.motion * g.cab >= 0 else -1)
    if not isinstance(sols, TrackSolutions) or not len(sols.best):
        return None
    b = sols.best
    t = b["t"].to_numpy(dtype=float)
    sig = b["sigma_m"].to_numpy(dtype=float)
    inside = (t >= g.t0) & (t <= g.t1) & np.isfinite(sig) & (sig > 0)
    return t[inside], b["km_m"].to_numpy(dtype=float)[inside], sig[inside]


def _dgps_points(result: PipelineResult, g: SegmentSpan) -> tuple[FloatArray, FloatArray, FloatArray] | None:
    """(t, km, 1) of the trusted D-GPS fixes matched to the segment's track."""
    gps = result.gps
    if gps is None or not len(gps.fixes):
        return None
    f = gps.fixes
    t = f["t"].to_numpy(dtype=float)
    on = (f["line_code"] == g.line_code).to_numpy(bool, na_value=False)
    on &= (f["track"] == g.track).to_numpy(bool, na_value=False)
    on &= f["trusted"].to_numpy(bool, na_value=False) & (t >= g.t0) & (t <= g.t1)
    km = f["km_m"].to_numpy(dtype=float, na_value=np.nan)
    on &= np.isfinite(km)
    return t[on], km[on], np.ones(int(on.sum()))


def along_track(
    result: PipelineResult, network: Network, segs: Sequence[SegmentSpan], source: str
) -> AlongTrack | None:
    """The run's GNSS points of ``source`` (``gnss`` or ``dgps``) as stretches (module
    docstring), or None when the run has none."""
    pick = _raw_points if source == GNSS else _dgps_points
    tc = result.positions["t"].to_numpy(dtype=float)
    dc = np.asarray(result.odometry.d, dtype=float)
    ac = np.asarray(result.odometry.allowance, dtype=float)
    parts: list[tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]] = []
    for g in segs:
        if g.motion == 0:
            continue
        pts = pick(result, g)
        if pts is None or pts[0].size == 0:
            continue
        t, km, sig = pts
        order = np.argsort(t, kind="stable")
        t, km, sig = t[order], km[order], sig[order]
        c = track_metric(network, g.line_code, g.track).c_of_km(km)
        parts.append((t, np.interp(t, tc, dc), g.motion * np.asarray(c, dtype=float), sig, np.interp(t, tc, ac)))
    if not parts:
        return None
    ids, offset = [], 0
    for p in parts:
        st = _stretches(p[4]) + offset
        ids.append(st)
        offset = int(st.max()) + 1
    segment = np.concatenate([np.full(p[0].size, k, dtype=np.int64) for k, p in enumerate(parts)])
    t, d, y, sig = (np.concatenate([p[k] for p in parts]) for k in range(4))
    return AlongTrack(t, d, y, sig, segment, np.concatenate(ids).astype(np.int64))


def _stretches(allowance: FloatArray) -> IntArray:
    """Stretch ids within a segment: a new one wherever the allowance grew since the
    previous point."""
    grew = np.concatenate([[False], np.diff(allowance) > 1e-9])
    return np.cumsum(grew).astype(np.int64)


@dataclass(frozen=True)
class _Whitened:
    """The whitened design of :func:`gls_scale`: per point the offsets' coefficients — ``a``
    on its own stretch, ``b`` on the previous point's stretch ``prev`` (where that differs
    inside one segment, else 0) — and the whitened travel and y."""

    sid: IntArray
    prev: IntArray
    a: FloatArray
    b: FloatArray
    d: FloatArray
    y: FloatArray


def _whiten(p: AlongTrack, tau_s: float) -> _Whitened:
    """Whitening along each segment (module docstring): the error process runs on across
    a stretch's end, where only the offset changes."""
    sid = np.unique(p.stretch, return_inverse=True)[1].astype(np.int64)
    first = np.concatenate([[True], p.segment[1:] != p.segment[:-1]])
    dt = np.diff(p.t, prepend=p.t[:1])
    rho = np.where(first, 0.0, np.exp(-np.maximum(dt, 0.0) / tau_s))
    q = np.sqrt(1.0 - rho * rho)
    prev = np.concatenate([sid[:1], sid[:-1]])
    same = prev == sid
    inv = 1.0 / p.sigma
    inv_prev = np.concatenate([inv[:1], inv[:-1]])

    def w(v: FloatArray) -> FloatArray:
        u = v * inv
        return np.asarray((u - rho * np.concatenate([u[:1], u[:-1]])) / q, dtype=float)

    a = (inv - np.where(same, rho * inv_prev, 0.0)) / q
    b = np.where(same, 0.0, -rho * inv_prev / q)
    return _Whitened(sid, prev, a, b, w(p.d - p.d.mean()), w(p.y - p.y.mean()))


@dataclass(frozen=True)
class Fit:
    """The GLS fit of one run's GNSS points."""

    scale: float
    se: float
    residual: FloatArray
    """Whitened residual per point."""
    plain: FloatArray
    """y − â_s − λ̂·d per point."""
    se_hac: float = 0.0
    """Sandwich standard error of λ̂ from the plain residuals' own autocovariance
    (:func:`hac_variance`)."""


def _normal(w: _Whitened, n_s: int, v: FloatArray) -> FloatArray:
    """Xₒᵀ·v over the offsets' columns."""
    return np.asarray(np.bincount(w.sid, w.a * v, n_s) + np.bincount(w.prev, w.b * v, n_s), dtype=float)


def gls_scale(p: AlongTrack, tau_s: float) -> Fit | None:
    """λ̂ and its standard error by generalised least squares (module docstring), the
    offsets eliminated through their (tridiagonal) normal equations; None when fewer than
    two degrees of freedom are left."""
    w = _whiten(p, tau_s)
    n_s = int(w.sid.max()) + 1 if w.sid.size else 0
    dof = p.n - n_s - 1
    if dof < 2:
        return None
    big = np.zeros((n_s, n_s))
    np.add.at(big, (w.sid, w.sid), w.a * w.a)
    np.add.at(big, (w.prev, w.prev), w.b * w.b)
    np.add.at(big, (w.sid, w.prev), w.a * w.b)
    np.add.at(big, (w.prev, w.sid), w.a * w.b)
    cd, cy = _normal(w, n_s, w.d), _normal(w, n_s, w.y)
    try:
        sol = np.linalg.solve(big, np.column_stack([cd, cy]))
    except np.linalg.LinAlgError:
        return None
    sxx = float(w.d @ w.d - cd @ sol[:, 0])
    if not sxx > 0:
        return None
    lam = float(w.y @ w.d - cd @ sol[:, 1]) / sxx
    off = sol[:, 1] - lam * sol[:, 0]
    r = w.y - lam * w.d - w.a * off[w.sid] - w.b * off[w.prev]
    plain = (p.y - p.y.mean()) - lam * (p.d - p.d.mean()) - off[w.sid]
    h = estimator_weights(p, w, np.asarray(sol[:, 0], dtype=float), tau_s) / sxx
    hac = hac_variance(p.t, p.segment, h, plain, HAC_BANDWIDTH_TAUS * tau_s)
    return Fit(lam, float(np.sqrt(float(r @ r) / dof / sxx)), r, plain, float(np.sqrt(hac)))


def estimator_weights(p: AlongTrack, w: _Whitened, off_d: FloatArray, tau_s: float) -> FloatArray:
    """h·sxx with λ̂ = hᵀy: the whitened travel with the offsets projected out, g = d̃ − Xₒ·A⁻¹cd,
    mapped back through the whitening, h = Wᵀg/sxx: (Wᵀg)ᵢ = gᵢ/(qᵢσᵢ) − ρᵢ₊₁gᵢ₊₁/(qᵢ₊₁σᵢ)."""
    g = w.d - w.a * off_d[w.sid] - w.b * off_d[w.prev]
    first = np.concatenate([[True], p.segment[1:] != p.segment[:-1]])
    dt = np.diff(p.t, prepend=p.t[:1])
    rho = np.where(first, 0.0, np.exp(-np.maximum(dt, 0.0) / tau_s))
    gq = g / np.sqrt(1.0 - rho * rho)
    nxt = np.concatenate([rho[1:] * gq[1:], [0.0]])
    return np.asarray((gq - nxt) / p.sigma, dtype=float)


def hac_variance(t: FloatArray, segment: IntArray, h: FloatArray, u: FloatArray, bandwidth_s: float) -> float:
    """Var(hᵀe) with e's autocovariance estimated from the residuals u (module docstring,
    "Interval"): per segment on the points' time grid (step: the median spacing), γ̂(ℓ) =
    Σ uᵢuᵢ₊ℓ / #pairs at lag ℓ steps, S(ℓ) = Σ hᵢhᵢ₊ℓ, and Σ_ℓ k_ℓ·γ̂(ℓ)·S(ℓ) with the Bartlett
    weights k₀ = 1, k_ℓ = 2·(1 − ℓ/L) for 0 < ℓ < L = bandwidth / step (0 beyond); at least 0."""
    total = 0.0
    for k in np.unique(segment):
        m = segment == k
        tk = t[m]
        if tk.size < 2:
            total += float(np.sum(h[m] ** 2 * u[m] ** 2))
            continue
        step = float(np.median(np.diff(tk)))
        if not step > 0:
            step = 1.0
        idx = np.rint((tk - tk[0]) / step).astype(np.int64)
        n = int(idx[-1]) + 1
        hu = np.zeros((3, n))
        np.add.at(hu[0], idx, h[m])
        np.add.at(hu[1], idx, u[m])
        np.add.at(hu[2], idx, 1.0)
        lags = max(1, min(n, int(np.floor(bandwidth_s / step))))
        gam = np.correlate(hu[1], hu[1], "full")[n - 1 : n - 1 + lags]
        cnt = np.correlate(hu[2], hu[2], "full")[n - 1 : n - 1 + lags]
        sh = np.correlate(hu[0], hu[0], "full")[n - 1 : n - 1 + lags]
        kern = 2.0 * (1.0 - np.arange(lags) / lags)
        kern[0] = 1.0
        with np.errstate(invalid="ignore", divide="ignore"):
            total += float(np.sum(np.where(cnt > 0, kern * gam / np.maximum(cnt, 1.0) * sh, 0.0)))
    return max(total, 0.0)


def _usable(a: AlongTrack) -> tuple[AlongTrack, float]:
    """The points of stretches with at least MIN_STRETCH_POINTS points, and their travel."""
    _, inv, count = np.unique(a.stretch, return_inverse=True, return_counts=True)
    keep = count[inv] >= MIN_STRETCH_POINTS
    a = a.subset(keep)
    if a.n == 0:
        return a, 0.0
    inv = np.unique(a.stretch, return_inverse=True)[1]
    lo = np.full(int(inv.max()) + 1, np.inf)
    hi = np.full(int(inv.max()) + 1, -np.inf)
    np.minimum.at(lo, inv, a.d)
    np.maximum.at(hi, inv, a.d)
    return a, float(np.sum(hi - lo))


def _outlying(r: FloatArray, z: float) -> npt.NDArray[np.bool_]:
    """|r − median| beyond ``z`` robust σ (1.4826·MAD)."""
    dev = np.abs(r - np.median(r))
    return np.asarray(dev > z * max(1.4826 * float(np.median(dev)), 1e-12), dtype=bool)


def gnss_scale(a: AlongTrack | None, source: str, cfg: SurveyConfig) -> AidScale | None:
    """The GNSS wheel scale with outlier rejection (module docstring), if it rests on
    ``wheel_min_distance_m`` of travel."""
    if a is None:
        return None
    for k in range(MAX_ROUNDS):
        a, used = _usable(a)
        fit = gls_scale(a, cfg.gnss_error_tau_s) if used >= cfg.wheel_min_distance_m else None
        if fit is None:
            return None
        bad = _outlying(fit.residual, cfg.gnss_outlier_z) | _outlying(fit.plain, cfg.gnss_outlier_z)
        if not bad.any() or k == MAX_ROUNDS - 1:
            return AidScale(source, fit.scale, max(fit.se, fit.se_hac), used, a.n)
        a = a.subset(~bad)
    return None


def run_gnss_scale(
    result: PipelineResult, network: Network, segs: Sequence[SegmentSpan], cfg: SurveyConfig
) -> AidScale | None:
    """The run's GNSS wheel scale: from its track-constrained solutions when it has raw GNSS,
    else from its D-GPS fixes (module docstring)."""
    for source in (GNSS, DGPS):
        est = gnss_scale(along_track(result, network, segs, source), source, cfg)
        if est is not None:
            return est
    return None
