"""The columnar CSV writer writes pandas' own bytes (dbtools/csvwrite.py)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.csvwrite import csv_bytes, write_csv

FLOATS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=-1e7, max_value=1e7),
    st.integers(-(10**6), 10**6).map(float),
    st.sampled_from([0.0, -0.0, 1e-4, 9.999999999999999e-05, 1e10, 9999999999.999998, 1e16, 5e-324]),
)
TEXT = st.one_of(st.none(), st.text(max_size=6), st.sampled_from(["determined", "a,b", 'say "x"', "l1\nl2", ""]))


def pandas_bytes(frame: pd.DataFrame) -> bytes:
    return str(frame.to_csv(index=False, lineterminator="\n")).encode("utf-8")


@settings(max_examples=150, deadline=None)
@given(
    st.integers(0, 25).flatmap(
        lambda n: st.tuples(
            st.lists(FLOATS, min_size=n, max_size=n),
            st.lists(TEXT, min_size=n, max_size=n),
            st.lists(st.booleans(), min_size=n, max_size=n),
            st.lists(st.integers(-(2**40), 2**40), min_size=n, max_size=n),
        )
    ),
    st.sampled_from(["string", "str", "object"]),
)
def test_bytes_are_pandas_to_csv(cols, text_dtype) -> None:  # type: ignore[no-untyped-def]
    f, s, b, i = cols
    frame = pd.DataFrame(
        {
            "x": np.array(f, dtype=float),
            "s": pd.Series(s, dtype=text_dtype),
            "b": np.array(b, dtype=bool),
            "i": np.array(i, dtype=np.int64),
        }
    )
    assert csv_bytes(frame) == pandas_bytes(frame)


def test_other_frames_are_written_by_pandas(tmp_path: Path) -> None:
    frames = [
        pd.DataFrame({"only": ["", "a"]}),  # one column: csv quotes an empty cell
        pd.DataFrame({"t": pd.to_datetime(["2026-01-01", None]), "x": [1.5, np.nan]}),
        pd.DataFrame({"n": pd.array([1, None], dtype="Int64"), "x": [1.0, 2.0]}),
        pd.DataFrame({"a,b": [1.0], "x": [2.0]}),  # a column name that needs quotes
        pd.DataFrame({"o": [{"k": 1}, None], "x": [1.0, 2.0]}),  # a non-string object
        pd.DataFrame({"x": [], "y": []}),
    ]
    for j, frame in enumerate(frames):
        write_csv(frame, tmp_path / f"{j}.csv")
        assert (tmp_path / f"{j}.csv").read_bytes() == pandas_bytes(frame), j


def test_hand_written_cells() -> None:
    frame = pd.DataFrame({"km": [1150.0, 0.1 + 0.2, np.nan, -0.0, 1e16, 1.5e-05], "s": ["a", None, "b", "", "c", "d"]})
    assert csv_bytes(frame) == (b"km,s\n1150.0,a\n0.30000000000000004,\n,b\n-0.0,\n1e+16,c\n1.5e-05,d\n")
