"""The replayer: a per-run worker over many runs, in this process, a local pool or Dask.

``replay(worker, tasks)`` calls ``worker(run_path, *args)`` for every task ``(run_path,
args)`` and yields one :class:`Outcome` per run, as the runs complete or (``ordered``) in
task order. The worker must be a module-level function and its arguments picklable; it
may raise: the exception becomes the outcome's one-line ``error`` (:func:`error_message`),
as does a worker process that dies, and the other runs go on.

Where the runs go (one call path, :func:`run_task`, for all three):

* ``workers=1`` (or a single run): in this process;
* ``workers=N``: a pool of at most N processes, never more than the runs
  (:func:`pool_size`). On Linux they are forked from this process (``START_METHOD``
  "fork") once it has imported the worker's modules: they start in milliseconds with
  everything this process loaded (the DB of :mod:`fieldlogs.replay.network` included) and
  this process only stores results — the pool's fixed cost is a few tens of ms of CPU, not a
  second interpreter's imports (bench/NOTES.md, "Audit on 2 workers, issue 34"). A fork
  is safe here although the caller may run threads (a progress bar's refresh): a worker
  touches none of their locks, gets fresh standard streams (:func:`fork_worker_init`),
  and the stdlib re-creates the import and logging locks. Elsewhere they come from a fork
  server that imports the worker's module once; starting it takes seconds, so meanwhile
  this process replays runs from the back of the queue itself until the pool's first
  result arrives;
* ``scheduler="tcp://host:8786"``: an existing Dask cluster (:mod:`fieldlogs.replay.cluster`),
  whose workers must see the runs and the DB under the same paths.

Cancellation: closing the iterator (``with closing(replay(...))``, or an exception such as
KeyboardInterrupt while it runs) drops the queued runs, terminates the running workers and
stops the fork server and the resource tracker this replay started, so no process is left
behind; results already yielded are the caller's.
"""

from __future__ import annotations

import contextlib
import gc
import importlib
import os
import signal
import sys
import threading
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from types import TracebackType
from typing import Any, Generic, TypeVar

from fieldlogs.replay.tasks import (
    Outcome,
    Outcomes,
    Progress,
    Task,
    failed,
    run_task,
)

R = TypeVar("R")

#: How pool workers start: "fork" (Linux) or "forkserver" (module docstring).
START_METHOD = "fork" if sys.platform.startswith("linux") else "forkserver"
#: Fewest runs per pool worker: below, fewer workers (at one, the runs stay in this process).
MIN_RUNS_PER_WORKER = 2


def pool_size(workers: int, runs: int) -> int:
    """Worker processes for ``runs`` runs asked to go on ``workers``: no more than the
    cores, and each with at least ``MIN_RUNS_PER_WORKER`` runs (a worker that would replay
    one run costs its start and its first run's warm-up for at most one run's time); 1 =
    in this process."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return max(1, min(workers, cores, runs // MIN_RUNS_PER_WORKER))


def replay(
    worker: Callable[..., R],
    tasks: Iterable[Task],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    ordered: bool = False,
    progress: Progress | None = None,
    preload: Sequence[str] = (),
) -> Outcomes[R]:
    """Outcomes of ``worker`` over ``tasks`` (module docstring).

    ``workers``: processes of the local pool (default: all cores; 1 = in this process).
    ``scheduler``: a Dask scheduler address instead of the local pool. ``preload``: more
    modules for the fork server to import (the worker's own module always is).
    """
    todo = list(tasks)
    source: Outcomes[R]
    if scheduler:
        from fieldlogs.replay.cluster import cluster_outcomes

        source = cluster_outcomes(worker, todo, scheduler)
    else:
        modules = [getattr(worker, "__module__", None) or "", *preload]
        source = _local(worker, todo, workers or os.cpu_count() or 1, [m for m in modules if m])
    if ordered:
        source = _in_order(source)
    return _reporting(source, len(todo), progress)


def replay_values(
    worker: Callable[..., R], tasks: Iterable[Task], *, failure: str, **options: Any
) -> tuple[list[R], list[tuple[str, str]]]:
    """Every run's value in task order and the runs that failed as (run folder, message;
    ``failure`` when the worker gave none), for callers that report a failed run and go on
    with the others. ``options``: those of :func:`replay` (``ordered`` is implied)."""
    values: list[R] = []
    failed_runs: list[tuple[str, str]] = []
    with contextlib.closing(replay(worker, tasks, ordered=True, **options)) as outcomes:
        for out in outcomes:
            if out.value is None:
                failed_runs.append((out.run, out.error or failure))
            else:
                values.append(out.value)
    return values, failed_runs


def _reporting(source: Outcomes[R], total: int, progress: Progress | None) -> Outcomes[R]:
    done = 0
    try:
        for out in source:
            done += 1
            if progress:
                progress(done, total, out.run)
            yield out
    finally:
        source.close()  # stops the pool or the cluster work at once


def _in_order(source: Outcomes[R]) -> Outcomes[R]:
    """Outcomes in task order (later ones wait in memory for the earlier ones)."""
    waiting: dict[int, Outcome[R]] = {}
    nxt = 0
    try:
        for out in source:
            waiting[out.index] = out
            while nxt in waiting:
                yield waiting.pop(nxt)
                nxt += 1
    finally:
        source.close()


def _local(worker: Callable[..., R], tasks: list[Task], n: int, preload: list[str]) -> Outcomes[R]:
    n = pool_size(n, len(tasks))
    if n <= 1:
        for i, (run, args) in enumerate(tasks):
            yield run_task(worker, i, run, args)
        return
    with LocalPool(n, preload) as pool:
        yield from pool.outcomes(worker, tasks)


def worker_init() -> None:
    """Start of every pool worker: die with the fork server; exit at once when it is
    already gone (nothing would ever stop this process otherwise)."""
    from fieldlogs.replay import _server

    _server.die_with_parent()
    if _server.SERVER_PID != os.getpid() and os.getppid() != _server.SERVER_PID:
        os._exit(0)


def fork_worker_init(coordinator: int) -> None:
    """Start of a pool worker forked from the coordinating process (``START_METHOD``
    "fork"): ignore SIGINT (the coordinator handles Ctrl-C and stops the workers), die with
    the coordinator and exit at once when it is already gone; new standard streams, since
    a thread of the coordinator (a progress bar) may have held the old ones' locks at the
    fork; the garbage collector back on (:meth:`LocalPool.restart` froze it for the fork)."""
    from fieldlogs.replay._server import die_with_parent

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    die_with_parent()
    if os.getppid() != coordinator:
        os._exit(0)
    for name, fd in (("stdout", 1), ("stderr", 2)):
        old = getattr(sys, name, None)
        if old is None:
            continue
        try:
            new = open(fd, "w", encoding=old.encoding, errors=old.errors, closefd=False, buffering=1)
        except (OSError, ValueError, AttributeError):  # no such descriptor: keep the old one
            continue
        setattr(sys, name, new)


class LocalPool:
    """A fork-server process pool for one replay, stopped with everything it started.

    At most ``2 n`` runs are in the pool at a time (enough to keep every worker busy while
    this process stores results), so that a worker process that dies takes few runs with
    it: the pool is restarted, those runs are retried one at a time and only a run that
    breaks the pool again is an error (:class:`_Schedule`).
    """

    def __init__(self, n: int, preload: list[str]) -> None:
        self.n = n
        self.method = START_METHOD
        self.preload = ["fieldlogs.replay._server", *dict.fromkeys(preload)]
        self.pool: ProcessPoolExecutor | None = None
        self.own_server = self.own_tracker = False
        self.frozen = False

    def __enter__(self) -> LocalPool:
        from multiprocessing import forkserver, get_context, resource_tracker

        if self.method == "fork":  # the workers inherit what this process imported
            for name in self.preload[1:]:
                importlib.import_module(name)
            self.restart()
            return self
        ctx = get_context("forkserver")
        ctx.set_forkserver_preload(self.preload)  # for a server started now (a running one keeps its own)
        tracker, server = _pid(resource_tracker, "_resource_tracker"), _pid(forkserver, "_forkserver")
        # started from this thread: PR_SET_PDEATHSIG ties the server to it (not to a feeder thread)
        with _safe_path():
            forkserver.ensure_running()
        self.own_tracker = _pid(resource_tracker, "_resource_tracker") != tracker
        self.own_server = _pid(forkserver, "_forkserver") != server
        self.restart()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close(cancel=exc_type is not None)

    def restart(self) -> ProcessPoolExecutor:
        """A new pool (the first one, or after a worker process died and broke the last)."""
        from multiprocessing import get_context

        if self.pool is not None:
            self._shutdown(cancel=True)
        if self.method == "fork":
            # the workers fork at the first submit; objects already here are kept out of
            # their collections (a collection writes to every object it visits: a private
            # copy of each page of the coordinator's heap per worker)
            if not self.frozen:
                gc.freeze()
                self.frozen = True
            self.pool = ProcessPoolExecutor(
                max_workers=self.n,
                mp_context=get_context("fork"),
                initializer=fork_worker_init,
                initargs=(os.getpid(),),
            )
        else:
            self.pool = ProcessPoolExecutor(
                max_workers=self.n, mp_context=get_context("forkserver"), initializer=worker_init
            )
        return self.pool

    def _shutdown(self, *, cancel: bool) -> None:
        pool, self.pool = self.pool, None
        if pool is None:
            return
        if cancel:
            # no public way to stop a running worker before Python 3.14 (terminate_workers)
            procs = list((getattr(pool, "_processes", None) or {}).values())
            for p in procs:
                p.terminate()
            for p in procs:
                p.join(10)
        pool.shutdown(wait=True, cancel_futures=True)

    def close(self, *, cancel: bool) -> None:
        """Shut the pool down (``cancel``: terminate running workers, drop the queue), then
        stop the fork server and the resource tracker if this pool started them."""
        from multiprocessing import forkserver, resource_tracker

        self._shutdown(cancel=cancel)
        if self.frozen:
            gc.unfreeze()
            self.frozen = False
        if self.method == "fork":
            return  # no server, no tracker: a forked pool's semaphores are unlinked at once
        gc.collect()  # release the pool's semaphores before their tracker stops
        if self.own_server:
            _stop(forkserver, "_forkserver")
        if self.own_tracker:
            _stop(resource_tracker, "_resource_tracker")

    def outcomes(self, worker: Callable[..., R], tasks: list[Task]) -> Iterator[Outcome[R]]:
        """Outcomes in completion order (see :class:`_Schedule`)."""
        return _Schedule(self, worker, tasks).outcomes()


class _Schedule(Generic[R]):
    """Which run goes where, and when.

    Start-up, fork server only: the server imports the worker's modules for seconds and
    ``submit`` blocks meanwhile, so a thread submits the first runs while this process
    replays runs from the back of the queue itself until the pool's first result arrives.
    Forked workers start at once: this process only stores results (a third CPU-bound
    process would take a core from the workers). Then: at most ``2 n`` runs in the pool,
    the next submitted as one completes.
    """

    def __init__(self, owner: LocalPool, worker: Callable[..., R], tasks: list[Task]) -> None:
        self.owner, self.worker = owner, worker
        assert owner.pool is not None
        self.pool = owner.pool
        self.limit = 2 * owner.n
        self.queue: deque[tuple[int, Task]] = deque(enumerate(tasks))
        self.inflight: dict[Future[Outcome[R]], tuple[int, Task]] = {}
        self.strikes: dict[int, int] = {}
        self.restarts = 0
        self.lock = threading.Lock()
        self.helps = owner.method != "fork"

    def outcomes(self) -> Iterator[Outcome[R]]:
        if not self.helps:
            while self.inflight or self.queue:
                self._fill()
                yield from self._completed()
            return
        feeder = threading.Thread(target=self._fill, name="replay-submit", daemon=True)
        feeder.start()
        try:
            while True:  # until the pool's first result
                with self.lock:
                    busy = any(f.done() for f in self.inflight)
                    item = self.queue.pop() if self.queue and not busy else None
                if item is None:
                    break
                yield run_task(self.worker, item[0], *item[1])
            feeder.join()
            while self.inflight or self.queue:
                self._fill()
                yield from self._completed()
        finally:
            with self.lock:
                self.queue.clear()  # interrupted: submit nothing more
            feeder.join()

    def _fill(self) -> None:
        """Submit runs up to the limit; a run that was in the pool when a worker died goes
        alone (nothing else in the pool) so that a second break names it."""
        while True:
            with self.lock:
                if not self.queue or len(self.inflight) >= self.limit or self._solo():
                    return
                i, task = self.queue.popleft()
                if self.strikes.get(i) and self.inflight:
                    self.queue.appendleft((i, task))
                    return
            try:
                fut = self.pool.submit(run_task, self.worker, i, task[0], task[1])
            except BaseException:  # shut down (interrupted) or broken: handled by the caller
                with self.lock:
                    self.queue.appendleft((i, task))
                return
            with self.lock:
                self.inflight[fut] = (i, task)

    def _solo(self) -> bool:
        return any(self.strikes.get(i) for i, _ in self.inflight.values())

    def _completed(self) -> Iterator[Outcome[R]]:
        """Outcomes of the runs that completed next; restarts a broken pool."""
        if not self.inflight:  # the pool refused new work: it is broken
            self.restarts += 1
            if self.restarts > 2:  # and cannot be restarted: the remaining runs fail
                while self.queue:
                    i, task = self.queue.popleft()
                    yield failed(i, task[0], RuntimeError("the process pool cannot be restarted"))
                return
            self.pool = self.owner.restart()
            return
        done, _ = wait(list(self.inflight), return_when=FIRST_COMPLETED)
        self.restarts = 0
        broken = False
        for fut in done:
            i, task = self.inflight.pop(fut)
            try:
                yield fut.result()
            except BrokenProcessPool as exc:  # a worker died: this run or another in the pool
                broken = True
                self.strikes[i] = self.strikes.get(i, 0) + 1
                if self.strikes[i] >= 2:  # it was alone in the pool: it broke it
                    yield failed(i, task[0], exc)
                else:
                    self.queue.appendleft((i, task))
            except Exception as exc:
                yield failed(i, task[0], exc)
        if broken and not self.inflight:
            self.pool = self.owner.restart()


@contextlib.contextmanager
def _safe_path() -> Iterator[None]:
    """The fork server runs as ``python -c``, which puts the working folder first on its
    ``sys.path``: a folder there named like one of the suite's packages (``fieldlogs/`` of
    someone's logs) would then shadow an editable install as a namespace package in the
    server and every worker it forks. ``PYTHONSAFEPATH`` (Python ≥ 3.11) keeps it off; the
    workers get this process's own ``sys.path`` anyway (``multiprocessing.spawn.prepare``)."""
    old = os.environ.get("PYTHONSAFEPATH")
    os.environ["PYTHONSAFEPATH"] = "1"
    try:
        yield
    finally:
        if old is None:
            del os.environ["PYTHONSAFEPATH"]
        else:
            os.environ["PYTHONSAFEPATH"] = old


def _pid(module: Any, singleton: str) -> int | None:
    """The pid of a multiprocessing helper process (fork server, resource tracker), if started."""
    obj = getattr(module, singleton, None)
    pid = getattr(obj, "_forkserver_pid", None) if singleton == "_forkserver" else getattr(obj, "_pid", None)
    return None if pid is None else int(pid)


def _stop(module: Any, singleton: str) -> None:
    """Stop a multiprocessing helper process (``_stop``: the stdlib's own, used by its tests)."""
    stop = getattr(getattr(module, singleton, None), "_stop", None)
    if stop is not None:
        stop()
