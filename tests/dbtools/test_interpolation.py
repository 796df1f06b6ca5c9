"""``Interpolation`` (dbtools.rules.track_geometry): the bracket of each x searched once, every
value ``np.interp``'s to the bit."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.rules.track_geometry import Interpolation

FLOATS = st.floats(min_value=-50.0, max_value=50.0, allow_nan=False, width=64)


def same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


def test_hand_computed() -> None:
    xp = np.array([0.0, 10.0, 10.0, 30.0])
    fp = np.array([1.0, 3.0, 5.0, 9.0])
    x = np.array([-1.0, 0.0, 5.0, 10.0, 20.0, 30.0, 31.0, np.nan])
    got = Interpolation(x, xp)(fp)
    # left of xp: fp[0]; 5 m: 1 + 2·5/10; at the doubled 10: the last of the pair; 20: 5 + 4·10/20; from 30 on: fp[-1]
    assert np.array_equal(got, [1.0, 1.0, 2.0, 5.0, 7.0, 9.0, 9.0, np.nan], equal_nan=True)
    assert same_bits(got, np.interp(x, xp, fp))


def test_nan_slope_from_the_other_end() -> None:
    xp = np.array([0.0, 1.0, 2.0])
    fp = np.array([np.inf, np.inf, 4.0])
    x = np.array([0.5, 1.5])
    assert same_bits(Interpolation(x, xp)(fp), np.interp(x, xp, fp))


def test_falls_back_to_np_interp_for_a_short_or_unsorted_xp() -> None:
    for xp in (np.array([2.0]), np.array([0.0, 2.0, 1.0]), np.array([0.0, np.nan, 1.0])):
        x = np.array([np.nan, 0.5, 3.0])
        fp = np.arange(len(xp), dtype=float)
        lookup = Interpolation(x, xp)
        assert lookup.plain
        assert same_bits(lookup(fp), np.interp(x, xp, fp))


@settings(max_examples=300, deadline=None)
@given(
    st.lists(FLOATS, min_size=2, max_size=30),
    st.lists(st.one_of(FLOATS, st.just(float("nan"))), min_size=1, max_size=30),
    st.lists(st.one_of(FLOATS, st.just(float("nan")), st.just(float("inf"))), min_size=30, max_size=30),
    st.booleans(),
)
def test_bit_identical_to_np_interp(
    xp_list: list[float], x_list: list[float], fp_list: list[float], snap: bool
) -> None:
    xp = np.sort(np.array(xp_list))
    x = np.array(x_list)
    if snap:  # many x exactly on a point of xp
        x[::2] = xp[np.arange(0, len(x), 2) % len(xp)]
    lookup = Interpolation(x, xp)
    for fp in (np.array(fp_list[: len(xp)]), np.cumsum(np.abs(np.nan_to_num(fp_list[: len(xp)], posinf=1.0)))):
        assert same_bits(lookup(fp), np.interp(x, xp, fp))
