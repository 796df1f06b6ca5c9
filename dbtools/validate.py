"""``db validate``: every consistency rule of SPEC §3 → findings (pure over a Network)."""

from __future__ import annotations

from pathlib import Path

from dbtools.database import integrity_findings, read_network
from dbtools.network import Network
from dbtools.sources import read_source_set
from schemas.findings import Finding
from schemas.frames import check_frame
from schemas.tables import DB_TABLES


def validate_network(network: Network, *, schema_checks: bool = True) -> list[Finding]:
    """Schema checks of the loaded frames (skipped for sources: already done while reading)
    plus the domain rules."""
    findings: list[Finding] = []
    if schema_checks:
        for t in DB_TABLES:
            findings.extend(check_frame(t, network.tables[t.name]))
    return findings


def validate_path(path: Path) -> list[Finding]:
    """Validate a DB file (with SQLite integrity and content hash) or a source set folder."""
    path = Path(path)
    if path.is_dir():
        network, findings = read_source_set(path)
        return findings + validate_network(network, schema_checks=False)
    network = read_network(path)
    return integrity_findings(path, network) + validate_network(network)
