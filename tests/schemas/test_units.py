from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from schemas.units import G, format_km, kmh_s_to_mps2, parse_km, parse_km_array


@pytest.mark.parametrize(
    ("text", "metres"),
    [("12k345.6", 12345.6), ("0k005", 5.0), ("12345.6", 12345.6), ("-0k100.0", -100.0), (" 1k000 ", 1000.0)],
)
def test_parse_km(text: str, metres: float) -> None:
    assert parse_km(text) == pytest.approx(metres)


@pytest.mark.parametrize("text", ["12k34.5", "abc", "1k", "nan", "inf"])
def test_parse_km_rejects(text: str) -> None:
    with pytest.raises(ValueError):
        parse_km(text)


def test_parse_km_array_marks_bad_cells() -> None:
    vals, ok = parse_km_array(["1k000", "", "x", "20"])
    assert ok.tolist() == [True, True, False, True]
    assert vals[0] == 1000.0 and math.isnan(vals[1]) and vals[3] == 20.0


@given(st.floats(min_value=-1e7, max_value=1e7, allow_nan=False))
def test_format_parse_roundtrip(m: float) -> None:
    assert parse_km(format_km(m)) == pytest.approx(round(m, 1), abs=0.051)


def test_paper_threshold_in_si() -> None:
    # Ta = 1.23 km/h/s is the gravity component of a 35 permille gradient (SPEC 5.1)
    assert kmh_s_to_mps2(1.23) == pytest.approx(G * np.sin(np.arctan(0.035)), rel=0.01)
