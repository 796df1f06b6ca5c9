"""``db release`` / ``db releases`` / ``db verify-release``: a registry of immutable DB versions.

A registry is a folder (layout in :mod:`schemas.registry`)::

    DIR/registry.sqlite        one row per release
    DIR/<db_version>.sqlite    the released DB, byte-identical to the validated input, mode 0444
    DIR/<db_version>.sha256    manifest in sha256sum format: "<hex>  <db_version>.sqlite"
    DIR/<db_version>.impact.json  (``--impact``) the ``db impact`` report of the release, mode 0444

so ``cd DIR && sha256sum -c *.sha256`` checks the files without trainpos.

Releasing validates the file first (any error refuses), then, holding the registry's write
lock, refuses a version that is already registered (or whose file is already in the
folder), copies the file to a temp file in ``DIR``, checks the copy's SHA-256 against the
validated input, makes it read-only and renames it into place, writes the manifest the same
way and records the row. If anything fails, the files written so far are removed and the
registry is left unchanged. The input file is only ever read.
"""

from __future__ import annotations

import contextlib
import getpass
import hashlib
import os
import re
import tempfile
from collections.abc import Set as AbstractSet
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from dbtools.database import (
    check_sqlite_file,
    integrity_findings,
    read_impacts,
    read_meta,
    read_registry,
    registry_find,
    registry_insert,
    registry_transaction,
    schema_version,
)
from dbtools.tabular import sha256_file
from dbtools.validate import validate_path
from schemas.enums import Severity
from schemas.errors import FindingsError, InputError, RefusedError, UsageError
from schemas.findings import Finding, has_errors
from schemas.registry import DB_VERSION_RULE, IMPACTS, REGISTRY_FILE, RELEASES, db_version_problem

#: Mode of released files and manifests: read-only for everyone.
READ_ONLY = 0o444
_MANIFEST_RE = re.compile(r"^([0-9a-fA-F]{64}) [ *](.+)$")
_CHUNK = 1 << 20


@dataclass(frozen=True)
class Release:
    """One registry row (columns declared in ``schemas.registry.RELEASES``)."""

    db_version: str
    file: str
    sha256: str
    content_hash: str
    schema_version: int
    released_at: str
    released_by: str
    note: str | None
    source_file: str

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_row(cls, row: dict[str, Any]) -> Release:
        note = row.get("note")
        return cls(
            db_version=str(row["db_version"]),
            file=str(row["file"]),
            sha256=str(row["sha256"]),
            content_hash=str(row["content_hash"]),
            schema_version=int(row["schema_version"]),
            released_at=str(row["released_at"]),
            released_by=str(row["released_by"]),
            note=None if note is None else str(note),
            source_file=str(row["source_file"]),
        )


@dataclass(frozen=True)
class ImpactAttachment:
    """An impact report (``db impact`` as JSON) to store with a release (``db release --impact``)."""

    report_json: bytes
    against_version: str | None
    """db_version of the DB the release was compared with."""
    against_content_hash: str
    runs: int
    runs_changed: int


@dataclass
class ReleaseResult:
    release: Release
    path: Path
    """The released file."""
    warnings: list[Finding]
    """Validation warnings (errors refuse the release)."""
    impact_path: Path | None = None
    """The stored impact report (``<db_version>.impact.json``), if one was given."""


def impact_file_name(db_version: str) -> str:
    """File name of a release's impact report in its registry folder."""
    return f"{db_version}.impact.json"


@dataclass
class VerifyReport:
    """What ``verify-release`` found: the releases checked and every problem."""

    registry: str
    checked: list[Release]
    findings: list[Finding]

    @property
    def ok(self) -> bool:
        return not has_errors(self.findings)

    def failed(self, db_version: str) -> bool:
        return any(f.severity == Severity.ERROR and f.keys.get("db_version") == db_version for f in self.findings)

    def to_dict(self) -> dict[str, Any]:
        return {
            "ok": self.ok,
            "registry": self.registry,
            "checked": [
                {"db_version": r.db_version, "file": r.file, "ok": not self.failed(r.db_version)} for r in self.checked
            ],
            "findings": [f.to_dict() for f in self.findings],
        }


# --------------------------------------------------------------------------- release


def release_db(
    file: Path,
    registry: Path,
    *,
    note: str = "",
    now: datetime | None = None,
    user: str | None = None,
    impact: ImpactAttachment | None = None,
) -> ReleaseResult:
    """Validate ``file`` and add it to ``registry`` as an immutable version; with
    ``impact``, store that report read-only as ``<db_version>.impact.json`` beside it and
    record it (table ``release_impacts``) in the same transaction.

    Raises FindingsError (validation errors; nothing written), RefusedError (version
    already released, or its file already in the folder), InputError (unreadable input or
    registry; the input changed while being released).
    """
    file, registry = Path(file), Path(registry)
    check_sqlite_file(file)
    if registry.exists() and not registry.is_dir():
        raise InputError("release registry must be a folder", path=registry)
    digest = sha256_file(file)
    findings = validate_path(file)
    errors = [f for f in findings if f.severity == Severity.ERROR]
    if errors:
        raise FindingsError(f"{len(errors)} validation error(s); not released", findings, path=file)
    meta = read_meta(file)
    version = meta.get("db_version") or ""
    problem = db_version_problem(version)
    if problem is not None:
        raise RefusedError(
            f"db_version '{version}' {problem}: it cannot name a released file; a DB version is {DB_VERSION_RULE} "
            "(rebuild it with db build --version)",
            path=file,
        )
    target = registry / f"{version}.sqlite"
    manifest = registry / f"{version}.sha256"
    impact_path = registry / impact_file_name(version) if impact is not None else None
    released_at = (now or datetime.now(UTC)).astimezone(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
    release = Release(
        db_version=version,
        file=target.name,
        sha256=digest,
        content_hash=meta.get("content_hash", ""),
        schema_version=schema_version(file),
        released_at=released_at,
        released_by=user or _current_user(),
        note=note or None,
        source_file=str(file.resolve()),
    )
    registry.mkdir(parents=True, exist_ok=True)
    created: list[Path] = []
    try:
        with registry_transaction(registry / REGISTRY_FILE) as conn:
            existing = registry_find(conn, version)
            if existing is not None:
                what = (
                    "this same file; nothing to do"
                    if existing["sha256"] == digest
                    else f"a different file (sha256 {existing['sha256']}); a released version is immutable: "
                    "build the change under a new version"
                )
                raise RefusedError(
                    f"db_version {version} was already released on {existing['released_at']} as {what}", path=file
                )
            for p in (target, manifest, impact_path):
                if p is not None and p.exists():
                    raise RefusedError(
                        f"{p.name} already exists in the registry folder but is not registered; "
                        "remove it by hand if it is debris of an interrupted release",
                        path=p,
                    )
            _atomic_copy(file, target, digest, created)
            _atomic_write(manifest, f"{digest}  {target.name}\n".encode(), created)
            registry_insert(conn, release.to_dict())
            if impact is not None and impact_path is not None:
                _store_impact(conn, impact, impact_path, version, created)
    except BaseException:
        for p in created:
            with contextlib.suppress(OSError):
                p.unlink()
        raise
    return ReleaseResult(release, target, findings, impact_path)


def _store_impact(conn: Any, impact: ImpactAttachment, path: Path, version: str, created: list[Path]) -> None:
    """The report file (read-only, atomically) and its registry row."""
    _atomic_write(path, impact.report_json, created)
    row: dict[str, object] = {
        "db_version": version,
        "file": path.name,
        "sha256": hashlib.sha256(impact.report_json).hexdigest(),
        "against_version": impact.against_version,
        "against_content_hash": impact.against_content_hash,
        "runs": impact.runs,
        "runs_changed": impact.runs_changed,
    }
    registry_insert(conn, row, IMPACTS)


def list_impacts(registry: Path) -> dict[str, dict[str, object]]:
    """The impact-report rows of a registry folder by db_version (releases made with ``--impact``)."""
    return read_impacts(Path(registry) / REGISTRY_FILE)


def _current_user() -> str:
    try:
        return getpass.getuser()
    except (OSError, KeyError, ImportError):  # no login name in some containers
        return "unknown"


def _temp_in(folder: Path, name: str) -> Path:
    fd, tmp = tempfile.mkstemp(prefix=f".{name}.", suffix=".tmp", dir=folder)
    os.close(fd)
    return Path(tmp)


def _finish(tmp: Path, dst: Path, created: list[Path]) -> None:
    """Read-only, then renamed into place; never over an existing file."""
    os.chmod(tmp, READ_ONLY)
    if dst.exists():
        raise RefusedError("appeared while releasing; not replaced", path=dst)
    os.replace(tmp, dst)
    created.append(dst)


def _atomic_copy(src: Path, dst: Path, expected_sha256: str, created: list[Path]) -> None:
    """Copy through a temp file in the target folder, checking the copy's SHA-256."""
    tmp = _temp_in(dst.parent, dst.name)
    try:
        h = hashlib.sha256()
        with open(src, "rb") as fin, open(tmp, "wb") as fout:
            for chunk in iter(lambda: fin.read(_CHUNK), b""):
                h.update(chunk)
                fout.write(chunk)
            fout.flush()
            os.fsync(fout.fileno())
        if h.hexdigest() != expected_sha256:
            raise InputError("the file changed while it was being released; nothing was released", path=src)
        _finish(tmp, dst, created)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


def _atomic_write(dst: Path, data: bytes, created: list[Path]) -> None:
    tmp = _temp_in(dst.parent, dst.name)
    try:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        _finish(tmp, dst, created)
    finally:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()


# --------------------------------------------------------------------------- list and verify


def list_releases(registry: Path) -> list[Release]:
    """Every release of a registry folder, oldest first."""
    registry = Path(registry)
    if not registry.exists():
        raise InputError("no such registry folder", path=registry)
    if not registry.is_dir():
        raise InputError("release registry must be a folder", path=registry)
    return [Release.from_row(r) for r in read_registry(registry / REGISTRY_FILE)]


def verify_releases(registry: Path, db_version: str | None = None) -> VerifyReport:
    """Re-hash every released file (or one) against the registry and its manifest, and
    check each DB's own integrity and content hash. Problems are findings, never
    exceptions; only an unreadable registry or an unknown version raises."""
    registry = Path(registry)
    releases = list_releases(registry)
    if db_version is not None:
        releases = [r for r in releases if r.db_version == db_version]
        if not releases:
            raise UsageError(f"db_version {db_version} is not in the registry", path=registry / REGISTRY_FILE)
    findings: list[Finding] = []
    impacts = list_impacts(registry)
    for r in releases:
        findings.extend(_verify_one(registry, r))
        if r.db_version in impacts:
            findings.extend(_verify_impact(registry, r, impacts[r.db_version]))
    if db_version is None:
        findings.extend(_unregistered(registry, releases, set(impacts)))
    return VerifyReport(str(registry), releases, findings)


def _finding(
    rule: str,
    r: Release,
    message: str,
    path: Path,
    *,
    severity: Severity = Severity.ERROR,
    value: Any = None,
    limit: Any = None,
) -> Finding:
    return Finding(
        rule,
        severity,
        RELEASES.name,
        message,
        keys={"db_version": r.db_version},
        value=value,
        limit=limit,
        file=str(path),
    )


def _verify_one(registry: Path, r: Release) -> list[Finding]:
    out: list[Finding] = []
    if Path(r.file).name != r.file or not r.file:
        return [_finding("release.registry", r, f"registry names an unsafe file '{r.file}'", registry / REGISTRY_FILE)]
    path = registry / r.file
    manifest = registry / f"{r.db_version}.sha256"
    out.extend(_check_manifest(manifest, r))
    if not path.is_file():
        out.append(_finding("release.missing_file", r, "released file is missing", path))
        return out
    actual = sha256_file(path)
    if actual != r.sha256:
        out.append(
            _finding(
                "release.sha256",
                r,
                "file does not match its registered SHA-256: it was modified after release",
                path,
                value=actual[:16],
                limit=r.sha256[:16],
            )
        )
    if path.stat().st_mode & 0o222:
        out.append(
            _finding(
                "release.writable",
                r,
                "released file is writable (expected read-only 0444)",
                path,
                severity=Severity.WARNING,
                value=oct(path.stat().st_mode & 0o777),
                limit=oct(READ_ONLY),
            )
        )
    try:
        meta = read_meta(path)
        own = integrity_findings(path)
    except InputError as exc:
        out.append(_finding("release.unreadable", r, f"released file cannot be read as a DB: {exc.message}", path))
        return out
    for f in own:
        out.append(
            Finding(
                f.rule,
                f.severity,
                f.table,
                f.message,
                keys={"db_version": r.db_version, **f.keys},
                value=f.value,
                limit=f.limit,
                file=str(path),
                column=f.column,
            )
        )
    for key, registered in (("db_version", r.db_version), ("content_hash", r.content_hash)):
        if meta.get(key) != registered:
            out.append(
                _finding(
                    "release.meta",
                    r,
                    f"meta {key} does not match the registry",
                    path,
                    value=meta.get(key),
                    limit=registered,
                )
            )
    return out


def _check_manifest(manifest: Path, r: Release) -> list[Finding]:
    if not manifest.is_file():
        return [_finding("release.manifest", r, "manifest is missing", manifest)]
    try:
        lines = [ln for ln in manifest.read_text(encoding="utf-8").splitlines() if ln.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        return [_finding("release.manifest", r, f"manifest cannot be read: {exc}", manifest)]
    m = _MANIFEST_RE.match(lines[0]) if len(lines) == 1 else None
    if m is None:
        return [_finding("release.manifest", r, "manifest is not one '<sha256>  <file>' line", manifest)]
    digest, name = m.group(1).lower(), m.group(2)
    out = []
    if name != r.file:
        out.append(_finding("release.manifest", r, "manifest names another file", manifest, value=name, limit=r.file))
    if digest != r.sha256:
        out.append(
            _finding(
                "release.manifest",
                r,
                "manifest SHA-256 does not match the registry",
                manifest,
                value=digest,
                limit=r.sha256,
            )
        )
    return out


def _verify_impact(registry: Path, r: Release, row: dict[str, object]) -> list[Finding]:
    """A release's stored impact report: present and unchanged since the release."""
    path = registry / str(row["file"])
    if Path(str(row["file"])).name != row["file"] or not path.is_file():
        return [_finding("release.impact", r, "impact report is missing", path)]
    actual = sha256_file(path)
    if actual != row["sha256"]:
        return [
            _finding(
                "release.impact",
                r,
                "impact report does not match its registered SHA-256: it was modified after release",
                path,
                value=actual[:16],
                limit=str(row["sha256"])[:16],
            )
        ]
    return []


def _unregistered(
    registry: Path, releases: list[Release], with_impact: AbstractSet[str] = frozenset()
) -> list[Finding]:
    """Released-looking files that no registry row names (debris or smuggled in)."""
    known = {r.file for r in releases} | {f"{r.db_version}.sha256" for r in releases} | {REGISTRY_FILE}
    known |= {impact_file_name(v) for v in with_impact}
    out = []
    for p in sorted(registry.iterdir()):
        if p.suffix in (".sqlite", ".sha256", ".json") and p.name not in known and not p.name.startswith("."):
            out.append(
                Finding(
                    "release.unregistered",
                    Severity.WARNING,
                    RELEASES.name,
                    "file in the registry folder is not registered",
                    file=str(p),
                    value=p.name,
                )
            )
    return out
