"""What an onboard DB file is, for ``trainpos db info``: version, meta, content hash and
whether the content still matches it, source hashes, rows per table, operating area and
CRS, file size, schema version and application id.

Everything but the content check is read with ``PRAGMA``, the ``meta`` table and
``COUNT(*)`` (:mod:`dbtools.browse`), read-only. The content check is the one every DB
load makes (:func:`dbtools.database.read_network` and
:func:`dbtools.network.network_content_hash`, compared as :mod:`dbtools.integrity` does),
so it reads every row (≈ 1 s for a million GIS points); ``verify=False`` skips it. A DB
of another schema version is described as it is (every table it has is counted) but its
content is not hashed: the hash is defined over this version's tables.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

from dbtools.browse import table_counts
from dbtools.integrity import mismatch_text
from dbtools.sqlite_file import connect_ro, quoted
from schemas.errors import InputError
from schemas.tables import GEOREF_META_KEYS, META, READABLE_SCHEMA_VERSIONS, SOURCE_HASH_PREFIX

MATCHES = "matches the content"


@dataclass(frozen=True)
class ContentCheck:
    """The stored content hash against the content's own: ``verified`` None when not checked."""

    stored: str | None
    actual: str | None = None
    verified: bool | None = None
    status: str = "not checked"


@dataclass(frozen=True)
class DbInfo:
    """One DB file described (JSON shape: :meth:`to_dict`)."""

    path: str
    size_bytes: int
    application_id: int
    schema_version: int
    meta: dict[str, str | None]
    tables: dict[str, int]
    content: ContentCheck

    @property
    def source_sha256(self) -> dict[str, str | None]:
        """Source file → SHA-256 (meta ``source_sha256:<file>``)."""
        n = len(SOURCE_HASH_PREFIX)
        return {k[n:]: v for k, v in self.meta.items() if k.startswith(SOURCE_HASH_PREFIX)}

    @property
    def georef(self) -> dict[str, object]:
        """Operating area (parsed from its JSON), metric CRS and heights, the keys meta has."""
        out: dict[str, object] = {k: self.meta[k] for k in GEOREF_META_KEYS if k in self.meta}
        area = out.get("area")
        if isinstance(area, str):
            try:
                out["area"] = json.loads(area)
            except json.JSONDecodeError:
                pass  # shown as stored
        return out

    def to_dict(self) -> dict[str, object]:
        """JSON shape of ``db info --format json``."""
        return {
            "file": self.path,
            "size_bytes": self.size_bytes,
            "application_id": f"{self.application_id:#010x}",
            "schema_version": self.schema_version,
            "schema_supported": self.schema_version in READABLE_SCHEMA_VERSIONS,
            "db_version": self.meta.get("db_version"),
            "content_hash": asdict(self.content),
            "source_sha256": self.source_sha256,
            "georef": self.georef,
            "tables": self.tables,
            "meta": self.meta,
        }


def content_check(path: Path, stored: str | None, schema_version: int) -> ContentCheck:
    """Hash the DB's content as every load does and compare it with the ``stored`` hash."""
    if schema_version not in READABLE_SCHEMA_VERSIONS:
        readable = ", ".join(map(str, READABLE_SCHEMA_VERSIONS))
        why = f"schema version {schema_version} (this tool reads {readable})"
        return ContentCheck(stored, status=f"not checked: {why}")
    from dbtools.database import read_network  # pandas: only for the content check
    from dbtools.network import network_content_hash

    try:
        actual = network_content_hash(read_network(path, verify=False))
    except InputError as exc:
        return ContentCheck(stored, status=f"not checked: {exc.message}")
    ok = bool(stored) and stored == actual
    return ContentCheck(stored, actual, ok, MATCHES if ok else mismatch_text(stored, actual))


def db_info(path: Path, *, verify: bool = True) -> DbInfo:
    """Describe the onboard DB ``path`` (read-only); ``verify``: recompute the content hash.

    InputError when the file is not a trainpos onboard DB or cannot be read.
    """
    path = Path(path)
    with connect_ro(path) as conn:  # no user text runs here: no authorizer needed
        app_id = int(conn.execute("PRAGMA application_id").fetchone()[0])
        version = int(conn.execute("PRAGMA user_version").fetchone()[0])
        tables = table_counts(conn, path)
        meta: dict[str, str | None] = {}
        if META.name in tables:
            rows = conn.execute(f"SELECT key, value FROM {quoted(META.name)} ORDER BY key").fetchall()
            meta = {str(k): None if v is None else str(v) for k, v in rows}
    stored = meta.get("content_hash")
    content = content_check(path, stored, version) if verify else ContentCheck(stored)
    return DbInfo(str(path), path.stat().st_size, app_id, version, meta, tables, content)
