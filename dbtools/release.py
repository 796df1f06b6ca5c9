"""``db release`` / ``db releases`` / ``db verify-release``: a registry of immutable DB versions.

A registry is a folder (layout in :mod:`schemas.registry`)::

    DIR/registry.sqlite        one row per release
    DIR/<db_version>.sqlite    the released DB: exactly the bytes that were validated and hashed, mode 0444
    DIR/<db_version>.sha256    manifest in sha256sum format: "<hex>  <db_version>.sqlite"
    DIR/<db_version>.impact.json  (``--impact``) the ``db impact`` report of the release, mode 0444

so ``cd DIR && sha256sum -c *.sha256`` checks the files without trainpos.

**What is released is what was validated.** The input is copied as SQLite reads it into a
private snapshot in ``DIR`` (:func:`dbtools.database.snapshot_db`: WAL included, in a
rollback-journal mode: readers of a release create no -wal/-shm). The snapshot is validated
(any error refuses) and hashed, and that same file is renamed into place. The input is only
ever read — never checkpointed or modified.

**Publication is recoverable.** Under the registry's write lock a release refuses a version
already registered, records its intent (table ``release_pending``: each file's name and
SHA-256, its process) and commits; it then publishes its files (read-only, renamed into
place) and, in a second transaction, registers the release and deletes the intent. A failure
removes its files and intent. After a ``kill -9`` in between, the intent's process is gone:
the next release removes the files it names that still have the recorded SHA-256, and the
intent (``verify-release`` names them as such debris). Unregistered files holding exactly
the bytes a release writes (debris of an older trainpos) are written again; any other file
the registry knows nothing about is never removed (refused, exit 3).
"""

from __future__ import annotations

import contextlib
import getpass
import hashlib
import json
import os
import re
import socket
from collections.abc import Set as AbstractSet
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from dbtools.atomic import output_errors, process_alive, sweep_stale, temp_sibling
from dbtools.database import (
    check_sqlite_file,
    integrity_findings,
    read_meta,
    read_registry,
    read_registry_table,
    registry_delete,
    registry_find,
    registry_insert,
    registry_rows,
    registry_transaction,
    schema_version,
    snapshot_db,
)
from dbtools.tabular import sha256_file
from dbtools.validate import validate_path
from schemas.enums import Severity
from schemas.errors import FindingsError, InputError, RefusedError, UsageError
from schemas.findings import Finding, has_errors
from schemas.registry import DB_VERSION_RULE, IMPACTS, PENDING, REGISTRY_FILE, RELEASES, db_version_problem

#: Mode of released files and manifests: read-only for everyone.
READ_ONLY = 0o444
_MANIFEST_RE = re.compile(r"^([0-9a-fA-F]{64}) [ *](.+)$")
#: Name the private snapshot of a release is a temporary sibling of (``dbtools.atomic``).
_SNAPSHOT = "snapshot.sqlite"


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
    """Snapshot ``file``, validate the snapshot and add it to ``registry`` as an immutable
    version (see the module docstring); with ``impact``, store that report read-only as
    ``<db_version>.impact.json`` beside it and record it (table ``release_impacts``) in the
    same transaction.

    Raises FindingsError (validation errors; nothing written), RefusedError (version
    already released or being released, or its file already in the folder unregistered),
    InputError (unreadable input or registry).
    """
    file, registry = Path(file), Path(registry)
    check_sqlite_file(file)
    if (new_folder := not registry.exists()) is False and not registry.is_dir():
        raise InputError("release registry must be a folder", path=registry)
    with output_errors(registry, registry):  # disk full, read-only …: reported against the registry
        registry.mkdir(parents=True, exist_ok=True)
        sweep_stale(registry / _SNAPSHOT)  # snapshots of killed releases
        snap = temp_sibling(registry / _SNAPSHOT)
        try:
            release, findings = _snapshot_and_validate(file, snap, note=note, now=now, user=user)
            impact_path = _publish(registry, snap, release, impact)
            return ReleaseResult(release, registry / release.file, findings, impact_path)
        except BaseException:
            if new_folder:  # nothing was released: leave no empty registry folder behind
                with contextlib.suppress(OSError):
                    snap.unlink(missing_ok=True)
                    registry.rmdir()
            raise
        finally:
            snap.unlink(missing_ok=True)


def _snapshot_and_validate(
    file: Path, snap: Path, *, note: str, now: datetime | None, user: str | None
) -> tuple[Release, list[Finding]]:
    """The snapshot of ``file`` in ``snap``, validated and hashed: its registry row and the
    validation warnings. FindingsError on errors, RefusedError on an unusable version."""
    snapshot_db(file, snap)
    digest = sha256_file(snap)
    findings = validate_path(snap)
    errors = [f for f in findings if f.severity == Severity.ERROR]
    if errors:
        raise FindingsError(f"{len(errors)} validation error(s); not released", findings, path=file)
    meta = read_meta(snap)
    version = meta.get("db_version") or ""
    problem = db_version_problem(version)
    if problem is not None:
        raise RefusedError(
            f"db_version '{version}' {problem}: it cannot name a released file; a DB version is {DB_VERSION_RULE} "
            "(rebuild it with db build --version)",
            path=file,
        )
    released_at = (now or datetime.now(UTC)).astimezone(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")
    release = Release(
        db_version=version,
        file=f"{version}.sqlite",
        sha256=digest,
        content_hash=meta.get("content_hash", ""),
        schema_version=schema_version(snap),
        released_at=released_at,
        released_by=user or _current_user(),
        note=note or None,
        source_file=str(file.resolve()),
    )
    return release, findings


def _publish(registry: Path, snap: Path, release: Release, impact: ImpactAttachment | None) -> Path | None:
    """Intent, files, registration (the module docstring); the impact report's path."""
    version = release.db_version
    report = (registry / impact_file_name(version), impact.report_json) if impact is not None else None
    extras = [(registry / f"{version}.sha256", f"{release.sha256}  {release.file}\n".encode())]
    extras += [report] if report is not None else []
    files = {release.file: release.sha256} | {p.name: hashlib.sha256(data).hexdigest() for p, data in extras}
    with registry_transaction(registry / REGISTRY_FILE) as conn:
        _refuse_released(conn, release)
        _clear_interrupted(conn, registry, version)
        for name, sha in files.items():
            _remove_if_ours(registry, name, sha)  # the very bytes this release writes (older debris): no loss
            _refuse_unregistered(registry / name)
        registry_insert(conn, _intent(version, files), PENDING)
    created: list[Path] = []
    try:
        _finish(snap, registry / release.file, created)
        for p, data in extras:
            _atomic_write(p, data, created)
        with registry_transaction(registry / REGISTRY_FILE) as conn:
            registry_insert(conn, release.to_dict())
            if impact is not None and report is not None:
                registry_insert(conn, _impact_row(impact, report[0], version), IMPACTS)
            registry_delete(conn, PENDING, version)
    except BaseException:
        for p in created:
            with contextlib.suppress(OSError):
                p.unlink()
        with contextlib.suppress(Exception), registry_transaction(registry / REGISTRY_FILE) as conn:
            registry_delete(conn, PENDING, version)
        raise
    return report[0] if report is not None else None


def _intent(version: str, files: dict[str, str]) -> dict[str, object]:
    """The ``release_pending`` row of this process releasing ``version``."""
    return {
        "db_version": version,
        "files": json.dumps(files, sort_keys=True),
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "started_at": datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z"),
    }


def _refuse_released(conn: Any, release: Release) -> None:
    existing = registry_find(conn, release.db_version)
    if existing is None:
        return
    what = (
        "this same file; nothing to do"
        if existing["sha256"] == release.sha256
        else f"a different file (sha256 {existing['sha256']}); a released version is immutable: "
        "build the change under a new version"
    )
    raise RefusedError(
        f"db_version {release.db_version} was already released on {existing['released_at']} as {what}",
        path=Path(release.source_file),
    )


def _refuse_unregistered(p: Path) -> None:
    sweep_stale(p)  # temporary siblings of a killed release
    if p.exists() or p.is_symlink():
        raise RefusedError(
            f"{p.name} already exists in the registry folder but is not registered (nor is it, unchanged, "
            "what an interrupted release left): it is left as it is; look at it and remove it by hand if it "
            "is not needed",
            path=p,
        )


def _owner_gone(row: dict[str, object]) -> bool:
    """Whether the process of an intent is gone (only known on the machine it ran on)."""
    return row.get("host") == socket.gethostname() and not process_alive(int(str(row["pid"])))


def _clear_interrupted(conn: Any, registry: Path, version: str) -> None:
    """Remove what killed releases left (their intents and the files those name, still with
    the recorded SHA-256); refuse ``version`` while another live process releases it."""
    for v, row in registry_rows(conn, PENDING).items():
        if not _owner_gone(row):
            if v == version:
                raise RefusedError(
                    f"db_version {version} is being released by process {row['pid']} on {row['host']} "
                    f"since {row['started_at']} (a release killed on another machine is cleaned up by the next "
                    "release there)",
                    path=registry,
                )
            continue
        for name, sha in _intent_files(row).items():
            _remove_if_ours(registry, name, sha)
        registry_delete(conn, PENDING, v)  # a file still there is not its own any more (changed since)


def _intent_files(row: dict[str, object]) -> dict[str, str]:
    try:
        files = json.loads(str(row["files"]))
    except ValueError:
        return {}
    return {str(k): str(v) for k, v in files.items()} if isinstance(files, dict) else {}


def _remove_if_ours(registry: Path, name: str, sha256: str) -> None:
    """Remove ``registry/name`` if it is the file an interrupted release wrote (same
    SHA-256: the same bytes); anything else standing there is kept."""
    p = registry / name
    if name and Path(name).name == name and p.is_file() and not p.is_symlink() and sha256_file(p) == sha256:
        p.unlink()


def _impact_row(impact: ImpactAttachment, path: Path, version: str) -> dict[str, object]:
    """The ``release_impacts`` row of a stored report."""
    return {
        "db_version": version,
        "file": path.name,
        "sha256": hashlib.sha256(impact.report_json).hexdigest(),
        "against_version": impact.against_version,
        "against_content_hash": impact.against_content_hash,
        "runs": impact.runs,
        "runs_changed": impact.runs_changed,
    }


def list_impacts(registry: Path) -> dict[str, dict[str, object]]:
    """The impact-report rows of a registry folder by db_version (releases made with ``--impact``)."""
    return read_registry_table(Path(registry) / REGISTRY_FILE, IMPACTS)


def _current_user() -> str:
    try:
        return getpass.getuser()
    except (OSError, KeyError, ImportError):  # no login name in some containers
        return "unknown"


def _finish(tmp: Path, dst: Path, created: list[Path]) -> None:
    """Read-only, then renamed into place; never over an existing file."""
    os.chmod(tmp, READ_ONLY)
    if dst.exists():
        raise RefusedError("appeared while releasing; not replaced", path=dst)
    os.replace(tmp, dst)
    created.append(dst)


def _atomic_write(dst: Path, data: bytes, created: list[Path]) -> None:
    """``data`` into a temporary sibling (fsynced), then :func:`_finish`."""
    tmp = temp_sibling(dst)
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
        pending = read_registry_table(registry / REGISTRY_FILE, PENDING)
        findings.extend(_unregistered(registry, releases, set(impacts), pending))
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
    registry: Path,
    releases: list[Release],
    with_impact: AbstractSet[str] = frozenset(),
    pending: dict[str, dict[str, object]] | None = None,
) -> list[Finding]:
    """Released-looking files that no registry row names: debris of an interrupted release
    (an intent names them; the next ``db release`` removes them) or unknown (smuggled in, or
    left by a trainpos that recorded no intents)."""
    known = {r.file for r in releases} | {f"{r.db_version}.sha256" for r in releases} | {REGISTRY_FILE}
    known |= {impact_file_name(v) for v in with_impact}
    owners = {name: row for row in (pending or {}).values() for name in _intent_files(row)}
    out = []
    for p in sorted(registry.iterdir()):
        if p.suffix in (".sqlite", ".sha256", ".json") and p.name not in known and not p.name.startswith("."):
            out.append(_unregistered_finding(p, owners.get(p.name)))
    return out


def _unregistered_finding(p: Path, intent: dict[str, object] | None) -> Finding:
    if intent is None:
        message = "file in the registry folder is not registered"
    elif _owner_gone(intent):
        message = (
            f"left by a release of {intent['db_version']} interrupted after {intent['started_at']} "
            f"(process {intent['pid']} is gone); the next db release removes it"
        )
    else:
        message = f"being written by a release of {intent['db_version']} in progress (process {intent['pid']})"
    return Finding("release.unregistered", Severity.WARNING, RELEASES.name, message, file=str(p), value=p.name)
