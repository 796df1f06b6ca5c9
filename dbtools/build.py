"""``db build``: a source set → one onboard DB version (SQLite), atomically. The meta gets
the network's operating area, metric CRS and height datum, declared or derived
(:mod:`dbtools.gis.georef`)."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, datetime
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

from dbtools.csv_locale import CsvLocale
from dbtools.database import write_db
from dbtools.gis.index import network_georef
from dbtools.network import content_hash
from dbtools.sources import read_source_set
from dbtools.validate import validate_network
from schemas.enums import Severity
from schemas.errors import FindingsError, RefusedError, UsageError
from schemas.findings import Finding
from schemas.registry import DB_VERSION_RULE, db_version_problem
from schemas.tables import SCHEMA_VERSION


def tool_version() -> str:
    try:
        return version("trainpos")
    except PackageNotFoundError:  # running from a checkout without install
        return "0+unknown"


@dataclass
class BuildResult:
    path: Path
    db_version: str
    content_hash: str
    rows: dict[str, int]
    warnings: list[Finding]
    """What reading the source set found (no error: those stop the build)."""
    validation: list[Finding] | None = None
    """The domain rules of ``db validate`` on the content written (None: not run)."""


def build_db(
    source_dir: Path,
    out: Path,
    *,
    db_version: str | None = None,
    note: str = "",
    force: bool = False,
    now: datetime | None = None,
    validate: bool = False,
    strict: bool = False,
    locale: CsvLocale | None = None,
) -> BuildResult:
    """Read, check and write. Nothing is written when a source has an error or
    ``db_version`` is no valid DB version (:data:`schemas.registry.DB_VERSION_PATTERN`:
    UsageError). ``validate``: also run the domain rules of ``db validate`` (the DB would
    fail them: the result carries them); ``strict``: their errors stop the build too
    (FindingsError, nothing written). ``locale``: the CSV convention of the source files
    (:func:`dbtools.sources.read_source_set`)."""
    problem = db_version_problem(db_version) if db_version is not None else None
    if problem is not None:
        raise UsageError(f"version '{db_version}' {problem}: a DB version is {DB_VERSION_RULE}")
    source_dir, out = Path(source_dir), Path(out)
    if out.resolve().parent == source_dir.resolve() or source_dir.resolve() in out.resolve().parents:
        raise RefusedError("the output must not be written into the source folder", path=out)
    if out.exists() and not force:
        raise RefusedError("output exists; use --force to replace it", path=out)
    network, findings = read_source_set(source_dir, locale)
    errors = [f for f in findings if f.severity == Severity.ERROR]
    if errors:
        raise FindingsError(f"{len(errors)} error(s) in the source set; nothing was written", findings, path=source_dir)
    validation = validate_network(network, schema_checks=False) if validate or strict else None
    if strict and validation and any(f.severity == Severity.ERROR for f in validation):
        n = sum(f.severity == Severity.ERROR for f in validation)
        raise FindingsError(f"{n} validation error(s) (--strict); nothing was written", validation, path=source_dir)
    created = (now or datetime.now(UTC)).astimezone(UTC)
    version_str = db_version or created.strftime("%Y%m%d.%H%M%S")
    digest = content_hash(network.tables, ordered=True)  # read_source_set's frames are canonical
    georef = network_georef(network)
    meta = {
        "db_version": version_str,
        "created_at": created.isoformat(timespec="seconds").replace("+00:00", "Z"),
        "tool_version": tool_version(),
        "schema_version": str(SCHEMA_VERSION),
        "content_hash": digest,
        "note": note,
        **network.meta,
        **(georef.to_meta() if georef is not None else {}),
    }
    write_db(out, network, meta, force=force, inputs=[source_dir], ordered=True)
    return BuildResult(out, version_str, digest, {k: len(v) for k, v in network.tables.items()}, findings, validation)
