"""Audit databases (``trainpos audit``): tables declared in ``schemas/audit.py``, created and
written here through the same declarations as every other table (:func:`dbtools.database.create_tables`).
"""

from __future__ import annotations

import contextlib
import sqlite3
from collections.abc import Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import pandas as pd
import sqlite_utils

from dbtools.atomic import refuse_registry
from dbtools.database import SQLITE_MAGIC, create_tables, sqlite_input_error
from dbtools.inputs import regular_file
from dbtools.sqlite_file import ro_uri
from schemas.audit import (
    AUDIT_APPLICATION_ID,
    AUDIT_SCHEMA_CHANGE,
    AUDIT_SCHEMA_VERSION,
    AUDIT_TABLES,
    AUDIT_VIEWS,
    ROUTE_SUMMARY,
    TRACK_SUMMARY,
)
from schemas.enums import SLIP_EVENTS
from schemas.errors import InputError
from schemas.model import Table

# --------------------------------------------------------------------------- audit databases

AUDIT_NAMES: dict[str, Table] = {t.name: t for t in (*AUDIT_TABLES, *AUDIT_VIEWS)}
_RUNS, _EVENTS, _TRACES, _META, _PATH = (t.name for t in AUDIT_TABLES)

#: ``route_summary`` (columns: :data:`schemas.audit.ROUTE_SUMMARY`): per (track_id, direction)
#: over the runs with status ok, line and track as display names; mean/max % over their
#: balise corrections.
ROUTE_SUMMARY_SQL = f"""
SELECT r.track_id, MIN(r.line_code) AS line_code, MIN(r.track) AS track, r.direction,
       COUNT(*) AS n_runs,
       SUM(r.distance_m) AS distance_m,
       SUM(r.n_corrections) AS n_corrections,
       (SELECT AVG(e.correction_pct) FROM {_EVENTS} e JOIN {_RUNS} r2 USING (run_path)
         WHERE e.type = 'balise_correction' AND r2.status = 'ok' AND r2.track_id IS r.track_id
           AND r2.direction IS r.direction) AS mean_correction_pct,
       (SELECT MAX(e.correction_pct) FROM {_EVENTS} e JOIN {_RUNS} r2 USING (run_path)
         WHERE e.type = 'balise_correction' AND r2.status = 'ok' AND r2.track_id IS r.track_id
           AND r2.direction IS r.direction) AS max_correction_pct,
       SUM(r.n_feature_corrections) AS n_feature_corrections,
       SUM(r.n_feature_refused) AS n_feature_refused,
       SUM(r.n_slips) AS n_slips,
       SUM(r.n_failsafe) AS n_failsafe,
       SUM(r.n_anomalies) AS n_anomalies
FROM {_RUNS} r WHERE r.status = 'ok'
GROUP BY r.track_id, r.direction
"""

_SLIPS = ", ".join(f"'{t.value}'" for t in SLIP_EVENTS)
#: ``track_summary`` (columns: :data:`schemas.audit.TRACK_SUMMARY`): per track_id over the
#: determined stretches of ``audit_track_path`` (runs with status ok); an event belongs to
#: the track of the stretch whose [t_from, t_to] holds its time (stretches of a run do not
#: overlap), as ``trainpos report --by track`` counts them.
TRACK_SUMMARY_SQL = f"""
WITH s AS (
  SELECT p.run_path, p.track_id, p.line_code, p.track, p.t_from, p.t_to, p.distance_m, p.n_cycles
  FROM {_PATH} p JOIN {_RUNS} r USING (run_path)
  WHERE r.status = 'ok' AND p.state = 'determined'),
e AS (
  SELECT s.track_id, ev.type, ev.correction_pct
  FROM s JOIN {_EVENTS} ev ON ev.run_path = s.run_path AND ev.t BETWEEN s.t_from AND s.t_to),
b AS (
  SELECT track_id, COUNT(*) AS n, AVG(correction_pct) AS mean_pct, MAX(correction_pct) AS max_pct
  FROM e WHERE type = 'balise_correction' GROUP BY track_id),
o AS (
  SELECT track_id, SUM(type IN ({_SLIPS})) AS n_slips, SUM(type = 'failsafe') AS n_failsafe,
         SUM(type = 'balise_anomaly') AS n_anomalies
  FROM e GROUP BY track_id)
SELECT s.track_id, MIN(s.line_code) AS line_code, MIN(s.track) AS track,
       COUNT(DISTINCT s.run_path) AS n_runs, SUM(s.distance_m) AS distance_m, SUM(s.n_cycles) AS n_cycles,
       COALESCE(MIN(b.n), 0) AS n_corrections, MIN(b.mean_pct) AS mean_correction_pct,
       MIN(b.max_pct) AS max_correction_pct, COALESCE(MIN(o.n_slips), 0) AS n_slips,
       COALESCE(MIN(o.n_failsafe), 0) AS n_failsafe, COALESCE(MIN(o.n_anomalies), 0) AS n_anomalies
FROM s LEFT JOIN b USING (track_id) LEFT JOIN o USING (track_id)
GROUP BY s.track_id
"""


def _enum_checks(conn: sqlite3.Connection, tables: tuple[Table, ...]) -> None:
    """A trigger per enumerated column that refuses any other value (sqlite-utils has no
    CHECK constraints)."""
    for t in tables:
        for c in t.columns:
            if not c.enum:
                continue
            allowed = ", ".join("'" + v.replace("'", "''") + "'" for v in c.enum)
            for op, when in (("insert", "INSERT"), ("update", f"UPDATE OF [{c.name}]")):
                conn.execute(
                    f"CREATE TRIGGER IF NOT EXISTS [{t.name}_{c.name}_{op}] BEFORE {when} ON [{t.name}] "
                    f"WHEN NEW.[{c.name}] IS NOT NULL AND NEW.[{c.name}] NOT IN ({allowed}) "
                    f"BEGIN SELECT RAISE(ABORT, '{t.name}.{c.name} must be one of {', '.join(c.enum)}'); END"
                )


#: Seconds an audit waits for another process's lock on its audit DB before it gives up (BusyError).
AUDIT_LOCK_WAIT_S = 5.0


def _audit_probe(path: Path) -> tuple[int, int]:
    """(application_id, number of schema objects) as SQLite sees them, write-ahead log included."""
    try:
        with contextlib.closing(sqlite3.connect(ro_uri(path), uri=True)) as conn:
            app_id = int(conn.execute("PRAGMA application_id").fetchone()[0])
            return app_id, int(conn.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()[0])
    except sqlite3.DatabaseError as exc:
        raise sqlite_input_error(exc, path, "audit database is unreadable") from exc


def _is_audit_file(path: Path) -> bool:
    """True when ``path`` is an audit DB, False when it is an empty file (or an empty SQLite
    DB) that may become one; InputError for anything else."""
    regular_file(path, "audit database file (.sqlite)")
    with open(path, "rb") as fh:
        head = fh.read(100)
    if not head:
        return False
    if not head.startswith(SQLITE_MAGIC):
        raise InputError("not an SQLite database", path=path)
    if len(head) >= 72 and int.from_bytes(head[68:72], "big") == AUDIT_APPLICATION_ID:
        return True
    # the file header lags the write-ahead log until a checkpoint (an audit DB of schema 1
    # killed before its first one): ask SQLite
    app_id, n = _audit_probe(path)
    if app_id == AUDIT_APPLICATION_ID:
        return True
    if n:
        raise InputError(f"not a trainpos audit database (application_id {app_id:#x})", path=path)
    return False


def _check_audit_version(conn: sqlite3.Connection, path: Path, is_audit: bool) -> None:
    version = int(conn.execute("PRAGMA user_version").fetchone()[0])
    if version > AUDIT_SCHEMA_VERSION:
        raise InputError(
            f"audit database schema {version} is newer than this tool's ({AUDIT_SCHEMA_VERSION})", path=path
        )
    if is_audit and version < AUDIT_SCHEMA_VERSION:
        raise InputError(
            f"audit database schema {version} is older than this tool's ({AUDIT_SCHEMA_VERSION}: "
            f"{AUDIT_SCHEMA_CHANGE}): audit the runs again into a new audit database",
            path=path,
        )


def _create_audit_schema(conn: sqlite3.Connection) -> None:
    """Identity and tables of an audit DB, committed to the main file (rollback journal)
    *before* it switches to WAL: its header names it an audit DB from the first moment,
    whatever happens later (a kill -9 before the first checkpoint). Idempotent: completes a
    schema whose creation was cut short."""
    conn.execute("PRAGMA journal_mode=DELETE")
    conn.execute(f"PRAGMA application_id={AUDIT_APPLICATION_ID}")
    conn.execute(f"PRAGMA user_version={AUDIT_SCHEMA_VERSION}")
    db = sqlite_utils.Database(conn)
    create_tables(db, AUDIT_TABLES, if_not_exists=True)
    _enum_checks(conn, AUDIT_TABLES)
    db.create_view(ROUTE_SUMMARY.name, ROUTE_SUMMARY_SQL, ignore=True)
    db.create_view(TRACK_SUMMARY.name, TRACK_SUMMARY_SQL, ignore=True)
    conn.commit()


def _connect_audit(path: Path, *, create: bool, is_audit: bool) -> sqlite3.Connection:
    if create:
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        conn = (
            sqlite3.connect(path, timeout=AUDIT_LOCK_WAIT_S)
            if create
            else sqlite3.connect(ro_uri(path), uri=True, timeout=AUDIT_LOCK_WAIT_S)
        )
    except sqlite3.Error as exc:
        raise sqlite_input_error(exc, path, "cannot open audit database") from exc
    try:
        _check_audit_version(conn, path, is_audit)
        conn.execute("PRAGMA foreign_keys=ON")
        if create:
            _create_audit_schema(conn)
            conn.execute("PRAGMA journal_mode=WAL")
            # one commit per run: WAL + NORMAL survives a crash of the process (not of the OS)
            conn.execute("PRAGMA synchronous=NORMAL")
    except BaseException as exc:
        conn.close()
        if isinstance(exc, sqlite3.DatabaseError):
            raise sqlite_input_error(exc, path, "audit database is unreadable") from exc
        raise
    return conn


class AuditDB:
    """An open audit DB (:func:`open_audit_db`): the runs, events, traces and meta tables of
    :mod:`schemas.audit`, one transaction per write."""

    def __init__(self, conn: sqlite3.Connection, path: Path) -> None:
        self.conn = conn
        self.path = path

    def fingerprints(self) -> dict[str, tuple[str, str, str, str]]:
        """run_path → (fingerprint, quick_key, status, context) of every recorded run."""
        rows = self.conn.execute(f"SELECT run_path, fingerprint, quick_key, status, context FROM {_RUNS}")
        return {r[0]: (r[1], r[2], r[3], r[4]) for r in rows}

    def touch_run(self, run_path: str, quick_key: str) -> None:
        """Record a new quick key for a run whose content was found unchanged."""
        with self.conn:
            self.conn.execute(f"UPDATE {_RUNS} SET quick_key = ? WHERE run_path = ?", (quick_key, run_path))

    def store_run(
        self,
        record: Mapping[str, Any],
        events: Iterable[Sequence[Any]],
        trace: bytes | None,
        trace_rows: int = 0,
        track_path: Iterable[Sequence[Any]] = (),
    ) -> None:
        """Replace one run's rows in a single transaction: its record (columns of
        ``audit_runs``), events (rows in ``audit_events`` column order after run_path),
        trace blob and path of tracks (rows in ``audit_track_path`` column order after run_path)."""
        runs, ev_cols = AUDIT_NAMES[_RUNS].column_names, AUDIT_NAMES[_EVENTS].column_names
        path_cols = AUDIT_NAMES[_PATH].column_names
        path = record["run_path"]
        with self.conn:
            for table in (_EVENTS, _TRACES, _PATH, _RUNS):
                self.conn.execute(f"DELETE FROM {table} WHERE run_path = ?", (path,))
            self.conn.execute(
                f"INSERT INTO {_RUNS} ({','.join(runs)}) VALUES ({','.join('?' * len(runs))})",
                [record.get(c) for c in runs],
            )
            self.conn.executemany(
                f"INSERT INTO {_EVENTS} ({','.join(ev_cols)}) VALUES ({','.join('?' * len(ev_cols))})",
                ((path, *r) for r in events),
            )
            self.conn.executemany(
                f"INSERT INTO {_PATH} ({','.join(path_cols)}) VALUES ({','.join('?' * len(path_cols))})",
                ((path, *r) for r in track_path),
            )
            if trace:
                self.conn.execute(
                    f"INSERT INTO {_TRACES} (run_path, n_rows, format, data) VALUES (?, ?, 'parquet', ?)",
                    (path, trace_rows, trace),
                )

    def set_meta(self, values: Mapping[str, str]) -> None:
        with self.conn:
            self.conn.executemany(f"INSERT OR REPLACE INTO {_META} (key, value) VALUES (?, ?)", values.items())

    def meta(self) -> dict[str, str]:
        return dict(self.conn.execute(f"SELECT key, value FROM {_META}").fetchall())

    def read(
        self, name: str, *, where: Mapping[str, str | float] | None = None, order_by: Sequence[str] = ()
    ) -> pd.DataFrame:
        """Rows of one audit table or view; ``where``: column = value filters."""
        table = AUDIT_NAMES.get(name)
        if table is None:
            raise KeyError(f"not an audit table or view: {name}")
        where = where or {}
        for c in [*where, *order_by]:
            table.column(c)  # KeyError for an undeclared column
        sql = f"SELECT * FROM [{name}]"
        if where:
            sql += " WHERE " + " AND ".join(f"[{c}] = ?" for c in where)
        if order_by:
            sql += " ORDER BY " + ", ".join(f"[{c}]" for c in order_by)
        return pd.read_sql_query(sql, self.conn, params=tuple(where.values()))

    def trace(self, run_path: str) -> bytes | None:
        """One run's trace blob (None when it has none)."""
        row = self.conn.execute(f"SELECT data FROM {_TRACES} WHERE run_path = ?", (run_path,)).fetchone()
        return None if row is None else bytes(row[0])


@contextlib.contextmanager
def open_audit_db(path: Path, *, create: bool = True) -> Iterator[AuditDB]:
    """Open an audit DB: created or resumed (``create=True``, read-write) or read-only.

    Refuses a path inside a release registry (:func:`dbtools.atomic.refuse_registry`),
    SQLite files that are not audit DBs (an onboard DB passed by mistake is never
    modified) and audit DBs of another schema version. A writer leaves one file behind
    (journal back to DELETE: readers then leave no -wal/-shm either).
    """
    path = Path(path)
    if create:
        refuse_registry(path)  # the output rule's registry check (exit 3): written in place, never in a registry
    is_audit = path.exists() and _is_audit_file(path)
    if not create and not is_audit:
        raise InputError("no such audit database" if not path.exists() else "empty audit database", path=path)
    conn = _connect_audit(path, create=create, is_audit=is_audit)
    try:
        yield AuditDB(conn, path)
    except sqlite3.DatabaseError as exc:
        raise sqlite_input_error(exc, path, "audit database error") from exc
    finally:
        if create:
            with contextlib.suppress(sqlite3.DatabaseError):  # a reader still open keeps the WAL
                conn.execute("PRAGMA journal_mode=DELETE")
        conn.close()
