"""The foreign keys checked on the frames are SQLite's ``foreign_key_check`` (dbtools/foreign_keys.py)."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.foreign_keys import check_foreign_keys, dangling, parent_keys
from dbtools.network import canonical, empty_frame
from schemas.tables import SOURCE_TABLES

LINES, TRACKS, TRACK_POINTS = (SOURCE_TABLES[n] for n in ("lines", "tracks", "track_points"))
CODES = st.sampled_from(["0001", "0002", "0001 ", "é", "", "1"])


def frames(lines: list[str], tracks: list[tuple[str, str | None]], points: list[str]) -> list:  # type: ignore[type-arg]
    lf = pd.DataFrame({"line_code": sorted(set(lines))})
    tf = pd.DataFrame(
        {
            "track_id": [f"T{i}" for i in range(len(tracks))],
            "line_code": [code for _, code in tracks],
            "kind": "station",
            "length_m": 10.0,
        }
    )
    pf = pd.DataFrame({"track_id": points, "pos_m": [float(i) for i in range(len(points))], "lat": 35.0, "lon": 139.0})
    pairs = ((LINES, lf), (TRACKS, tf), (TRACK_POINTS, pf))
    return [(t, canonical(t, f if len(f) else empty_frame(t))) for t, f in pairs]


def sqlite_finds(tables: list, tmp_path: Path) -> bool:  # type: ignore[type-arg]
    """Whether SQLite's ``foreign_key_check`` lists a row of the tables written as ``write_db`` writes them."""
    import sqlite_utils

    from dbtools.database import create_tables, table_rows

    path = tmp_path / "fk.sqlite"
    path.unlink(missing_ok=True)
    conn = sqlite3.connect(path)
    try:
        create_tables(sqlite_utils.Database(conn), tuple(t for t, _ in tables))
        for t, f in tables:
            marks = ",".join("?" * len(t.columns))
            conn.executemany(f"INSERT INTO [{t.name}] VALUES ({marks})", table_rows(t, f))
        conn.commit()
        return conn.execute("PRAGMA foreign_key_check").fetchone() is not None
    finally:
        conn.close()


@settings(max_examples=60, deadline=None)
@given(
    st.lists(CODES, max_size=3),
    st.lists(st.one_of(st.none(), CODES), max_size=4),
    st.lists(st.sampled_from(["T0", "T1", "T2", "T3", "t0", "T0 "]), max_size=5),
)
def test_the_frames_fail_when_sqlite_finds_a_row(lines, track_lines, points) -> None:  # type: ignore[no-untyped-def]
    import tempfile

    tables = frames(lines, [(f"T{i}", code) for i, code in enumerate(track_lines)], points)
    with tempfile.TemporaryDirectory() as tmp:
        expected = sqlite_finds(tables, Path(tmp))
    if expected:
        with pytest.raises(sqlite3.IntegrityError, match="FOREIGN KEY constraint failed"):
            check_foreign_keys(tables)
    else:
        check_foreign_keys(tables)


def _first_dangling(child: pd.Series, parent: pd.Series) -> int:
    """:func:`dangling` of ``child`` against the key column ``parent`` (via :func:`parent_keys`)."""
    keys = parent_keys({"p": pd.DataFrame({"k": parent})})
    return dangling(child, lambda: keys("p", "k"))


def test_by_hand() -> None:
    parent = pd.Series(["A", "B"], dtype="string")
    assert _first_dangling(pd.Series(["A", None, "B", "A"], dtype="string"), parent) == -1  # a null references nothing
    assert _first_dangling(pd.Series(["A", "b", "C"], dtype="string"), parent) == 1  # case counts
    assert _first_dangling(pd.Series([None, None], dtype="string"), pd.Series([], dtype="string")) == -1
    assert _first_dangling(pd.Series(["A"], dtype="string"), pd.Series([], dtype="string")) == 0
    tables = frames(["0001"], [("T0", "0001"), ("T1", "0002")], [])
    with pytest.raises(sqlite3.IntegrityError, match="tracks row 2: line_code '0002' is not a line_code of lines"):
        check_foreign_keys(tables)


def test_write_db_writes_nothing_when_a_track_is_missing(tmp_path: Path) -> None:
    from dbtools.database import write_db
    from dbtools.network import Network

    tables = frames(["0001"], [("T0", "0001")], ["T0", "T9"])
    net = Network({t.name: f for t, f in tables})
    out = tmp_path / "out.sqlite"
    with pytest.raises(sqlite3.IntegrityError, match="track_points row 2: track_id 'T9'"):
        write_db(out, net, {"db_version": "t"})
    assert not out.exists() and list(tmp_path.iterdir()) == []
