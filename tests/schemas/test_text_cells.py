"""The byte-judged stripping of text cells is the Arrow kernels' (schemas/text_cells.py)."""

from __future__ import annotations

import pyarrow as pa
from hypothesis import given, settings
from hypothesis import strategies as st

from schemas.text_cells import stripped_text, stripped_text_kernels

#: Pads (ASCII and Unicode whitespace, controls), blank words in any case, non-ASCII letters.
PIECES = ["a", "N", "n", "A", "u", "l", "L", "0001-D", " ", "\t", "\x0b", "\x1f", "\u3000", "\xa0", "é", "Ｆ", "\x7f"]
CELLS = st.one_of(
    st.none(),
    st.sampled_from(["", "nan", "NaN", "NA", "na", "null", "NULL", "nul", "nana", "n", " na ", "x"]),
    st.lists(st.sampled_from(PIECES), max_size=4).map("".join),
)


@settings(max_examples=300, deadline=None)
@given(
    st.lists(st.lists(CELLS, max_size=6), min_size=1, max_size=3),
    st.booleans(),
    st.integers(0, 2),
)
def test_stripped_text_is_the_kernels(chunks: list[list[str | None]], large: bool, cut: int) -> None:
    t = pa.large_string() if large else pa.string()
    arrays = [pa.array(c, type=t) for c in chunks]
    arrays = [a.slice(min(cut, len(a))) for a in arrays]  # chunks with an offset
    arr = pa.chunked_array(arrays, type=t)
    ours, ref = stripped_text(arr), stripped_text_kernels(arr)
    assert ours.type == ref.type
    assert ours.to_pylist() == ref.to_pylist()


def test_by_hand() -> None:
    arr = pa.chunked_array([pa.array(["0001", "", "NaN", None, "nul", "D"]), pa.array([" x", "y\u3000"])])
    out = stripped_text(arr)
    assert out.to_pylist() == ["0001", None, None, None, "nul", "D", "x", "y"]
    assert out.num_chunks == 2
    clean = pa.chunked_array([pa.array(["0001-D-1", "end"])])
    assert stripped_text(clean).chunk(0) is clean.chunk(0) or stripped_text(clean).equals(clean)
