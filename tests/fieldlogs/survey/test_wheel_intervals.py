"""The wheel intervals hold the truth as often as they say: sources sharing the GIS grid's
length error, their GLS combination (against a dense GLS), the Birge ratio, and a vehicle's
runs pooled over one grid — seeded synthetic fits, fast."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.survey.wheels import Z95, combine, pool

D = 0.86
#: Grid length error (1σ, relative) and own errors of balise, radar, GNSS (1σ, relative),
#: about the sizes of the bench (bench/NOTES.md, "Wheels").
G, OWN = 2e-5, np.array([4.5e-5, 3e-4, 4e-5])
SHARES = np.array([1.0, 0.0, 1.0])


def _draw(rng: np.random.Generator, rows: int, g: float = G) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Estimates D·(1 + ε·shares + eᵢ) of three sources, their total 95 % half-widths and
    the 1σ of their shared part (ε of 1σ ``g``)."""
    eps = rng.normal(0.0, g, (rows, 1))
    own = OWN * rng.uniform(0.5, 1.5, (rows, 3))
    d = D * (1.0 + eps * SHARES + rng.normal(size=(rows, 3)) * own)
    grid = D * g * SHARES * np.ones((rows, 1))
    half = Z95 * np.sqrt((D * own) ** 2 + grid**2)
    return d, half, grid


def _covered(est: np.ndarray, half: np.ndarray) -> float:
    return float(np.mean(np.abs(est - D) <= half))


def test_each_source_and_the_combination_cover_95_percent() -> None:
    d, half, grid = _draw(np.random.default_rng(1), 20_000)
    for j in range(3):
        assert 0.94 < _covered(d[:, j], half[:, j]) < 0.96
    mean, ci, k, _ = combine(d, half, grid)
    assert (k == 3).all()
    assert 0.95 <= _covered(mean, ci) < 0.985  # the Birge ratio only ever widens
    two = d.copy()
    two[:, 1] = np.nan  # balise and GNSS only: the shared error does not average out
    mean2, ci2, _, _ = combine(two, half, grid)
    assert 0.95 <= _covered(mean2, ci2) < 0.985
    assert np.median(ci2 / D) < 1.2e-4  # intervals of about 0.01 %: far inside a 0.1–0.3 % alert share
    d, half, grid = _draw(np.random.default_rng(4), 20_000, g=6e-5)  # a grid error the size of the fits'
    d[:, 1] = np.nan
    mean, ci, _, _ = combine(d, half, grid)
    naive, naive_ci, _, _ = combine(d, half)  # as if the grid error were independent
    assert _covered(mean, ci) >= 0.95 and _covered(naive, naive_ci) < 0.92


def test_sources_that_disagree_widen_the_interval_by_the_birge_ratio() -> None:
    """GNSS 0.03 % off (a bad fit, 7.5 of its σ) on every run: the combination's intervals
    widen (× 3 in the median) and still hold the truth in four runs of five — with two
    degrees of freedom the ratio is itself uncertain, which is why such runs are also
    flagged inconsistent."""
    d, half, grid = _draw(np.random.default_rng(2), 5000)
    _, ci0, _, _ = combine(d, half, grid)
    d[:, 2] *= 1.0003
    mean, ci, _, agree = combine(d, half, grid)
    assert float(np.median(ci / ci0)) > 3.0
    assert _covered(mean, ci) > 0.78
    assert np.mean([a is False for a in agree]) > 0.9


@settings(max_examples=30, deadline=None)
@given(st.integers(min_value=0, max_value=2**31 - 1), st.integers(min_value=2, max_value=3))
def test_the_combination_is_the_dense_generalised_least_squares(seed: int, k: int) -> None:
    rng = np.random.default_rng(seed)
    rows = 5
    own = rng.uniform(1e-5, 5e-4, (rows, k))
    g = rng.uniform(0.0, 3e-4, (rows, k)) * (rng.uniform(size=(rows, k)) < 0.7)
    d = D * (1.0 + rng.normal(size=(rows, k)) * own)
    half = Z95 * np.sqrt(own**2 + g**2)
    mean, ci, _, _ = combine(d, half, g)
    for i in range(rows):
        c = np.diag(own[i] ** 2) + np.outer(g[i], g[i])
        ci_inv = np.linalg.inv(c)
        one = np.ones(k)
        s11 = float(one @ ci_inv @ one)
        m = float(one @ ci_inv @ d[i]) / s11
        r = d[i] - m
        birge = max(1.0, float(np.sqrt(r @ ci_inv @ r / (k - 1))))
        assert mean[i] == pytest.approx(m, rel=1e-12)
        assert ci[i] == pytest.approx(Z95 * birge / np.sqrt(s11), rel=1e-6)


def test_a_vehicle_pooled_over_one_grid_covers_95_percent() -> None:
    """Eight runs of one vehicle on one grid: its runs' shared error is one draw, so the
    pooled interval keeps it whole; treating it as independent would cover far less."""
    rng = np.random.default_rng(3)
    hits, naive_hits, halves = [], [], []
    for _ in range(1500):
        eps = rng.normal(0.0, G)
        u = 4e-5 * rng.uniform(0.5, 1.5, 8)
        d = D * (1.0 + eps + rng.normal(size=8) * u)
        half = Z95 * D * np.sqrt(u**2 + G**2)
        m, h, n = pool(d, half, 3, np.full(8, Z95 * D * G))
        assert n == 8
        hits.append(abs(m - D) <= h)
        halves.append(h / D)
        mn, hn, _ = pool(d, half, 3)
        naive_hits.append(abs(mn - D) <= hn)
    assert 0.95 <= float(np.mean(hits)) < 0.995
    assert float(np.mean(naive_hits)) < 0.93
    assert float(np.median(halves)) < 6e-5


def test_pooling_with_a_shared_part_adds_it_once() -> None:
    d = np.array([0.8600, 0.8610, 0.8620])
    half = np.full(3, 2e-4)
    mean, h, n = pool(d, half, 3, np.full(3, 1e-4))
    assert (mean, n) == (pytest.approx(0.861), 3)
    assert h == pytest.approx(np.hypot(4.302653 * 0.001 / np.sqrt(3), 1e-4), rel=1e-5)
