"""The release registry (``db release``): one folder of immutable DB versions.

Layout of a registry folder::

    registry.sqlite          table ``releases`` below, one row per released version
    <db_version>.sqlite      the released onboard DB: the snapshot that was validated and hashed, mode 0444
    <db_version>.sha256      manifest in ``sha256sum`` format: "<hex>  <db_version>.sqlite"
"""

from __future__ import annotations

import re

from schemas.model import Column, Table

#: Registry database file inside a registry folder.
REGISTRY_FILE = "registry.sqlite"
#: ``PRAGMA application_id`` of a registry: ASCII "TPRG".
REGISTRY_APPLICATION_ID = 0x54505247
#: ``PRAGMA user_version`` of a registry; bumped when ``releases`` changes shape.
REGISTRY_SCHEMA_VERSION = 1
#: A db_version names the released file ``<db_version>.sqlite``: runs of ASCII letters and
#: digits joined by single ``.``, ``_`` or ``-`` (``2026.11``, ``2026.11.1``, ``v3``,
#: ``sample-1``, ``20261201.093000``), at most :data:`DB_VERSION_MAX_LENGTH` characters.
DB_VERSION_PATTERN = r"[A-Za-z0-9]+(?:[._-][A-Za-z0-9]+)*"
DB_VERSION_MAX_LENGTH = 100
#: The rule in words, for messages and help texts.
DB_VERSION_RULE = (
    "letters and digits with single '.', '_' or '-' between them, e.g. 2026.11, 2026.11.1, v3, sample-1 "
    f"(at most {DB_VERSION_MAX_LENGTH} characters)"
)


def db_version_problem(version: str) -> str | None:
    """What makes ``version`` no valid DB version (:data:`DB_VERSION_PATTERN`), or None."""
    if not version:
        return "is empty"
    if len(version) > DB_VERSION_MAX_LENGTH:
        return f"is {len(version)} characters long"
    if re.fullmatch(DB_VERSION_PATTERN, version):
        return None
    bad = sorted({c for c in version if not (c.isascii() and (c.isalnum() or c in "._-"))})
    if bad:
        return "has " + ", ".join("a space" if c == " " else repr(c) for c in bad)
    return "has a '.', '_' or '-' at its start or end, or two of them in a row"


RELEASES = Table(
    name="releases",
    kind="db",
    description="Release registry (registry.sqlite of a release folder): one row per released DB version.",
    columns=(
        Column("db_version", "str", "Released DB version (meta db_version of the file)"),
        Column("file", "str", "Released file name inside the registry folder"),
        Column("sha256", "str", "SHA-256 of the released file (hex)"),
        Column("content_hash", "str", "Content hash from the DB's meta"),
        Column("schema_version", "int", "PRAGMA user_version of the DB"),
        Column("released_at", "str", "When it was released (UTC, ISO 8601 with Z)"),
        Column("released_by", "str", "OS user who released it"),
        Column("note", "str", "Release note", nullable=True),
        Column("source_file", "str", "Absolute path the released file was copied from"),
    ),
    primary_key=("db_version",),
)

#: Impact reports stored with a release (``db release --impact``): one row per release
#: that has one, the JSON file ``<db_version>.impact.json`` beside the released DB. The
#: table is created by the first such release, so registries without it stay readable and
#: ``releases`` keeps its shape (no schema-version bump).
IMPACTS = Table(
    name="release_impacts",
    kind="db",
    description="Impact reports of releases (registry.sqlite): what the release changed on recorded runs.",
    columns=(
        Column("db_version", "str", "Released DB version the report belongs to"),
        Column("file", "str", "Report file name inside the registry folder (<db_version>.impact.json)"),
        Column("sha256", "str", "SHA-256 of the report file (hex)"),
        Column("against_version", "str", "db_version of the DB it was compared with", nullable=True),
        Column("against_content_hash", "str", "Content hash of the DB it was compared with"),
        Column("runs", "int", "Runs replayed"),
        Column("runs_changed", "int", "Runs whose figures changed"),
    ),
    primary_key=("db_version",),
)

#: Releases in progress: a row is committed before a release publishes any file and deleted
#: in the transaction that registers it, so files a killed release left behind are known as
#: its own (name and SHA-256 of each) and the next ``db release`` removes them. Created by the
#: first release that needs it (older registries stay readable; no schema-version bump).
PENDING = Table(
    name="release_pending",
    kind="db",
    description="Releases in progress (registry.sqlite): the files each will publish, until it is registered.",
    columns=(
        Column("db_version", "str", "DB version being released"),
        Column("files", "str", "JSON object: file name in the registry folder → SHA-256 (hex) of what is written"),
        Column("pid", "int", "Process id of the release"),
        Column("host", "str", "Host name of the machine running it"),
        Column("started_at", "str", "When it started (UTC, ISO 8601 with Z)"),
    ),
    primary_key=("db_version",),
)
