"""Runs of True (dbtools/masks.py): hand-computed cases and a property test against a loop."""

from __future__ import annotations

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from dbtools.masks import merge_runs, run_around, sign_runs, true_runs


def test_true_runs_by_hand() -> None:
    starts, ends = true_runs([True, True, False, True, False, False, True])
    assert starts.tolist() == [0, 3, 6]
    assert ends.tolist() == [2, 4, 7]  # exclusive; the last run reaches the end of the mask


def test_true_runs_empty_and_none() -> None:
    for mask in ([], [False, False]):
        s, e = true_runs(mask)
        assert s.size == 0 and e.size == 0


def test_merge_runs_by_hand() -> None:
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 10.0, 11.0])
    s, e = true_runs([True, False, True, False, False, True, True])  # runs [0,1) [2,3) [5,7)
    ms, me = merge_runs(s, e, x, 2.5)  # gaps 2 − 0 = 2 < 2.5 merged; 10 − 2 = 8 kept apart
    assert ms.tolist() == [0, 5] and me.tolist() == [3, 7]
    ms, me = merge_runs(s, e, x, 2.0)  # a gap equal to the limit is not merged
    assert ms.tolist() == [0, 2, 5] and me.tolist() == [1, 3, 7]


def test_merge_runs_nan_gap_does_not_merge() -> None:
    x = np.array([0.0, np.nan, 0.5])
    s, e = true_runs([True, False, True])
    ms, _ = merge_runs(s, e, np.array([np.nan, 0.0, 0.5]), 10.0)
    assert ms.tolist() == [0, 2]
    ms, _ = merge_runs(s, e, x, 10.0)
    assert ms.tolist() == [0]


def test_sign_runs_left_then_right() -> None:
    k = np.array([0.0, 2.0, 2.0, np.nan, -3.0, -3.0, 0.0, 2.0])
    x = np.arange(k.size, dtype=float)
    assert sign_runs(k, x, 1.0, 0.5) == [(1, 3, 1), (7, 8, 1), (4, 6, -1)]
    assert sign_runs(k, x, 1.0, 10.0) == [(1, 8, 1), (4, 6, -1)]


@given(st.lists(st.booleans(), max_size=60), st.floats(0.0, 8.0))
def test_runs_match_a_loop(mask: list[bool], gap: float) -> None:
    x = np.cumsum(np.arange(len(mask), dtype=float) % 3)
    loop: list[list[int]] = []
    for i, m in enumerate(mask):
        if m and (not loop or loop[-1][1] != i):
            if loop and x[i] - x[loop[-1][1] - 1] < gap:
                loop[-1][1] = i + 1
                continue
            loop.append([i, i + 1])
        elif m:
            loop[-1][1] = i + 1
    s, e = merge_runs(*true_runs(mask), x, gap)
    assert [[a, b] for a, b in zip(s.tolist(), e.tolist(), strict=True)] == loop
    plain = true_runs(mask)
    assert all(np.asarray(mask)[a:b].all() for a, b in zip(*plain, strict=True))
    assert int(sum(b - a for a, b in zip(*plain, strict=True))) == sum(mask)


def test_run_around_by_hand() -> None:
    mask = [False, True, True, True, False, True]
    assert run_around(mask, 2) == (1, 3)
    assert run_around(mask, 5) == (5, 5)  # a run at the end
    assert run_around([True, True], 0) == (0, 1)


@given(st.lists(st.booleans(), min_size=1, max_size=40), st.integers(0, 39))
def test_run_around_is_the_true_run_holding_i(mask: list[bool], i: int) -> None:
    i = i % len(mask)
    if not mask[i]:
        return
    starts, ends = true_runs(mask)
    k = int(np.searchsorted(starts, i, side="right")) - 1
    assert run_around(mask, i) == (int(starts[k]), int(ends[k]) - 1)
