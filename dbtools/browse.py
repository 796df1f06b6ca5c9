"""Read-only SQL on an onboard DB for ``trainpos db info`` and ``db show``: the tables a DB
actually has, their row counts, and the rows of one table matching a user's ``--where``.

Safe to point at a released DB. The file is opened read-only (``mode=ro``,
:func:`dbtools.sqlite_file.connect_ro`: no journal, no ``-wal``/``-shm`` beside it) and, before
any user text is compiled, the connection is made unable to do anything but read:
``PRAGMA query_only`` and an SQLite authorizer that allows SELECT, the READ of a column and
FUNCTION calls only — a second statement, PRAGMA, ATTACH, a recursive CTE, any write is
refused when SQLite compiles it (and :mod:`sqlite3` refuses a second statement anyway). The
table name is checked against the DB's real tables and quoted; the expression sits
between parentheses on lines of its own, so it can neither close the WHERE clause early
nor comment out what follows it. Reads are ``COUNT(*)`` and one ``LIMIT``ed SELECT: fast
whatever the table's size (bench/NOTES.md, "`db info` and `db show` on a national DB").
"""

from __future__ import annotations

import contextlib
import sqlite3
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from dbtools.sqlite_file import connect_ro, quoted
from schemas.errors import InputError, UsageError
from schemas.tables import ALL_DB_TABLES

#: Authorizer actions a ``--where`` may compile to: reading, nothing else.
ALLOWED_ACTIONS = frozenset({sqlite3.SQLITE_SELECT, sqlite3.SQLITE_READ, sqlite3.SQLITE_FUNCTION})
#: SQL functions refused although FUNCTION calls are allowed.
REFUSED_FUNCTIONS = frozenset({"load_extension"})

Value = int | float | str | None


def user_tables(conn: sqlite3.Connection) -> list[str]:
    """The tables the DB has (SQLite's own ``sqlite_*`` left out): the declared ones in
    declaration order, then any other (a newer schema's) by name."""
    rows = conn.execute("SELECT name FROM sqlite_master WHERE type = 'table' AND substr(name, 1, 7) != 'sqlite_'")
    names = {str(r[0]) for r in rows}
    declared = [t.name for t in ALL_DB_TABLES if t.name in names]
    return declared + sorted(names - set(declared))


def table_counts(conn: sqlite3.Connection, path: Path) -> dict[str, int]:
    """Rows of every table of :func:`user_tables` (``COUNT(*)``: no row is read)."""
    counts: dict[str, int] = {}
    for name in user_tables(conn):
        try:
            counts[name] = int(conn.execute(f"SELECT COUNT(*) FROM {quoted(name)}").fetchone()[0])
        except sqlite3.Error as exc:
            raise InputError(f"table '{name}' cannot be counted: {exc}", path=path) from exc
    return counts


def _authorize(action: int, arg1: str | None, arg2: str | None, _db: str | None, _trigger: str | None) -> int:
    """SQLite authorizer: reading only (see the module docstring)."""
    if action not in ALLOWED_ACTIONS:
        return sqlite3.SQLITE_DENY
    if action == sqlite3.SQLITE_FUNCTION and (arg2 or "").lower() in REFUSED_FUNCTIONS:
        return sqlite3.SQLITE_DENY
    return sqlite3.SQLITE_OK


@contextlib.contextmanager
def read_only(path: Path) -> Iterator[sqlite3.Connection]:
    """A read-only connection that refuses every statement but a plain read (module docstring)."""
    with connect_ro(path) as conn:
        conn.execute("PRAGMA query_only = ON")
        conn.set_authorizer(_authorize)
        yield conn


@dataclass(frozen=True)
class TableRows:
    """The first ``limit`` rows of a table that match ``where``, and how many match in all."""

    table: str
    columns: list[str]
    rows: list[tuple[Value, ...]]
    matched: int
    where: str | None
    limit: int

    def to_dict(self) -> dict[str, object]:
        """JSON shape of ``db show --format json``."""
        return {
            "table": self.table,
            "where": self.where,
            "matched": self.matched,
            "limit": self.limit,
            "columns": self.columns,
            "rows": [dict(zip(self.columns, r, strict=True)) for r in self.rows],
        }


def _plain(v: object) -> Value:
    """A cell as text or a number (a BLOB, which no declared table has, as hex)."""
    if isinstance(v, bytes):
        return v.hex()
    return v if v is None or isinstance(v, int | float | str) else str(v)


def _check_table(conn: sqlite3.Connection, table: str, path: Path) -> None:
    names = user_tables(conn)
    if table not in names:
        raise UsageError(f"no table '{table}' (tables: {', '.join(names)})", path=path)


def _columns(conn: sqlite3.Connection, table: str) -> list[str]:
    return [str(d[0]) for d in conn.execute(f"SELECT * FROM {quoted(table)} LIMIT 0").description]


@dataclass(frozen=True)
class _Query:
    """The statements of one ``db show``: a table and the user's expression, for messages."""

    conn: sqlite3.Connection
    path: Path
    table: str
    where: str

    def run(self, sql: str, params: Sequence[int] = ()) -> sqlite3.Cursor:
        """Run one statement that holds the user's expression; its errors are bad usage."""
        try:
            return self.conn.execute(sql, params)
        except (sqlite3.Error, sqlite3.Warning) as exc:
            cols = ", ".join(_columns(self.conn, self.table))
            refused = "not authorized" in str(exc)
            why = "only a read is allowed (no second statement, PRAGMA, write …)" if refused else str(exc)
            raise UsageError(
                f"--where {self.where!r} on table '{self.table}': {why} (columns: {cols})", path=self.path
            ) from exc


def select_rows(path: Path, table: str, where: str | None = None, limit: int = 20) -> TableRows:
    """The first ``limit`` rows of ``table`` (stored order) matching the SQL expression ``where``.

    UsageError for a table the DB does not have (the message lists its tables) or an
    expression that does not compile to a single read (a syntax error, an unknown column,
    a second statement, a write …); InputError when the DB cannot be read.
    """
    if where is not None and not where.strip():
        raise UsageError("--where is empty: give an SQL expression, e.g. \"line_code = '0420'\"")
    if limit < 0:
        raise UsageError(f"--limit {limit}: give 0 or more rows")  # SQLite reads a negative LIMIT as none
    with read_only(path) as conn:
        _check_table(conn, table, path)
        clause = "" if where is None else f" WHERE (\n{where}\n)"
        body = f"FROM {quoted(table)}{clause}"
        query = _Query(conn, path, table, where or "")
        matched = int(query.run(f"SELECT COUNT(*) {body}").fetchone()[0])
        cur = query.run(f"SELECT * {body}\nLIMIT ?", (limit,))
        rows = [tuple(_plain(v) for v in r) for r in cur.fetchall()]
        columns = [str(d[0]) for d in cur.description]
    return TableRows(table, columns, rows, matched, where, limit)
