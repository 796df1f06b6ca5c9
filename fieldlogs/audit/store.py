"""The audit database (SQLite): runs, events, traces and per-route aggregates.

Every finished run is committed on its own, so an interrupted audit loses nothing and
resumes by skipping runs whose fingerprint (file hashes, DB content hash, config) is
already recorded as audited.

Tables (one writer: the coordinating process of ``fieldlogs.audit.runner``):

* ``runs`` — one row per run folder (``run_path``, absolute): status ``ok`` or ``error``
  (with the error message), route (line, track, direction = ``down`` when km increased over
  the run, ``up`` otherwise), headline figures. ``n_corrections``, ``mean_correction_pct``
  and ``max_correction_pct`` count **balise** position corrections only (SPEC §5.2);
  feature-point corrections are ``n_feature_corrections`` / ``n_feature_refused``.
  ``context`` is the hash of the onboard DB content hash and the pipeline config the run
  was audited with; ``fingerprint`` adds the run's file contents. ``elapsed_s`` and
  ``cpu_s``: wall and CPU time of the run in its worker.
* ``events`` — the pipeline's events of every run (corrections, refusals, slips, ...).
* ``traces`` — one row per run: its 1 Hz trace (full rate around slip/slide episodes;
  columns ``TRACE_COLUMNS``) for the report's plots, stored as one Parquet blob (``data``)
  so that storing a one-hour run costs one insert, not thousands. Read it with
  :func:`read_trace`.
* ``route_summary`` (view) — per (line, track, direction): runs, distance, balise
  corrections with mean/max %, feature corrections, slips, fail-safe, anomalies. Always up
  to date, since it is computed from the committed rows. ``trainpos report`` adds the
  median and the share above target.
* ``audit_meta`` — key/value: onboard DB path, version and content hash, config (JSON),
  time of the last audit.
"""

from __future__ import annotations

import contextlib
import json
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from schemas.errors import InputError

AUDIT_APPLICATION_ID = 0x54504155  # "TPAU"
AUDIT_SCHEMA_VERSION = 1

DDL = """
CREATE TABLE IF NOT EXISTS runs (
    run_path TEXT PRIMARY KEY,
    run_id TEXT, vehicle_id TEXT, vehicle_kind TEXT,
    fingerprint TEXT NOT NULL,
    quick_key TEXT,
    context TEXT,
    status TEXT NOT NULL CHECK (status IN ('ok', 'error')),
    error TEXT,
    db_version TEXT,
    line_code TEXT, track TEXT, direction TEXT,
    duration_s REAL, distance_m REAL,
    n_corrections INTEGER, n_feature_corrections INTEGER,
    n_feature_refused INTEGER, mean_correction_pct REAL, max_correction_pct REAL,
    n_slips INTEGER, n_failsafe INTEGER, n_anomalies INTEGER, gps_decisions INTEGER,
    gps_trusted_share REAL,
    max_margin_m REAL, first_determined_t REAL,
    summary_json TEXT,
    audited_at TEXT NOT NULL,
    elapsed_s REAL,
    cpu_s REAL
);
CREATE TABLE IF NOT EXISTS events (
    run_path TEXT NOT NULL REFERENCES runs(run_path) ON DELETE CASCADE,
    t REAL, type TEXT, km_m REAL, correction_m REAL, correction_pct REAL, detail TEXT
);
CREATE INDEX IF NOT EXISTS events_run ON events(run_path);
CREATE INDEX IF NOT EXISTS events_type ON events(type);
CREATE TABLE IF NOT EXISTS traces (
    run_path TEXT PRIMARY KEY REFERENCES runs(run_path) ON DELETE CASCADE,
    n_rows INTEGER NOT NULL,
    format TEXT NOT NULL CHECK (format = 'parquet'),
    data BLOB NOT NULL
);
CREATE TABLE IF NOT EXISTS audit_meta (key TEXT PRIMARY KEY, value TEXT);
CREATE VIEW IF NOT EXISTS route_summary AS
SELECT r.line_code, r.track, r.direction,
       COUNT(*) AS n_runs,
       SUM(r.distance_m) AS distance_m,
       SUM(r.n_corrections) AS n_corrections,
       (SELECT AVG(e.correction_pct) FROM events e JOIN runs r2 USING (run_path)
         WHERE e.type = 'balise_correction' AND r2.status = 'ok' AND r2.line_code IS r.line_code
           AND r2.track IS r.track AND r2.direction IS r.direction) AS mean_correction_pct,
       (SELECT MAX(e.correction_pct) FROM events e JOIN runs r2 USING (run_path)
         WHERE e.type = 'balise_correction' AND r2.status = 'ok' AND r2.line_code IS r.line_code
           AND r2.track IS r.track AND r2.direction IS r.direction) AS max_correction_pct,
       SUM(r.n_feature_corrections) AS n_feature_corrections,
       SUM(r.n_feature_refused) AS n_feature_refused,
       SUM(r.n_slips) AS n_slips,
       SUM(r.n_failsafe) AS n_failsafe,
       SUM(r.n_anomalies) AS n_anomalies
FROM runs r WHERE r.status = 'ok'
GROUP BY r.line_code, r.track, r.direction;
"""

RUN_COLUMNS = (
    "run_path",
    "run_id",
    "vehicle_id",
    "vehicle_kind",
    "fingerprint",
    "quick_key",
    "context",
    "status",
    "error",
    "db_version",
    "line_code",
    "track",
    "direction",
    "duration_s",
    "distance_m",
    "n_corrections",
    "n_feature_corrections",
    "n_feature_refused",
    "mean_correction_pct",
    "max_correction_pct",
    "n_slips",
    "n_failsafe",
    "n_anomalies",
    "gps_decisions",
    "gps_trusted_share",
    "max_margin_m",
    "first_determined_t",
    "summary_json",
    "audited_at",
    "elapsed_s",
    "cpu_s",
)
EVENT_COLUMNS = ("t", "type", "km_m", "correction_m", "correction_pct", "detail")
TRACE_COLUMNS = ("t", "km_m", "margin_m", "speed_mps", "v_pulse_mps", "kappa", "lat", "lon", "error_m", "state")


def _check_file(path: Path) -> bool:
    """True when ``path`` is an audit DB, False when it is an empty file (or empty SQLite
    DB) that may become one; InputError for anything else."""
    with open(path, "rb") as fh:
        head = fh.read(100)
    if not head:
        return False
    if not head.startswith(b"SQLite format 3\x00"):
        raise InputError("not an SQLite database", path=path)
    app_id = int.from_bytes(head[68:72], "big") if len(head) >= 72 else 0
    if app_id == AUDIT_APPLICATION_ID:
        return True
    try:
        with sqlite3.connect(f"file:{path.resolve()}?mode=ro", uri=True) as conn:
            n = conn.execute("SELECT COUNT(*) FROM sqlite_master").fetchone()[0]
    except sqlite3.DatabaseError as exc:
        raise InputError(f"audit database is unreadable: {exc}", path=path) from exc
    if n:
        raise InputError(f"not a trainpos audit database (application_id {app_id:#x})", path=path)
    return False


@contextmanager
def open_audit(path: Path, *, create: bool = True) -> Iterator[sqlite3.Connection]:
    """Open an audit DB: created or resumed (``create=True``, read-write) or read-only.

    Refuses SQLite files that are not audit DBs (an onboard DB passed by mistake is never
    modified) and audit DBs of a newer schema.
    """
    path = Path(path)
    is_audit = path.is_file() and _check_file(path)
    if not create and not is_audit:
        raise InputError("no such audit database" if not path.exists() else "empty audit database", path=path)
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        if create:
            conn = sqlite3.connect(path)
        else:
            conn = sqlite3.connect(f"file:{path.resolve()}?mode=ro", uri=True)
        version = int(conn.execute("PRAGMA user_version").fetchone()[0])
        if version > AUDIT_SCHEMA_VERSION:
            conn.close()
            raise InputError(
                f"audit database schema {version} is newer than this tool's ({AUDIT_SCHEMA_VERSION})", path=path
            )
        conn.execute("PRAGMA foreign_keys=ON")
        if create:
            conn.execute("PRAGMA journal_mode=WAL")
            # one commit per run: WAL + NORMAL survives a crash of the process (not of the OS)
            conn.execute("PRAGMA synchronous=NORMAL")
            conn.execute(f"PRAGMA application_id={AUDIT_APPLICATION_ID}")
            conn.execute(f"PRAGMA user_version={AUDIT_SCHEMA_VERSION}")
            conn.executescript(DDL)
    except sqlite3.DatabaseError as exc:
        raise InputError(f"audit database is unreadable: {exc}", path=path) from exc
    try:
        yield conn
    except sqlite3.DatabaseError as exc:
        raise InputError(f"audit database error: {exc}", path=path) from exc
    finally:
        if create:
            # back to a single file: readers (reports, read-only) then leave no -wal/-shm behind
            with contextlib.suppress(sqlite3.DatabaseError):
                conn.execute("PRAGMA journal_mode=DELETE")
        conn.close()


def fingerprints(conn: sqlite3.Connection) -> dict[str, tuple[str, str, str, str]]:
    """run_path → (fingerprint, quick_key, status, context) of every recorded run."""
    return {
        r[0]: (r[1], r[2], r[3], r[4])
        for r in conn.execute("SELECT run_path, fingerprint, quick_key, status, context FROM runs")
    }


def touch_run(conn: sqlite3.Connection, run_path: str, quick_key: str) -> None:
    """Record a new quick key for a run whose content was found unchanged."""
    with conn:
        conn.execute("UPDATE runs SET quick_key = ? WHERE run_path = ?", (quick_key, run_path))


#: Trace columns kept in float64 (time, position); the others are stored as float32 (plots).
TRACE_FLOAT64 = frozenset({"t", "km_m", "lat", "lon"})


def encode_trace(trace: pd.DataFrame) -> bytes:
    """A trace frame as Parquet bytes (zstd); columns ``TRACE_COLUMNS``."""
    frame = trace.reindex(columns=list(TRACE_COLUMNS))
    for c in TRACE_COLUMNS:
        if c != "state":
            frame[c] = pd.to_numeric(frame[c], errors="coerce").astype("float64" if c in TRACE_FLOAT64 else "float32")
    buf = pa.BufferOutputStream()
    pq.write_table(pa.Table.from_pandas(frame, preserve_index=False), buf, compression="zstd")
    return bytes(buf.getvalue().to_pybytes())


def decode_trace(data: bytes | None) -> pd.DataFrame:
    if not data:
        return pd.DataFrame({c: pd.Series(dtype=object if c == "state" else float) for c in TRACE_COLUMNS})
    frame = pq.read_table(pa.BufferReader(data)).to_pandas()
    return frame.astype({c: "float64" for c in TRACE_COLUMNS if c != "state"})


def _rows(frame: pd.DataFrame, cols: tuple[str, ...]) -> Iterator[tuple[Any, ...]]:
    """Rows as Python values, missing values as None (NaN floats are stored as NULL)."""
    f = frame.reindex(columns=list(cols))
    lists = [f[c].astype(object).where(f[c].notna(), None).tolist() for c in cols]
    return zip(*lists, strict=True)


def store_run(
    conn: sqlite3.Connection,
    record: dict[str, Any],
    events: pd.DataFrame | None,
    trace: pd.DataFrame | bytes | None,
) -> None:
    """Replace one run's rows in a single transaction (``trace`` as a frame or as the
    bytes of :func:`encode_trace`)."""
    path = record["run_path"]
    with conn:
        conn.execute("DELETE FROM events WHERE run_path = ?", (path,))
        conn.execute("DELETE FROM traces WHERE run_path = ?", (path,))
        conn.execute("DELETE FROM runs WHERE run_path = ?", (path,))
        conn.execute(
            f"INSERT INTO runs ({','.join(RUN_COLUMNS)}) VALUES ({','.join('?' * len(RUN_COLUMNS))})",
            [record.get(c) for c in RUN_COLUMNS],
        )
        if events is not None and not events.empty:
            conn.executemany(
                f"INSERT INTO events (run_path, {','.join(EVENT_COLUMNS)}) VALUES (?{',?' * len(EVENT_COLUMNS)})",
                ((path, *r) for r in _rows(events, EVENT_COLUMNS)),
            )
        if isinstance(trace, pd.DataFrame):
            trace = encode_trace(trace) if not trace.empty else None
        if trace:
            n = pq.read_metadata(pa.BufferReader(trace)).num_rows
            conn.execute(
                "INSERT INTO traces (run_path, n_rows, format, data) VALUES (?, ?, 'parquet', ?)", (path, n, trace)
            )


def set_meta(conn: sqlite3.Connection, values: dict[str, Any]) -> None:
    with conn:
        conn.executemany(
            "INSERT OR REPLACE INTO audit_meta (key, value) VALUES (?, ?)",
            [(k, v if isinstance(v, str) else json.dumps(v)) for k, v in values.items()],
        )


def read_table(path: Path, name: str, where: str = "", params: tuple[Any, ...] = ()) -> pd.DataFrame:
    """Rows of one table or view (``where``: an SQL suffix with ``?`` placeholders)."""
    with open_audit(path, create=False) as conn:
        return pd.read_sql_query(f"SELECT * FROM {name} {where}", conn, params=params)


def read_trace(path: Path, run_path: str) -> pd.DataFrame:
    """One run's trace (``TRACE_COLUMNS``; empty when the run has none)."""
    with open_audit(path, create=False) as conn:
        row = conn.execute("SELECT data FROM traces WHERE run_path = ?", (run_path,)).fetchone()
    return decode_trace(row[0] if row else None)


def read_meta(path: Path) -> dict[str, str]:
    with open_audit(path, create=False) as conn:
        return dict(conn.execute("SELECT key, value FROM audit_meta").fetchall())
