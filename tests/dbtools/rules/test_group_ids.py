"""dbtools.rules.common.group_ids: the groups of rows by several typed columns, numbered in
the order they first appear, −1 where a key is missing (the balise pairs and the features)."""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.rules.common import column, group_ids


def test_group_ids_by_hand() -> None:
    frame = pd.DataFrame(
        {
            "line": pd.array(["B", "A", "B", None, "A", "B"], dtype="str"),
            "track": pd.array(["U", "U", "U", "U", "D", "U"], dtype="str"),
            "n": pd.array([1, 1, 1, 1, 1, None], dtype="Int64"),
        }
    )
    assert group_ids(frame, ("line", "track", "n")).tolist() == [0, 1, 0, -1, 2, -1]
    assert group_ids(frame, ("track",)).tolist() == [0, 0, 0, 0, 1, 0]
    assert group_ids(frame.iloc[:0], ("line",)).tolist() == []


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["a", "b", "ü", None]), st.sampled_from(["U", "D", None])), max_size=40))
def test_group_ids_are_the_groupby_of_the_object_columns(rows: list[tuple[str | None, str | None]]) -> None:
    """The same numbers as ``groupby(sort=False).ngroup()`` of the rows' object copies (what
    the rules grouped before), over the rows with every key present."""
    frame = pd.DataFrame(
        {"l": pd.array([r[0] for r in rows], dtype="str"), "t": pd.array([r[1] for r in rows], dtype="str")}
    )
    got = group_ids(frame, ("l", "t"))
    line, track = column(frame, "l"), column(frame, "t")
    keyed = pd.notna(line) & pd.notna(track)
    want = np.full(len(rows), -1, dtype=np.int64)
    if keyed.any():
        objs = pd.DataFrame({"l": line[keyed], "t": track[keyed]}, dtype=object)
        want[keyed] = objs.groupby(["l", "t"], sort=False).ngroup().to_numpy()
    assert got.tolist() == want.tolist()
