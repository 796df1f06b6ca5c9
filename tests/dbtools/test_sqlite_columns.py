"""Whole tables read as Arrow columns are the frames the sqlite3 path gives (dbtools/sqlite_columns.py)."""

from __future__ import annotations

import shutil
import sqlite3
import sys
from pathlib import Path

import pandas as pd
import pytest

from dbtools.database import read_network
from dbtools.network import canonical
from dbtools.sqlite_columns import read_table_columns
from schemas.tables import DB_TABLES, GIS


def sqlite3_frames(path: Path) -> dict[str, pd.DataFrame]:
    """The reference: pandas over sqlite3, then canonical form."""
    with sqlite3.connect(path) as conn:
        return {
            t.name: canonical(t, pd.read_sql_query(f"SELECT {','.join(t.column_names)} FROM [{t.name}]", conn))
            for t in DB_TABLES
        }


def assert_same(a: pd.DataFrame, b: pd.DataFrame) -> None:
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert list(a.dtypes) == list(b.dtypes)


def test_columns_are_the_sqlite3_frames(sample_db: Path) -> None:
    fast = read_table_columns(sample_db, DB_TABLES, min_bytes=0)
    assert set(fast) == {t.name for t in DB_TABLES}
    ref = sqlite3_frames(sample_db)
    for name, frame in fast.items():
        assert_same(frame, ref[name])


@pytest.mark.parametrize("rows", [1, 7, 1000])
def test_batches_of_any_size_give_the_sqlite3_frames(
    sample_db: Path, rows: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The driver's batch size (``BATCH_ROWS``) changes how the columns arrive, not what they hold
    (a table whose first batch makes the driver infer another type for a column — a batch of
    rows with no value there — is left to sqlite3, as the module says); text comes as one chunk."""
    import dbtools.sqlite_columns as sqlite_columns

    monkeypatch.setattr(sqlite_columns, "BATCH_ROWS", rows)
    fast = read_table_columns(sample_db, DB_TABLES, min_bytes=0)
    ref = sqlite3_frames(sample_db)
    assert "gis" in fast and set(fast) <= set(ref)
    for name, frame in fast.items():
        assert_same(frame, ref[name])
    assert fast["gis"]["line_code"].array._pa_array.num_chunks == 1


def test_rows_stored_out_of_key_order_come_back_in_key_order(sample_db: Path, tmp_path: Path) -> None:
    db = tmp_path / "shuffled.sqlite"
    shutil.copy(sample_db, db)
    with sqlite3.connect(db) as conn:
        conn.execute("CREATE TEMP TABLE g AS SELECT * FROM gis")
        conn.execute("DELETE FROM gis")
        conn.execute("INSERT INTO gis SELECT * FROM g ORDER BY lat DESC, km_m DESC")
    fast = read_table_columns(db, [GIS], min_bytes=0)
    assert_same(fast["gis"], sqlite3_frames(db)["gis"])
    assert_same(fast["gis"], read_network(sample_db).gis)


def test_a_value_of_another_type_leaves_the_table_to_sqlite3(sample_db: Path, tmp_path: Path) -> None:
    db = tmp_path / "typed.sqlite"
    shutil.copy(sample_db, db)
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE gis SET height_m = 'high' WHERE rowid = (SELECT max(rowid) FROM gis)")
    fast = read_table_columns(db, DB_TABLES, min_bytes=0)
    assert "gis" not in fast
    assert "balises" in fast


def test_small_files_and_a_missing_driver_read_nothing(sample_db: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    assert read_table_columns(sample_db, DB_TABLES) == {}  # the sample DB is below MIN_FILE_BYTES
    monkeypatch.setitem(sys.modules, "adbc_driver_sqlite.dbapi", None)  # import fails
    assert read_table_columns(sample_db, DB_TABLES, min_bytes=0) == {}


def test_a_corrupt_file_reads_nothing(tmp_path: Path) -> None:
    bad = tmp_path / "bad.sqlite"
    bad.write_bytes(b"SQLite format 3\x00" + b"\xff" * 8192)
    assert read_table_columns(bad, DB_TABLES, min_bytes=0) == {}


def stored_rows(db: Path) -> dict[str, list[tuple[object, ...]]]:
    with sqlite3.connect(db) as conn:
        return {
            t.name: conn.execute(
                f"SELECT {','.join(f'{c}, typeof({c})' for c in t.column_names)} FROM [{t.name}] "
                f"ORDER BY {','.join(t.primary_key) if t.without_rowid else 'rowid'}"  # a WITHOUT ROWID table has none
            ).fetchall()
            for t in DB_TABLES
        }


def test_bulk_insert_stores_what_executemany_stores(
    sample_db: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from dbtools.database import read_meta, write_db

    net, meta = read_network(sample_db), read_meta(sample_db)
    write_db(tmp_path / "bulk.sqlite", net, meta)
    monkeypatch.setitem(sys.modules, "adbc_driver_sqlite.dbapi", None)  # no driver: executemany
    write_db(tmp_path / "rows.sqlite", net, meta)
    bulk, rows = stored_rows(tmp_path / "bulk.sqlite"), stored_rows(tmp_path / "rows.sqlite")
    assert bulk == rows
    assert bulk == stored_rows(sample_db)
    assert any(r for r in bulk["gis"])


def test_whole_numbers_and_flags_with_missing_values_are_the_sqlite3_frames(tmp_path: Path) -> None:
    """A network DB (ETCS group columns, buffer-stop flags) with missing values among given
    ones: the integer and boolean columns built from Arrow's buffers (values and mask) are
    the sqlite3 path's ``Int64`` and ``boolean`` columns."""
    from dbtools.build import build_db

    db = tmp_path / "net.sqlite"
    build_db(Path(__file__).resolve().parents[1] / "data" / "networks" / "station4", db, db_version="t1")
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE balises SET nid_c = NULL, n_pig = NULL WHERE rowid = 1")
        first, second = (r[0] for r in conn.execute("SELECT track_id FROM tracks ORDER BY track_id LIMIT 2"))
        conn.execute("UPDATE tracks SET begin_buffer_stop = 1, end_buffer_stop = NULL WHERE track_id = ?", (first,))
        conn.execute("UPDATE tracks SET begin_buffer_stop = 0, end_buffer_stop = 1 WHERE track_id = ?", (second,))
    fast = read_table_columns(db, DB_TABLES, min_bytes=0)
    ref = sqlite3_frames(db)
    assert {"balises", "tracks"} <= set(fast)
    assert fast["balises"]["nid_c"].isna().sum() == 1 and fast["balises"]["nid_c"].notna().any()
    assert fast["tracks"]["begin_buffer_stop"].tolist()[:2] == [True, False]
    for name, frame in fast.items():
        assert_same(frame, ref[name])
