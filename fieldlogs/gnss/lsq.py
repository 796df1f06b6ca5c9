"""Classical unconstrained single-point positioning, batched over epochs (for comparison).

Unknowns per epoch x = (x, y, z, b) plus an inter-system bias b_E for Galileo when the epoch
has both Galileo and GPS/QZSS satellites (QZSST is steered to GPS time, IS-QZSS-PNT;
GST differs by the GGTO, a few ns). Iterative weighted least squares from the Earth's centre
(or a given start): v = ρ_c − |r_s − r| − sagnac − b − b_E·[Galileo], H = [−û, 1, [Galileo]],
(HᵀWH)δ = HᵀWv (≤ 10 iterations, |δ| < 1 mm). An unobservable b_E is pinned to 0.

DOPs from Q = (HᵀH)⁻¹ with the position block rotated to local east/north/up:
GDOP = √tr Q, PDOP = √(Q_ee + Q_nn + Q_uu), HDOP = √(Q_ee + Q_nn), VDOP = √Q_uu,
TDOP = √Q_bb. A solution counts as available with ≥ 4 (5 with b_E) satellites and
PDOP ≤ ``max_pdop`` — the usual receiver rule; no fault detection (the receiver black box the
paper replaces).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.gnss.constants import C_MPS, BoolArray, FloatArray, IntArray, StrArray
from fieldlogs.gnss.geodesy import ecef_to_geodetic, enu_basis
from fieldlogs.gnss.linalg import inv_safe, solve_safe


@dataclass
class LsqSolution:
    """Per-epoch unconstrained solution."""

    pos: FloatArray
    clock_m: FloatArray
    isb_m: FloatArray
    gdop: FloatArray
    pdop: FloatArray
    hdop: FloatArray
    vdop: FloatArray
    tdop: FloatArray
    n_used: IntArray
    converged: BoolArray
    available: BoolArray
    residual_m: FloatArray


def solve_lsq(
    sat_pos: FloatArray,
    pr_m: FloatArray,
    sigma_m: FloatArray,
    used: BoolArray,
    system: StrArray,
    omega_e: FloatArray,
    *,
    start: FloatArray | None = None,
    max_pdop: float = 6.0,
    max_iter: int = 10,
) -> LsqSolution:
    """Weighted least squares of every epoch (module docstring); rows (E, S)."""
    e = pr_m.shape[0]
    used = used & np.isfinite(pr_m) & np.isfinite(sigma_m) & np.all(np.isfinite(sat_pos), axis=-1)
    gal = (np.asarray(system) == "E") & used
    other = used & ~gal
    isb_free = gal.any(axis=1) & other.any(axis=1)
    w = np.where(used, 1.0 / np.where(used, sigma_m, 1.0) ** 2, 0.0)
    x = np.zeros((e, 5))
    if start is not None:
        x[:, :3] = start
    sp = np.where(used[..., None], sat_pos, 0.0)
    converged = np.zeros(e, dtype=bool)
    h = np.zeros((*pr_m.shape, 5))
    v = np.zeros_like(pr_m)
    for _ in range(max_iter):
        d = sp - x[:, None, :3]
        rng = np.linalg.norm(d, axis=-1)
        sag = (omega_e / C_MPS) * (sp[..., 0] * x[:, None, 1] - sp[..., 1] * x[:, None, 0])
        u = d / np.where(rng > 0, rng, 1.0)[..., None]
        v = np.where(used, pr_m - rng - np.nan_to_num(sag) - x[:, None, 3] - x[:, None, 4] * gal, 0.0)
        h = np.concatenate([-u, np.ones((*pr_m.shape, 1)), gal[..., None].astype(float)], axis=-1)
        n = np.einsum("esi,es,esj->eij", h, w, h)
        n[:, 4, 4] += np.where(isb_free, 0.0, 1.0)
        n[:, :4, :4] += np.where(used.sum(axis=1) == 0, 1.0, 0.0)[:, None, None] * np.eye(4)
        rhs = np.einsum("esi,es,es->ei", h, w, v)
        delta, bad = solve_safe(n, rhs)
        x += delta
        converged = (np.max(np.abs(delta), axis=1) < 1e-3) & ~bad
        if converged.all():
            break
    hu = np.where(used[..., None], h, 0.0)
    qn = np.einsum("esi,esj->eij", hu, hu)
    qn[:, 4, 4] += np.where(isb_free, 0.0, 1.0)
    n_used = used.sum(axis=1)
    enough = n_used >= 4 + isb_free
    qn[~enough] = np.eye(5)
    q = inv_safe(qn)
    enough &= np.isfinite(q[:, 0, 0])
    lat, lon, _ = ecef_to_geodetic(
        np.where(np.linalg.norm(x[:, :3], axis=1, keepdims=True) > 1e6, x[:, :3], [6.4e6, 0, 0])
    )
    r = enu_basis(lat, lon)
    q_enu = np.einsum("eik,ekl,ejl->eij", r, q[:, :3, :3], r)
    nan = np.where(enough, 1.0, np.nan)
    pdop = np.sqrt(np.trace(q_enu, axis1=1, axis2=2)) * nan
    return LsqSolution(
        pos=x[:, :3],
        clock_m=x[:, 3],
        isb_m=x[:, 4],
        gdop=np.sqrt(np.trace(q[:, :4, :4], axis1=1, axis2=2)) * nan,
        pdop=pdop,
        hdop=np.sqrt(q_enu[:, 0, 0] + q_enu[:, 1, 1]) * nan,
        vdop=np.sqrt(q_enu[:, 2, 2]) * nan,
        tdop=np.sqrt(q[:, 3, 3]) * nan,
        n_used=n_used.astype(np.int64),
        converged=converged,
        available=enough & converged & (np.nan_to_num(pdop, nan=np.inf) <= max_pdop),
        residual_m=np.where(used, v, np.nan),
    )
