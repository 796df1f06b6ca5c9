"""Fleet audits: the pipeline over many runs, in parallel, stored as each run finishes.

Runs are replayed by :mod:`fieldlogs.replay` — in this process, a local process pool or an
existing Dask cluster (``dask.distributed``) when a scheduler address is given — all
through the same worker function :func:`audit_one`, so the cluster path is the local path.
Results are written by the coordinating process only (one SQLite writer, through
:mod:`fieldlogs.audit.store`). Ctrl-C stops the workers and keeps every run finished so far.

Skip and resume: a run is identified by its folder (absolute path); its fingerprint is the
SHA-256 of its files' contents plus the *context*: the onboard DB's content hash — of the
tables as read, not the hash in its meta table, so a hand-edited DB is a new context — and
the pipeline config. A quick key (file names, sizes, mtimes) plus an unchanged context
skips a run without reading it; when only the quick key differs (a file touched, copied
back) the worker hashes the content and an unchanged fingerprint is still skipped. Runs
recorded with status ``error`` are retried. The context is kept per run, so resuming an
audit interrupted under another config or DB never skips a run audited with the old one.

Unit: ``unit`` F (the default: the pipeline as it always runs), R (the R cab's unit) or both
(unit F's figures stored with the units' comparison), :mod:`fieldlogs.audit.units`. A unit
other than F is part of the context, so switching units re-audits every run.

A run's route is keyed by its **track id**: the track claimed (state not undetermined) on
the most cycles, ties broken by line, local name, then id — on a line-only DB the same
(line, track) as the pipeline summary's main route; ``line_code`` and ``track`` of the
record are that track's display names (null off a line: a crossover, a connecting curve).

A run fails (status ``error``, message stored) when run.json is unusable, a stream its
vehicle kind needs (tacho and IMU for a train, GPS and cab for a road-rail vehicle) is
missing or has no usable row, or the pipeline raises; the other runs go on.

Workers send back compact results: one record, the events as plain column arrays (no
DataFrame machinery to pickle) and the 1 Hz trace already encoded as Parquet bytes, so the
coordinator (the single SQLite writer) does little per run and never becomes the
bottleneck of a parallel audit.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Iterable
from contextlib import closing
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.audit_db import AuditDB
from fieldlogs.audit.store import (
    encode_trace,
    fingerprints,
    open_audit,
    pack,
    path_rows,
    set_meta,
    store_run,
    touch_run,
    unpack,
)
from fieldlogs.audit.track_path import append_path, empty_path, track_path
from fieldlogs.audit.units import check_unit
from fieldlogs.pipeline.summary import TrackClaims, main_track, merge_claims, track_claims
from fieldlogs.replay.discovery import discover_runs
from fieldlogs.replay.network import DbRef, load_network, open_db
from fieldlogs.replay.pool import replay
from fieldlogs.replay.tasks import Outcome, error_message
from schemas.jsonable import jsonable

__all__ = ["AuditStats", "audit", "audit_one", "discover_runs", "pack", "unpack"]

#: Modules the replay's fork server imports once, besides this one.
PRELOAD = ("fieldlogs.pipeline.run", "fieldlogs.runs.handle", "fieldlogs.pipeline.warm")
#: Figures of the pipeline summary copied into a run's record.
SUMMARY_FIELDS = (
    "duration_s",
    "distance_m",
    "n_feature_corrections",
    "n_feature_refused",
    "n_slips",
    "n_failsafe",
    "n_anomalies",
    "gps_decisions",
    "gps_trusted_share",
    "max_margin_m",
    "first_determined_t",
)


def quick_key(run: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(Path(run).iterdir()):
        if p.is_file():
            st = p.stat()
            h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def context_key(db_hash: str, cfg_json: str, unit: str = "F") -> str:
    """What a run's result depends on besides its files: DB content, pipeline config and
    (when not F, the default) the unit replayed."""
    extra = b"" if unit == "F" else b"\0unit=" + unit.encode()
    return hashlib.sha256(db_hash.encode() + b"\0" + cfg_json.encode() + extra).hexdigest()


def content_fingerprint(run: Path, context: str) -> str:
    h = hashlib.sha256()
    for p in sorted(Path(run).iterdir()):
        if p.is_file():
            h.update(p.name.encode() + b"\0")
            with open(p, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    h.update(chunk)
            h.update(b"\0")
    h.update(context.encode())
    return h.hexdigest()


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _trace(result: Any, earlier: list[Any] | None = None) -> pd.DataFrame:
    """1 Hz trace of a run for plots: km, margin, speeds, κ, GPS position, truth error;
    full rate around the slip/slide episodes (``earlier``: those of a long run's earlier
    windows, one of which may reach into this window's part)."""
    pos = result.positions
    dt = float(np.median(np.diff(pos["t"]))) if len(pos) > 1 else 0.1
    step = max(round(1.0 / max(dt, 1e-3)), 1)
    keep = np.zeros(len(pos), dtype=bool)
    keep[::step] = True
    t = pos["t"].to_numpy()
    for ep in [*(earlier or []), *result.odometry.episodes]:  # full rate around slip/slide episodes
        keep |= (t >= ep.t_start - 5.0) & (t <= ep.t_end + 5.0)
    sel = pos[keep]
    idx = np.flatnonzero(keep)
    out = pd.DataFrame(
        {
            "t": sel["t"].to_numpy(dtype=float),
            "km_m": sel["km_m"].to_numpy(dtype=float, na_value=np.nan),
            "margin_m": sel["margin_m"].to_numpy(dtype=float, na_value=np.nan),
            "speed_mps": sel["speed_mps"].to_numpy(dtype=float, na_value=np.nan),
            "state": sel["state"].astype(str).to_numpy(),
        }
    )
    cyc = result.cycles
    out["v_pulse_mps"] = cyc.v_pulse[idx] if cyc is not None and cyc.v_pulse.size == len(pos) else np.nan
    out["kappa"] = result.kappa[idx] if result.kappa is not None and len(result.kappa) == len(pos) else np.nan
    gps = result.gps.fixes if result.gps is not None and result.gps.fixes is not None else None
    if gps is not None and len(gps) and "lat" in gps:
        gt = gps["t"].to_numpy(dtype=float)
        j = np.clip(np.searchsorted(gt, out["t"].to_numpy(), side="right") - 1, 0, len(gt) - 1)
        near = np.abs(gt[j] - out["t"].to_numpy()) <= 1.0
        out["lat"] = np.where(near, gps["lat"].to_numpy(dtype=float, na_value=np.nan)[j], np.nan)
        out["lon"] = np.where(near, gps["lon"].to_numpy(dtype=float, na_value=np.nan)[j], np.nan)
    else:
        out["lat"] = np.nan
        out["lon"] = np.nan
    if result.truth is not None and len(result.truth):
        tt = result.truth["t"].to_numpy(dtype=float)
        out["error_m"] = out["km_m"] - np.interp(
            out["t"], tt, result.truth["km_m"].to_numpy(dtype=float, na_value=np.nan)
        )
    else:
        out["error_m"] = np.nan
    return out


def audit_one(
    run_path: str, db: DbRef, cfg_json: str, context: str, known_fingerprint: str | None = None, unit: str = "F"
) -> dict[str, Any]:
    """Worker: run the pipeline on one run with ``unit`` (:mod:`fieldlogs.audit.units`).
    Never raises: errors become a record.

    Returns ``{"record": {...}, "events": pack(events), "trace": Parquet bytes}``, or
    ``{"record": ..., "unchanged": True}`` when the content fingerprint equals
    ``known_fingerprint``.
    """
    import tempfile

    from fieldlogs.audit.units import replay_unit
    from fieldlogs.pipeline.config import PipelineConfig
    from fieldlogs.runs.handle import read_run

    t0, c0 = time.perf_counter(), time.process_time()
    base: dict[str, Any] = {
        "run_path": run_path,
        "quick_key": None,
        "context": context,
        "fingerprint": "",
        "audited_at": _now(),
        "unit": unit,
    }
    try:
        base["quick_key"] = quick_key(Path(run_path))
        fp = content_fingerprint(Path(run_path), context)
        base["fingerprint"] = fp
        if known_fingerprint == fp:
            return {"record": base, "unchanged": True}
        network = load_network(db)
        cfg = PipelineConfig.from_dict(json.loads(cfg_json))
        run = read_run(Path(run_path))
        seen = _Seen()
        with tempfile.TemporaryDirectory(prefix="trainpos-unit-") as scratch:
            # refuses an unusable run; a long one by windows
            result, compared = replay_unit(run, network, cfg, unit, seen.add, Path(scratch))
        record = {
            **base,
            **_record(result.summary, seen.route(), seen.direction()),
            **compared,
            "elapsed_s": time.perf_counter() - t0,
            "cpu_s": time.process_time() - c0,
        }
        trace = encode_trace(seen.trace())
        return {"record": record, "events": pack(result.events), "trace": trace, "path": path_rows(seen.path)}
    except Exception as exc:  # a bad run or a bug on one run must not stop a fleet audit
        msg = error_message(exc)
    end = {"elapsed_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
    return {"record": {**base, "status": "error", "error": msg, **end}}


class _Seen:
    """What the audit keeps of a run's results as they come (the whole run's, or each
    window's of a long one): its 1 Hz trace, its path of tracks and its first and last km."""

    def __init__(self) -> None:
        self.traces: list[pd.DataFrame] = []
        self.path = empty_path()
        self.episodes: list[Any] = []
        self.first_km: float | None = None
        self.last_km: float | None = None
        self.kms = 0
        self.claims: TrackClaims = {}

    def add(self, result: Any) -> None:
        self.traces.append(_trace(result, self.episodes))
        self.episodes += result.odometry.episodes
        self.path = append_path(self.path, track_path(result.positions))
        self.claims = merge_claims([self.claims, track_claims(result.positions)])
        km = result.positions["km_m"].dropna()
        if len(km):
            self.first_km = float(km.iloc[0]) if self.first_km is None else self.first_km
            self.last_km = float(km.iloc[-1])
            self.kms += len(km)

    def route(self) -> tuple[str | None, str | None, str | None]:
        """(track_id, line_code, track) of the track claimed on most cycles
        (:func:`fieldlogs.pipeline.summary.main_track`)."""
        return main_track(self.claims)

    def direction(self) -> str | None:
        """``down`` when the km grew over the run, ``up`` when it fell (None if never determined)."""
        if self.kms < 2 or self.first_km is None or self.last_km is None:
            return None
        return "down" if self.last_km >= self.first_km else "up"

    def trace(self) -> pd.DataFrame:
        return self.traces[0] if len(self.traces) == 1 else pd.concat(self.traces, ignore_index=True)


def _record(
    s: dict[str, Any], route: tuple[str | None, str | None, str | None], direction: str | None
) -> dict[str, Any]:
    """The record fields of a run the pipeline went through (``elapsed_s``: wall time in
    the worker, ``cpu_s`` its CPU time; wall / CPU > 1: a busy machine)."""
    return {
        "status": "ok",
        **{k: s[k] for k in ("run_id", "vehicle_id", "vehicle_kind", "db_version")},
        **dict(zip(("track_id", "line_code", "track"), route, strict=True)),
        "direction": direction,
        **{k: s[k] for k in ("n_corrections", "mean_correction_pct", "max_correction_pct")},
        **{k: s.get(k) for k in SUMMARY_FIELDS},
        "summary_json": json.dumps(jsonable({k: v for k, v in s.items() if k != "config"})),
    }


@dataclass
class AuditStats:
    total: int = 0
    """Runs found."""
    audited: int = 0
    """Runs audited by this call (status ok)."""
    skipped: int = 0
    """Runs already audited with the same files, DB content and config."""
    failed: int = 0
    """Runs recorded with status error by this call."""
    elapsed_s: float = 0.0
    errors: list[tuple[str, str]] = field(default_factory=list)
    """(run path, error message) of the failed runs."""
    warnings: list[str] = field(default_factory=list)
    """Things the user should know (e.g. a DB modified after it was built)."""

    @property
    def runs_per_min(self) -> float:
        return 60.0 * (self.audited + self.failed) / self.elapsed_s if self.elapsed_s > 0 else 0.0

    @property
    def done(self) -> int:
        """Runs skipped, audited or failed so far."""
        return self.skipped + self.audited + self.failed


ProgressFn = Callable[[int, int, str], None]
"""``progress(done, total, run_path)``: called once before the first run (done = runs
skipped without reading them) and after every run."""


def audit(
    roots: Iterable[Path],
    db_path: Path,
    audit_path: Path,
    *,
    config: Any = None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: ProgressFn | None = None,
    unit: str = "F",
) -> AuditStats:
    """Audit every run below ``roots`` into ``audit_path`` (created or resumed).

    ``unit``: the positioning unit replayed, F (default), R or both (module docstring).

    ``workers``: processes of the local pool (default: all cores; 1 = in this process).
    ``scheduler``: address of a Dask scheduler (``tcp://host:8786``); its workers must see
    the run folders and the DB under the same paths.
    """
    from fieldlogs.pipeline.config import PipelineConfig

    check_unit(unit)
    cfg = config or PipelineConfig()
    cfg_json = json.dumps(jsonable(cfg.to_dict()), sort_keys=True)
    db, net = open_db(Path(db_path))  # fails early (exit 2) on an unreadable DB
    context = context_key(db.content_hash, cfg_json, unit)
    runs = discover_runs(roots)
    stats = AuditStats(total=len(runs))
    if net.meta.get("content_hash") != db.content_hash:
        stats.warnings.append(
            f"{db.path}: content hash does not match its meta table: the DB was modified after it was built"
        )
    t0 = time.perf_counter()
    with open_audit(audit_path) as conn:
        set_meta(
            conn,
            {
                "db_path": db.path,
                "db_version": net.meta.get("db_version", ""),
                "db_content_hash": db.content_hash,
                "config": cfg_json,
                "unit": unit,
            },
        )
        todo = _plan(conn, runs, context, stats)
        if progress:
            progress(stats.done, stats.total, "")
        tasks = [(p, (db, cfg_json, context, k, unit)) for p, k in todo]
        results = replay(audit_one, tasks, workers=workers, scheduler=scheduler, preload=PRELOAD)
        with closing(results):  # interrupted: stop the pool / cluster work at once
            for out in results:
                _store(conn, out, context, unit, stats)
                if progress:
                    progress(stats.done, stats.total, out.run)
        set_meta(conn, {"last_audit_at": datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")})
    stats.elapsed_s = time.perf_counter() - t0
    return stats


def _plan(conn: AuditDB, runs: list[Path], context: str, stats: AuditStats) -> list[tuple[str, str | None]]:
    """(run path, fingerprint it was audited with) of the runs to replay; counts the runs
    skipped without reading them (unchanged files, same DB content, same config)."""
    known = fingerprints(conn)
    todo: list[tuple[str, str | None]] = []
    for r in runs:
        prev = known.get(str(r))
        ok = prev is not None and prev[2] == "ok" and bool(prev[0])
        if ok and prev is not None and prev[3] == context and prev[1] == quick_key(r):
            stats.skipped += 1
            continue
        # the worker hashes the content; an unchanged fingerprint is still skipped
        todo.append((str(r), prev[0] if ok and prev is not None else None))
    return todo


def _store(conn: AuditDB, out: Outcome[dict[str, Any]], context: str, unit: str, stats: AuditStats) -> None:
    """Record one run's outcome; a worker that died becomes an error record of its run
    (retried by the next audit)."""
    res = out.value
    if res is None:
        res = {
            "record": {
                "unit": unit,
                "run_path": out.run,
                "fingerprint": "",
                "context": context,
                "status": "error",
                "error": out.error,
                "audited_at": _now(),
            }
        }
    rec = res["record"]
    if res.get("unchanged"):
        touch_run(conn, rec["run_path"], rec["quick_key"])
        stats.skipped += 1
        return
    store_run(conn, rec, res.get("events"), res.get("trace"), res.get("path"))
    if rec.get("status") == "error":
        stats.failed += 1
        stats.errors.append((rec["run_path"], rec.get("error") or ""))
    else:
        stats.audited += 1
