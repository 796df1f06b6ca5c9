"""A straightforward per-epoch implementation of the track-constrained solution (one receiver).

The same equations as ``constrained`` written epoch by epoch and row by row — Gauss–Newton
on (s, b), the no-on-track-solution leave-one-out, the χ² test with exclusion of the largest
normalised residual, the prior as a test observation — without batching. It is the yardstick
of ``bench/bench_gnss.py`` (throughput ratio) and an independent check of the batched code
in the tests; it is not used by the positioning itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from fieldlogs.gnss.constants import C_MPS, FloatArray
from fieldlogs.gnss.constrained import (
    STATUS_FAULT,
    STATUS_GEOMETRY,
    STATUS_NOT_CONVERGED,
    STATUS_OFF_TRACK,
    STATUS_OK,
    STATUS_TOO_FEW,
    ConstrainedConfig,
    chi2_thresholds,
)
from fieldlogs.gnss.track import Antenna, TrackLine


@dataclass
class EpochResult:
    s: float
    clock_m: float
    sigma_s: float
    status: int
    used: list[bool]


def _antenna(track: TrackLine, s: float, ant: Antenna, d: float) -> tuple[FloatArray, FloatArray]:
    sa = s + d * ant.along_m
    j = int(min(max(np.searchsorted(track.s, sa, side="right") - 1, 0), track.s.size - 2))
    pos = track.xyz[j] + (sa - track.s[j]) * track.tangent[j] + d * ant.lateral_m * track.left[j] + ant.height_m * track.up[j]
    return pos, track.tangent[j]


def _fit(
    track: TrackLine, sats: FloatArray, pr: FloatArray, sig: FloatArray, we: FloatArray, used: list[bool],
    ant: Antenna, d: float, s: float, prior: tuple[float, float] | None, cfg: ConstrainedConfig,
) -> tuple[float, float, FloatArray, FloatArray, FloatArray, bool]:
    """Gauss–Newton of one epoch: returns s, b, H (n, 2), v (n,), N⁻¹, converged."""
    idx = [i for i, u in enumerate(used) if u]
    pos, _ = _antenna(track, s, ant, d)
    b = float(np.mean([pr[i] - _range(sats[i], pos, we[i]) for i in idx])) if idx else 0.0
    converged = False
    h = np.zeros((len(idx), 2))
    v = np.zeros(len(idx))
    n_inv = np.eye(2)
    for _ in range(cfg.max_iter + 1):
        pos, t = _antenna(track, s, ant, d)
        for r, i in enumerate(idx):
            rho = _range(sats[i], pos, we[i])
            u = (sats[i] - pos) / np.linalg.norm(sats[i] - pos)
            h[r] = (-float(u @ t), 1.0)
            v[r] = pr[i] - rho - b
        w = np.array([1.0 / sig[i] ** 2 for i in idx])
        n = (h * w[:, None]).T @ h
        rhs = (h * w[:, None]).T @ v
        if prior is not None and math.isfinite(prior[1]):
            n[0, 0] += 1.0 / prior[1] ** 2
            rhs[0] += (prior[0] - s) / prior[1] ** 2
        n_inv = np.linalg.inv(n)
        if converged:
            break
        delta = n_inv @ rhs
        delta[0] = min(max(delta[0], -5_000.0), 5_000.0)
        s, b = s + float(delta[0]), b + float(delta[1])
        converged = bool(np.max(np.abs(delta)) < cfg.tol_m)
    return s, b, h, v, n_inv, converged


def _range(sat: FloatArray, pos: FloatArray, we: float) -> float:
    return float(np.linalg.norm(sat - pos) + we / C_MPS * (sat[0] * pos[1] - sat[1] * pos[0]))


def solve_epoch(
    track: TrackLine, sats: FloatArray, pr: FloatArray, sig: FloatArray, we: FloatArray, usable: list[bool],
    ant: Antenna, direction: float, s0: float, prior: tuple[float, float] | None, cfg: ConstrainedConfig,
) -> EpochResult:
    """One epoch, one receiver (module docstring)."""
    used = list(usable)
    thr = chi2_thresholds(cfg.p_false_alarm)

    def on_track(s: float, n_inv: FloatArray, conv: bool, pri: tuple[float, float] | None) -> bool:
        ok = conv and 0.0 <= s <= track.length_m
        if pri is not None:
            ok = ok and abs(s - pri[0]) <= cfg.prior_window_sigmas * math.sqrt(pri[1] ** 2 + abs(n_inv[0, 0]))
        return ok

    def stats(h: FloatArray, v: FloatArray, n_inv: FloatArray, s: float, u: list[bool], pri: tuple[float, float] | None) -> tuple[float, int, list[float]]:
        idx = [i for i, x in enumerate(u) if x]
        t, wres = 0.0, []
        for r, i in enumerate(idx):
            w = 1.0 / sig[i] ** 2
            q = min(max(1.0 - w * float(h[r] @ n_inv @ h[r]), 1e-12), 1.0)
            t += w * v[r] ** 2
            wres.append(abs(v[r]) * math.sqrt(w) / math.sqrt(q))
        dof = len(idx) - 2
        if pri is not None and math.isfinite(pri[1]):
            pw = 1.0 / pri[1] ** 2
            pq = min(max(1.0 - pw * n_inv[0, 0], 1e-12), 1.0)
            t += pw * (pri[0] - s) ** 2
            dof += 1
            wres.append(abs(pri[0] - s) * math.sqrt(pw) / math.sqrt(pq))
        return t, dof, wres

    s, b, h, v, n_inv, conv = _fit(track, sats, pr, sig, we, used, ant, direction, s0, prior, cfg)
    if not on_track(s, n_inv, conv, prior) and sum(used) > 2:
        best: tuple[float, int, tuple[float, float, FloatArray, FloatArray, FloatArray, bool]] | None = None
        for j in [i for i, x in enumerate(used) if x]:
            u = list(used)
            u[j] = False
            f = _fit(track, sats, pr, sig, we, u, ant, direction, s, prior, cfg)
            t, dof, _ = stats(f[2], f[3], f[4], f[0], u, None)
            score = (t / thr[dof] if dof >= 1 else 0.0) if on_track(f[0], f[4], f[5], prior) else math.inf
            if score < math.inf and (best is None or score < best[0]):
                best = (score, j, f)
        if best is not None:
            used[best[1]] = False
            s, b, h, v, n_inv, conv = best[2]
    pri = prior
    fail = False
    for _ in range(cfg.max_exclusions + 1):
        t, dof, wres = stats(h, v, n_inv, s, used, pri)
        fail = dof >= 1 and (t > thr[dof] or max(wres, default=0.0) > cfg.k_w)
        if not (fail and dof >= 2):
            break
        idx = [i for i, x in enumerate(used) if x]
        used[idx[int(np.argmax(wres[: len(idx)]))]] = False
        s, b, h, v, n_inv, conv = _fit(track, sats, pr, sig, we, used, ant, direction, s, pri, cfg)
    if prior is not None:
        s, b, h, v, n_inv, conv = _fit(track, sats, pr, sig, we, used, ant, direction, s, None, cfg)
    hh = h.T @ h
    adop = math.sqrt(abs(np.linalg.inv(hh)[0, 0])) if abs(np.linalg.det(hh)) > 1e-12 else math.inf
    status = STATUS_OK
    if adop > cfg.max_adop:
        status = STATUS_GEOMETRY
    if fail:
        status = STATUS_FAULT
    if not on_track(s, n_inv, conv, prior):
        status = STATUS_OFF_TRACK
    if not conv:
        status = STATUS_NOT_CONVERGED
    if sum(used) < 2:
        status = STATUS_TOO_FEW
    return EpochResult(s, b, math.sqrt(abs(n_inv[0, 0])), status, used)
