"""Batched small linear systems that may be singular (a degenerate epoch must not stop a batch).

A matrix counts as singular when |det N| ≤ 1e-12·Π|N_ii| (a scale-free test for the 2–5
unknowns of the solvers); its solution is then 0 and its inverse NaN, and the caller marks the
epoch unsolved.
"""

from __future__ import annotations

import numpy as np

from fieldlogs.gnss.constants import BoolArray, FloatArray


def singular(n: FloatArray) -> BoolArray:
    """Normal matrices too close to singular to solve (relative determinant below 1e-12)."""
    diag = np.prod(np.abs(np.diagonal(n, axis1=1, axis2=2)), axis=1)
    return np.asarray(~(np.abs(np.linalg.det(n)) > 1e-12 * np.maximum(diag, 1e-300)), dtype=bool)


def solve_safe(n: FloatArray, rhs: FloatArray) -> tuple[FloatArray, BoolArray]:
    bad = singular(n)
    n = np.where(bad[:, None, None], np.eye(n.shape[1]), n)
    delta = np.linalg.solve(n, rhs[..., None])[..., 0]
    return np.where(bad[:, None], 0.0, delta), bad


def inv_safe(n: FloatArray) -> FloatArray:
    bad = singular(n)
    inv = np.linalg.inv(np.where(bad[:, None, None], np.eye(n.shape[1]), n))
    return np.where(bad[:, None, None], np.nan, inv)
