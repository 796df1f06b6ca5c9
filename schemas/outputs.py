"""Pipeline outputs (``trainpos run``): positions per cycle and events."""

from __future__ import annotations

from schemas.enums import PositionState, Track
from schemas.model import Column, Table

POSITIONS = Table(
    name="positions",
    kind="output",
    description="One row per 100 ms cycle: what the onboard unit concluded.",
    columns=(
        Column("t", "float", "Cycle time", unit="s"),
        Column("state", "str", "undetermined, determined or uncertain", enum=tuple(s.value for s in PositionState)),
        Column("line_code", "str", "Line", nullable=True),
        Column("track", "str", "Track", nullable=True, enum=tuple(t.value for t in Track)),
        Column("km_m", "float", "Actual kilometrage", unit="m", nullable=True),
        Column("km_equipment_m", "float", "Equipment kilometrage", unit="m", nullable=True),
        Column("speed_mps", "float", "Speed estimate", unit="m/s"),
        Column("margin_m", "float", "Safety margin: |km error| ≤ margin", unit="m", nullable=True),
        Column("last_fix_source", "str", "balise, feature, gps, gnss or none", nullable=True),
    ),
)

EVENTS = Table(
    name="events",
    kind="output",
    description="Events: corrections, refusals, slips, anomalies, fail-safe.",
    columns=(
        Column("t", "float", "Time", unit="s"),
        Column("type", "str", "Event type"),
        Column("km_m", "float", "Kilometrage at the event", unit="m", nullable=True),
        Column("correction_m", "float", "Correction amount (computed − DB)", unit="m", nullable=True),
        Column("correction_pct", "float", "Position-correction percentage", unit="%", nullable=True),
        Column("detail", "str", "Human-readable detail / JSON", nullable=True),
    ),
)

OUTPUT_TABLES: dict[str, Table] = {t.name: t for t in (POSITIONS, EVENTS)}
