"""The pandera-free screen of check_frame: whenever it clears a frame pandera finds nothing,
so check_frame's findings are pandera's on every frame (hypothesis over damaged cells)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import schemas.frames as frames_mod
from schemas.findings import Finding
from schemas.frame_screen import key_order, passes_checks
from schemas.frames import check_frame
from schemas.model import Table
from schemas.tables import BALISES, FEATURE_POINTS, GIS

_CLEAN_GIS: dict[str, list[object]] = {
    "line_code": ["A", "A", "A", "B"],
    "track": ["D", "U", "U", "U"],
    "km_m": [0.0, 0.0, 20.0, 0.0],
    "lat": [35.0, 35.0, 35.0001, 36.0],
    "lon": [139.0, 139.0, 139.0, 139.5],
    "height_m": [1.0, None, 2.0, None],
}
_BAD: dict[str, list[object]] = {
    "line_code": [None, "A", "B", "A"],
    "track": [None, "X", "U", "D"],
    "km_m": [math.nan, math.inf, -3e6, 20.0, 0.0],
    "lat": [95.0, -math.inf, math.nan, 35.0],
    "lon": [200.0, math.nan, 139.0],
    "height_m": [math.inf, -1.0, math.nan],
}


def _gis(cells: dict[str, list[object]]) -> pd.DataFrame:
    return pd.DataFrame(
        {
            c.name: pd.Series(cells[c.name], dtype="string" if c.dtype == "str" else "float64")
            for c in GIS.columns
            if c.name in cells
        }
    )


def _pandera_only(table: Table, frame: pd.DataFrame, monkeypatch: pytest.MonkeyPatch) -> list[Finding]:
    with monkeypatch.context() as m:
        m.setattr(frames_mod, "passes_checks", lambda *a, **k: False)
        return check_frame(table, frame)


def test_clean_frames_pass_without_pandera(monkeypatch: pytest.MonkeyPatch) -> None:
    frame = _gis(_CLEAN_GIS)
    assert passes_checks(GIS, frame)
    assert check_frame(GIS, frame) == [] == _pandera_only(GIS, frame, monkeypatch)


def test_each_kind_of_problem_goes_to_pandera(monkeypatch: pytest.MonkeyPatch) -> None:
    cases = [
        ("line_code", 0, None),  # null in a non-nullable column
        ("track", 1, "X"),  # outside the enumeration
        ("lat", 2, 95.0),  # outside the range
        ("lon", 3, math.inf),  # infinite: no finding here (check_values' schema.not_finite)
        ("km_m", 2, 0.0),  # repeated key (A, U, 0)
    ]
    for column, row, value in cases:
        cells = {k: list(v) for k, v in _CLEAN_GIS.items()}
        cells[column][row] = value
        frame = _gis(cells)
        assert not passes_checks(GIS, frame), (column, value)
        found = check_frame(GIS, frame)
        assert repr(found) == repr(_pandera_only(GIS, frame, monkeypatch)), (column, value)
        assert bool(found) == (value is not math.inf), (column, value)


@settings(max_examples=60, deadline=None)
@given(st.data())
def test_findings_are_pandera_s(data: st.DataObject) -> None:
    cells = {k: list(v) for k, v in _CLEAN_GIS.items()}
    for _ in range(data.draw(st.integers(0, 3))):
        column = data.draw(st.sampled_from(sorted(cells)))
        row = data.draw(st.integers(0, len(cells[column]) - 1))
        cells[column][row] = data.draw(st.sampled_from(_BAD[column]))
    frame = _gis(cells)
    if data.draw(st.booleans()):
        frame = frame.iloc[data.draw(st.permutations(range(len(frame))))].reset_index(drop=True)
    with pytest.MonkeyPatch.context() as m:
        expected = _pandera_only(GIS, frame, m)
    assert repr(check_frame(GIS, frame)) == repr(expected)  # repr: a NaN value equals itself
    if passes_checks(GIS, frame):
        assert expected == []


def test_int_and_other_tables(monkeypatch: pytest.MonkeyPatch) -> None:
    fp = pd.DataFrame(
        {
            "line_code": pd.Series(["A", "A"], dtype="string"),
            "track": pd.Series(["U", "U"], dtype="string"),
            "feature_id": pd.Series(["f", "f"], dtype="string"),
            "seq": pd.Series([1, 2], dtype="Int64"),
            "km_m": [0.0, 20.0],
        }
    )
    assert check_frame(FEATURE_POINTS, fp) == _pandera_only(FEATURE_POINTS, fp, monkeypatch)
    fp.loc[1, "seq"] = 1  # repeated key
    assert not passes_checks(FEATURE_POINTS, fp)
    assert check_frame(FEATURE_POINTS, fp) == _pandera_only(FEATURE_POINTS, fp, monkeypatch) != []
    empty = pd.DataFrame({c.name: pd.Series([], dtype=object) for c in BALISES.columns})
    assert passes_checks(BALISES, empty) and check_frame(BALISES, empty) == []


def test_key_order() -> None:
    frame = pd.DataFrame({"a": pd.Series(["x", "x", "y"], dtype="string"), "b": [1.0, 2.0, 0.0]})
    assert key_order(frame, ("a", "b")) == (True, True)
    assert key_order(frame, ("a",)) == (True, False)
    assert key_order(frame.iloc[::-1], ("a", "b")) == (False, False)
    frame.loc[0, "b"] = np.nan
    assert key_order(frame, ("a", "b")) == (False, False)


@settings(max_examples=150, deadline=None)
@given(
    st.lists(
        st.tuples(st.sampled_from(["", "a", "ab", "b", "é", "😀"]), st.sampled_from(["U", "D"]), st.integers(0, 3)),
        max_size=30,
    ),
    st.booleans(),
)
def test_key_order_is_that_of_the_key_tuples(rows: list[tuple[str, str, int]], sort: bool) -> None:
    """(sorted, unique) of the rows' key tuples as Python orders them (text by code point),
    for text keys whose order is decided only where two texts differ."""
    rows = sorted(rows) if sort else rows
    frame = pd.DataFrame(
        {
            "l": pd.array([r[0] for r in rows], dtype="str"),
            "t": pd.array([r[1] for r in rows], dtype="str"),
            "k": [float(r[2]) for r in rows],
        }
    )
    in_order = all(a <= b for a, b in itertools.pairwise(rows))
    unique = all(a < b for a, b in itertools.pairwise(rows))
    assert key_order(frame, ("l", "t", "k")) == ((True, unique) if in_order else (False, False))
    pairs = [(r[0], r[1]) for r in rows]
    in_order = all(a <= b for a, b in itertools.pairwise(pairs))
    unique = all(a < b for a, b in itertools.pairwise(pairs))
    assert key_order(frame, ("l", "t")) == ((True, unique) if in_order else (False, False))
