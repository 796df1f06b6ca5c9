"""Ground speed of each frame from its Doppler lines: eq. 1 and eq. 2 of [S004].

A ground reflection m seen at depression θ_m has range R_m = h/sin θ_m and closes at
V_m = V_G·cos θ_m, hence (eq. 1)

    (h/R_m)² + (V_m/V_G)² − 1 ≈ sin²θ_m + cos²θ_m − 1 = 0,

and the paper estimates V_G = argmin_V Σ_m {(h/R_m)² + (V_m/V)² − 1}² (eq. 2). With
s_m = (h/R_m)², u_m = V_m² and w = 1/V², the residual s_m + u_m·w − 1 is linear in w, so
eq. 2's minimiser over V > 0 is exactly the linear least-squares solution

    w = Σ u_m(1 − s_m) / Σ u_m²,   V_G = w^(−1/2)   (when w > 0)

— no search is needed (``v_eq2``, the paper's estimate as published). (Off the vertical
plane, at lateral offset y, eq. 1 reads … = −(y/R)²; within the ±3° azimuth beam that is
below 0.3 %, averaged ~0.05 % of V: kept as the paper's "≈".)

**Departures, and why.** The range of a line comes from a phase with noise variance
≈ 1/SNR_m, so σ_R ∝ 1/√SNR_m: eq. 2's unweighted algebraic residual lets weak lines
dominate (var(s_m) ∝ s_m³/SNR_m) and, because s = h²/R² is convex in R, noisy ranges bias
s_m upward. So (a) eq. 2 is solved with weights SNR_m/s_m³ (∝ 1/var s_m) for a start, then
(b) V_G is refined by Gauss–Newton on the same model eq. 1 with the residual taken in
range, where the noise is additive and symmetric: minimise Σ_m (R_m − h/√(1 − u_m·w))²/σ_m²,
σ_m = max(σ_floor, c/(4π·Δf)/√SNR_m), leaving out lines more than ``gate_sigmas``·σ_m
(× the frame's robust residual scale, 1.4826·median |r/σ|) from the prediction — a
symmetric gate that adds no bias — and only over lines whose Doppler puts them in the
beam core (cos θ_m = V_m/V_G within θ0 ± ε_c): further out the spectrum's finite
resolution smears the strong centre into the weak edge bins and pulls their ranges toward
the centre's (bench/NOTES.md). One bin spans the angle δθ = ΔV/(V_G·sin θ0), so the pull
grows as the speed falls; the core is ε_c = β_e·max(``core_min_beamwidths``,
``core_beamwidths``·min(1, V_G/``core_speed_mps``)), taken at each step's V_G.
The 1σ of V_G follows from the Gauss–Newton normal equation, var(w) = χ²_ν / Σ J_m²/σ_m²
with χ²_ν ≥ 1 the reduced chi-square (J = ∂R_pred/∂w), and σ_V = ½·V_G³·σ_w, times
``sigma_scale`` for the errors the lines of a frame share.

**Which lines.** Ground lines have a range inside the beam's footprint (axis ± ``gate_
beamwidths`` elevation half-widths); a line whose range is there only after a shift of
c/(4·Δf) is aliased (see ``spectrum``). The direction of motion is the SNR-weighted sign of
the ground lines' Doppler (+: approaching, the vehicle moves toward where the radar
looks), each line counted against the power at its mirror bin, since ground moving past
is one-sided in Doppler and vibration sidebands are not; lines of the other sign are not
ground moving past and are left out.
**Naive**: the strongest line alone, v = f_d·λ/(2·cos θ0) — what a single-frequency
Doppler speedometer reports; its bias from the beam spread is what eq. 2 removes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.spectrum import Lines
from schemas.radar import RadarParams

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class LineClass:
    """Per line: in the ground gate, aliased, used in the final fit."""

    ground: BoolArray
    alias: BoolArray
    used: BoolArray


@dataclass(frozen=True)
class FrameFit:
    """Per frame of a block (speeds unsigned except where said)."""

    n_lines: IntArray
    n_ground: IntArray
    n_alias: IntArray
    n_used: IntArray
    direction: IntArray
    """+1 approaching (moving toward where the radar looks), −1 receding, 0 none."""
    consistency: FloatArray
    """|Σ sign f_d·(snr − snr_mirror)| / Σ (snr + snr_mirror) over the ground lines
    (1: every line one-sided and of one sign; 0: symmetric about 0 Hz)."""
    max_vm: FloatArray
    """Largest |V_m| of the frame's ground lines [m/s] (0 when none)."""
    v_eq2: FloatArray
    """The paper's unweighted eq. 2 [m/s]."""
    v: FloatArray
    """Refined V_G [m/s] (NaN when the fit fails)."""
    sigma: FloatArray
    residual_m: FloatArray
    eq1_rms: FloatArray
    snr_db: FloatArray
    v_naive: FloatArray
    """Strongest line, signed by its Doppler (+ approaching) [m/s]."""
    classes: LineClass


def _sum(fi: IntArray, x: FloatArray | BoolArray, n: int) -> FloatArray:
    return np.bincount(fi, weights=np.asarray(x, dtype=np.float64), minlength=n).astype(np.float64)


def _ratio(num: FloatArray, den: FloatArray) -> FloatArray:
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def range_gate(params: RadarParams, beamwidths: float) -> tuple[float, float]:
    """Ranges [m] where the ground is seen at depressions θ0 ± beamwidths·β_e."""
    lo, hi = params.depression_range_rad(beamwidths)
    return params.height_m / math.sin(hi), params.height_m / math.sin(lo)


def classify(lines: Lines, params: RadarParams, cfg: RadarConfig) -> tuple[BoolArray, BoolArray]:
    """(ground, aliased) masks of the lines."""
    r0, r1 = range_gate(params, cfg.gate_beamwidths)
    r = lines.range_m
    ground = (r >= r0) & (r <= r1)
    shifted = np.mod(r + params.r_max_m / 2.0, params.r_max_m)
    return ground, ~ground & (shifted >= r0) & (shifted <= r1)


def eq2_closed_form(fi: IntArray, u: FloatArray, s: FloatArray, c: FloatArray, n: int) -> FloatArray:
    """w = Σ c·u(1 − s) / Σ c·u² per frame: eq. 2 (c = 1) or its weighted form; NaN if none."""
    return _ratio(_sum(fi, c * u * (1.0 - s), n), _sum(fi, c * u * u, n))


def _median_per_frame(fi: IntArray, x: FloatArray, n: int) -> FloatArray:
    out = np.full(n, np.nan)
    if len(fi) == 0:
        return out
    order = np.lexsort((x, fi))
    f, xs = fi[order], x[order]
    counts = np.bincount(f, minlength=n)
    start = np.concatenate(([0], np.cumsum(counts)[:-1]))
    has = counts > 0
    lo = start[has] + (counts[has] - 1) // 2
    hi = start[has] + counts[has] // 2
    out[has] = 0.5 * (xs[lo] + xs[hi])
    return out


def _max_per_frame(fi: IntArray, x: FloatArray, n: int) -> FloatArray:
    out = np.zeros(n)
    np.maximum.at(out, fi, x)
    return out


def _naive(lines: Lines, params: RadarParams, n: int) -> FloatArray:
    out = np.full(n, np.nan)
    if len(lines) == 0:
        return out
    order = np.lexsort((-lines.snr, lines.frame))
    first = order[np.concatenate(([True], np.diff(lines.frame[order]) != 0))]
    out[lines.frame[first]] = lines.v_m[first] / math.cos(math.radians(params.depression_deg))
    return out


@dataclass
class _Fit:
    """Working arrays of the refinement (one entry per candidate line)."""

    fi: IntArray
    u: FloatArray
    r: FloatArray
    sig: FloatArray
    cand: BoolArray
    h: float
    n: int
    core: tuple[float, float, float, float, float]
    """The beam core: θ0, β_e [rad], ``core_beamwidths``, ``core_min_beamwidths`` and
    ``core_speed_mps``."""

    def in_core(self, w: FloatArray, wl: FloatArray, ok: BoolArray) -> BoolArray:
        """Lines in the beam core, cos²θ = u·w within [cos² hi, cos² lo]: the core of the
        frame's speed, or the widest core in a frame with no line in the narrowed one."""
        c_hi, c_lo = self.core_bounds(w)
        x = self.u * wl
        narrow = (x >= c_hi[self.fi]) & (x <= c_lo[self.fi])
        c_hi, c_lo = self.core_bounds(w, wide=True)
        wide = (x >= c_hi[self.fi]) & (x <= c_lo[self.fi])
        empty = _sum(self.fi, ok & narrow, self.n) == 0
        out: BoolArray = np.where(empty[self.fi], wide, narrow)
        return out

    def core_bounds(self, w: FloatArray, wide: bool = False) -> tuple[FloatArray, FloatArray]:
        """cos² of the core's highest and lowest depression at V_G = w^(−1/2) per entry of w
        (``wide``: of the widest core, ``core_beamwidths``)."""
        theta0, beta, full, narrowest, v_full = self.core
        with np.errstate(invalid="ignore", divide="ignore"):
            v = np.where(w > 0, 1.0 / np.sqrt(np.where(w > 0, w, 1.0)), 0.0)
        if wide or v_full <= 0:
            k = np.full(w.shape, full)
        else:
            k = np.maximum(narrowest, full * np.minimum(1.0, v / v_full))
        lo = np.clip(theta0 - k * beta, math.radians(0.5), math.radians(89.5))
        hi = np.clip(theta0 + k * beta, math.radians(0.5), math.radians(89.5))
        return np.cos(hi) ** 2, np.cos(lo) ** 2

    def step(self, w: FloatArray, gate: FloatArray | None) -> tuple[FloatArray, BoolArray, FloatArray, FloatArray]:
        """One Gauss–Newton step in w per frame: (new w, kept lines, residuals, J)."""
        wl = w[self.fi]
        q = 1.0 - self.u * wl
        ok = self.cand & np.isfinite(q) & (q > 1e-6)
        if gate is not None:
            ok &= self.in_core(w, wl, ok)
        qs = np.where(ok, q, 1.0)
        res = self.r - self.h / np.sqrt(qs)
        jac = self.h * self.u / (2.0 * qs**1.5)
        keep = ok if gate is None else ok & (np.abs(res) <= gate[self.fi] * self.sig)
        c = np.where(keep, 1.0 / self.sig**2, 0.0)
        dw = _ratio(_sum(self.fi, c * jac * res, self.n), _sum(self.fi, c * jac * jac, self.n))
        return w + np.where(np.isfinite(dw), dw, np.nan), keep, res, jac

    def chi2(self, keep: BoolArray, res: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(reduced chi-square, lines kept) per frame."""
        c = np.where(keep, 1.0 / self.sig**2, 0.0)
        k = _sum(self.fi, keep, self.n)
        return _ratio(_sum(self.fi, c * res * res, self.n), np.maximum(k - 1.0, 0.0)), k


def _direction(fi: IntArray, ground: BoolArray, lines: Lines, n: int) -> tuple[IntArray, FloatArray]:
    """Sign and consistency Σ sign(f_d)·(snr − snr_mirror) / Σ (snr + snr_mirror) of the
    ground lines: 1 when every line is one-sided, 0 for sidebands on both sides of 0 Hz."""
    sgn = np.sign(lines.fd_hz)
    wsum = _sum(fi, np.where(ground, lines.snr + lines.snr_mirror, 0.0), n)
    dsum = _sum(fi, np.where(ground, (lines.snr - lines.snr_mirror) * sgn, 0.0), n)
    consistency = np.abs(_ratio(dsum, wsum))
    return np.sign(dsum).astype(np.int64), consistency


def _gate(fit: _Fit, keep: BoolArray, res: FloatArray, cfg: RadarConfig) -> FloatArray:
    """Per frame ``gate_sigmas`` × max(1, 1.4826·median |r/σ|): a robust scale, so that one
    far outlier cannot widen the gate that should leave it out."""
    scale = 1.4826 * _median_per_frame(fit.fi[keep], np.abs(res[keep] / fit.sig[keep]), fit.n)
    return np.asarray(cfg.gate_sigmas * np.maximum(np.nan_to_num(scale, nan=1.0), 1.0))


def _refine(fit: _Fit, w0: FloatArray, cfg: RadarConfig) -> tuple[FloatArray, BoolArray, FloatArray, FloatArray]:
    """Gauss–Newton in range space from w0; the first step ungated, then gated (``_gate``,
    its scale taken after the first two steps and then held: the outliers are gone by then)."""
    w, keep, res, jac = fit.step(w0, None)
    gate = _gate(fit, keep, res, cfg)
    for i in range(max(cfg.iterations - 1, 0)):
        w, keep, res, jac = fit.step(w, gate)
        if i == 0:
            gate = _gate(fit, keep, res, cfg)
    # residuals and kept lines at the final w
    _w_next, keep, res, jac = fit.step(w, gate)
    return w, keep, res, jac


def fit_frames(lines: Lines, n_frames: int, params: RadarParams, cfg: RadarConfig) -> FrameFit:
    """Every frame's ground speed from its lines (see the module docstring)."""
    n, fi = n_frames, lines.frame
    ground, alias = classify(lines, params, cfg)
    direction, consistency = _direction(fi, ground, lines, n)
    cand = ground & (np.sign(lines.fd_hz).astype(np.int64) == direction[fi])
    h = params.height_m
    u = lines.v_m**2
    s = (h / np.maximum(lines.range_m, 1e-9)) ** 2
    w_eq2 = eq2_closed_form(fi, u, s, cand.astype(np.float64), n)
    c0 = np.where(cand, lines.snr / np.maximum(s, 1e-12) ** 3, 0.0)
    w0 = eq2_closed_form(fi, u, s, c0, n)
    w0 = np.where(w0 > 0, w0, np.nan)
    sig = np.maximum(cfg.range_floor_m, params.r_max_m / (2 * np.pi) / np.sqrt(np.maximum(lines.snr, 1e-12)))
    core = (
        math.radians(params.depression_deg),
        math.radians(params.beam_elev_deg),
        cfg.core_beamwidths,
        min(cfg.core_min_beamwidths, cfg.core_beamwidths),
        cfg.core_speed_mps,
    )
    fit = _Fit(fi, u, lines.range_m, sig, cand, h, n, core)
    w, keep, res, jac = _refine(fit, w0, cfg)
    chi2, k = fit.chi2(keep, res)
    c = np.where(keep, 1.0 / sig**2, 0.0)
    var_w = _ratio(np.maximum(np.nan_to_num(chi2, nan=1.0), 1.0), _sum(fi, c * jac * jac, n))
    with np.errstate(invalid="ignore", divide="ignore"):
        v = np.where((w > 0) & (k >= 1), 1.0 / np.sqrt(w), np.nan)
        sigma = cfg.sigma_scale * 0.5 * v**3 * np.sqrt(var_w)
        e1 = np.where(keep, s + u * w[fi] - 1.0, 0.0)
        eq1_rms = np.sqrt(_ratio(_sum(fi, e1 * e1, n), k))
        residual = np.sqrt(_ratio(_sum(fi, c * res * res, n), _sum(fi, c, n)))
        snr_db = _median_per_frame(fi[keep], 10.0 * np.log10(lines.snr[keep]), n)
        v_eq2 = np.where(w_eq2 > 0, 1.0 / np.sqrt(w_eq2), np.nan)
    return FrameFit(
        n_lines=np.bincount(fi, minlength=n).astype(np.int64),
        n_ground=_sum(fi, ground, n).astype(np.int64),
        n_alias=_sum(fi, alias, n).astype(np.int64),
        n_used=k.astype(np.int64),
        direction=direction,
        consistency=consistency,
        max_vm=_max_per_frame(fi[ground], np.abs(lines.v_m[ground]), n),
        v_eq2=v_eq2,
        v=v,
        sigma=sigma,
        residual_m=residual,
        eq1_rms=eq1_rms,
        snr_db=snr_db,
        v_naive=_naive(lines, params, n),
        classes=LineClass(ground, alias, keep),
    )
