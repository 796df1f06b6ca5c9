"""canonical() skips the primary-key sort only when the rows are already in sorted order."""

from __future__ import annotations

import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import canonical, sorted_by
from schemas.tables import GIS

CODES = st.sampled_from(["0420", "0421", "042", "1", "A", "a", "é", "路線", ""])
ROWS = st.lists(
    st.tuples(
        st.one_of(CODES, st.none()),
        st.sampled_from(["U", "D", "S"]),
        st.one_of(st.sampled_from([0.0, -0.0, 20.0, 40.0, 1e9, -20.0]), st.none()),
    ),
    max_size=12,
)


def _frame(rows: list[tuple[str | None, str, float | None]]) -> pd.DataFrame:
    return pd.DataFrame(
        {
            "line_code": pd.array([r[0] for r in rows], dtype="string"),
            "track": pd.array([r[1] for r in rows], dtype="string"),
            "km_m": pd.array([r[2] for r in rows], dtype="float64"),
            "lat": pd.array(range(len(rows)), dtype="float64"),  # tells the rows apart
            "lon": 0.0,
        }
    )


@settings(max_examples=300, deadline=None)
@given(ROWS)
def test_sorted_by_agrees_with_a_stable_sort(rows: list[tuple[str | None, str, float | None]]) -> None:
    frame = _frame(rows)
    key = list(GIS.primary_key)
    by_sort = frame.sort_values(key, kind="stable").reset_index(drop=True)
    if sorted_by(frame, GIS.primary_key):
        assert by_sort.equals(frame)  # skipping the sort changes nothing
    assert canonical(GIS, frame)[frame.columns].equals(by_sort)
    assert sorted_by(by_sort, GIS.primary_key) or by_sort[key].isna().any().any()
