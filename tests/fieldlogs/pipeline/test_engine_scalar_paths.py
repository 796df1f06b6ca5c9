"""The second pass on the engine's cost (issue 31) keeps every number: the one-point path of
the km ↔ rolled-length interpolation gives the array formula's value (and shape) exactly, and
:func:`~fieldlogs.pipeline.types.evolved` makes the object ``dataclasses.replace`` makes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.pipeline.metric import TrackMetric, _interp_extrapolated
from fieldlogs.pipeline.types import Fix, FloatArray, Hypothesis, evolved
from schemas.enums import FixSource, PositionState


def extrapolated_np(x: FloatArray | float, xp: FloatArray, fp: FloatArray) -> FloatArray:
    """The array formula: np.interp, then slope 1 below the first and above the last point."""
    xa = np.asarray(x, dtype=float)
    out = np.interp(xa, xp, fp)
    out = np.where(xa < xp[0], fp[0] + (xa - xp[0]), out)
    return np.asarray(np.where(xa > xp[-1], fp[-1] + (xa - xp[-1]), out), dtype=np.float64)


def same(a: FloatArray, b: FloatArray) -> bool:
    """Equal values (NaN as NaN, signed zeros apart), shape and dtype."""
    return (
        a.shape == b.shape
        and a.dtype == b.dtype
        and bool(np.array_equal(a, b, equal_nan=True))
        and bool(np.array_equal(np.signbit(a), np.signbit(b)))
    )


M = TrackMetric(np.array([100.0, 200.0, 400.0]), np.array([0.0, 100.2, 300.0]))


@pytest.mark.parametrize(
    ("km", "c"),
    [
        (100.0, 0.0),  # the first point
        (150.0, 50.1),  # halfway along the first interval: 0 + 0.5 · 100.2
        (300.0, 200.1),  # halfway along the second: 100.2 + 0.5 · 199.8
        (400.0, 300.0),  # the last point
        (90.0, -10.0),  # 10 m before the grid: slope 1
        (410.5, 310.5),  # 10.5 m beyond it: slope 1
    ],
)
def test_one_point_by_hand(km: float, c: float) -> None:
    for x in (km, np.array(km), np.array([km])):
        got = M.c_of_km(x)
        assert got.shape == np.shape(x) and got.dtype == np.float64
        assert math.isclose(float(got.reshape(-1)[0]), c, abs_tol=1e-9)
    assert math.isclose(float(M.km_of_c(c)), km, abs_tol=1e-9)


def test_one_point_nan_and_infinities() -> None:
    assert math.isnan(float(M.c_of_km(math.nan)))
    assert float(M.c_of_km(math.inf)) == math.inf
    assert float(M.c_of_km(-math.inf)) == -math.inf


finite = st.floats(-1e6, 1e6, allow_nan=False)


@settings(max_examples=300, deadline=None)
@given(
    xp=st.lists(finite, min_size=2, max_size=12, unique=True),
    steps=st.lists(st.floats(0.0, 5.0), min_size=12, max_size=12),
    x=st.one_of(st.floats(-2e6, 2e6), st.sampled_from([math.nan, math.inf, -math.inf, 0.0, -0.0])),
    shape=st.sampled_from([(), (1,), (1, 1)]),
    reverse=st.booleans(),
)
def test_one_point_is_the_array_formula(
    xp: list[float], steps: list[float], x: float, shape: tuple[int, ...], reverse: bool
) -> None:
    xs = np.sort(np.asarray(xp))
    xs = xs[::-1].copy() if reverse else xs  # np.interp's undefined order: still the same numbers
    fs = np.cumsum(np.asarray(steps[: xs.size]))
    xa = np.full(shape, x)
    assert same(_interp_extrapolated(xa, xs, fs), extrapolated_np(xa, xs, fs))
    assert same(_interp_extrapolated(x, xs, fs), extrapolated_np(x, xs, fs))
    # the points themselves: the grid's ends and between them
    for v in xs.tolist():
        assert same(_interp_extrapolated(v, xs, fs), extrapolated_np(v, xs, fs))


FIX = Fix(
    1.0, 2.0, 3.0, 4.0, 5.0, "L1", "1", 1, FixSource.GPS, 1.5, hyps=(Hypothesis("T1", 10.0, -1, extra_m=2.0, hid=7),)
)


def test_evolved_is_replace() -> None:
    h = FIX.hyps[0]
    for obj, changes in (
        (FIX, {"d_ref": 9.0, "t_ref": 8.0, "source": FixSource.FEATURE}),
        (FIX, {"state": PositionState.UNCERTAIN, "uncertain_since_d": None, "hyps": (h, h)}),
        (FIX, {}),
        (h, {"pos_m": 11.5, "extra_m": 0.0}),
    ):
        new, ref = evolved(obj, **changes), dataclasses.replace(obj, **changes)  # type: ignore[type-var]
        assert new == ref and new is not obj and type(new) is type(ref)
        assert vars(new) == vars(ref) and hash(new) == hash(ref)
    assert FIX.d_ref == 3.0  # the original is untouched
    with pytest.raises(dataclasses.FrozenInstanceError):
        evolved(FIX, d_ref=0.0).d_ref = 1.0  # type: ignore[misc]


def test_evolved_refuses_an_unknown_field() -> None:
    with pytest.raises(TypeError, match="no field bogus"):
        evolved(FIX, bogus=1)


@pytest.mark.parametrize("cls", [Fix, Hypothesis])
def test_evolved_classes_are_plain(cls: type) -> None:
    """What makes the copy ``replace``'s object: every field an ``__init__`` argument, no
    ``__post_init__``."""
    assert all(f.init for f in dataclasses.fields(cls))
    assert not hasattr(cls, "__post_init__")
