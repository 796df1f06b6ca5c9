"""One error tree for the whole suite.

Library code raises these; the CLI prints ``str(error)`` on one line to stderr and exits
with ``error.exit_code``. No other exception should reach a user.

Exit codes (documented in docs/reference/behaviour.md):

* 0 — success, nothing to report
* 1 — the input was read but has errors (findings), or a check failed
* 2 — the input cannot be read at all (missing, not CSV/SQLite, corrupt), or bad usage
* 3 — refused: the output exists, a version is already released, an input would be modified,
  a database is in use by another trainpos process (try again)
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

EXIT_OK = 0
EXIT_FINDINGS = 1
EXIT_UNREADABLE = 2
EXIT_REFUSED = 3


class TrainposError(Exception):
    """Base error: a message that names file, row and column where they are known."""

    exit_code: int = EXIT_UNREADABLE

    def __init__(
        self,
        message: str,
        *,
        path: str | Path | None = None,
        row: int | None = None,
        column: str | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.path = str(path) if path is not None else None
        self.row = row
        self.column = column

    def __str__(self) -> str:
        where = []
        if self.path:
            where.append(self.path if self.row is None else f"{self.path}:{self.row}")
        if self.column:
            where.append(f"column '{self.column}'")
        prefix = ", ".join(where)
        return f"{prefix}: {self.message}" if prefix else self.message


class InputError(TrainposError):
    """An input that cannot be read: missing, wrong format, corrupt."""

    exit_code = EXIT_UNREADABLE


class UsageError(TrainposError):
    """Arguments that do not make sense together."""

    exit_code = EXIT_UNREADABLE


class FindingsError(TrainposError):
    """The input was read, but it has errors; ``findings`` lists every one of them."""

    exit_code = EXIT_FINDINGS

    def __init__(self, message: str, findings: list[Any], **kw: Any) -> None:
        super().__init__(message, **kw)
        self.findings = findings


class RefusedError(TrainposError):
    """An action refused to protect existing data (overwrite, re-release, immutability)."""

    exit_code = EXIT_REFUSED


class BusyError(TrainposError):
    """A database locked by another process (SQLite's "database is locked" after its wait):
    nothing is wrong with it — try again once the other trainpos process has finished."""

    exit_code = EXIT_REFUSED
