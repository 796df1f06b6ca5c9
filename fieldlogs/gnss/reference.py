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
    j = int(np.clip(np.searchsorted(track.s, sa, side="right") - 1, 0, track.s.size - 2))
    pos = (
        track.xyz[j]
        + (sa - track.s[j]) * track.tangent[j]
        + d * ant.lateral_m * track.left[j]
        + ant.height_m * track.up[j]
    )
    return pos, track.tangent[j]


def _fit(
    track: TrackLine,
    sats: FloatArray,
    pr: FloatArray,
    sig: FloatArray,
    we: FloatArray,
    used: list[bool],
    ant: Antenna,
    d: float,
    s: float,
    prior: tuple[float, float] | None,
    cfg: ConstrainedConfig,
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


_FitResult = tuple[float, float, FloatArray, FloatArray, FloatArray, bool]


@dataclass
class _Epoch:
    """One epoch's inputs and the per-epoch steps of the algorithm."""

    track: TrackLine
    sats: FloatArray
    pr: FloatArray
    sig: FloatArray
    we: FloatArray
    ant: Antenna
    direction: float
    cfg: ConstrainedConfig

    def fit(self, used: list[bool], s: float, prior: tuple[float, float] | None) -> _FitResult:
        return _fit(
            self.track, self.sats, self.pr, self.sig, self.we, used, self.ant, self.direction, s, prior, self.cfg
        )

    def on_track(self, f: _FitResult, prior: tuple[float, float] | None) -> bool:
        s, n_inv, conv = f[0], f[4], f[5]
        ok = conv and 0.0 <= s <= self.track.length_m
        if prior is not None:
            ok = ok and abs(s - prior[0]) <= self.cfg.prior_window_sigmas * math.sqrt(prior[1] ** 2 + abs(n_inv[0, 0]))
        return ok

    def stats(self, f: _FitResult, u: list[bool], prior: tuple[float, float] | None) -> tuple[float, int, list[float]]:
        """T, dof and the normalised residuals (satellites, then the prior)."""
        s, h, v, n_inv = f[0], f[2], f[3], f[4]
        idx = [i for i, x in enumerate(u) if x]
        t, wres = 0.0, []
        for r, i in enumerate(idx):
            w = 1.0 / self.sig[i] ** 2
            q = min(max(1.0 - w * float(h[r] @ n_inv @ h[r]), 1e-12), 1.0)
            t += w * v[r] ** 2
            wres.append(abs(v[r]) * math.sqrt(w) / math.sqrt(q))
        dof = len(idx) - 2
        if prior is not None:
            pw = 1.0 / prior[1] ** 2
            pq = min(max(1.0 - pw * n_inv[0, 0], 1e-12), 1.0)
            t += pw * (prior[0] - s) ** 2
            dof += 1
            wres.append(abs(prior[0] - s) * math.sqrt(pw) / math.sqrt(pq))
        return t, dof, wres

    def reject_off_track(self, used: list[bool], f: _FitResult, prior: tuple[float, float] | None) -> _FitResult:
        """Leave-one-out when the solution is off the track (or the prior's window)."""
        if self.on_track(f, prior) or sum(used) <= 2:
            return f
        thr = chi2_thresholds(self.cfg.p_false_alarm)
        best: tuple[float, int, _FitResult] | None = None
        for j in [i for i, x in enumerate(used) if x]:
            u = list(used)
            u[j] = False
            g = self.fit(u, f[0], prior)
            t, dof, _ = self.stats(g, u, None)
            score = (t / thr[dof] if dof >= 1 else 0.0) if self.on_track(g, prior) else math.inf
            if score < math.inf and (best is None or score < best[0]):
                best = (score, j, g)
        if best is None:
            return f
        used[best[1]] = False
        return best[2]

    def exclude(self, used: list[bool], f: _FitResult, prior: tuple[float, float] | None) -> tuple[_FitResult, bool]:
        """χ² and w-test with exclusion of the largest normalised satellite residual."""
        thr = chi2_thresholds(self.cfg.p_false_alarm)
        fail = False
        for _ in range(self.cfg.max_exclusions + 1):
            t, dof, wres = self.stats(f, used, prior)
            fail = dof >= 1 and (t > thr[dof] or max(wres, default=0.0) > self.cfg.k_w)
            if not (fail and dof >= 2):
                break
            idx = [i for i, x in enumerate(used) if x]
            used[idx[int(np.argmax(wres[: len(idx)]))]] = False
            f = self.fit(used, f[0], prior)
        return f, fail

    def status(self, f: _FitResult, used: list[bool], fail: bool, prior: tuple[float, float] | None) -> int:
        hh = f[2].T @ f[2]
        adop = math.sqrt(abs(np.linalg.inv(hh)[0, 0])) if abs(np.linalg.det(hh)) > 1e-12 else math.inf
        checks = (
            (sum(used) < 2, STATUS_TOO_FEW),
            (not f[5], STATUS_NOT_CONVERGED),
            (not self.on_track(f, prior), STATUS_OFF_TRACK),
            (fail, STATUS_FAULT),
            (adop > self.cfg.max_adop, STATUS_GEOMETRY),
        )
        return next((code for bad, code in checks if bad), STATUS_OK)


def solve_epoch(
    track: TrackLine,
    sats: FloatArray,
    pr: FloatArray,
    sig: FloatArray,
    we: FloatArray,
    usable: list[bool],
    ant: Antenna,
    direction: float,
    s0: float,
    prior: tuple[float, float] | None,
    cfg: ConstrainedConfig,
) -> EpochResult:
    """One epoch, one receiver (module docstring)."""
    ep = _Epoch(track, sats, pr, sig, we, ant, direction, cfg)
    used = list(usable)
    f = ep.fit(used, s0, prior)
    f = ep.reject_off_track(used, f, prior)
    f, fail = ep.exclude(used, f, prior)
    if prior is not None:
        f = ep.fit(used, f[0], None)
    return EpochResult(f[0], f[1], math.sqrt(abs(f[4][0, 0])), ep.status(f, used, fail, prior), used)
