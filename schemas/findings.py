"""Findings: what validators and checkers report, one per problem, never stop at the first."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from schemas.enums import Severity
from schemas.jsonable import jsonable

#: Decimals of finding values in JSON.
FINDING_DIGITS = 6


@dataclass
class Finding:
    """One problem: rule id, severity, where (table, keys / file, row, column), measured vs limit.

    ``row`` is the 1-based line of the file (the header is line 1, so the first data row is
    line 2) when the finding comes from a file; ``keys`` are the domain keys of the row.
    """

    rule: str
    severity: Severity
    table: str
    message: str
    keys: dict[str, Any] = field(default_factory=dict)
    value: Any = None
    limit: Any = None
    file: str | None = None
    row: int | None = None
    column: str | None = None

    def to_dict(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "rule": self.rule,
            "severity": str(self.severity),
            "table": self.table,
            "keys": jsonable(self.keys, FINDING_DIGITS),
            "value": jsonable(self.value, FINDING_DIGITS),
            "limit": jsonable(self.limit, FINDING_DIGITS),
            "message": self.message,
        }
        for name in ("file", "row", "column"):
            v = getattr(self, name)
            if v is not None:
                d[name] = v
        return d

    @property
    def where(self) -> str:
        """``file:row, column 'c'`` or ``table key=value …`` for one-line messages."""
        parts: list[str] = []
        if self.file:
            parts.append(self.file if self.row is None else f"{self.file}:{self.row}")
        else:
            parts.append(self.table)
            if self.keys:
                parts.append(" ".join(f"{k}={_short(v)}" for k, v in self.keys.items()))
        if self.column:
            parts.append(f"column '{self.column}'")
        return ", ".join(parts)

    def __str__(self) -> str:
        return f"{self.severity} [{self.rule}] {self.where}: {self.message}"


def _short(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def count_by_severity(findings: Iterable[Finding]) -> dict[str, int]:
    out = {str(Severity.ERROR): 0, str(Severity.WARNING): 0}
    for f in findings:
        out[str(f.severity)] += 1
    return out


def has_errors(findings: Iterable[Finding], strict: bool = False) -> bool:
    """True when any finding is an error (or any at all with ``strict``)."""
    return any(strict or f.severity == Severity.ERROR for f in findings)


def findings_report(findings: list[Finding]) -> dict[str, Any]:
    """The documented JSON shape: ``{"ok": bool, "findings": [...]}``."""
    return {"ok": not has_errors(findings), "findings": [f.to_dict() for f in findings]}
