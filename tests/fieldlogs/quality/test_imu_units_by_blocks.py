"""The IMU unit rule computed block by block (``usability.imu_unit_problems``): the same
|a| and rate maxima, bit for bit, as the whole-frame n×3 computation it replaced, so the
same findings; whatever the frame's layout, the block size and non-finite values."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldlogs.quality.usability import _row_values, imu_unit_problems

ACC, RATE = ["ax", "ay", "az"], ["wx", "wy", "wz"]


def whole_mag(frame: pd.DataFrame) -> np.ndarray:
    """|a| as the rule computed it on the whole frame (before: one n×3 copy)."""
    a = frame[ACC].to_numpy(dtype=float, na_value=np.nan)
    mag = np.sqrt((a * a).sum(axis=1))
    return mag[np.isfinite(mag)]


def whole_w_max(frame: pd.DataFrame) -> np.ndarray:
    w = np.fmax.reduce(np.abs(frame[RATE].to_numpy(dtype=float, na_value=np.nan)), axis=1)
    return w[np.isfinite(w)]


def frames(values: np.ndarray) -> list[pd.DataFrame]:
    """The same columns as one 2-D block and as one array per column."""
    cols = ACC + RATE
    one_block = pd.DataFrame(values, columns=cols)
    per_column = pd.DataFrame({c: values[:, j].copy() for j, c in enumerate(cols)}, copy=False)
    return [one_block, per_column]


@settings(max_examples=200, deadline=None)
@given(
    cells=st.lists(
        st.one_of(st.floats(-1e3, 1e3), st.floats(-20.0, 20.0), st.just(float("nan")), st.just(float("inf"))),
        min_size=6,
        max_size=600,
    ),
    rows=st.integers(1, 40),
    scale=st.sampled_from([1.0, 1 / 9.80665, 57.3]),
)
def test_blocks_give_the_whole_frame_values(cells: list[float], rows: int, scale: float) -> None:
    n = len(cells) // 6
    values = np.asarray(cells[: 6 * n], dtype=float).reshape(n, 6) * scale
    for frame in frames(values):
        mag = _row_values(frame, ACC, lambda a: np.sqrt((a * a).sum(axis=1)), rows)
        w = _row_values(frame, RATE, lambda x: np.fmax.reduce(np.abs(x), axis=1), rows)
        assert np.array_equal(mag, whole_mag(frame)) and np.array_equal(w, whole_w_max(frame))
        assert imu_unit_problems(frame, rows) == imu_unit_problems(frame, 10**9)


def test_units_found_by_hand() -> None:
    """At rest: |a| = 9.81 m/s² passes; the same in g (1.0) and gyro rates in deg/s are named."""
    n = 200
    rest = pd.DataFrame({"ax": 0.0, "ay": 0.0, "az": np.full(n, 9.81), "wx": 0.0, "wy": 0.0, "wz": np.full(n, 0.01)})
    assert imu_unit_problems(rest, 7) == []
    in_g = rest.assign(az=1.0, wz=np.full(n, 0.01 * 57.3 * 20))
    found = imu_unit_problems(in_g, 7)
    assert [c for c, _ in found] == ["az", "wz"]
    assert "median |a| 1," in found[0][1] and "multiply by 9.80665" in found[0][1]
