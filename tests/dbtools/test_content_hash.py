"""The content hash's text bytes, built in Arrow, are those every stored hash was made of."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import joined_text


def former(s: pd.Series) -> bytes:
    """How content_hash joined a text column before (the reference of the stored hashes)."""
    return "\x1f".join(s.astype(object).where(s.notna(), "\x00").tolist()).encode("utf-8")


@settings(max_examples=100, deadline=None)
@given(st.lists(st.one_of(st.none(), st.text(max_size=5)), max_size=12), st.sampled_from(["string", "str", "object"]))
def test_joined_text_is_the_former_join(values: list[str | None], dtype: str) -> None:
    s = pd.Series(values, dtype=dtype)
    assert joined_text(s) == former(s)
    assert joined_text(s.iloc[1:]) == former(s.iloc[1:])  # a sliced (offset) column


def test_a_missing_value_is_the_empty_string() -> None:
    assert joined_text(pd.Series(["a", None, "é"], dtype="string")) == "a\x1f\x1fé".encode()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.one_of(st.none(), st.sampled_from(["", "a", "bc", "U", "é"])), max_size=20), st.integers(1, 4))
def test_parts_of_any_size_join_to_the_former_bytes(values: list[str | None], block: int) -> None:
    """Parts of ``block`` values (equal lengths reshaped, others with inserted separators),
    over a column of several Arrow chunks, concatenate to the former join."""
    import pyarrow as pa

    import dbtools.network as network_mod

    s = pd.Series(values, dtype="string")
    chunked = pd.Series(
        pd.arrays.ArrowStringArray(
            pa.chunked_array([pa.array(values[:3], pa.string()), pa.array(values[3:], pa.string())])
        )
    )
    old = network_mod.TEXT_BLOCK
    network_mod.TEXT_BLOCK = block
    try:
        assert joined_text(s) == former(s)
        assert joined_text(chunked) == former(s)
    finally:
        network_mod.TEXT_BLOCK = old


def test_a_negative_zero_hashes_as_zero() -> None:
    """SQLite keeps no sign of a zero REAL (stored as the integer 0): the hash must not either."""
    import numpy as np

    from dbtools.network import hashed_floats

    got = hashed_floats(pd.Series([-0.0, 0.0, float("nan"), -1.5, None], dtype="Float64"))
    assert got.tobytes() == np.array([0.0, 0.0, np.nan, -1.5, np.nan]).tobytes()
    assert not np.signbit(got[:2]).any()


def test_a_built_db_with_a_negative_zero_height_keeps_its_hash(tiny_sources: Path, tmp_path: Path) -> None:
    """Found on a 1.1 M-point synthetic network: a height of ``-0.0`` in the sources (rounded from
    a small negative number) read back as ``0.0`` from the DB, and ``db validate`` reported the DB
    as modified after it was built."""
    import sqlite3

    from dbtools.build import build_db
    from dbtools.validate import validate_path

    gis = pd.read_csv(tiny_sources / "gis.csv", dtype=str)
    gis["height_m"] = ["-0.0"] + ["0.5"] * (len(gis) - 1)
    gis.to_csv(tiny_sources / "gis.csv", index=False)
    db = tmp_path / "db.sqlite"
    build_db(tiny_sources, db, db_version="t")
    with sqlite3.connect(db) as con:  # what SQLite gives back: a zero without its sign
        assert con.execute("SELECT height_m FROM gis ORDER BY line_code, track, km_m LIMIT 1").fetchone()[0] == 0
    assert [f for f in validate_path(db) if f.rule == "db.content_hash"] == []
