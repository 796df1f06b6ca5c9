"""The audit database, audit side: what a run's record, events and trace are stored as.

Tables are declared in :mod:`schemas.audit` and created, written and read through
:mod:`dbtools.database` (the only SQLite user); this module turns pipeline results into
rows and back. Every finished run is committed on its own, so an interrupted audit loses
nothing and resumes by skipping runs whose fingerprint (file hashes, DB content hash,
config) is already recorded as audited.

* ``audit_runs`` — one row per run folder (``run_path``, absolute): status ``ok`` or
  ``error`` (with the error message), route (line, track, direction = ``down`` when km
  increased over the run, ``up`` otherwise), headline figures. ``n_corrections``,
  ``mean_correction_pct`` and ``max_correction_pct`` count **balise** position corrections
  only (SPEC §5.2); feature-point corrections are ``n_feature_corrections`` /
  ``n_feature_refused``. ``context`` is the hash of the onboard DB's content hash and the
  pipeline config the run was audited with; ``fingerprint`` adds the run's file contents.
  ``elapsed_s`` and ``cpu_s``: wall and CPU time of the run in its worker.
* ``audit_events`` — the pipeline's events of every run (corrections, refusals, slips, ...).
* ``audit_traces`` — one row per run: its 1 Hz trace (full rate around slip/slide episodes;
  columns ``TRACE_COLUMNS``) for the report's plots, stored as one Parquet blob so that
  storing a one-hour run costs one insert, not thousands. Read it with :func:`read_trace`.
* ``route_summary`` (view) — per (line, track, direction): runs, distance, balise
  corrections with mean/max %, feature corrections, slips, fail-safe, anomalies. Always up
  to date, since it is computed from the committed rows. ``trainpos report`` adds the
  median and the share above target.
* ``audit_track_path`` — a run's route as a path of tracks
  (:mod:`fieldlogs.audit.track_path`): one row per stretch claimed on one track (or
  ambiguous among candidates), in order, with its times and distance.
* ``audit_meta`` — key/value: onboard DB path, version and content hash, config (JSON),
  time of the last audit.
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from contextlib import AbstractContextManager
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

from dbtools.audit_db import AuditDB, open_audit_db
from schemas.audit import AUDIT_EVENTS, AUDIT_RUNS, AUDIT_TRACK_PATH
from schemas.jsonable import jsonable

RUN_COLUMNS = tuple(AUDIT_RUNS.column_names)
EVENT_COLUMNS = tuple(AUDIT_EVENTS.column_names[1:])  # after run_path
PATH_COLUMNS = tuple(AUDIT_TRACK_PATH.column_names[1:])  # after run_path
TRACE_COLUMNS = ("t", "km_m", "margin_m", "speed_mps", "v_pulse_mps", "kappa", "lat", "lon", "error_m", "state")
#: Trace columns kept in float64 (time, position); the others are stored as float32 (plots).
TRACE_FLOAT64 = frozenset({"t", "km_m", "lat", "lon"})


def open_audit(path: Path, *, create: bool = True) -> AbstractContextManager[AuditDB]:
    """An audit DB created or resumed (``create=True``) or opened read-only
    (:func:`dbtools.audit_db.open_audit_db`)."""
    return open_audit_db(Path(path), create=create)


def fingerprints(conn: AuditDB) -> dict[str, tuple[str, str, str, str]]:
    """run_path → (fingerprint, quick_key, status, context) of every recorded run."""
    return conn.fingerprints()


def touch_run(conn: AuditDB, run_path: str, quick_key: str) -> None:
    """Record a new quick key for a run whose content was found unchanged."""
    conn.touch_run(run_path, quick_key)


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
    frame: pd.DataFrame = pq.read_table(pa.BufferReader(data)).to_pandas()
    return frame.astype({c: "float64" for c in TRACE_COLUMNS if c != "state"})


Packed = dict[str, Any]
"""A frame as :func:`pack` sends it from a worker: column → float64 array, or (int32 codes,
categories) for a text column."""


def pack(frame: pd.DataFrame) -> Packed:
    """A frame as plain arrays (text columns as int32 codes + categories): small to pickle."""
    out: Packed = {}
    for c in frame.columns:
        s = frame[c]
        if pd.api.types.is_numeric_dtype(s.dtype) and not pd.api.types.is_bool_dtype(s.dtype):
            out[c] = s.to_numpy(dtype=float, na_value=np.nan)
        else:
            codes, cats = pd.factorize(s.astype(object), use_na_sentinel=True)
            out[c] = (codes.astype(np.int32), [str(x) for x in cats])
    return out


def unpack(packed: Packed | None) -> pd.DataFrame | None:
    if packed is None:
        return None
    cols: dict[str, Any] = {}
    for c, v in packed.items():
        if isinstance(v, tuple):
            codes, cats = v
            cols[c] = _text(codes, cats)
        else:
            cols[c] = v
    return pd.DataFrame(cols)


def _text(codes: npt.NDArray[np.int32], cats: Sequence[str]) -> npt.NDArray[np.object_]:
    table = np.array([*cats, None], dtype=object)
    out: npt.NDArray[np.object_] = table[np.where(codes < 0, len(cats), codes)]
    return out


def _values(v: Any) -> list[Any]:
    """One packed column as Python values, NaN and missing text as None."""
    if isinstance(v, tuple):
        text: list[Any] = _text(*v).tolist()
        return text
    arr = np.asarray(v, dtype=float)
    out: list[Any] = arr.tolist()
    for i in np.flatnonzero(np.isnan(arr)).tolist():
        out[i] = None
    return out


def _rows(events: pd.DataFrame | Packed, cols: tuple[str, ...]) -> Iterator[tuple[Any, ...]]:
    """Rows as Python values, missing values as None (NaN floats are stored as NULL); a
    packed frame is read without building a DataFrame (the coordinator's cost per run)."""
    if isinstance(events, pd.DataFrame):
        f = events.reindex(columns=list(cols))
        lists = [f[c].astype(object).where(f[c].notna(), None).tolist() for c in cols]
        return zip(*lists, strict=True)
    n = _length(events)
    lists = [_values(events[c]) if c in events else [None] * n for c in cols]
    return zip(*lists, strict=True)


def _length(packed: Packed) -> int:
    for v in packed.values():
        return len(v[0]) if isinstance(v, tuple) else len(v)
    return 0


def store_run(
    conn: AuditDB,
    record: Mapping[str, Any],
    events: pd.DataFrame | Packed | None,
    trace: pd.DataFrame | bytes | None,
    track_path: pd.DataFrame | Sequence[Sequence[Any]] | None = None,
) -> None:
    """Replace one run's rows in a single transaction (``events`` as a frame or as
    :func:`pack` made it, ``trace`` as a frame or as the bytes of :func:`encode_trace`,
    ``track_path`` as a frame or rows of :func:`path_rows`)."""
    empty = events is None or (events.empty if isinstance(events, pd.DataFrame) else not _length(events))
    rows = iter(()) if events is None or empty else _rows(events, EVENT_COLUMNS)
    if isinstance(trace, pd.DataFrame):
        trace = encode_trace(trace) if not trace.empty else None
    n = pq.read_metadata(pa.BufferReader(trace)).num_rows if trace else 0
    if isinstance(track_path, pd.DataFrame):
        track_path = path_rows(track_path)
    conn.store_run(record, rows, trace or None, n, track_path or ())


def path_rows(track_path: pd.DataFrame) -> list[tuple[Any, ...]]:
    """A path frame (:func:`fieldlogs.audit.track_path.track_path`) as plain rows in
    ``audit_track_path`` column order after run_path: small to send from a worker."""
    return list(_rows(track_path, PATH_COLUMNS))


def set_meta(conn: AuditDB, values: Mapping[str, Any]) -> None:
    """Meta values; anything but a string is stored as JSON."""
    conn.set_meta({k: v if isinstance(v, str) else json.dumps(jsonable(v)) for k, v in values.items()})


def read_table(
    path: Path, name: str, *, where: Mapping[str, str | float] | None = None, order_by: Sequence[str] = ()
) -> pd.DataFrame:
    """Rows of one audit table or view (``where``: column = value filters), read-only."""
    with open_audit(path, create=False) as conn:
        return conn.read(name, where=where, order_by=order_by)


def read_trace(path: Path, run_path: str) -> pd.DataFrame:
    """One run's trace (``TRACE_COLUMNS``; empty when the run has none)."""
    with open_audit(path, create=False) as conn:
        return decode_trace(conn.trace(run_path))


def read_meta(path: Path) -> dict[str, str]:
    with open_audit(path, create=False) as conn:
        return conn.meta()
