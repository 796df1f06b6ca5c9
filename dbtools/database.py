"""The SQLite layer: onboard DBs and the release registry (audit DBs: :mod:`dbtools.audit_db`;
together the only modules that talk to SQLite).

Onboard DB writes are atomic (temp file in the target folder, then ``os.replace``) and
never touch an existing file unless asked to. Reads open the file read-only so that
validating or diffing a released DB cannot modify it (:mod:`dbtools.sqlite_file`, light: the
read-only connection of ``db info`` and ``db show`` too). Every table is created from its
declaration in ``schemas/`` (:func:`create_tables`). Whole content tables are read as Arrow
columns by :mod:`dbtools.sqlite_columns`.

Findings of :func:`check_db` (``db validate`` of a DB file):

* ``db.integrity`` (error) — SQLite's ``integrity_check`` reports damage (a file cut short,
  bytes overwritten). Fix: take the DB again from the release registry or rebuild it with
  ``db build``; never edit a DB file by hand.
* ``db.foreign_key`` (error) — a row references a missing row of its parent table (the row
  named by its rowid, in a ``WITHOUT ROWID`` table by its primary key). Fix:
  rebuild the DB from its source set (``db build``); a DB edited by hand is not a release.
* ``db.meta`` (error) — the ``meta`` table lacks a required key (``content_hash``,
  ``db_version`` …). Fix: rebuild the DB with ``db build``, which writes every key.
* ``db.content_hash`` (error) — the content hash does not match ``meta``: the DB was
  modified after it was built. Fix: rebuild it from its source set with ``db build`` (or take
  the released file again); do not edit a built DB.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import sqlite3
from collections.abc import Iterable, Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import pandas as pd

from dbtools.atomic import atomic_file, sweep_stale, temp_sibling
from dbtools.foreign_keys import check_foreign_keys, fk_violations, foreign_keys_hold
from dbtools.inputs import regular_file
from dbtools.integrity import check_content_hash
from dbtools.network import Network, canonical, canonical_frame, empty_frame, network_content_hash
from dbtools.sqlite_columns import insert_tables, read_table_columns
from dbtools.sqlite_file import SQLITE_BUSY_CODES as SQLITE_BUSY_CODES
from dbtools.sqlite_file import SQLITE_MAGIC as SQLITE_MAGIC
from dbtools.sqlite_file import check_sqlite_file as check_sqlite_file
from dbtools.sqlite_file import connect_ro, quoted, ro_uri, row_key
from dbtools.sqlite_file import sqlite_input_error as sqlite_input_error
from schemas.enums import Severity
from schemas.errors import InputError
from schemas.findings import Finding
from schemas.model import Table
from schemas.registry import REGISTRY_APPLICATION_ID, REGISTRY_SCHEMA_VERSION, RELEASES
from schemas.tables import (
    ALL_DB_TABLES,
    APPLICATION_ID,
    DB_TABLES,
    META,
    READABLE_SCHEMA_VERSIONS,
    SCHEMA_VERSION,
    tables_absent_in,
)

if TYPE_CHECKING:
    import sqlite_utils

_PY_TYPES: dict[str, type] = {"str": str, "int": int, "float": float, "bool": int, "bytes": bytes}


def create_tables(
    db: sqlite_utils.Database, tables: tuple[Table, ...], *, indexes: bool = True, if_not_exists: bool = False
) -> None:
    """Schema work through sqlite-utils: columns, PK, NOT NULL, FKs and (unless a bulk load
    follows, see :func:`_create_indexes`) the secondary indexes. ``if_not_exists``: leave
    tables and indexes that exist already (completing a schema whose creation was cut)."""
    for t in tables:
        pk: str | list[str] | None = None
        if t.primary_key:
            pk = list(t.primary_key) if len(t.primary_key) > 1 else t.primary_key[0]
        sql = db.create_table_sql(
            t.name,
            {c.name: _PY_TYPES[c.dtype] for c in t.columns},
            pk=pk,
            not_null={c.name for c in t.columns if not c.nullable},
            foreign_keys=[(fk.columns[0], fk.other_table, fk.other_columns[0]) for fk in t.foreign_keys],
            if_not_exists=if_not_exists,
        )
        db.execute(f"{sql.rstrip().rstrip(';')} WITHOUT ROWID" if t.without_rowid else sql)
    if indexes:
        _create_indexes(db, tables, if_not_exists=if_not_exists)


def _create_indexes(db: sqlite_utils.Database, tables: tuple[Table, ...], *, if_not_exists: bool = False) -> None:
    """Secondary indexes, built once after a bulk load (cheaper than maintaining them per row)."""
    for t in tables:
        for idx in t.indexes:
            db[t.name].create_index(list(idx), if_not_exists=if_not_exists)  # type: ignore[union-attr]


def table_rows(table: Table, frame: pd.DataFrame) -> Iterator[tuple[object, ...]]:
    """Rows as Python tuples with None for missing values (the fast executemany path)."""
    cols = []
    for c in table.columns:
        s = frame[c.name]
        if c.dtype == "float":
            cols.append(s.to_numpy(dtype=float, na_value=float("nan")).tolist())  # NaN binds as NULL
        else:
            cols.append(s.astype(object).where(s.notna(), None).tolist())
    return zip(*cols, strict=True)


def write_db(
    path: Path,
    network: Network,
    meta: dict[str, str],
    *,
    force: bool = False,
    inputs: Iterable[Path | str] = (),
    ordered: bool = False,
) -> None:
    """Write a complete onboard DB atomically under the output rule of :mod:`dbtools.atomic`
    (an existing ``path`` only with ``force``; never over a registry or one of ``inputs``).
    ``ordered``: the network's frames are canonical already (:func:`dbtools.network.canonical_frame`).
    Nothing is written when a row references a missing row of another table
    (:func:`dbtools.foreign_keys.check_foreign_keys`: ``sqlite3.IntegrityError``)."""
    frames = [(t, canonical_frame(t, network.tables.get(t.name, empty_frame(t)), ordered=ordered)) for t in DB_TABLES]
    check_foreign_keys(frames)
    with atomic_file(Path(path), force=force, inputs=inputs) as tmp:
        tmp.unlink()  # SQLite creates the file itself
        conn = sqlite3.connect(tmp)
        try:
            conn.execute("PRAGMA journal_mode=OFF")
            conn.execute("PRAGMA synchronous=OFF")
            conn.execute("PRAGMA cache_size=-262144")  # ≤ 256 MB: the GIS key index stays in memory
            conn.execute(f"PRAGMA application_id={APPLICATION_ID}")
            conn.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
            conn.execute("PRAGMA foreign_keys=OFF")  # checked on the frames before (check_foreign_keys)
            import sqlite_utils  # writing only: reading a DB does not import it

            db = sqlite_utils.Database(conn)
            create_tables(db, ALL_DB_TABLES, indexes=False)
            conn.commit()
            bulk = insert_tables(tmp, frames)  # Arrow batches; False: no driver, rows below
            with conn:
                for t, frame in frames if not bulk else ():
                    marks = ",".join("?" * len(t.columns))
                    conn.executemany(
                        f"INSERT INTO [{t.name}] ({','.join(f'[{c}]' for c in t.column_names)}) VALUES ({marks})",
                        table_rows(t, frame),
                    )
                conn.executemany("INSERT INTO meta (key, value) VALUES (?, ?)", sorted(meta.items()))
            _create_indexes(db, ALL_DB_TABLES)
            # no VACUUM: the file was written once, in key order, with no deletions
        finally:
            conn.close()
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())


def write_sqlite(
    path: Path,
    script: Sequence[tuple[str, Iterable[Sequence[object]] | None]],
    *,
    pragmas: Sequence[str] = (),
    force: bool = False,
    inputs: Iterable[Path | str] = (),
) -> None:
    """Write any other SQLite file (a GeoPackage …) atomically: ``pragmas`` first, then each
    ``(sql, rows)`` of ``script`` (``executemany`` with rows, else ``execute``) in one transaction."""
    with atomic_file(Path(path), force=force, inputs=inputs) as tmp:
        tmp.unlink()
        conn = sqlite3.connect(tmp)
        try:
            for p in pragmas:
                conn.execute(f"PRAGMA {p}")
            with conn:
                for sql, rows in script:
                    conn.executemany(sql, rows) if rows is not None else conn.execute(sql)
        finally:
            conn.close()


#: Seconds a release waits for another process's write lock on the registry before it gives up (BusyError).
REGISTRY_LOCK_WAIT_S = 30.0


def snapshot_db(src: Path, dst: Path) -> None:
    """Copy an onboard DB as SQLite reads it — its write-ahead log included — into the new
    file ``dst``, in a rollback-journal mode (a reader of the copy needs no -wal/-shm and
    works on a read-only mount). ``src`` is only read: opened read-only, never checkpointed.

    Under one read transaction (writers of a rollback-journal DB wait; a WAL DB's readers see
    one fixed state): a DB in a rollback-journal mode is the file itself and is copied byte
    for byte; a WAL-mode DB is copied through SQLite's backup API and the copy set to
    ``journal_mode=DELETE``."""
    src, dst = Path(src), Path(dst)
    with connect_ro(src) as conn:
        wal = str(conn.execute("PRAGMA journal_mode").fetchone()[0]).lower() == "wal"
        conn.execute("BEGIN")
        conn.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()  # takes the read lock / WAL snapshot
        if wal:
            _backup_to(conn, dst)
        else:  # (closing this second descriptor drops SQLite's POSIX lock, but only once the copy is done)
            with open(src, "rb") as fin, open(dst, "wb") as fout:
                shutil.copyfileobj(fin, fout, 1 << 20)
        conn.execute("COMMIT")
    with open(dst, "rb+") as fh:
        os.fsync(fh.fileno())


def _backup_to(conn: sqlite3.Connection, dst: Path) -> None:
    """Every page of ``conn``'s main DB into ``dst``, then rollback journal (DELETE)."""
    out = sqlite3.connect(dst)
    try:
        conn.backup(out)
        out.execute("PRAGMA journal_mode=DELETE")
    finally:
        out.close()


def read_meta(path: Path) -> dict[str, str]:
    with connect_ro(path) as conn:
        return dict(conn.execute("SELECT key, value FROM meta").fetchall())


def schema_version(path: Path) -> int:
    with connect_ro(path) as conn:
        return int(conn.execute("PRAGMA user_version").fetchone()[0])


def read_network(path: Path, *, verify: bool = True) -> Network:
    """Load every content table of an onboard DB as canonical typed frames.

    ``verify``: check the content against the hash stored at build
    (:func:`dbtools.integrity.check_content_hash`: a mismatch raises ContentHashError unless
    the caller runs under ``hash_policy(verify=False)``). False only for code that reports
    the mismatch itself (validate, diff, verify-release) or that checks the content against
    a hash of its own (replay workers)."""
    path = Path(path)
    with connect_ro(path) as conn:
        version = int(conn.execute("PRAGMA user_version").fetchone()[0])
        if version not in READABLE_SCHEMA_VERSIONS:
            readable = ", ".join(map(str, READABLE_SCHEMA_VERSIONS))
            raise InputError(f"schema version {version} is not supported (this tool reads {readable})", path=path)
        existing = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
        since = tables_absent_in(version)
        missing = [t.name for t in DB_TABLES if t.name not in existing and t not in since]
        if missing:
            raise InputError(f"table '{missing[0]}' is missing", path=path)
        wanted = tuple(t for t in DB_TABLES if t.name in existing)
        tables = read_table_columns(path, wanted) if version == SCHEMA_VERSION else {}
        for t in DB_TABLES:
            if t.name not in tables:
                tables[t.name] = _read_sqlite3(conn, t, path) if t.name in existing else empty_frame(t)
        meta = dict(conn.execute(f"SELECT key, value FROM {META.name}").fetchall()) if META.name in existing else {}
    net = Network(tables, origin=str(path), meta=meta)
    if verify:
        check_content_hash(meta.get("content_hash"), network_content_hash(net), path)
    return net


def _read_sqlite3(conn: sqlite3.Connection, t: Table, path: Path) -> pd.DataFrame:
    """One table through ``sqlite3``; a nullable column the DB lacks (an older schema
    version) is read as missing values."""
    present = {r[1] for r in conn.execute(f"PRAGMA table_info([{t.name}])")}
    absent = [c.name for c in t.columns if c.name not in present]
    if any(not t.column(n).nullable for n in absent):
        raise InputError(f"table '{t.name}' has no column '{absent[0]}'", path=path)
    cols = ",".join(f"[{c}]" for c in t.column_names if c in present)
    try:
        frame = pd.read_sql_query(f"SELECT {cols} FROM [{t.name}]", conn)
    except (sqlite3.DatabaseError, pd.errors.DatabaseError) as exc:
        raise sqlite_input_error(exc, path, f"table '{t.name}' cannot be read") from exc
    try:
        return canonical(t, frame)
    except (ValueError, TypeError, OverflowError) as exc:  # a value of another storage class
        raise _storage_class_error(conn, t, path, present) or InputError(
            f"table '{t.name}' cannot be read: {exc}", path=path
        ) from exc


#: SQLite storage classes (``typeof``) each declared dtype accepts.
STORAGE_CLASSES = {"float": ("real", "integer", "null"), "int": ("integer", "null"), "bool": ("integer", "null")}


def _storage_class_error(conn: sqlite3.Connection, t: Table, path: Path, present: set[str]) -> InputError | None:
    """InputError naming table, column, row and value of the first cell whose storage class
    the declared type does not take (text or a blob in a REAL column, 2.5 in an INTEGER
    one); None when every cell fits."""
    key: tuple[str, ...] | None = None  # the columns naming a row (asked of the file once, when needed)
    for c in t.columns:
        allowed = STORAGE_CLASSES.get(c.dtype)
        if allowed is None or c.name not in present:
            continue
        marks = ",".join("?" * len(allowed))
        key = row_key(conn, t.name) if key is None else key
        hit = conn.execute(
            f"SELECT {','.join(quoted(k) for k in key)}, typeof([{c.name}]), quote([{c.name}]) FROM [{t.name}] "
            f"WHERE typeof([{c.name}]) NOT IN ({marks}) LIMIT 1",
            allowed,
        ).fetchone()
        if hit is not None:
            *row, kind, value = hit
            return InputError(
                f"table '{t.name}' row {_row_text(dict(zip(key, row, strict=True)))}: {kind} {str(value)[:60]} "
                f"where a {c.sql_type} ({c.dtype}) is "
                "declared; the DB was not written by trainpos or was edited: rebuild it from its sources",
                path=path,
                column=c.name,
            )
    return None


def integrity_findings(path: Path, network: Network | None = None) -> list[Finding]:
    """SQLite-level checks: integrity_check, foreign_key_check, and the meta content hash.
    ``network``: the file's tables as read; with it, ``foreign_key_check`` runs only when the
    frames cannot prove that it finds nothing (:func:`dbtools.foreign_keys.foreign_keys_hold`)."""
    findings: list[Finding] = []
    with connect_ro(path) as conn:
        rows = [r[0] for r in conn.execute("PRAGMA integrity_check").fetchall()]
        if rows != ["ok"]:
            for msg in rows[:50]:
                findings.append(
                    Finding("db.integrity", Severity.ERROR, "sqlite", f"integrity_check: {msg}", value=msg, limit="ok")
                )
        fk_rows = (
            []  # the frames read prove the pragma would list nothing (dbtools.foreign_keys)
            if network is not None and rows == ["ok"] and foreign_keys_hold(conn, network.tables, DB_TABLES)
            else fk_violations(conn)
        )
        for table, keys, parent in fk_rows:
            findings.append(
                Finding(
                    "db.foreign_key",
                    Severity.ERROR,
                    table,
                    f"row {_row_text(keys)} references a missing row of '{parent}'",
                    keys=keys,
                    value=parent,
                )
            )
    net = network if network is not None else read_network(path, verify=False)
    stored = net.meta.get("content_hash")
    if not stored:
        findings.append(
            Finding("db.meta", Severity.ERROR, "meta", "meta has no content_hash", value=None, limit="sha256")
        )
    else:
        actual = network_content_hash(net)
        if actual != stored:
            findings.append(
                Finding(
                    "db.content_hash",
                    Severity.ERROR,
                    "meta",
                    "content hash does not match meta: the DB was modified after it was built",
                    value=actual[:16],
                    limit=stored[:16],
                )
            )
    for key in ("db_version", "created_at", "tool_version", "schema_version"):
        if key not in net.meta:
            findings.append(Finding("db.meta", Severity.ERROR, "meta", f"meta has no '{key}'", keys={"key": key}))
    return findings


def _row_text(keys: dict[str, object]) -> str:
    """A row in a message: its rowid (``3``), or its primary key (``(track_id='T1', pos_m=20.0)``)."""
    if list(keys) == ["rowid"]:
        return str(keys["rowid"])
    return "(" + ", ".join(f"{k}={v!r}" for k, v in keys.items()) + ")"


# --------------------------------------------------------------------------- release registry


def _check_registry_file(path: Path) -> None:
    regular_file(path, "release registry (registry.sqlite)")
    with open(path, "rb") as fh:
        head = fh.read(100)
    if not head.startswith(SQLITE_MAGIC) or len(head) < 100:
        raise InputError("release registry is not an SQLite database (corrupt?)", path=path)
    app_id = int.from_bytes(head[68:72], "big")
    if app_id != REGISTRY_APPLICATION_ID:
        raise InputError(
            f"not a trainpos release registry (application_id {app_id:#x}, expected {REGISTRY_APPLICATION_ID:#x})",
            path=path,
        )


def _check_registry_schema(conn: sqlite3.Connection, path: Path) -> None:
    names = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    if RELEASES.name not in names:
        raise InputError(f"release registry has no '{RELEASES.name}' table", path=path)
    version = int(conn.execute("PRAGMA user_version").fetchone()[0])
    if version != REGISTRY_SCHEMA_VERSION:
        raise InputError(
            f"release registry schema version {version} is not supported (expected {REGISTRY_SCHEMA_VERSION})",
            path=path,
        )


def _create_registry(path: Path) -> None:
    """An empty registry, written to a temp file and renamed into place."""
    sweep_stale(path)  # a temp file of a release killed while creating it
    tmp = temp_sibling(path)
    try:
        tmp.unlink()
        conn = sqlite3.connect(tmp)
        try:
            conn.execute(f"PRAGMA application_id={REGISTRY_APPLICATION_ID}")
            conn.execute(f"PRAGMA user_version={REGISTRY_SCHEMA_VERSION}")
            import sqlite_utils

            create_tables(sqlite_utils.Database(conn), (RELEASES,))
            conn.commit()
        finally:
            conn.close()
        if path.exists():  # created meanwhile by a concurrent release: use that one
            tmp.unlink()
        else:
            os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def registry_transaction(path: Path) -> Iterator[sqlite3.Connection]:
    """Open the release registry for writing (creating it if absent) in one IMMEDIATE
    transaction: SQLite's write lock is held for the whole block, so two concurrent
    releases cannot both pass a "not released yet" check. Commits when the block ends
    normally, rolls back on any exception. Use with :func:`registry_find` and
    :func:`registry_insert`."""
    path = Path(path)
    if not path.exists():
        _create_registry(path)
    _check_registry_file(path)
    try:
        conn = sqlite3.connect(path, isolation_level=None, timeout=REGISTRY_LOCK_WAIT_S)
    except sqlite3.Error as exc:
        raise sqlite_input_error(exc, path, "cannot open release registry") from exc
    try:
        _check_registry_schema(conn, path)
        conn.execute("BEGIN IMMEDIATE")
        try:
            yield conn
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        conn.execute("COMMIT")
    except sqlite3.DatabaseError as exc:
        raise sqlite_input_error(exc, path, "release registry is corrupt or unreadable") from exc
    finally:
        conn.close()


def registry_find(conn: sqlite3.Connection, db_version: str) -> dict[str, object] | None:
    """The registry row of one version, or None."""
    cur = conn.execute(f"SELECT * FROM [{RELEASES.name}] WHERE db_version = ?", (db_version,))
    row = cur.fetchone()
    return None if row is None else dict(zip([d[0] for d in cur.description], row, strict=True))


def registry_insert(conn: sqlite3.Connection, row: dict[str, object], table: Table = RELEASES) -> None:
    """Insert one release row (a duplicate db_version violates the primary key), or a row of
    another registry table (``IMPACTS``: a release's impact report; ``PENDING``: a release in
    progress) — creating that table in a registry that has none yet (older registries stay
    readable: ``releases`` is unchanged)."""
    if table is not RELEASES:
        import sqlite_utils

        create_tables(sqlite_utils.Database(conn), (table,), if_not_exists=True)
    cols = table.column_names
    conn.execute(
        f"INSERT INTO [{table.name}] ({','.join(f'[{c}]' for c in cols)}) VALUES ({','.join('?' * len(cols))})",
        [row.get(c) for c in cols],
    )


def registry_delete(conn: sqlite3.Connection, table: Table, db_version: str) -> None:
    """Delete the row of ``db_version`` from an optional registry table (``PENDING``), if the
    table exists."""
    if _has_table(conn, table):
        conn.execute(f"DELETE FROM [{table.name}] WHERE db_version = ?", (db_version,))


def registry_rows(conn: sqlite3.Connection, table: Table) -> dict[str, dict[str, object]]:
    """The rows of an optional registry table (``IMPACTS``, ``PENDING``) by db_version; empty
    when the registry has no such table yet."""
    if not _has_table(conn, table):
        return {}
    cols = table.column_names
    cur = conn.execute(f"SELECT {','.join(f'[{c}]' for c in cols)} FROM [{table.name}]")
    return {str(r[0]): dict(zip(cols, r, strict=True)) for r in cur.fetchall()}


def _has_table(conn: sqlite3.Connection, table: Table) -> bool:
    return conn.execute("SELECT 1 FROM sqlite_master WHERE name = ?", (table.name,)).fetchone() is not None


def read_registry_table(path: Path, table: Table) -> dict[str, dict[str, object]]:
    """:func:`registry_rows` of a registry file, read-only (empty without a registry)."""
    if not Path(path).exists():
        return {}
    with _registry_ro(Path(path)) as conn:
        return registry_rows(conn, table)


def read_registry(path: Path) -> list[dict[str, object]]:
    """Every release row, oldest first, read-only. InputError when missing or corrupt."""
    path = Path(path)
    if not path.exists():
        raise InputError("no release registry here (nothing released yet?)", path=path)
    with _registry_ro(path) as conn:
        cols = RELEASES.column_names
        cur = conn.execute(
            f"SELECT {','.join(f'[{c}]' for c in cols)} FROM [{RELEASES.name}] ORDER BY released_at, db_version"
        )
        return [dict(zip(cols, r, strict=True)) for r in cur.fetchall()]


@contextlib.contextmanager
def _registry_ro(path: Path) -> Iterator[sqlite3.Connection]:
    """A read-only connection to a checked registry; InputError when it cannot be read."""
    _check_registry_file(path)
    try:
        conn = sqlite3.connect(ro_uri(path), uri=True)
    except sqlite3.Error as exc:
        raise sqlite_input_error(exc, path, "cannot open release registry") from exc
    try:
        _check_registry_schema(conn, path)
        yield conn
    except sqlite3.DatabaseError as exc:
        raise sqlite_input_error(exc, path, "release registry is corrupt or unreadable") from exc
    finally:
        conn.close()
