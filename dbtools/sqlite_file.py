"""An onboard DB file opened read-only, light (no pandas: ``db info --quick`` and ``db show``
start fast): the header check and the read-only connection every DB read goes through
(re-exported by :mod:`dbtools.database`)."""

from __future__ import annotations

import contextlib
import sqlite3
from collections.abc import Iterator
from pathlib import Path

from schemas.errors import InputError
from schemas.tables import APPLICATION_ID

SQLITE_MAGIC = b"SQLite format 3\x00"


def check_sqlite_file(path: Path) -> None:
    """Raise InputError unless ``path`` is an existing SQLite file with our application id."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such file", path=path)
    if path.is_dir():
        raise InputError("is a folder, expected an onboard DB file (.sqlite)", path=path)
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
        raise InputError(f"cannot open database: {exc}", path=path) from exc
    try:
        yield conn
    except sqlite3.DatabaseError as exc:
        raise InputError(f"database is corrupt or unreadable: {exc}", path=path) from exc
    finally:
        conn.close()
