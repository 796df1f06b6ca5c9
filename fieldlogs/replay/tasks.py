"""One run as a task of the replayer, wherever it is executed (a local process pool,
:mod:`fieldlogs.replay.pool`, or a Dask cluster, :mod:`fieldlogs.replay.cluster`): the task,
its outcome, and the worker call that turns any error of one run into a message."""

from __future__ import annotations

import ctypes
import os
import sys
import traceback
from collections.abc import Callable, Generator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

from schemas.errors import FindingsError, TrainposError

R = TypeVar("R")
Task = tuple[str, tuple[Any, ...]]
"""(run folder, further arguments of the worker)."""
Progress = Callable[[int, int, str], None]
"""``progress(done, total, run_path)``, called after every run."""

M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3  # glibc mallopt parameters (malloc.h)
_MALLOC_TUNED: list[bool] = []


@dataclass(frozen=True)
class Outcome(Generic[R]):
    """What one run gave: ``value`` (the worker's return value) or ``error``."""

    index: int
    """Position of the run in the tasks."""
    run: str
    value: R | None = None
    error: str | None = None
    """One-line message when the worker raised or its process died."""

    @property
    def ok(self) -> bool:
        return self.error is None


Outcomes = Generator[Outcome[R], None, None]
"""What :func:`replay` returns: close it to cancel the runs not finished yet."""


def error_message(exc: BaseException) -> str:
    """The message an error record of a run carries: the suite's own errors as they read
    (with the first findings of a FindingsError), an unreadable folder, or an internal
    error with its type and the last frames of its traceback."""
    if isinstance(exc, FindingsError):
        msg = str(exc)
        if exc.findings and "(" not in exc.message:
            msg += ": " + "; ".join(str(getattr(f, "message", f)) for f in exc.findings[:3])
        return msg
    if isinstance(exc, TrainposError):
        return str(exc)
    if isinstance(exc, OSError):  # the folder vanished or is unreadable
        return f"cannot read the run: {exc}"
    tb = "".join(traceback.format_exception(exc, limit=3))
    return f"internal error {type(exc).__name__}: {exc} | {tb}"


def _tune_malloc() -> None:
    """Undo a small ``MALLOC_TRIM_THRESHOLD_`` for this process (once; glibc only).

    Dask's nanny starts every worker with ``MALLOC_TRIM_THRESHOLD_=65536``, which also
    freezes glibc's mmap threshold at 128 kB: every array of a run (MBs each) is then
    mapped, page-faulted, zeroed and unmapped afresh (the cost is in bench/NOTES.md,
    "Replayer"). Arrays up to 32 MiB go back to the heap and memory is trimmed above
    256 MiB instead.
    """
    if _MALLOC_TUNED:
        return
    _MALLOC_TUNED.append(True)
    if not sys.platform.startswith("linux") or "MALLOC_TRIM_THRESHOLD_" not in os.environ:
        return
    try:
        libc = ctypes.CDLL("libc.so.6")
        libc.mallopt(M_MMAP_THRESHOLD, 32 << 20)
        libc.mallopt(M_TRIM_THRESHOLD, 256 << 20)
    except (OSError, AttributeError):  # not glibc
        pass


def run_task(worker: Callable[..., R], index: int, run: str, args: tuple[Any, ...]) -> Outcome[R]:
    """One run, wherever it is executed: the worker's value, or its error as a message."""
    _tune_malloc()
    try:
        return Outcome(index, run, worker(run, *args))
    except Exception as exc:  # one bad run must not stop the fleet
        return Outcome(index, run, error=error_message(exc))


def failed(index: int, run: str, exc: BaseException) -> Outcome[Any]:
    """The outcome of a run whose worker process died (killed, out of memory, lost)."""
    return Outcome(index, run, error=f"worker failed: {type(exc).__name__}: {exc}")
