"""Possession plans for road-rail works (SPEC §5.5)."""

from __future__ import annotations

from schemas.model import Column, Table
from schemas.tables import LINE_CODE

POSSESSIONS = Table(
    name="possessions",
    kind="plan",
    description=(
        "Possession plan: one row per possession. started_at/released_at empty while "
        "not started / not released. Times ISO 8601 with offset."
    ),
    columns=(
        Column("work_no", "str", "Work number"),
        LINE_CODE,
        Column(
            "track",
            "str",
            "U up (km decreasing), D down (km increasing), S single — or, on a network DB, the name of "
            "a station track of the line (e.g. 3): the possession is then on that network track",
        ),
        Column("km_from_m", "float", "Section start", unit="m", km_notation=True),
        Column("km_to_m", "float", "Section end", unit="m", km_notation=True),
        Column("planned_start", "str", "Planned start (ISO 8601)"),
        Column("planned_end", "str", "Planned end (ISO 8601)"),
        Column("started_at", "str", "Actual start (ISO 8601)", nullable=True),
        Column("released_at", "str", "Actual release (ISO 8601)", nullable=True),
        Column("vehicle_id", "str", "Vehicle the work is for (empty: any vehicle)", nullable=True, required=False),
        Column(
            "track_id",
            "str",
            "Network track of the possession (a station track, a crossover …; trainpos db tracks lists them): "
            "the wrong-track rule among n tracks uses it (empty: the line and track)",
            nullable=True,
            required=False,
        ),
        Column(
            "purpose",
            "str",
            "work, or protection: an adjacent-line protection possession [S001 §3.1(e)] that never "
            "allows running on its track (empty: work)",
            nullable=True,
            required=False,
            enum=("work", "protection"),
        ),
    ),
    primary_key=("work_no",),
)
