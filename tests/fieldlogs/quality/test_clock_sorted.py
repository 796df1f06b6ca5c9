"""``clocks._sorted`` (the streams the clock check correlates): returning an increasing
stream's own arrays gives what sorting and filtering them gave, bit for bit — and
anything else (unsorted, repeated, NaN or infinite t) still goes through the sort."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.quality.clocks import _sorted


def sorted_before(frame: pd.DataFrame, cols: list[str]) -> dict[str, np.ndarray]:
    """The implementation before the fast path: always argsort, index, filter."""
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    order = np.argsort(t, kind="stable")
    out = {"t": t[order]}
    for c in cols:
        out[c] = frame[c].to_numpy(dtype=float, na_value=np.nan)[order]
    keep = (np.diff(out["t"], prepend=-np.inf) > 0) & np.isfinite(out["t"])
    return {k: v[keep] for k, v in out.items()}


@settings(max_examples=300, deadline=None)
@given(
    steps=st.lists(st.one_of(st.floats(0.001, 1.0), st.just(0.0)), min_size=0, max_size=60),
    odd=st.lists(st.tuples(st.integers(0, 59), st.sampled_from([np.nan, np.inf, -np.inf, -5.0])), max_size=3),
)
def test_the_fast_path_equals_the_sort(steps: list[float], odd: list[tuple[int, float]]) -> None:
    t = np.cumsum(np.asarray(steps, dtype=float))
    for i, v in odd:
        if i < t.size:
            t[i] = v
    frame = pd.DataFrame({"t": t, "ax": np.arange(t.size, dtype=float) * 0.5})
    with np.errstate(invalid="ignore"):  # inf − inf in the steps of a t with two infinities
        got, want = _sorted(frame, ["ax"]), sorted_before(frame, ["ax"])
    assert got.keys() == want.keys()
    assert all(np.array_equal(got[k], want[k]) for k in want)


def test_an_increasing_stream_is_not_copied() -> None:
    frame = pd.DataFrame({"t": [0.0, 0.01, 0.02, 0.05], "ax": [1.0, 2.0, 3.0, 4.0]})
    got = _sorted(frame, ["ax"])
    assert np.shares_memory(got["t"], frame["t"].to_numpy()) and np.shares_memory(got["ax"], frame["ax"].to_numpy())
    last_inf = frame.assign(t=[0.0, 0.01, 0.02, np.inf])
    assert np.array_equal(_sorted(last_inf, ["ax"])["t"], [0.0, 0.01, 0.02])
