"""A correction's speed from the inertial solution and a ground speed (the radar [S004]).

Not in S000, which bridges a slip with the inertial solution alone (eq. 2) and whose error
therefore grows as eq. 13, ½·Δa·t², until the fail-safe at ``max_correction_s``. With a
ground speed, the inertial solution of :mod:`.integration` and the radar are fused over the
correction, by their variances, where both exist; the inertial increments bridge the
radar's gaps.

Filter (scalar Kalman filter on the aligned cycles i0 … i_far)

    predict   v⁻_m = v_{m−1} + Δv_m,        P⁻_m = P_{m−1} + (Δa·h_m)²
    update    ν_m = z_m − v⁻_m,  S_m = P⁻_m + n_c·σ_m²,  K_m = P⁻_m / S_m
              v_m = v⁻_m + K_m·ν_m,  P_m = (1 − K_m)·P⁻_m

Δv_m are the inertial increments (eq. 2's A_x = a_x − G·sinθ integrated, trapezoid), Δa
eq. 13's acceleration error budget taken as the process noise per cycle h_m, z_m ± σ_m the
ground speed (n_c·σ² because n_c cycles share one radar frame and its error). It starts
from the adhering pulses' v0 ± (tol0 + WEAR_SHARE·v0). Speeds are clipped at 0.

Cross-check of the inertial bridging
    An innovation |ν| > GATE_Z·√S is refused — a radar frame far from a consistent
    inertial solution, or an inertial solution that has left the radar. Refusals lasting
    longer than one frame (n_c + 1 cycles) mean the inertial solution is off (a start point
    inside the slip, a wrong θ0): the filter re-seats on the radar (v = z, P = n_c·σ²).
    ``Fusion.refused`` and ``reseated`` count them; ``Fusion.inertial_dev_mps`` is the
    largest |1 s mean of (inertial − ground speed)| over the correction, how far the inertial
    solution alone would have been.

Smoother (Rauch–Tung–Striebel) over the correction i0 … ie

    v^s_m = v_m + C_m·(v^s_{m+1} − v⁻_{m+1}),   C_m = P_m / P⁻_{m+1}

The correction is retroactive anyway (it is applied from the start point once the episode
is known), so each cycle's speed also uses the ground speed after it.

Error budget of the corrected distance (replaces eq. 13's ½·Δa·T²)

    B(m) = z_B·(√(Σ_{covered} n_c·σ_j²·h_j²) + b·T_covered) + RADAR_SCALE_SHARE·Σ_{covered} v_j·h_j
           + Σ_{uncovered} (Δa·ḡ_j + z_B·σ_last)·h_j + 2·q (once covered)

the frames' errors being independent (z_B = BUDGET_Z) beside a systematic error of 1σ
b = ``GROUND_BIAS_MPS`` and the radar's scale (its mounting height and depression: not
estimated here); a gap bounded by eq. 13 from its start (ḡ_j the time since the last
ground value at mid-cycle, so a gap of g adds exactly ½·Δa·g²) plus the fused speed's error
σ_last where the gap began (0 for a gap from i0, where the pulses gave the speed: a
correction without any ground value has exactly eq. 13's budget); and one pulse q at
either end. A correction fails safe when B reaches
eq. 13's budget at ``max_correction_s`` (22.8 m; without a ground speed that is the SPEC's
time limit) or at ``ground_max_correction_s``.

Re-adhesion and the fail-safe watch (:func:`agreement`) compare the 1 s mean pulse speed
with the radar's own 1 s mean where its window is whole (the ground-speed criterion's
quantity, stage 2) within ``ground.tolerance`` with z = AGREE_Z (< the criterion's
``ground_detect_z``: a hysteresis) and its σ; in the radar's gaps with the filtered speed's
1 s mean (forward: what is known at the cycle), which coasts on the inertial increments
from the last radar mean, so the tolerance grows from there by β·t and the error bound by
Δa·t as in the S000 path — a correction without any radar value is tested as there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.ground import GROUND_BIAS_MPS, WEAR_SHARE, GroundSpeed, tolerance
from fieldlogs.pipeline.odometry.integration import Integration
from fieldlogs.pipeline.odometry.signals import BoolArray, ma, readonly
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.types import FloatArray

#: Innovations beyond this many σ of S are refused (the cross-check) [–].
GATE_Z = 6.0
#: z of the error budget: two-sided 99.9 % of a normal distribution [–].
BUDGET_Z = 3.3
#: z of the re-adhesion and watch tolerance on the filtered speed's σ [–].
AGREE_Z = 3.0
#: The radar's scale error (height, depression of the mounting) in the budget [–].
RADAR_SCALE_SHARE = 0.002


@dataclass(frozen=True, eq=False)
class Fusion:
    """The filtered speed of one correction on the aligned cycles i0 … i0 + L − 1 (read-only)."""

    i0: int
    v: FloatArray
    """Filtered speed v_m (forward) [m/s]."""
    p: FloatArray
    """Its variance P_m [m²/s²]."""
    v_prior: FloatArray
    """Predicted v⁻_m [m/s]."""
    p_prior: FloatArray
    used: BoolArray
    """A ground value was used at the cycle (update or re-seat)."""
    refused: int
    reseated: int
    inertial_dev: FloatArray
    """1 s mean of (inertial − ground speed) where both exist (NaN elsewhere) [m/s]."""
    ground_v1: FloatArray
    """The ground speed's own 1 s mean over the span (``GroundSpeed.v1``) [m/s]."""
    ground_sigma1: FloatArray

    @property
    def size(self) -> int:
        return int(self.v.size)

    def inertial_dev_mps(self, m_end: int) -> float:
        """Largest |1 s mean of (inertial − ground speed)| over the first ``m_end`` cycles:
        how far the inertial solution alone was from the radar (0: never both) [m/s]."""
        dev = np.abs(self.inertial_dev[:m_end])
        return float(np.nanmax(dev)) if np.isfinite(dev).any() else 0.0


def _update(x: float, p: float, z: float, r: float, gate2: float) -> tuple[float, float, bool]:
    """One measurement update; (x, p, accepted)."""
    nu = z - x
    sm = p + r
    if nu * nu > gate2 * sm:
        return x, p, False
    k = p / sm
    return x + k * nu, p - k * p, True


@dataclass(frozen=True, eq=False)
class Filtered:
    """What :func:`kalman_speed` returns, as lists (one per cycle)."""

    v: list[float]
    p: list[float]
    v_prior: list[float]
    p_prior: list[float]
    used: list[bool]
    refused: int
    reseated: int


def kalman_speed(
    v0: float, p0: float, dv: FloatArray, q: FloatArray, z: FloatArray, r: FloatArray, max_run: int
) -> Filtered:
    """The scalar Kalman recursion of the module docstring (NaN z: no ground value; more
    than ``max_run`` refusals in a row re-seat on the ground value). Sequential by nature;
    it runs over one correction's cycles only."""
    x, p = v0, p0
    out = Filtered([], [], [], [], [], 0, 0)
    run = refused = reseated = 0
    gate2 = GATE_Z * GATE_Z
    for dvm, qm, zm, rm in zip(dv.tolist(), q.tolist(), z.tolist(), r.tolist(), strict=True):
        x, p = x + dvm, p + qm
        out.v_prior.append(x)
        out.p_prior.append(p)
        ok = zm == zm  # a ground value
        if ok:
            x, p, ok = _update(x, p, zm, rm, gate2)
            run = 0 if ok else run + 1
            refused += 0 if ok else 1
            if run > max_run:  # the inertial solution has left the radar: re-seat on it
                x, p, ok, run = zm, rm, True, 0
                reseated += 1
        x = max(x, 0.0)
        out.v.append(x)
        out.p.append(p)
        out.used.append(ok)
    return Filtered(out.v, out.p, out.v_prior, out.p_prior, out.used, refused, reseated)


def rts(v: FloatArray, p: FloatArray, v_prior: FloatArray, p_prior: FloatArray, m_end: int) -> FloatArray:
    """The Rauch–Tung–Striebel smoothed speed on the first ``m_end`` cycles (backward)."""
    xf, pf, xp, pp = v.tolist(), p.tolist(), v_prior.tolist(), p_prior.tolist()
    xs = xf[:m_end]
    for m in range(m_end - 2, -1, -1):
        c = pf[m] / pp[m + 1] if pp[m + 1] > 0 else 0.0
        xs[m] = max(xf[m] + c * (xs[m + 1] - xp[m + 1]), 0.0)
    return np.array(xs, dtype=float)


def fuse(s: AlignedStreams, g: GroundSpeed, cfg: OdometryConfig, ig: Integration) -> Fusion:
    """The forward filter over the integration's cycles i0 … i_far."""
    i0 = ig.i0
    span = slice(i0, i0 + ig.v_in.size)
    h = s.dt[span].copy()
    h[0] = 0.0
    dv = np.diff(ig.v_in, prepend=ig.v_in[0])
    q = (cfg.delta_a_mps2 * h) ** 2
    z = g.v[span]
    r = g.n_corr * g.sigma[span] ** 2
    v0 = ig.start.v0
    sd0 = float(tolerance(cfg, np.array([v0]), np.zeros(1), 0.0)[0])
    k = kalman_speed(v0, sd0 * sd0, dv, q, z, r, int(np.ceil(g.n_corr)) + 1)
    return Fusion(
        i0=i0,
        v=readonly(np.array(k.v, dtype=float)),
        p=readonly(np.array(k.p, dtype=float)),
        v_prior=readonly(np.array(k.v_prior, dtype=float)),
        p_prior=readonly(np.array(k.p_prior, dtype=float)),
        used=readonly(np.array(k.used, dtype=bool)),
        refused=k.refused,
        reseated=k.reseated,
        inertial_dev=readonly(ma(ig.v_in - z, s.filters.P)),
        ground_v1=g.v1[span],
        ground_sigma1=g.sigma1[span],
    )


def smooth(f: Fusion, m_end: int) -> FloatArray:
    """The smoothed speed of a correction on its first ``m_end`` cycles."""
    return rts(f.v, f.p, f.v_prior, f.p_prior, m_end)


def budget_path(s: AlignedStreams, g: GroundSpeed, cfg: OdometryConfig, f: Fusion, pulse_m: float) -> FloatArray:
    """B(m): the error budget of the corrected distance from i0 to each cycle [m]."""
    span = slice(f.i0, f.i0 + f.size)
    h = s.dt[span].copy()
    h[0] = 0.0
    t = s.t[span] - s.t[f.i0]
    used = f.used
    var = np.where(used, g.n_corr * np.nan_to_num(g.sigma[span]) ** 2 * h * h, 0.0)
    t_cov = np.cumsum(np.where(used, h, 0.0))
    sd_last, gap = _since_last(t, used, np.sqrt(f.p))
    mid_gap = np.maximum(gap - 0.5 * h, 0.0)  # mid-cycle: a gap of g adds exactly ½·Δa·g²
    gap_inc = np.where(used, 0.0, (cfg.delta_a_mps2 * mid_gap + BUDGET_Z * sd_last) * h)
    scale = RADAR_SCALE_SHARE * np.cumsum(np.where(used, f.v * h, 0.0))
    own = BUDGET_Z * (np.sqrt(np.cumsum(var)) + GROUND_BIAS_MPS * t_cov)
    anchors = np.where(t_cov > 0, 2.0 * pulse_m, 0.0)
    out: FloatArray = own + np.cumsum(gap_inc) + scale + anchors
    return out


def _since_last(t: FloatArray, has: BoolArray, sd: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per cycle: ``sd`` at the last cycle ≤ it where ``has`` (0 before any) and the time
    since that cycle (since the first cycle before any)."""
    idx = np.arange(t.size)
    last = np.maximum.accumulate(np.where(has, idx, -1))
    j = np.maximum(last, 0)
    sd_last = np.where(last >= 0, sd[j], 0.0)
    gap = t - np.where(last >= 0, t[j], t[0] if t.size else 0.0)
    return sd_last, gap


@dataclass(frozen=True, eq=False)
class Agreement:
    """What the pulses are compared with over a correction's cycles (re-adhesion, watch)."""

    v1: FloatArray
    """The radar's own 1 s mean where its window is whole, else the filtered speed's [m/s]."""
    tol: FloatArray
    """Allowed |v̄_p − v1| [m/s]."""
    own: FloatArray
    """The error bound of v1 [m/s]."""
    agree: BoolArray
    """|v̄_p − v1| ≤ tol."""


def agreement(s: AlignedStreams, cfg: OdometryConfig, f: Fusion, lead: FloatArray) -> Agreement:
    """The re-adhesion test on the radar over i0 … (``lead``: the adhering pulse speeds
    before i0): against the radar's own 1 s mean within ``tolerance`` (z = AGREE_Z, its σ);
    where it has none, against the filtered speed's 1 s mean, which coasts on the inertial
    increments from the last radar mean — there the tolerance and the error bound grow as
    in the S000 path from it, by β·t and Δa·t (t since that mean, or since i0)."""
    p = s.filters.P
    fused = ma(np.concatenate([lead, f.v]), p)[lead.size :]
    has = np.isfinite(f.ground_v1)
    t = s.t[f.i0 : f.i0 + f.size]
    sd_anchor, gap = _since_last(t, has, np.nan_to_num(f.ground_sigma1))
    sd1 = np.where(has, f.ground_sigma1, sd_anchor)
    v1 = np.where(has, f.ground_v1, fused)
    vp1 = s.vp1[f.i0 : f.i0 + f.size]
    coast = np.where(has, 0.0, gap)
    tol = tolerance(cfg, vp1, sd1, AGREE_Z) + cfg.beta_mps2 * coast
    own = AGREE_Z * sd1 + cfg.delta_a_mps2 * coast
    with np.errstate(invalid="ignore"):
        agree = np.abs(v1 - vp1) <= tol
    return Agreement(readonly(v1), readonly(tol), readonly(own), readonly(agree))


def ground_share(f: Fusion, m_end: int) -> float:
    """Share of the correction's cycles with a ground value used."""
    return float(f.used[:m_end].mean()) if m_end > 0 else 0.0


__all__ = [
    "AGREE_Z",
    "BUDGET_Z",
    "GATE_Z",
    "RADAR_SCALE_SHARE",
    "WEAR_SHARE",
    "Agreement",
    "Filtered",
    "Fusion",
    "agreement",
    "budget_path",
    "fuse",
    "ground_share",
    "kalman_speed",
    "rts",
    "smooth",
]
