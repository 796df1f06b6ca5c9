"""Fleet audits: the pipeline over many runs, in parallel, stored as each run finishes.

Runs go to a process pool on this machine by default, or to an existing Dask cluster
(``dask.distributed``) when a scheduler address is given — both call the same worker
function :func:`audit_one`, so the cluster path is the local path. Results are written
by the coordinating process only (one SQLite writer).

Skip and resume: a run is identified by its folder; its fingerprint is the SHA-256 of its
files' contents plus the onboard DB's content hash plus the pipeline config. A quick key
(file names, sizes, mtimes) avoids re-hashing unchanged runs; when it differs the worker
hashes the content and an unchanged fingerprint is still skipped.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import traceback
from collections.abc import Callable, Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field
from datetime import UTC, datetime
from multiprocessing import get_context
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.database import read_meta, read_network
from dbtools.network import Network
from fieldlogs.auditdb import fingerprints, open_audit, set_meta, store_run
from schemas.errors import InputError, TrainposError

_NETWORK_CACHE: dict[tuple[str, int, int], Network] = {}


def discover_runs(roots: Iterable[Path]) -> list[Path]:
    """Every folder holding a ``run.json`` below the given roots (a root may be a run)."""
    found: set[Path] = set()
    for root in roots:
        root = Path(root)
        if not root.exists():
            raise InputError("no such folder", path=root)
        if (root / "run.json").is_file():
            found.add(root.resolve())
            continue
        for p in root.rglob("run.json"):
            found.add(p.parent.resolve())
    return sorted(found)


def quick_key(run: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(Path(run).iterdir()):
        if p.is_file():
            st = p.stat()
            h.update(f"{p.name}:{st.st_size}:{st.st_mtime_ns}\n".encode())
    return h.hexdigest()


def content_fingerprint(run: Path, db_hash: str, cfg_json: str) -> str:
    h = hashlib.sha256()
    for p in sorted(Path(run).iterdir()):
        if p.is_file():
            h.update(p.name.encode() + b"\0")
            with open(p, "rb") as fh:
                for chunk in iter(lambda: fh.read(1 << 20), b""):
                    h.update(chunk)
    h.update(db_hash.encode() + b"\0" + cfg_json.encode())
    return h.hexdigest()


def _network(db_path: str) -> Network:
    st = os.stat(db_path)
    key = (db_path, st.st_mtime_ns, st.st_size)
    if key not in _NETWORK_CACHE:
        _NETWORK_CACHE.clear()
        _NETWORK_CACHE[key] = read_network(Path(db_path))
    return _NETWORK_CACHE[key]


def _direction(pos: pd.DataFrame) -> str | None:
    km = pos["km_m"].dropna()
    if len(km) < 2:
        return None
    return "down" if float(km.iloc[-1]) >= float(km.iloc[0]) else "up"


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
            "t": sel["t"].to_numpy(),
            "km_m": sel["km_m"].to_numpy(),
            "margin_m": sel["margin_m"].to_numpy(),
            "speed_mps": sel["speed_mps"].to_numpy(),
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


def audit_one(run_path: str, db_path: str, cfg_json: str, known_fingerprint: str | None = None) -> dict[str, Any]:
    """Worker: run the pipeline on one run. Never raises: errors become a record."""
    from fieldlogs.io import read_run
    from fieldlogs.pipeline import PipelineConfig, run_pipeline

    t0 = time.perf_counter()
    now = datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
    base: dict[str, Any] = {"run_path": run_path, "quick_key": None, "audited_at": now}
    try:
        base["quick_key"] = quick_key(Path(run_path))
        network = _network(db_path)
        fp = content_fingerprint(Path(run_path), network.meta.get("content_hash", ""), cfg_json)
        base["fingerprint"] = fp
        if known_fingerprint == fp:
            return {"record": base, "unchanged": True}
        cfg = PipelineConfig.from_dict(json.loads(cfg_json))
        result = run_pipeline(read_run(Path(run_path)), network, cfg)
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
            **{
                k: s.get(k)
                for k in (
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
                )
            },
            "summary_json": json.dumps({k: v for k, v in s.items() if k != "config"}, default=str),
            "elapsed_s": time.perf_counter() - t0,
        }
        return {"record": record, "events": result.events, "trace": _trace(result)}
    except TrainposError as exc:
        msg = str(exc)
    except Exception as exc:  # a bug on one run must not stop a fleet audit
        msg = f"internal error {type(exc).__name__}: {exc} | {traceback.format_exc(limit=3)}"
    return {
        "record": {
            **base,
            "fingerprint": base.get("fingerprint", ""),
            "status": "error",
            "error": msg,
            "elapsed_s": time.perf_counter() - t0,
        }
    }


@dataclass
class AuditStats:
    total: int = 0
    audited: int = 0
    skipped: int = 0
    failed: int = 0
    elapsed_s: float = 0.0
    errors: list[tuple[str, str]] = field(default_factory=list)

    @property
    def runs_per_min(self) -> float:
        return 60.0 * self.audited / self.elapsed_s if self.elapsed_s > 0 else 0.0


ProgressFn = Callable[[int, int, str], None]


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
    """Audit every run below ``roots`` into ``audit_path`` (created or resumed)."""
    from fieldlogs.pipeline import PipelineConfig

    cfg = config or PipelineConfig()
    cfg_json = json.dumps(cfg.to_dict(), sort_keys=True)
    db_path = Path(db_path).resolve()
    db_meta = read_meta(db_path)  # fails early (exit 2) on an unreadable DB
    runs = discover_runs(roots)
    stats = AuditStats(total=len(runs))
    t0 = time.perf_counter()
    with open_audit(audit_path) as conn:
        previous = dict(conn.execute("SELECT key, value FROM audit_meta").fetchall())
        same_context = (
            previous.get("db_content_hash") == db_meta.get("content_hash", "") and previous.get("config") == cfg_json
        )
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
            if same_context and prev and prev[2] == "ok" and prev[0] and prev[1] == quick_key(r):
                stats.skipped += 1  # unchanged files, same DB content, same config
                continue
            # the worker hashes the content; an unchanged fingerprint is still skipped
            todo.append((str(r), prev[0] if prev and prev[2] == "ok" else None))
        done = stats.skipped
        if progress:
            progress(done, stats.total, "")

        def handle(res: dict[str, Any]) -> None:
            nonlocal done
            rec = res["record"]
            if res.get("unchanged"):
                stats.skipped += 1
            else:
                store_run(conn, rec, res.get("events"), res.get("trace"))
                if rec.get("status") == "error":
                    stats.failed += 1
                    stats.errors.append((rec["run_path"], rec.get("error", "")))
                else:
                    stats.audited += 1
            done += 1
            if progress:
                progress(done, stats.total, rec["run_path"])

        for res in _execute(todo, str(db_path), cfg_json, workers, scheduler):
            handle(res)
        set_meta(conn, {"last_audit_at": datetime.now(UTC).isoformat(timespec="seconds")})
    stats.elapsed_s = time.perf_counter() - t0
    return stats


def _execute(
    todo: list[tuple[str, str | None]], db_path: str, cfg_json: str, workers: int | None, scheduler: str | None
) -> Iterable[dict[str, Any]]:
    if not todo:
        return
    if scheduler:
        from distributed import Client
        from distributed import as_completed as dask_completed

        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise InputError(f"cannot reach the Dask scheduler: {exc}", path=scheduler) from exc
        try:
            n = len(todo)
            futures = client.map(
                audit_one, [p for p, _ in todo], [db_path] * n, [cfg_json] * n, [k for _, k in todo], pure=False
            )
            for fut in dask_completed(futures):
                yield fut.result()
        finally:
            client.close()
        return
    n = workers or os.cpu_count() or 1
    if n <= 1 or len(todo) == 1:
        for p, k in todo:
            yield audit_one(p, db_path, cfg_json, k)
        return
    with ProcessPoolExecutor(max_workers=min(n, len(todo)), mp_context=get_context("forkserver")) as pool:
        futs = [pool.submit(audit_one, p, db_path, cfg_json, k) for p, k in todo]
        for fut in as_completed(futs):
            yield fut.result()
