"""The inputs of the IMU clock check without full-length copies: ``clocks._sorted`` returns
an increasing stream's own arrays — what sorting and filtering them gave, bit for bit;
anything else (unsorted, repeated, NaN or infinite t) still goes through the sort — and
``clocks._in_travel_frame`` turns a_x by the cab sign block by block, bit for bit the
whole-array product."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.cycles import cab_signs
from fieldlogs.quality.clocks import _in_travel_frame, _sorted


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


@settings(max_examples=200, deadline=None)
@given(
    n=st.integers(0, 200),
    events=st.lists(st.tuples(st.floats(-1.0, 3.0), st.sampled_from(["F", "R"])), max_size=6),
    rows=st.integers(1, 50),
)
def test_travel_frame_by_blocks_equals_the_whole_product(n: int, events: list[tuple[float, str]], rows: int) -> None:
    t = np.linspace(0.0, 2.0, n)
    ax = np.sin(7.0 * t) - 0.3
    cab = pd.DataFrame({"t": [e[0] for e in events], "direction": [e[1] for e in events]}) if events else None
    if cab is None:
        want = ax * np.ones(n)
    else:
        te = cab["t"].to_numpy(dtype=float)
        order = np.argsort(te, kind="stable")
        want = ax * cab_signs(t, te[order], cab["direction"].astype(str).to_numpy()[order])
    got = _in_travel_frame(cab, t, ax, rows)
    assert np.array_equal(got, want) and not np.shares_memory(got, ax)


def test_travel_frame_by_hand() -> None:
    cab = pd.DataFrame({"t": [1.0, 0.0], "direction": ["R", "F"]})  # unsorted events
    t = np.array([-0.5, 0.5, 1.0, 2.0])
    assert np.array_equal(_in_travel_frame(cab, t, np.full(4, 2.0), rows=3), [2.0, 2.0, -2.0, -2.0])
