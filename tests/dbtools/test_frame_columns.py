"""dbtools.gis.frame_columns.text_codes: codes of a text column in the sorted order of its
values — by runs of equal texts (a GIS frame's line and track) or by Arrow's dictionary
encoding — by hand and the same either way (hypothesis)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import dbtools.gis.frame_columns as fc


def test_text_codes_by_hand() -> None:
    frame = pd.DataFrame({"t": pd.array(["b"] * 20 + ["a"] * 20 + ["é"] * 10 + ["b"] * 14, dtype="str")})
    codes, values = fc.text_codes(frame, "t")
    assert values.tolist() == ["a", "b", "é"]
    assert codes.tolist() == [1] * 20 + [0] * 20 + [2] * 10 + [1] * 14
    frame.loc[3, "t"] = None  # a missing value: −1, by the dictionary
    codes, values = fc.text_codes(frame, "t")
    assert codes[3] == -1 and values.tolist() == ["a", "b", "é"]


@settings(max_examples=100, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["", "U", "D", "0001", "😀", "ab"]), st.integers(1, 40)), max_size=12))
def test_runs_give_the_dictionary_codes(runs: list[tuple[str, int]]) -> None:
    texts = [t for t, k in runs for _ in range(k)]
    frame = pd.DataFrame({"t": pd.array(texts, dtype="str")})
    by_runs = fc.text_codes(frame, "t")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(fc, "_run_codes", lambda arr: None)
        by_dict = fc.text_codes(frame, "t")
    assert by_runs[0].dtype == by_dict[0].dtype == np.int64
    assert by_runs[0].tolist() == by_dict[0].tolist() and by_runs[1].tolist() == by_dict[1].tolist()
    assert by_runs[1].tolist() == sorted(set(texts))
