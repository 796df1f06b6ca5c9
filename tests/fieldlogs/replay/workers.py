"""Small per-run workers for the replayer's tests (module level: the pool imports them)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from fieldlogs.replay.network import DbRef, load_network
from schemas.errors import InputError


def run_info(run: str, pause_s: float = 0.0) -> dict[str, object]:
    """run_id from run.json and the pid that read it; InputError for an unreadable run.json."""
    time.sleep(pause_s)
    try:
        meta = json.loads((Path(run) / "run.json").read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise InputError(f"run.json is not JSON: {exc.msg}", path=Path(run) / "run.json") from None
    return {"run_id": meta["run_id"], "pid": os.getpid()}


def balise_count(run: str, db: DbRef) -> tuple[str, int, int]:
    """(run folder name, balises of the cached DB, id of the cached Network object)."""
    net = load_network(db)
    return Path(run).name, len(net.balises), id(net)


def crash(run: str, coordinator_pid: int) -> None:
    """A worker process dying on ``*-1`` runs (as when killed or out of memory); the
    coordinating process, which replays runs too while the pool starts, is spared."""
    time.sleep(0.2)
    if Path(run).name.endswith("1") and os.getpid() != coordinator_pid:
        os._exit(3)
