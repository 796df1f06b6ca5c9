"""The audit database (SQLite): runs, events, traces and per-route aggregates.

Every finished run is committed on its own, so an interrupted audit loses nothing and
resumes by skipping runs whose fingerprint (file hashes, DB content hash, config) is
already recorded as audited.
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import pandas as pd

from schemas.errors import InputError

AUDIT_APPLICATION_ID = 0x54504155  # "TPAU"
AUDIT_SCHEMA_VERSION = 1

DDL = """
CREATE TABLE IF NOT EXISTS runs (
    run_path TEXT PRIMARY KEY,
    run_id TEXT, vehicle_id TEXT, vehicle_kind TEXT,
    fingerprint TEXT NOT NULL,
    quick_key TEXT,
    status TEXT NOT NULL CHECK (status IN ('ok', 'error')),
    error TEXT,
    db_version TEXT,
    line_code TEXT, track TEXT, direction TEXT,
    duration_s REAL, distance_m REAL,
    n_corrections INTEGER, n_balise_corrections INTEGER, n_feature_corrections INTEGER,
    n_feature_refused INTEGER, mean_correction_pct REAL, max_correction_pct REAL,
    n_slips INTEGER, n_failsafe INTEGER, n_anomalies INTEGER, gps_decisions INTEGER,
    max_margin_m REAL, first_determined_t REAL,
    summary_json TEXT,
    audited_at TEXT NOT NULL,
    elapsed_s REAL
);
CREATE TABLE IF NOT EXISTS events (
    run_path TEXT NOT NULL REFERENCES runs(run_path) ON DELETE CASCADE,
    t REAL, type TEXT, km_m REAL, correction_m REAL, correction_pct REAL, detail TEXT
);
CREATE INDEX IF NOT EXISTS events_run ON events(run_path);
CREATE INDEX IF NOT EXISTS events_type ON events(type);
CREATE TABLE IF NOT EXISTS traces (
    run_path TEXT NOT NULL REFERENCES runs(run_path) ON DELETE CASCADE,
    t REAL, km_m REAL, margin_m REAL, speed_mps REAL, v_pulse_mps REAL, kappa REAL,
    lat REAL, lon REAL, error_m REAL, state TEXT
);
CREATE INDEX IF NOT EXISTS traces_run ON traces(run_path);
CREATE TABLE IF NOT EXISTS audit_meta (key TEXT PRIMARY KEY, value TEXT);
"""

RUN_COLUMNS = (
    "run_path",
    "run_id",
    "vehicle_id",
    "vehicle_kind",
    "fingerprint",
    "quick_key",
    "status",
    "error",
    "db_version",
    "line_code",
    "track",
    "direction",
    "duration_s",
    "distance_m",
    "n_corrections",
    "n_balise_corrections",
    "n_feature_corrections",
    "n_feature_refused",
    "mean_correction_pct",
    "max_correction_pct",
    "n_slips",
    "n_failsafe",
    "n_anomalies",
    "gps_decisions",
    "max_margin_m",
    "first_determined_t",
    "summary_json",
    "audited_at",
    "elapsed_s",
)
EVENT_COLUMNS = ("t", "type", "km_m", "correction_m", "correction_pct", "detail")
TRACE_COLUMNS = ("t", "km_m", "margin_m", "speed_mps", "v_pulse_mps", "kappa", "lat", "lon", "error_m", "state")


@contextmanager
def open_audit(path: Path, *, create: bool = True) -> Iterator[sqlite3.Connection]:
    """Open (or create) an audit DB; refuses files that are not audit DBs."""
    path = Path(path)
    exists = path.exists()
    if not exists and not create:
        raise InputError("no such audit database", path=path)
    if exists:
        with open(path, "rb") as fh:
            head = fh.read(100)
        if head and not head.startswith(b"SQLite format 3\x00"):
            raise InputError("not an SQLite database", path=path)
        if len(head) >= 72 and int.from_bytes(head[68:72], "big") not in (0, AUDIT_APPLICATION_ID):
            raise InputError("not a trainpos audit database (wrong application_id)", path=path)
    else:
        path.parent.mkdir(parents=True, exist_ok=True)
    try:
        conn = sqlite3.connect(path)
        conn.execute("PRAGMA foreign_keys=ON")
        conn.execute("PRAGMA journal_mode=WAL")
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
        conn.close()


def fingerprints(conn: sqlite3.Connection) -> dict[str, tuple[str, str, str]]:
    """run_path → (fingerprint, quick_key, status) of every recorded run."""
    return {r[0]: (r[1], r[2], r[3]) for r in conn.execute("SELECT run_path, fingerprint, quick_key, status FROM runs")}


def store_run(
    conn: sqlite3.Connection, record: dict[str, Any], events: pd.DataFrame | None, trace: pd.DataFrame | None
) -> None:
    """Replace one run's rows in a single transaction."""
    with conn:
        conn.execute("DELETE FROM runs WHERE run_path = ?", (record["run_path"],))
        conn.execute("DELETE FROM events WHERE run_path = ?", (record["run_path"],))
        conn.execute("DELETE FROM traces WHERE run_path = ?", (record["run_path"],))
        conn.execute(
            f"INSERT INTO runs ({','.join(RUN_COLUMNS)}) VALUES ({','.join('?' * len(RUN_COLUMNS))})",
            [record.get(c) for c in RUN_COLUMNS],
        )
        for name, frame, cols in (("events", events, EVENT_COLUMNS), ("traces", trace, TRACE_COLUMNS)):
            if frame is None or frame.empty:
                continue
            f = frame.reindex(columns=list(cols))
            rows = f.astype(object).where(f.notna(), None).itertuples(index=False, name=None)
            conn.executemany(
                f"INSERT INTO {name} (run_path, {','.join(cols)}) VALUES (?{',?' * len(cols)})",
                ((record["run_path"], *r) for r in rows),
            )


def set_meta(conn: sqlite3.Connection, values: dict[str, Any]) -> None:
    with conn:
        conn.executemany(
            "INSERT OR REPLACE INTO audit_meta (key, value) VALUES (?, ?)",
            [(k, v if isinstance(v, str) else json.dumps(v)) for k, v in values.items()],
        )


def read_table(path: Path, name: str, where: str = "", params: tuple[Any, ...] = ()) -> pd.DataFrame:
    with open_audit(path, create=False) as conn:
        return pd.read_sql_query(f"SELECT * FROM {name} {where}", conn, params=params)


def read_meta(path: Path) -> dict[str, str]:
    with open_audit(path, create=False) as conn:
        return dict(conn.execute("SELECT key, value FROM audit_meta").fetchall())
