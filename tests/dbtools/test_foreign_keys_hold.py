"""``db validate`` skips ``PRAGMA foreign_key_check`` only where the frames it read prove the
pragma would list nothing (dbtools/foreign_keys.py ``foreign_keys_hold``): on DBs edited with
sqlite3 — broken references, deleted parents, NULLs, blobs, changed foreign keys — the
``db.foreign_key`` findings (ids, messages, order) equal those of the pragma itself, which
``integrity_findings`` runs when it is given no frames."""

from __future__ import annotations

import functools
import shutil
import sqlite3
from collections.abc import Iterator
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import dbtools.database as database
import dbtools.foreign_keys as foreign_keys
from dbtools.build import build_db
from dbtools.database import integrity_findings, read_network
from dbtools.foreign_keys import foreign_keys_hold
from dbtools.sqlite_columns import read_table_columns
from dbtools.sqlite_file import connect_ro
from schemas.tables import DB_TABLES
from tests.dbtools.test_topology_golden import synthetic


def nth(table: str, condition: str) -> str:
    """An SQL condition selecting the rows of ``table`` whose number ``n`` (1-based, in primary-key
    order: a rowid table's rowid as built) satisfies ``condition``; a ``WITHOUT ROWID`` table's
    rows have no rowid to select them by."""
    declared = next(t for t in DB_TABLES if t.name == table)
    if not declared.without_rowid:
        return f"rowid IN (SELECT n FROM (SELECT rowid AS n FROM {table}) WHERE {condition})"
    key = ", ".join(declared.primary_key)
    numbered = f"SELECT {key}, row_number() OVER (ORDER BY {key}) AS n FROM {table}"
    return f"({key}) IN (SELECT {key} FROM ({numbered}) WHERE {condition})"


#: (child table, column) of every foreign key of a network DB, and its parent (table, key).
LINKS = [(t.name, fk.columns[0], fk.other_table, fk.other_columns[0]) for t in DB_TABLES for fk in t.foreign_keys]

EDITS = {
    "a reference to no track": [f"UPDATE connections SET track_b = 'NOPE' WHERE {nth('connections', 'n IN (2, 5)')}"],
    "a track deleted": [f"DELETE FROM tracks WHERE {nth('tracks', 'n = 3')}"],
    "a line deleted": ["DELETE FROM lines WHERE rowid = 1"],
    "track points renamed": [
        f"UPDATE track_points SET track_id = track_id || 'x' WHERE {nth('track_points', 'n % 7 = 0')}"
    ],
    "a blob equal to its line's text": ["UPDATE gis SET line_code = CAST(line_code AS BLOB) WHERE rowid = 4"],
    "a blob track id": [f"UPDATE connections SET track_a = CAST(track_a AS BLOB) WHERE {nth('connections', 'n = 1')}"],
    "a blob parent key": ["UPDATE lines SET line_code = CAST(line_code AS BLOB) WHERE rowid = 2"],
    "a NULL reference": [f"UPDATE switches SET line_code = NULL WHERE {nth('switches', 'n = 1')}"],
    "a key with a trailing space": ["UPDATE balises SET line_code = line_code || ' ' WHERE rowid < 4"],
    "many": ["UPDATE gis SET line_code = 'ZZ' || rowid WHERE rowid % 2 = 0"],
    "a foreign key removed": [
        "PRAGMA writable_schema = ON",
        "UPDATE sqlite_master SET sql = replace(sql, 'REFERENCES \"lines\"(\"line_code\")', '') "
        "WHERE name = 'switches'",
    ],
    "a foreign key added": [
        "PRAGMA writable_schema = ON",
        "UPDATE sqlite_master SET sql = "
        'replace(sql, \'"name" TEXT\', \'"name" TEXT REFERENCES "lines"("line_code")\') '
        "WHERE name = 'tracks'",
    ],
    "a key column declared without type": [
        "PRAGMA writable_schema = ON",
        "UPDATE sqlite_master SET sql = replace(sql, '\"track_id\" TEXT', '\"track_id\"') WHERE name = 'track_points'",
    ],
}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("fk")
    db = tmp / "net.sqlite"
    build_db(synthetic(tmp / "src"), db, db_version="t")
    return db


@pytest.fixture(params=["sqlite3", "adbc"])
def reader(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> Iterator[str]:
    """Both readers of read_network: sqlite3 (files < 4 MB) and ADBC (forced for small files)."""
    if request.param == "adbc":
        pytest.importorskip("adbc_driver_sqlite")
        monkeypatch.setattr(database, "read_table_columns", functools.partial(read_table_columns, min_bytes=0))
    yield str(request.param)


def edited(built: Path, folder: Path, sqls: list[str]) -> Path:
    db = folder / "edited.sqlite"
    shutil.copy(built, db)
    with sqlite3.connect(db) as conn:
        for sql in sqls:
            conn.execute(sql)
    conn.close()
    return db


def fk_findings(db: Path, *, frames: bool) -> list[dict[str, object]]:
    net = read_network(db, verify=False) if frames else None
    return [f.to_dict() for f in integrity_findings(db, net) if f.rule == "db.foreign_key"]


def holds(db: Path) -> bool:
    net = read_network(db, verify=False)
    with connect_ro(db) as conn:
        return foreign_keys_hold(conn, net.tables, DB_TABLES)


def test_a_built_db_holds_without_the_pragma(built: Path, reader: str) -> None:
    assert holds(built)
    assert fk_findings(built, frames=True) == fk_findings(built, frames=False) == []


@pytest.mark.parametrize("name", list(EDITS))
def test_edited_db_same_findings_as_the_pragma(built: Path, tmp_path: Path, reader: str, name: str) -> None:
    db = edited(built, tmp_path, EDITS[name])
    by_pragma = fk_findings(db, frames=False)
    assert fk_findings(db, frames=True) == by_pragma
    assert not holds(db) or by_pragma == []  # never True where the pragma lists a row
    if name.startswith("a blob") or name in ("a reference to no track", "a track deleted", "many"):
        assert by_pragma and not holds(db)  # the damage is seen, by the pragma


def test_each_column_checked_and_each_parent_read_once(built: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A parent key many foreign keys point at (lines.line_code, tracks.track_id) is asked of
    the file and made a key set once, whatever the number of its children."""
    asked: list[tuple[str, str]] = []
    made: list[int] = []
    text_column, keys = foreign_keys._text_column, foreign_keys._keys

    def counted_text_column(conn: sqlite3.Connection, table: str, column: str) -> bool:
        asked.append((table, column))
        return text_column(conn, table, column)

    def counted_keys(parent: pd.Series) -> pa.Array:
        made.append(id(parent))
        return keys(parent)

    monkeypatch.setattr(foreign_keys, "_text_column", counted_text_column)
    monkeypatch.setattr(foreign_keys, "_keys", counted_keys)
    assert holds(built)
    parents = [(p, k) for _, _, p, k in LINKS]
    assert max(parents.count(pk) for pk in set(parents)) > 1  # the case this is about
    assert sorted(asked) == sorted(set(asked)) == sorted({(c, col) for c, col, _, _ in LINKS} | set(parents))
    assert 0 < len(made) <= len(set(parents))


def test_a_changed_foreign_key_is_not_taken_on_trust(built: Path, tmp_path: Path) -> None:
    """No row dangles, but the file's foreign keys are not the declared ones: the pragma runs."""
    for name in ("a foreign key removed", "a foreign key added", "a key column declared without type"):
        assert not holds(edited(built, tmp_path, EDITS[name]))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(
        st.tuples(
            st.sampled_from(LINKS),
            st.integers(1, 60),
            st.sampled_from(["other", "nope", "null", "blob", "space", "upper", "delete parent"]),
        ),
        min_size=1,
        max_size=4,
    )
)
def test_random_edits_same_findings_as_the_pragma(
    built: Path, tmp_path: Path, edits: list[tuple[tuple[str, str, str, str], int, str]]
) -> None:
    sqls = []
    for (child, column, parent, key), rowid, how in edits:
        value = {
            "other": f"(SELECT {key} FROM {parent} ORDER BY {key} DESC LIMIT 1)",
            "nope": "'nope'",
            "null": "NULL",
            "blob": f"CAST({column} AS BLOB)",
            "space": f"{column} || ' '",
            "upper": f"upper({column})",
        }.get(how)
        if value is None:
            sqls.append(f"DELETE FROM {parent} WHERE {nth(parent, f'n = {rowid}')}")
        else:
            sqls.append(f"UPDATE {child} SET {column} = {value} WHERE {nth(child, f'n = {rowid}')}")
    try:
        db = edited(built, tmp_path, sqls)
    except sqlite3.IntegrityError:  # a NOT NULL column set to NULL, a key made twice: no such file
        return
    by_pragma = fk_findings(db, frames=False)
    assert fk_findings(db, frames=True) == by_pragma
    assert not (holds(db) and by_pragma)
