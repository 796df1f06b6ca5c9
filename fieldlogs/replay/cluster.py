"""The Dask path of the replayer: the same :func:`~fieldlogs.replay.pool.run_task` on an
existing ``dask.distributed`` cluster (imported only when a scheduler address is given).

Each task is one opaque :class:`_Call` (so that Dask never reads a worker's arguments as a
task graph); its outcome comes back when it completes. A worker lost or killed makes the
run's outcome an error. Closing the iterator cancels every run not finished yet.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from fieldlogs.replay.tasks import Outcome, Task, failed, run_task
from schemas.errors import InputError

R = TypeVar("R")


@dataclass(frozen=True)
class _Call(Generic[R]):
    worker: Callable[..., R]
    index: int
    run: str
    args: tuple[Any, ...]


def _invoke(call: _Call[R]) -> Outcome[R]:
    return run_task(call.worker, call.index, call.run, call.args)


def cluster_outcomes(worker: Callable[..., R], tasks: list[Task], scheduler: str) -> Generator[Outcome[R], None, None]:
    """Outcomes in completion order from the cluster at ``scheduler``."""
    if not tasks:
        return
    distributed: Any = importlib.import_module("distributed")  # untyped: kept as Any
    try:
        client = distributed.Client(scheduler, timeout="10s")
    except (OSError, TimeoutError) as exc:
        raise InputError(f"cannot reach the Dask scheduler: {exc}", path=scheduler) from exc
    futures: list[Any] = []
    try:
        calls = [_Call(worker, i, run, args) for i, (run, args) in enumerate(tasks)]
        futures = client.map(_invoke, calls, pure=False)
        index = {fut.key: i for i, fut in enumerate(futures)}
        for fut in distributed.as_completed(futures):
            i = index[fut.key]
            try:
                out: Outcome[R] = fut.result()
            except Exception as exc:  # the worker died or was lost
                out = failed(i, tasks[i][0], exc)
            fut.release()
            yield out
    finally:
        if futures:
            client.cancel(futures)
        client.close()
