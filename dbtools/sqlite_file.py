"""An onboard DB file opened read-only, light (no pandas: ``db info --quick`` and ``db show``
start fast): the header check and the read-only connection every DB read goes through
(re-exported by :mod:`dbtools.database`)."""

from __future__ import annotations

import contextlib
import re
import sqlite3
from collections.abc import Iterator
from pathlib import Path

from dbtools.inputs import regular_file
from schemas.errors import BusyError, InputError
from schemas.tables import APPLICATION_ID

SQLITE_MAGIC = b"SQLite format 3\x00"


#: SQLite's primary result codes of a database another connection holds (SQLITE_BUSY, SQLITE_LOCKED).
SQLITE_BUSY_CODES = (5, 6)


def sqlite_input_error(exc: Exception, path: Path, message: str) -> InputError | BusyError:
    """The error to raise for a ``sqlite3`` error on the database ``path``: a database
    locked by another process (still locked after SQLite's wait) is :class:`BusyError`
    ("in use by another trainpos process; try again", exit 3), anything else an InputError
    ``message: reason`` (exit 2). Every reader and writer of a trainpos database maps its
    ``sqlite3`` errors through here."""
    code = getattr(exc, "sqlite_errorcode", None)
    if (code is not None and code & 0xFF in SQLITE_BUSY_CODES) or "database is locked" in str(exc):
        return BusyError(
            "is in use by another trainpos process (the database is locked); try again when it has finished",
            path=path,
        )
    return InputError(f"{message}: {exc}", path=path)


def check_sqlite_file(path: Path) -> None:
    """Raise InputError unless ``path`` is an existing regular SQLite file with our application id."""
    path = regular_file(Path(path), "onboard DB file (.sqlite)")
    with open(path, "rb") as fh:
        head = fh.read(100)
    if not head.startswith(SQLITE_MAGIC):
        raise InputError("not an SQLite database (bad header)", path=path)
    if len(head) < 100:
        raise InputError("truncated SQLite file", path=path)
    app_id = int.from_bytes(head[68:72], "big")
    if app_id != APPLICATION_ID:
        raise InputError(
            f"not a trainpos onboard DB (application_id {app_id:#x}, expected {APPLICATION_ID:#x})", path=path
        )


def ro_uri(path: Path | str) -> str:
    """The SQLite URI opening ``path`` read-only. The path is percent-encoded: a ``#``, ``?``
    or ``%`` in a file name would otherwise end the path early (``net#1.sqlite`` would open
    — and create — ``net`` read-write, the ``?mode=ro`` lost in the fragment)."""
    return f"{Path(path).resolve().as_uri()}?mode=ro"


@contextlib.contextmanager
def connect_ro(path: Path) -> Iterator[sqlite3.Connection]:
    """Read-only connection (URI ``mode=ro``: no journal, nothing written beside the file)."""
    check_sqlite_file(path)
    uri = ro_uri(path)
    try:
        conn = sqlite3.connect(uri, uri=True)
    except sqlite3.Error as exc:
        raise sqlite_input_error(exc, path, "cannot open database") from exc
    try:
        yield conn
    except sqlite3.DatabaseError as exc:
        raise sqlite_input_error(exc, path, "database is corrupt or unreadable") from exc
    finally:
        conn.close()


def row_key(conn: sqlite3.Connection, table: str) -> tuple[str, ...]:
    """The columns that name a row of ``table`` in findings: ``("rowid",)`` for a rowid table,
    the primary key's columns (in key order) for a ``WITHOUT ROWID`` table, which has no rowid
    (:attr:`schemas.model.Table.without_rowid`; a DB built before they were used has none).
    Told by ``pragma_table_list``'s ``wr`` flag; an SQLite older than 3.37 has no such pragma,
    and the table's ``CREATE`` statement then says it (it ends with the clause)."""
    try:
        wr = conn.execute("SELECT wr FROM pragma_table_list WHERE schema = 'main' AND name = ?", (table,)).fetchone()
    except sqlite3.OperationalError:  # no pragma_table_list
        sql = conn.execute("SELECT sql FROM sqlite_master WHERE type = 'table' AND name = ?", (table,)).fetchone()
        wr = (
            sql is not None and re.search(r"\)[^)]*\bWITHOUT\s+ROWID\b[^)]*$", str(sql[0]), re.IGNORECASE) is not None,
        )
    if wr is None or not wr[0]:
        return ("rowid",)
    pk = conn.execute("SELECT name FROM pragma_table_info(?) WHERE pk > 0 ORDER BY pk", (table,)).fetchall()
    return tuple(str(r[0]) for r in pk)


def quoted(name: str) -> str:
    """An SQL identifier quoted."""
    return '"' + name.replace('"', '""') + '"'
