"""``db validate``: every consistency rule of SPEC §3 → findings (pure over a Network).

Rule families, each in its own pure module (frames in → list of findings):

* schema — :func:`schemas.frames.check_frame` (types, nulls, enumerations, lat/lon inside
  the operating area, duplicate keys) and :mod:`dbtools.rules.schema` (radius vs attribute,
  non-finite numbers);
* GIS grid — :mod:`dbtools.rules.gis`; its heights — :mod:`dbtools.rules.heights`;
* balises — :mod:`dbtools.rules.balises`;
* feature points — :mod:`dbtools.rules.features`, those of network tracks
  :mod:`dbtools.rules.track_features`;
* network topology — :mod:`dbtools.rules.topology` (tracks, connections, switches, their
  geometry) and :mod:`dbtools.rules.balise_groups` (ETCS groups, identification along routes);
* DB file — :func:`dbtools.database.integrity_findings` (SQLite integrity_check,
  foreign_key_check, meta and content hash) and tables without rows
  (:func:`dbtools.rules.schema.check_empty_tables`; a source set's are found on reading).

All limits are in :class:`ValidationConfig`. Findings on a source set name the file and
line of the row (``Network.source_rows``); on a DB the table and the row's domain keys.
"""

from __future__ import annotations

from pathlib import Path

from dbtools.csv_locale import CsvLocale
from dbtools.database import integrity_findings, read_network
from dbtools.gis.index import grid_index
from dbtools.network import Network
from dbtools.rules.area import check_area
from dbtools.rules.balise_groups import check_balise_network
from dbtools.rules.balises import check_balises
from dbtools.rules.common import Locator
from dbtools.rules.config import ValidationConfig
from dbtools.rules.features import check_features
from dbtools.rules.gis import check_gis
from dbtools.rules.heights import check_heights
from dbtools.rules.schema import check_empty_tables, check_values
from dbtools.rules.topology import check_topology
from dbtools.rules.track_features import check_track_features
from schemas.findings import Finding
from schemas.frames import check_frame
from schemas.tables import DB_TABLES

__all__ = ["ValidationConfig", "validate_network", "validate_path"]


def validate_network(
    network: Network, *, schema_checks: bool = True, config: ValidationConfig | None = None
) -> list[Finding]:
    """Schema checks of the loaded frames (skipped for sources: already done while reading)
    plus the domain rules."""
    config = config or ValidationConfig()
    loc = Locator(network.files, network.source_rows)
    findings: list[Finding] = []
    if schema_checks:
        for t in DB_TABLES:
            findings.extend(check_frame(t, network.tables[t.name], max_per_check=config.max_findings_per_rule))
        findings.extend(check_area(network, loc, config.max_findings_per_rule))  # sources: done on reading
    findings.extend(check_values(network.tables, config, loc))
    grid = grid_index(network)
    findings.extend(check_gis(grid, network.km_breaks, config, loc))
    findings.extend(check_heights(network.gis, network.meta, config, loc, grid))
    findings.extend(check_balises(network.balises, grid, config, loc))
    findings.extend(check_features(network.feature_points, grid, config, loc))
    findings.extend(check_topology(network, config, loc))
    findings.extend(check_track_features(network, config, loc))
    findings.extend(check_balise_network(network, config, loc))
    return findings


def validate_path(
    path: Path, *, config: ValidationConfig | None = None, locale: CsvLocale | None = None
) -> list[Finding]:
    """Validate a DB file (with SQLite integrity and content hash) or a source set folder
    (``locale``: the CSV convention of its files, :func:`dbtools.sources.read_source_set`).

    Raises :class:`~schemas.errors.InputError` (exit 2) when the input cannot be read.
    """
    path = Path(path)
    if path.is_dir():
        from dbtools.sources import read_source_set  # a source set's readers: not loaded for a DB

        network, findings = read_source_set(path, locale)
        return findings + validate_network(network, schema_checks=False, config=config)
    network = read_network(path, verify=False)  # the hash is a finding here (integrity_findings)
    empty = check_empty_tables(network.tables, Locator())  # sources: checked on reading
    return integrity_findings(path, network) + empty + validate_network(network, config=config)
