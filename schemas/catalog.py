"""Every declaration of :mod:`schemas` by name (:data:`ALL_SCHEMAS`), for ``trainpos schema
show`` and the docs' schema reference (docs/reference/schemas.md)."""

from __future__ import annotations

from schemas.audit import AUDIT_TABLES, AUDIT_VIEWS
from schemas.gisinput import GIS_INPUT_TABLES
from schemas.logs import LOG_STREAMS
from schemas.model import Table
from schemas.outputs import OUTPUT_TABLES
from schemas.plans import POSSESSIONS
from schemas.registry import IMPACTS, PENDING, RELEASES
from schemas.tables import ALL_DB_TABLES

#: Every declaration by name, for ``trainpos schema show`` and the docs.
ALL_SCHEMAS: dict[str, Table] = {
    **{t.name: t for t in ALL_DB_TABLES},
    **LOG_STREAMS,
    **OUTPUT_TABLES,
    POSSESSIONS.name: POSSESSIONS,
    **GIS_INPUT_TABLES,
    RELEASES.name: RELEASES,
    IMPACTS.name: IMPACTS,
    PENDING.name: PENDING,
    **{t.name: t for t in (*AUDIT_TABLES, *AUDIT_VIEWS)},
}
