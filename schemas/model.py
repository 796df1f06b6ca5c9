"""Declarative column and table model: the single source of truth for every table.

Readers, validators, the SQLite DDL, the docs' schema reference and ``trainpos schema show`` are all
derived from these declarations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

DType = Literal["str", "int", "float", "bool", "bytes"]

#: The plausible range of every kilometrage column (``km_notation``): ±2,000 km. No line is
#: longer; a km beyond it is a typing error (23469.0 → 234690000) or a value that was
#: never a km (1e308), caught as ``schema.range`` in sources and DBs alike.
KM_PLAUSIBLE_M = 2_000_000.0
Kind = Literal["db", "source", "log", "output", "plan", "audit"]


@dataclass(frozen=True)
class Column:
    """One column: name (unit suffix in the name, e.g. ``km_m``), type, unit, limits."""

    name: str
    dtype: DType
    description: str
    unit: str = ""
    required: bool = True
    """The column must be present in a source or log file."""
    nullable: bool = False
    """Empty cells allowed."""
    enum: tuple[str, ...] | None = None
    min: float | None = None
    max: float | None = None
    km_notation: bool = False
    """Accept ``12k345.6`` as well as plain metres when reading sources; the column's range
    is then at most :data:`KM_PLAUSIBLE_M` either way."""
    float32: bool = False
    """Stored as 32-bit float in Parquet and read back as float32 (raw radar samples, where
    4 bytes per value halve a 10 kHz stream); ``t`` and every derived value stay 64-bit."""

    def __post_init__(self) -> None:
        if self.km_notation:  # every km column: within the plausible range unless it declares a narrower one
            object.__setattr__(self, "min", -KM_PLAUSIBLE_M if self.min is None else max(self.min, -KM_PLAUSIBLE_M))
            object.__setattr__(self, "max", KM_PLAUSIBLE_M if self.max is None else min(self.max, KM_PLAUSIBLE_M))

    @property
    def sql_type(self) -> str:
        return {"str": "TEXT", "int": "INTEGER", "float": "REAL", "bool": "INTEGER", "bytes": "BLOB"}[self.dtype]


@dataclass(frozen=True)
class ForeignKey:
    columns: tuple[str, ...]
    other_table: str
    other_columns: tuple[str, ...]


@dataclass(frozen=True)
class Table:
    """A table, a source file or a log stream."""

    name: str
    kind: Kind
    description: str
    columns: tuple[Column, ...]
    primary_key: tuple[str, ...] = ()
    """Key used for SQLite PRIMARY KEY, sorting, content hash and diff."""
    unique: tuple[tuple[str, ...], ...] = ()
    foreign_keys: tuple[ForeignKey, ...] = ()
    indexes: tuple[tuple[str, ...], ...] = ()
    """Secondary indexes of the SQLite table (onboard DBs: built after the bulk load). Each costs
    every ``db build`` its creation and every ``db validate`` a look-up per row
    (``integrity_check``): declare one only for a query that needs it (the onboard readers
    read whole tables; ``db show --where`` works without one, by a scan)."""
    without_rowid: bool = False
    """Onboard DBs: an SQLite ``WITHOUT ROWID`` table, its rows stored once, in the b-tree of
    the primary key (a rowid table holds them in a rowid b-tree plus the key's index: every row
    twice, which ``db validate``'s ``integrity_check`` reads and cross-checks). For tables read
    whole, in key order, and looked up by nothing but their key. Their rows have no rowid:
    findings name the key (:func:`dbtools.foreign_keys.fk_violations`). A DB built before
    (rowid tables) reads, hashes and validates the same."""
    required: bool = True
    """For sources and log streams: must the file exist?"""
    rate_hz: float | None = None
    """Nominal sampling rate of a log stream (None for event streams)."""
    held: bool = False
    """Log streams: each row holds until a later one (a state, e.g. the cab's direction), so a
    time window of the stream also takes every row before it (:meth:`fieldlogs.runs.handle.Run.window`)."""
    extra: dict[str, str] = field(default_factory=dict)

    @property
    def column_names(self) -> list[str]:
        return [c.name for c in self.columns]

    def column(self, name: str) -> Column:
        for c in self.columns:
            if c.name == name:
                return c
        raise KeyError(name)

    @property
    def required_columns(self) -> list[str]:
        return [c.name for c in self.columns if c.required]
