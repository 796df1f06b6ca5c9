"""The findings of one checked file, capped per rule: what every stream check writes into."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from schemas.enums import Severity
from schemas.findings import Finding
from schemas.frames import FIRST_DATA_LINE


class FileFindings:
    """Findings of one file of a run (``logs check``), capped per rule; the stream checks of
    :mod:`fieldlogs.quality.checks` and :mod:`fieldlogs.quality.gnss` add to it."""

    def __init__(self, table: str, file: str, cap: int) -> None:
        self.table, self.file, self.cap = table, file, cap
        self.items: list[Finding] = []

    def add(self, rule: str, severity: Severity, message: str, **kw: Any) -> None:
        self.items.append(Finding(rule, severity, self.table, message, file=self.file, **kw))

    def rows(
        self,
        rule: str,
        severity: Severity,
        pos: np.ndarray,
        message: Callable[[int], str],
        *,
        column: str | None = None,
        value: Callable[[int], Any] | None = None,
        limit: Any = None,
        what: str = "rows",
    ) -> None:
        """One finding per positional row index in ``pos`` (capped), via callables of the k-th."""
        n = len(pos)
        for k in range(min(n, self.cap)):
            self.add(
                rule,
                severity,
                message(k),
                row=int(pos[k]) + FIRST_DATA_LINE,
                column=column,
                value=None if value is None else value(k),
                limit=limit,
            )
        if n > self.cap:
            self.add(rule, severity, f"{n - self.cap} more {what} like the above", column=column, value=n, limit=0)
