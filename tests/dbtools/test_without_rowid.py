"""The network tables of an onboard DB are SQLite ``WITHOUT ROWID`` tables
(``schemas.model.Table.without_rowid``): their rows are stored once, in the primary key's
b-tree. A finding on such a row names its key (a rowid table's still its rowid), and a DB built
before (every table with a rowid) reads, hashes and validates as it did."""

from __future__ import annotations

import shutil
import sqlite3
from collections import Counter
from pathlib import Path
from typing import cast

import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.network import network_content_hash
from dbtools.sqlite_file import row_key
from dbtools.validate import validate_path
from schemas.errors import InputError
from schemas.tables import DB_TABLES
from tests.dbtools.test_foreign_keys_hold import LINKS, edited, nth

NETWORK = Path(__file__).resolve().parents[1] / "data" / "networks" / "crossover"
WITHOUT_ROWID = {"tracks", "connections", "switches", "track_points"}


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Path:
    db = tmp_path_factory.mktemp("wr") / "net.sqlite"
    build_db(NETWORK, db, db_version="t")
    return db


def with_rowids(built: Path, folder: Path) -> Path:
    """The DB as built before: the same tables, each with a rowid (rows inserted in key order)."""
    db = folder / "rowid.sqlite"
    shutil.copy(built, db)
    with sqlite3.connect(db) as conn:
        conn.execute("PRAGMA foreign_keys = OFF")
        conn.execute("PRAGMA legacy_alter_table = ON")  # the references keep naming the new tables
        for name in sorted(WITHOUT_ROWID):
            sql = conn.execute("SELECT sql FROM sqlite_master WHERE name = ?", (name,)).fetchone()[0]
            conn.execute(f"ALTER TABLE {name} RENAME TO old_{name}")
            conn.execute(sql.replace(" WITHOUT ROWID", ""))
            conn.execute(f"INSERT INTO {name} SELECT * FROM old_{name}")  # a scan: key order
            conn.execute(f"DROP TABLE old_{name}")
    conn.execute("VACUUM")
    conn.close()
    return db


def test_network_tables_are_stored_without_rowid(built: Path) -> None:
    with sqlite3.connect(built) as conn:
        wr = dict(conn.execute("SELECT name, wr FROM pragma_table_list WHERE schema = 'main'").fetchall())
        indexes = {r[0] for r in conn.execute("SELECT tbl_name FROM sqlite_master WHERE type = 'index'")}
    conn.close()
    assert {t.name for t in DB_TABLES if t.without_rowid} == WITHOUT_ROWID
    assert {name for name, flag in wr.items() if flag} == WITHOUT_ROWID
    assert not indexes & WITHOUT_ROWID  # no second b-tree of the key


def test_foreign_key_findings_name_the_key(built: Path, tmp_path: Path) -> None:
    """Track X1 deleted: the four connections at its ends and its 20 m points dangle; one
    connection renamed at both ends dangles twice (two findings, one key)."""
    db = edited(
        built,
        tmp_path,
        [
            "DELETE FROM tracks WHERE track_id = 'X1'",
            "UPDATE connections SET track_a = 'Q', track_b = 'Q' WHERE track_a = 'U2' AND track_b = 'U3'",
        ],
    )
    fk = [f for f in validate_path(db) if f.rule == "db.foreign_key"]
    assert {f.value for f in fk} == {"tracks"}
    conn_keys = [tuple(f.keys.values()) for f in fk if f.table == "connections"]
    assert conn_keys == [
        ("D1", "end", "X1", "begin"),
        ("Q", "end", "Q", "begin"),
        ("Q", "end", "Q", "begin"),
        ("U2", "begin", "X1", "end"),
        ("X1", "begin", "D2", "begin"),
        ("X1", "end", "U1", "end"),
    ]
    first = next(f for f in fk if f.table == "connections")
    assert list(first.keys) == ["track_a", "end_a", "track_b", "end_b"]
    assert first.message == (
        "row (track_a='D1', end_a='end', track_b='X1', end_b='begin') references a missing row of 'tracks'"
    )
    points = pd.read_csv(NETWORK / "track_points.csv")
    x1 = sorted(float(p) for p in points.loc[points["track_id"] == "X1", "pos_m"])
    assert [f.keys for f in fk if f.table == "track_points"] == [{"track_id": "X1", "pos_m": p} for p in x1]
    assert len(fk) == 6 + len(x1)


def test_a_value_of_another_storage_class_names_the_key(built: Path, tmp_path: Path) -> None:
    db = edited(built, tmp_path, ["UPDATE tracks SET length_m = 'long' WHERE track_id = 'D2'"])
    with pytest.raises(InputError, match=r"table 'tracks' row \(track_id='D2'\): text 'long' where a REAL"):
        read_network(db, verify=False)


def test_a_db_with_rowids_reads_and_validates_the_same(built: Path, tmp_path: Path) -> None:
    old = with_rowids(built, tmp_path)
    with sqlite3.connect(old) as conn:
        assert not any(r[0] for r in conn.execute("SELECT wr FROM pragma_table_list WHERE schema = 'main'"))
    conn.close()
    new_net, old_net = read_network(built), read_network(old)  # the stored hash verified
    for t in DB_TABLES:
        pd.testing.assert_frame_equal(old_net.tables[t.name], new_net.tables[t.name], check_exact=True)
    assert network_content_hash(old_net) == network_content_hash(new_net)
    assert [f.to_dict() for f in validate_path(old)] == [f.to_dict() for f in validate_path(built)]
    damaged = edited(old, tmp_path, ["DELETE FROM tracks WHERE track_id = 'X1'"])
    fk = [f for f in validate_path(damaged) if f.rule == "db.foreign_key" and f.table == "connections"]
    assert [f.keys for f in fk] == [{"rowid": 2}, {"rowid": 7}, {"rowid": 11}, {"rowid": 12}]  # key order
    assert fk[0].message == "row 2 references a missing row of 'tracks'"


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    st.lists(
        st.tuples(
            st.sampled_from([link for link in LINKS if link[0] in WITHOUT_ROWID or link[2] == "tracks"]),
            st.integers(1, 40),
            st.sampled_from(["nope", "space", "blob", "delete parent"]),
        ),
        min_size=1,
        max_size=4,
    )
)
def test_each_keyed_finding_is_a_dangling_row(
    built: Path, tmp_path: Path, edits: list[tuple[tuple[str, str, str, str], int, str]]
) -> None:
    """Random broken references: each ``db.foreign_key`` finding on a ``WITHOUT ROWID`` table
    names by its key a row that exists and holds a value its parent lacks, and each table has as
    many findings as ``PRAGMA foreign_key_check`` lists rows."""
    sqls = []
    for (child, column, parent, _key), n, how in edits:
        if how == "delete parent":
            sqls.append(f"DELETE FROM {parent} WHERE {nth(parent, f'n = {n}')}")
        else:
            value = {"nope": "'nope'", "space": f"{column} || ' '", "blob": f"CAST({column} AS BLOB)"}[how]
            sqls.append(f"UPDATE {child} SET {column} = {value} WHERE {nth(child, f'n = {n}')}")
    try:
        db = edited(built, tmp_path, sqls)
    except sqlite3.IntegrityError:  # a key made twice: no such file
        return
    fk = [f for f in validate_path(db) if f.rule == "db.foreign_key"]
    with sqlite3.connect(db) as conn:
        listed = Counter(r[0] for r in conn.execute("PRAGMA foreign_key_check"))
        assert Counter(f.table for f in fk) == listed
        for f in fk:
            if f.table not in WITHOUT_ROWID:
                assert list(f.keys) == ["rowid"]
                continue
            declared = next(t for t in DB_TABLES if t.name == f.table)
            assert list(f.keys) == list(declared.primary_key)
            where = " AND ".join(f"{k} = ?" for k in f.keys)
            row = conn.execute(f"SELECT * FROM {f.table} WHERE {where}", tuple(f.keys.values())).fetchone()
            assert row is not None
            values = dict(zip(declared.column_names, row, strict=True))
            dangles = [
                fk_.other_table
                for fk_ in declared.foreign_keys
                if values[fk_.columns[0]] is not None
                and conn.execute(
                    f"SELECT 1 FROM {fk_.other_table} WHERE {fk_.other_columns[0]} = ?", (values[fk_.columns[0]],)
                ).fetchone()
                is None
            ]
            assert f.value in dangles
    conn.close()


class _OldSqlite:
    """A connection as an SQLite older than 3.37 answers it: no ``pragma_table_list``."""

    def __init__(self, conn: sqlite3.Connection) -> None:
        self.conn = conn

    def execute(self, sql: str, params: tuple[object, ...] = ()) -> sqlite3.Cursor:
        if "pragma_table_list" in sql:
            raise sqlite3.OperationalError("no such table: pragma_table_list")
        return self.conn.execute(sql, params)


def test_row_key_without_pragma_table_list(built: Path, tmp_path: Path) -> None:
    old = with_rowids(built, tmp_path)
    for db, connections_key in ((built, ("track_a", "end_a", "track_b", "end_b")), (old, ("rowid",))):
        with sqlite3.connect(db) as conn:
            for wrapped in (conn, _OldSqlite(conn)):
                keys = {
                    name: row_key(cast(sqlite3.Connection, wrapped), name) for name in ("gis", "connections", "tracks")
                }
                assert keys["gis"] == ("rowid",)
                assert keys["connections"] == connections_key
                assert keys["tracks"] == (("track_id",) if db == built else ("rowid",))
        conn.close()
