"""The foreign keys of the declared tables, checked on the frames an onboard DB is written from.

``write_db`` loads with SQLite's ``foreign_keys`` off (enforcing them row by row costs a third
of the insert) and used to run ``PRAGMA foreign_key_check`` over the written file: a scan of
every child row and a b-tree look-up of its key in the parent's primary-key index — on the
national network 1 M GIS rows against ``lines`` and 0.6 M track references against
``tracks``, 0.13 s line-only and 0.26 s with stations. Here the same relation is tested on
the canonical frames before anything is written, one hash-set membership test per foreign
key column (Arrow's ``is_in``), a few hundredths of a second.

It is the relation SQLite checks: a child row passes when its key column is null
(https://sqlite.org/foreignkeys.html: "if any of the child key columns … are NULL … there
is no requirement for a corresponding row in the parent table") or its value equals a
parent key. Every foreign key of :mod:`schemas.tables` is one text column referencing a
text primary key, both stored with TEXT affinity, so
SQLite's equality under the parent column's BINARY collation is the equality of the UTF-8
bytes, which is what ``is_in`` compares. The frames are the values ``write_db`` binds, so
a failure here is exactly a row ``foreign_key_check`` would have listed.

``db validate`` of a DB file reads every table anyway: :func:`foreign_keys_hold` tells from
those frames, and a few look-ups in the file, that ``PRAGMA foreign_key_check`` would list no
row — the common case, where the pragma costs 0.13 s line-only and 0.26 s with stations on the
national network (bench/NOTES.md). It answers True only when every premise of the frame test
is checked on the file itself (the function's docstring); on any doubt, or any dangling value,
the caller runs the pragma, whose rows (ids, order) are the findings.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable, Mapping, Sequence
from functools import cache, partial

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from dbtools.sqlite_file import quoted, row_key
from schemas.model import Table

#: Rows of ``PRAGMA foreign_key_check`` reported (the rest are not named).
MAX_FK_ROWS = 1000


def _text(s: pd.Series) -> pa.Array:
    """The column as one Arrow large_string array (nulls where missing)."""
    arr = pa.array(s.array if isinstance(s.dtype, pd.StringDtype) else s.astype(object), from_pandas=True)
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    return arr.cast(pa.large_string())


def _keys(parent: pd.Series) -> pa.Array:
    """The parent key column's values without its nulls (the value set of :func:`dangling`)."""
    return _text(parent).drop_null()


def parent_keys(frames: Mapping[str, pd.DataFrame]) -> Callable[[str, str], pa.Array]:
    """``keys(table, column)``: :func:`_keys` of ``frames[table][column]``, made once however
    many foreign keys point at it (a table absent from ``frames`` has no rows)."""

    @cache
    def keys(table: str, column: str) -> pa.Array:
        f = frames.get(table)
        return _keys(f[column] if f is not None else pd.Series([], dtype="string"))

    return keys


def dangling(child: pd.Series, keys: Callable[[], pa.Array]) -> int:
    """The position of the first value of ``child`` that is neither missing nor one of the parent
    key values ``keys()`` (-1 when every value is one or the other); ``keys`` is asked only when
    some child value is not null (:func:`parent_keys` makes each set once)."""
    values = _text(child)
    if values.null_count == len(values):
        return -1
    found = pc.is_in(values, value_set=keys())
    missing = pc.and_(pc.invert(found), pc.is_valid(values))
    return int(pc.index(missing, True).as_py())


def check_foreign_keys(frames: Sequence[tuple[Table, pd.DataFrame]]) -> None:
    """Raise ``sqlite3.IntegrityError`` (what a failed ``PRAGMA foreign_key_check`` raised,
    naming the table, column, row and value) when a row of one of the frames references a
    key absent from its parent table's frame. A parent absent from ``frames`` has no rows."""
    keys = parent_keys({t.name: f for t, f in frames})
    for table, frame in frames:
        for fk in table.foreign_keys:
            if len(fk.columns) != 1:
                raise NotImplementedError(f"{table.name}: a foreign key of {len(fk.columns)} columns")
            column, parent_column = fk.columns[0], fk.other_columns[0]
            i = dangling(frame[column], partial(keys, fk.other_table, parent_column))
            if i >= 0:
                raise sqlite3.IntegrityError(
                    f"FOREIGN KEY constraint failed: {table.name} row {i + 1}: {column} "
                    f"'{frame[column].iat[i]}' is not a {parent_column} of {fk.other_table}"
                )


def foreign_keys_hold(conn: sqlite3.Connection, frames: Mapping[str, pd.DataFrame], tables: Sequence[Table]) -> bool:
    """True only if ``PRAGMA foreign_key_check`` on ``conn`` (a file whose ``integrity_check``
    is ``ok``: its indexes agree with its tables) would list no row, ``frames`` being every
    row of its tables as read (by name; ``tables`` the declared ones). Each premise of the
    frame test (module doc) is checked on the file:

    * the pragma compiles (``EXPLAIN``: no "foreign key mismatch", no unknown collation);
    * every table of the file has exactly the declared single-column foreign keys (none for a
      table not declared), so the pragma checks the relations tested here and no other;
    * the child and parent columns are declared ``TEXT``: a stored value is text, NULL or a
      blob, and no affinity converts it before the parent look-up;
    * no child or parent value is a blob (SQLite orders every blob after all text, so
      ``column >= X''`` finds one; an index seek where the column leads an index): a blob
      equals no text key in SQLite, but is read back as the text of its bytes;
    * every non-null child value is a parent key, byte for byte (:func:`dangling`); SQLite
      finds such a row whatever the parent index's collation, as equal bytes compare equal
      under BINARY, NOCASE and RTRIM alike.

    Each parent key column is checked and read once, however many foreign keys point at it.
    False on any doubt or failure (the caller then runs the pragma)."""
    by_name = {t.name: t for t in tables}
    try:
        conn.execute("EXPLAIN PRAGMA foreign_key_check").fetchall()
        names = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table'")}
        return _declared_only(conn, names, by_name) and _relations_hold(conn, frames, names, by_name)
    except sqlite3.Error:
        return False


def _declared_only(conn: sqlite3.Connection, names: set[str], by_name: Mapping[str, Table]) -> bool:
    """Every table ``names`` of the file has exactly the declared single-column foreign keys."""
    for name in names:
        rows = conn.execute('SELECT "from", "table", "to", seq FROM pragma_foreign_key_list(?)', (name,)).fetchall()
        table = by_name.get(name)
        declared = (
            {(fk.columns[0], fk.other_table, fk.other_columns[0]) for fk in table.foreign_keys} if table else set()
        )
        if any(r[3] != 0 for r in rows) or len(rows) != len(declared) or {r[:3] for r in rows} != declared:
            return False
    return True


def _relations_hold(
    conn: sqlite3.Connection, frames: Mapping[str, pd.DataFrame], names: set[str], by_name: Mapping[str, Table]
) -> bool:
    """Every declared foreign key of the file's tables has TEXT columns without a blob and no
    dangling child value; a column asked of the file, a parent key set made, once."""

    @cache
    def text_column(table: str, column: str) -> bool:
        return _text_column(conn, table, column)

    keys = parent_keys(frames)
    for name in sorted(names & by_name.keys()):
        for fk in by_name[name].foreign_keys:
            parent, column, key = fk.other_table, fk.columns[0], fk.other_columns[0]
            if parent not in names or parent not in frames or name not in frames:
                return False
            if not (text_column(name, column) and text_column(parent, key)):
                return False
            if dangling(frames[name][column], partial(keys, parent, key)) >= 0:
                return False
    return True


def _text_column(conn: sqlite3.Connection, table: str, column: str) -> bool:
    """``table.column`` is declared TEXT and holds no blob."""
    declared = conn.execute("SELECT type FROM pragma_table_info(?) WHERE name = ?", (table, column)).fetchone()
    if declared is None or str(declared[0]).upper() != "TEXT":
        return False
    q = f"SELECT 1 FROM {quoted(table)} WHERE {quoted(column)} >= X'' LIMIT 1"
    return conn.execute(q).fetchone() is None


def fk_violations(conn: sqlite3.Connection) -> list[tuple[str, dict[str, object], str]]:
    """The first ``MAX_FK_ROWS`` rows of ``PRAGMA foreign_key_check``, each as (child table,
    the keys naming the row, parent table). A rowid table's row is named by its rowid, as the
    pragma gives it; a ``WITHOUT ROWID`` table's (the pragma's rowid is NULL) by its primary
    key (:func:`_keyed`)."""
    rows = conn.execute("PRAGMA foreign_key_check").fetchall()[:MAX_FK_ROWS]
    keyed: dict[str, list[dict[str, object]] | None] = {}
    out: list[tuple[str, dict[str, object], str]] = []
    for table, rowid, parent, _fkid in rows:
        if rowid is not None:
            out.append((table, {"rowid": rowid}, parent))
            continue
        if table not in keyed:
            keyed[table] = _keyed(conn, table, [(r[3], r[2]) for r in rows if r[0] == table and r[1] is None])
        names = keyed[table]
        out.append((table, names.pop(0) if names else {"rowid": None}, parent))
    return out


def _keyed(conn: sqlite3.Connection, table: str, listed: list[tuple[int, str]]) -> list[dict[str, object]] | None:
    """The primary keys of the rows of the ``WITHOUT ROWID`` ``table`` behind the pragma's rows
    ``listed`` ((foreign key id, parent) each, in the pragma's order), or None when they cannot
    be told apart. The pragma scans the table in its b-tree's order — the primary key's — and
    for each row lists every failing foreign key in id order; the same scan here (``ORDER BY``
    the key) tests each single-column key as the pragma does: a non-null value with no equal
    parent key (every declared key is TEXT against TEXT: no affinity conversion, BINARY
    equality). The pairs found must be the pragma's, id and parent, one for one (any other
    foreign key — several columns, an implicit parent key — gives None: the rows are then
    named by no key, as before)."""
    key = row_key(conn, table)
    fks = conn.execute('SELECT id, "table", "from", "to", seq FROM pragma_foreign_key_list(?)', (table,)).fetchall()
    if key == ("rowid",) or not key or any(r[4] != 0 or r[3] is None for r in fks):
        return None
    fails = [
        f"(t.{quoted(c)} IS NOT NULL AND "
        f"NOT EXISTS (SELECT 1 FROM {quoted(p)} AS p WHERE p.{quoted(k)} = t.{quoted(c)}))"
        for _, p, c, k, _ in fks
    ]
    cols = ", ".join(f"t.{quoted(c)}" for c in key)
    sql = (
        f"SELECT {cols}, {', '.join(fails)} FROM {quoted(table)} AS t WHERE {' OR '.join(fails)} "
        f"ORDER BY {cols} LIMIT {len(listed)}"
    )
    pairs: list[tuple[int, str]] = []
    names: list[dict[str, object]] = []
    for row in conn.execute(sql):
        for (fkid, parent, *_), failed in zip(fks, row[len(key) :], strict=True):
            if failed:
                pairs.append((fkid, parent))
                names.append(dict(zip(key, row[: len(key)], strict=True)))
    return names[: len(listed)] if pairs[: len(listed)] == listed else None
