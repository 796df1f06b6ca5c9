"""Viterbi decoding and forward–backward posteriors of the track HMM, in log space (numba).

Steps k = 0 … n−1 (the fixes that have candidates) with candidates ``coff[k]:coff[k+1]``
and emission log-likelihoods ``loge``; the transition log-probabilities from step k−1 to k
are ``logt[poff[k] + (i − p0)·m + (j − a0)]`` for candidate i of step k−1 (first p0) and j of
step k (first a0, m candidates). Recursions [Rabiner 1989; Newson & Krumm 2009]:

* Viterbi: δ_k(j) = log e_k(j) + max_i (δ_{k−1}(i) + log a(i, j)), back-pointer the argmax;
* forward: α_k(j) = log e_k(j) + logsumexp_i (α_{k−1}(i) + log a(i, j));
* backward: β_k(i) = logsumexp_j (log a(i, j) + log e_{k+1}(j) + β_{k+1}(j)), β = 0 at a
  chain's last step;
* posterior γ_k(j) = α_k(j) + β_k(j) − log Z, log Z = logsumexp_j α_last(j) of the chain.

A *chain* starts at step 0 and wherever no transition from step k−1 to k is possible (every
δ_k = −∞: no candidate reachable, e.g. only across a ``none`` relation); the chain is then
broken (``broken[k]``) and restarted there from the emissions alone — never forced.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B8 = npt.NDArray[np.bool_]

NEG = -np.inf


@njit(cache=True, nogil=True)
def _into(  # pragma: no cover - numba
    j: int, p0: int, p1: int, col: int, m: int, logt: F64, delta: F64, alpha: F64
) -> tuple[float, int, float]:
    """max and argmax of δ_{k−1}(i) + log a(i, j), logsumexp of α_{k−1}(i) + log a(i, j);
    ``col`` = poff[k] + (j − a0), ``m`` candidates at step k."""
    best, arg, mx = NEG, -1, NEG
    for i in range(p0, p1):
        lt = logt[col + (i - p0) * m]
        v = delta[i] + lt
        if v > best:
            best, arg = v, i
        w = alpha[i] + lt
        if w > mx:
            mx = w
    if arg < 0:
        return NEG, -1, NEG
    s = 0.0
    for i in range(p0, p1):
        w = alpha[i] + logt[col + (i - p0) * m]
        if w > NEG:
            s += np.exp(w - mx)
    return best, arg, mx + np.log(s)


@njit(cache=True, nogil=True)
def _forward(coff: I64, loge: F64, poff: I64, logt: F64) -> tuple[F64, F64, I64, B8]:  # pragma: no cover - numba
    n = len(coff) - 1
    nc = len(loge)
    delta = np.full(nc, NEG)
    alpha = np.full(nc, NEG)
    back = np.full(nc, -1, dtype=np.int64)
    start = np.zeros(n, dtype=np.bool_)
    for k in range(n):
        a0, a1 = coff[k], coff[k + 1]
        feasible = False
        if k > 0:
            for j in range(a0, a1):
                best, arg, lse = _into(j, coff[k - 1], coff[k], poff[k] + (j - a0), a1 - a0, logt, delta, alpha)
                if arg >= 0:
                    feasible = True
                    delta[j], alpha[j], back[j] = best + loge[j], lse + loge[j], arg
        if not feasible:
            start[k] = True
            for j in range(a0, a1):
                delta[j], alpha[j], back[j] = loge[j], loge[j], -1
    return delta, alpha, back, start


@njit(cache=True, nogil=True)
def _backward(coff: I64, loge: F64, poff: I64, logt: F64, start: B8) -> F64:  # pragma: no cover - numba
    n = len(coff) - 1
    beta = np.zeros(len(loge))
    for k in range(n - 2, -1, -1):
        if start[k + 1]:
            continue  # step k ends its chain: β = 0
        a0, a1 = coff[k + 1], coff[k + 2]
        p0, p1 = coff[k], coff[k + 1]
        m = a1 - a0
        base = poff[k + 1]
        for i in range(p0, p1):
            mx = NEG
            for j in range(a0, a1):
                w = logt[base + (i - p0) * m + (j - a0)] + loge[j] + beta[j]
                if w > mx:
                    mx = w
            if mx == NEG:
                beta[i] = NEG
                continue
            s = 0.0
            for j in range(a0, a1):
                w = logt[base + (i - p0) * m + (j - a0)] + loge[j] + beta[j]
                if w > NEG:
                    s += np.exp(w - mx)
            beta[i] = mx + np.log(s)
    return beta


@njit(cache=True, nogil=True)
def _decode(coff: I64, delta: F64, alpha: F64, back: I64, start: B8) -> tuple[I64, F64]:  # pragma: no cover
    """Viterbi path (candidate per step) and log Z of each step's chain."""
    n = len(coff) - 1
    best = np.full(n, -1, dtype=np.int64)
    logz = np.zeros(n)
    k = n - 1
    while k >= 0:
        a0, a1 = coff[k], coff[k + 1]
        arg, v, mx = a0, NEG, NEG
        for j in range(a0, a1):
            if delta[j] > v:
                v, arg = delta[j], j
            if alpha[j] > mx:
                mx = alpha[j]
        s = 0.0
        for j in range(a0, a1):
            s += np.exp(alpha[j] - mx)
        z = mx + np.log(s)
        cur = arg
        while True:
            best[k] = cur
            logz[k] = z
            if start[k]:
                break
            cur = back[cur]
            k -= 1
        k -= 1
    return best, logz


def decode(coff: I64, loge: F64, poff: I64, logt: F64) -> tuple[I64, F64, B8, F64, F64]:
    """(Viterbi candidate per step, posterior γ per candidate, chain starts, α, β) — see the
    module docstring; ``γ`` is a probability (exp of the log posterior)."""
    delta, alpha, back, start = _forward(coff, loge, poff, logt)
    beta = _backward(coff, loge, poff, logt, start)
    best, logz = _decode(coff, delta, alpha, back, start)
    step = np.repeat(np.arange(len(coff) - 1), np.diff(coff))
    gamma = np.minimum(np.exp(alpha + beta - logz[step]), 1.0) if len(step) else np.empty(0)  # rounding: ≤ 1
    return best, gamma, start, alpha, beta


def warm() -> None:
    """Compile (or load from the on-disk cache) the kernels on a two-step problem."""
    coff = np.array([0, 1, 2], dtype=np.int64)
    decode(coff, np.zeros(2), np.array([0, 0], dtype=np.int64), np.zeros(1))
