"""dbtools.rules.topology_tables: the integer join of the topology rules."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given
from hypothesis import strategies as st

from dbtools.rules.topology_tables import int_join


def test_int_join_hand_computed() -> None:
    """left [5, 1, 5, 9], right [5, 7, 5, 1]: 5 → right rows 0 and 2, 1 → row 3, 9 → none;
    pairs by left row, then right row."""
    li, ri = int_join(np.array([5, 1, 5, 9]), np.array([5, 7, 5, 1]))
    assert list(zip(li.tolist(), ri.tolist(), strict=True)) == [(0, 0), (0, 2), (1, 3), (2, 0), (2, 2)]


keys = st.lists(st.integers(0, 6), max_size=30)


@given(keys, keys)
def test_int_join_is_the_inner_merge(left: list[int], right: list[int]) -> None:
    """The same row pairs in the same order as pandas' inner merge (what the rules used)."""
    li, ri = int_join(np.array(left, dtype=np.int64), np.array(right, dtype=np.int64))
    a = pd.DataFrame({"k": pd.Series(left, dtype=np.int64), "i": np.arange(len(left))})
    b = pd.DataFrame({"k": pd.Series(right, dtype=np.int64), "j": np.arange(len(right))})
    m = a.merge(b, on="k")
    assert li.tolist() == m["i"].tolist() and ri.tolist() == m["j"].tolist()
