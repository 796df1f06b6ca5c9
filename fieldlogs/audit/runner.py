"""Fleet audits: the pipeline over many runs, in parallel, stored as each run finishes.

Runs go to a process pool on this machine by default, or to an existing Dask cluster
(``dask.distributed``) when a scheduler address is given — both call the same worker
function :func:`audit_one`, so the cluster path is the local path. Results are written
by the coordinating process only (one SQLite writer). The local pool uses a fork server
that imports the pipeline once (and ignores Ctrl-C: the coordinator handles it); while it
starts, the coordinating process audits runs itself.

Skip and resume: a run is identified by its folder (absolute path); its fingerprint is the
SHA-256 of its files' contents plus the *context* (the onboard DB's content hash and the
pipeline config). A quick key (file names, sizes, mtimes) plus an unchanged context skips a
run without reading it; when only the quick key differs (a file touched, copied back) the
worker hashes the content and an unchanged fingerprint is still skipped. Runs recorded
with status ``error`` are retried. The context is kept per run, so resuming an audit
interrupted under another config or DB never skips a run audited with the old one.

A run fails (status ``error``, message stored) when run.json is unusable, a stream its
vehicle kind needs (tacho and IMU for a train, GPS and cab for a road-rail vehicle) is
missing or has no usable row, or the pipeline raises; the other runs go on.

Workers send back compact results: one record, the events as plain column arrays (no
DataFrame machinery to pickle) and the 1 Hz trace already encoded as Parquet bytes, so the
coordinator (the single SQLite writer) does little per run and never becomes the
bottleneck of a parallel audit.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import os
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable, Generator, Iterable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from contextlib import closing
from dataclasses import dataclass, field
from datetime import UTC, datetime
from multiprocessing import get_context
from pathlib import Path
from typing import Any, cast

import numpy as np
import pandas as pd

from dbtools.database import read_meta, read_network
from dbtools.network import Network
from fieldlogs.audit.store import encode_trace, fingerprints, open_audit, set_meta, store_run, touch_run
from schemas.errors import FindingsError, InputError, TrainposError

_NETWORK_CACHE: dict[tuple[str, int, int], Network] = {}
_MALLOC_TUNED = False
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc mallopt parameters (malloc.h)
#: Events whose correction % enters the position-correction statistics (SPEC §5.2).


def discover_runs(roots: Iterable[Path]) -> list[Path]:
    """Every folder holding a ``run.json`` below the given roots (a root may be a run)."""
    found: set[Path] = set()
    for root in roots:
        root = Path(root)
        if not root.is_dir():
            raise InputError("no such folder", path=root)
        if (root / "run.json").is_file():
            found.add(root.resolve())
            continue
        for p in root.rglob("run.json"):
            rel = p.parent.relative_to(root).parts
            if any(part.startswith(".") for part in rel):
                continue  # temporary folders of an atomic write (.name.xxxx), hidden folders
            found.add(p.parent.resolve())
    return sorted(found)


def quick_key(run: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(Path(run).iterdir()):
        if p.is_file():
            st = p.stat()
            h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def context_key(db_hash: str, cfg_json: str) -> str:
    """What a run's result depends on besides its files: DB content and pipeline config."""
    return hashlib.sha256(db_hash.encode() + b"\0" + cfg_json.encode()).hexdigest()


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


def _tune_malloc() -> None:
    """Undo a small ``MALLOC_TRIM_THRESHOLD_`` for this process (once; glibc only).

    Dask's nanny starts every worker with ``MALLOC_TRIM_THRESHOLD_=65536``, which also
    freezes glibc's mmap threshold at 128 kB: every array of a run (MBs each) is then mapped,
    page-faulted, zeroed and unmapped afresh, and a run costs 2.5× the CPU it costs in a
    plain process. Arrays up to 32 MiB go back to the heap and memory is trimmed above
    256 MiB instead.
    """
    global _MALLOC_TUNED
    if _MALLOC_TUNED:
        return
    _MALLOC_TUNED = True
    if not sys.platform.startswith("linux") or "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(M_MMAP_THRESHOLD, 32 << 20)
        libc.mallopt(M_TRIM_THRESHOLD, 256 << 20)
    except (OSError, AttributeError):  # not glibc
        pass


def _network(db_path: str) -> Network:
    st = os.stat(db_path)
    key = (db_path, st.st_mtime_ns, st.st_size)
    if key not in _NETWORK_CACHE:
        _NETWORK_CACHE.clear()
        _NETWORK_CACHE[key] = read_network(Path(db_path))
    return _NETWORK_CACHE[key]


def _direction(pos: pd.DataFrame) -> str | None:
    """``down`` when the km grew over the run, ``up`` when it fell (None if never determined)."""
    km = pos["km_m"].dropna()
    if len(km) < 2:
        return None
    return "down" if float(km.iloc[-1]) >= float(km.iloc[0]) else "up"


Packed = dict[str, Any]


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
            text = np.array([*cats, None], dtype=object)
            cols[c] = text[np.where(codes < 0, len(cats), codes)]
        else:
            cols[c] = v
    return pd.DataFrame(cols)


def _trace(result: Any) -> pd.DataFrame:
    """1 Hz trace of a run for plots: km, margin, speeds, κ, GPS position, truth error."""
    pos = result.positions
    dt = float(np.median(np.diff(pos["t"]))) if len(pos) > 1 else 0.1
    step = max(round(1.0 / max(dt, 1e-3)), 1)
    keep = np.zeros(len(pos), dtype=bool)
    keep[::step] = True
    t = pos["t"].to_numpy()
    for ep in result.odometry.episodes:  # full rate around slip/slide episodes
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


def _check_usable(run: Any) -> None:
    """InputError when run.json is unusable or a stream the vehicle kind needs is missing or
    has no usable row (fewer than 2 rows with every required column valid)."""
    from fieldlogs.io import REQUIRED_STREAMS
    from schemas.enums import Severity
    from schemas.logs import LOG_STREAMS

    if run.meta is None:
        errors = [f for f in run.findings if f.severity == Severity.ERROR]
        detail = "; ".join(f"{f.column or f.table}: {f.message}" for f in errors[:3])
        raise FindingsError(f"run.json is unusable ({detail})", errors, path=run.folder / "run.json")
    problems = []
    for name in REQUIRED_STREAMS.get(run.meta.vehicle_kind, ()):
        if not run.has(name):
            problems.append(f"{name}: missing")
            continue
        frame = run.stream(name)
        cols = [c.name for c in LOG_STREAMS[name].columns if c.required and not c.nullable]
        usable = 0
        if frame is not None and all(c in frame.columns for c in cols):
            usable = int(frame[cols].notna().all(axis=1).sum())
        if usable < 2:
            first = next((f for f in run.stream_findings(name) if f.severity == Severity.ERROR), None)
            problems.append(f"{name}: no usable rows" + (f" ({first.message})" if first else ""))
    if problems:
        raise InputError(f"unusable run: {'; '.join(problems)}", path=run.folder)


def audit_one(
    run_path: str, db_path: str, cfg_json: str, context: str, known_fingerprint: str | None = None
) -> dict[str, Any]:
    """Worker: run the pipeline on one run. Never raises: errors become a record.

    Returns ``{"record": {...}, "events": pack(events), "trace": Parquet bytes}``, or
    ``{"record": ..., "unchanged": True}`` when the content fingerprint equals
    ``known_fingerprint``.
    """
    from fieldlogs.io import read_run
    from fieldlogs.pipeline import PipelineConfig, run_pipeline

    _tune_malloc()
    t0, c0 = time.perf_counter(), time.process_time()
    now = datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")
    base: dict[str, Any] = {
        "run_path": run_path,
        "quick_key": None,
        "context": context,
        "fingerprint": "",
        "audited_at": now,
    }
    try:
        base["quick_key"] = quick_key(Path(run_path))
        fp = content_fingerprint(Path(run_path), context)
        base["fingerprint"] = fp
        if known_fingerprint == fp:
            return {"record": base, "unchanged": True}
        network = _network(db_path)
        cfg = PipelineConfig.from_dict(json.loads(cfg_json))
        run = read_run(Path(run_path))
        _check_usable(run)
        result = run_pipeline(run, network, cfg)
        s = result.summary
        record = {
            **base,
            "status": "ok",
            "run_id": s["run_id"],
            "vehicle_id": s["vehicle_id"],
            "vehicle_kind": s["vehicle_kind"],
            "db_version": s["db_version"],
            "line_code": s["line_code"],
            "track": s["track"],
            "direction": _direction(result.positions),
            **{k: s[k] for k in ("n_corrections", "mean_correction_pct", "max_correction_pct")},
            **{
                k: s.get(k)
                for k in (
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
            },
            "summary_json": json.dumps({k: v for k, v in s.items() if k != "config"}, default=str),
            "elapsed_s": time.perf_counter() - t0,  # wall time in the worker
            "cpu_s": time.process_time() - c0,  # its CPU time (wall / CPU > 1: a busy machine)
        }
        return {"record": record, "events": pack(result.events), "trace": encode_trace(_trace(result))}
    except FindingsError as exc:
        msg = str(exc)
        if exc.findings and "(" not in exc.message:
            msg += ": " + "; ".join(f.message for f in exc.findings[:3])
    except TrainposError as exc:
        msg = str(exc)
    except OSError as exc:  # the folder vanished or is unreadable
        msg = f"cannot read the run: {exc}"
    except Exception as exc:  # a bug on one run must not stop a fleet audit
        msg = f"internal error {type(exc).__name__}: {exc} | {traceback.format_exc(limit=3)}"
    end = {"elapsed_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0}
    return {"record": {**base, "status": "error", "error": msg, **end}}


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

    @property
    def runs_per_min(self) -> float:
        return 60.0 * (self.audited + self.failed) / self.elapsed_s if self.elapsed_s > 0 else 0.0


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
) -> AuditStats:
    """Audit every run below ``roots`` into ``audit_path`` (created or resumed).

    ``workers``: processes of the local pool (default: all cores; 1 = in this process).
    ``scheduler``: address of a Dask scheduler (``tcp://host:8786``); its workers must see
    the run folders and the DB under the same paths.
    """
    from fieldlogs.pipeline import PipelineConfig

    cfg = config or PipelineConfig()
    cfg_json = json.dumps(cfg.to_dict(), sort_keys=True)
    db_path = Path(db_path).resolve()
    db_meta = read_meta(db_path)  # fails early (exit 2) on an unreadable DB
    context = context_key(db_meta.get("content_hash", ""), cfg_json)
    runs = discover_runs(roots)
    stats = AuditStats(total=len(runs))
    t0 = time.perf_counter()
    with open_audit(audit_path) as conn:
        set_meta(
            conn,
            {
                "db_path": str(db_path),
                "db_version": db_meta.get("db_version", ""),
                "db_content_hash": db_meta.get("content_hash", ""),
                "config": cfg_json,
            },
        )
        known = fingerprints(conn)
        todo: list[tuple[str, str | None]] = []
        for r in runs:
            prev = known.get(str(r))
            ok = prev is not None and prev[2] == "ok" and bool(prev[0])
            if ok and prev is not None and prev[3] == context and prev[1] == quick_key(r):
                stats.skipped += 1  # unchanged files, same DB content, same config
                continue
            # the worker hashes the content; an unchanged fingerprint is still skipped
            todo.append((str(r), prev[0] if ok and prev is not None else None))
        done = stats.skipped
        if progress:
            progress(done, stats.total, "")
        results = _execute(todo, str(db_path), cfg_json, context, workers, scheduler)
        with closing(results):  # interrupted: stop the pool / cluster work at once
            for res in results:
                rec = res["record"]
                if res.get("unchanged"):
                    touch_run(conn, rec["run_path"], rec["quick_key"])
                    stats.skipped += 1
                else:
                    store_run(conn, rec, unpack(res.get("events")), res.get("trace"))
                    if rec.get("status") == "error":
                        stats.failed += 1
                        stats.errors.append((rec["run_path"], rec.get("error") or ""))
                    else:
                        stats.audited += 1
                done += 1
                if progress:
                    progress(done, stats.total, rec["run_path"])
        set_meta(conn, {"last_audit_at": datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")})
    stats.elapsed_s = time.perf_counter() - t0
    return stats


def _execute(
    todo: list[tuple[str, str | None]],
    db_path: str,
    cfg_json: str,
    context: str,
    workers: int | None,
    scheduler: str | None,
) -> Generator[dict[str, Any], None, None]:
    """Results of ``audit_one`` over ``todo`` in completion order. Closing the generator
    early (an interrupted audit) cancels the runs not started yet."""
    if not todo:
        return
    if scheduler:
        yield from _execute_dask(todo, db_path, cfg_json, context, scheduler)
        return
    n = workers or os.cpu_count() or 1
    if n <= 1 or len(todo) == 1:
        for p, k in todo:
            yield audit_one(p, db_path, cfg_json, context, k)
        return
    # forkserver, not fork: the caller may run threads (progress bar, Dask client, BLAS). The
    # server imports the pipeline once; workers fork from it ready to run.
    ctx = get_context("forkserver")
    ctx.set_forkserver_preload(
        ["fieldlogs.audit._ignore_sigint", "fieldlogs.audit.runner", "fieldlogs.pipeline", "fieldlogs.io"]
    )
    pool = ProcessPoolExecutor(max_workers=min(n, len(todo)), mp_context=ctx)
    try:
        yield from _pool_results(pool, todo, db_path, cfg_json, context)
    finally:
        # normal end: nothing left; interrupted: drop the queue, let running runs finish
        pool.shutdown(wait=True, cancel_futures=True)


def _pool_results(
    pool: ProcessPoolExecutor, todo: list[tuple[str, str | None]], db_path: str, cfg_json: str, context: str
) -> Iterator[dict[str, Any]]:
    """Results from the pool in completion order.

    Starting the pool takes seconds (the fork server imports the pipeline) and ``submit``
    blocks meanwhile, so a thread submits the runs from the front of the queue while this
    process audits runs from its back itself until the pool's first result arrives: a small
    audit is never slower than one worker, and a large one loses no time to the start-up.
    """
    items = deque(todo)
    lock = threading.Lock()
    submitted: dict[Future[dict[str, Any]], str] = {}

    def feed() -> None:
        while True:
            with lock:
                if not items:
                    return
                p, k = items.popleft()
            try:
                fut = pool.submit(audit_one, p, db_path, cfg_json, context, k)
            except BaseException:  # pool shut down (interrupted) or broken: the rest is done here
                with lock:
                    items.appendleft((p, k))
                return
            with lock:
                submitted[fut] = p

    feeder = threading.Thread(target=feed, name="audit-submit", daemon=True)
    feeder.start()
    try:
        while True:
            with lock:
                item = items.pop() if items and not any(f.done() for f in submitted) else None
            if item is None:
                break
            yield audit_one(item[0], db_path, cfg_json, context, item[1])
        feeder.join()
        for fut in as_completed(list(submitted)):
            yield _result(fut, submitted[fut], context)
        while items:  # the pool broke before taking them all
            p, k = items.pop()
            yield audit_one(p, db_path, cfg_json, context, k)
    finally:
        with lock:
            items.clear()  # interrupted: submit nothing more
        feeder.join()


def _result(fut: Any, run_path: str, context: str) -> dict[str, Any]:
    """A finished future's result; a worker that died (killed, out of memory, lost) becomes
    an error record of its run (retried by the next audit)."""
    try:
        return cast(dict[str, Any], fut.result())
    except Exception as exc:
        now = datetime.now(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")
        msg = f"worker failed: {type(exc).__name__}: {exc}"
        return {
            "record": {
                "run_path": run_path,
                "fingerprint": "",
                "context": context,
                "status": "error",
                "error": msg,
                "audited_at": now,
            }
        }


def _execute_dask(
    todo: list[tuple[str, str | None]], db_path: str, cfg_json: str, context: str, scheduler: str
) -> Iterator[dict[str, Any]]:
    from distributed import Client
    from distributed import as_completed as dask_completed

    try:
        client = Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler: {exc}", path=scheduler) from exc
    futures: list[Any] = []
    try:
        n = len(todo)
        futures = client.map(
            audit_one,
            [p for p, _ in todo],
            [db_path] * n,
            [cfg_json] * n,
            [context] * n,
            [k for _, k in todo],
            pure=False,
        )
        paths = {fut.key: p for fut, (p, _) in zip(futures, todo, strict=True)}
        for fut in dask_completed(futures):
            yield _result(fut, paths[fut.key], context)
            fut.release()
    finally:
        if futures:
            client.cancel(futures)
        client.close()
