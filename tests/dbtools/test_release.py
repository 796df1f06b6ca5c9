"""``db release`` / ``releases`` / ``verify-release``: immutable, verifiable DB versions."""

from __future__ import annotations

import dataclasses
import shutil
import sqlite3
import stat
from datetime import UTC, datetime
from pathlib import Path

import pytest

import dbtools.release as release_mod
from dbtools.build import build_db
from dbtools.release import Release, list_releases, release_db, verify_releases
from dbtools.tabular import sha256_file
from schemas.errors import FindingsError, InputError, RefusedError, UsageError
from schemas.registry import REGISTRY_FILE, RELEASES
from schemas.tables import SCHEMA_VERSION
from tests.dbtools.release_sources import write_sources

NOW = datetime(2026, 11, 1, 9, 30, tzinfo=UTC)


@pytest.fixture(scope="module")
def dbs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Built once: v1 (2026.10), v2 (2026.11), and v1b (also 2026.10 but other content)."""
    root = tmp_path_factory.mktemp("release")
    src1 = write_sources(root / "src1")
    src2 = write_sources(root / "src2", c_km=612.0)
    out = {"v1": root / "v1.sqlite", "v2": root / "v2.sqlite", "v1b": root / "v1b.sqlite"}
    build_db(src1, out["v1"], db_version="2026.10", now=NOW)
    build_db(src2, out["v2"], db_version="2026.11", now=NOW)
    _set_version(out["v2"], out["v1b"], "2026.10")  # meta is outside the content hash: still valid
    return out


def _set_version(src: Path, dst: Path, version: str) -> None:
    shutil.copyfile(src, dst)
    with sqlite3.connect(dst) as conn:
        conn.execute("UPDATE meta SET value = ? WHERE key = 'db_version'", (version,))
    conn.close()


@pytest.fixture
def db(dbs: dict[str, Path], tmp_path: Path) -> Path:
    """A private copy of v1 (safe to damage)."""
    p = tmp_path / "in" / "net.sqlite"
    p.parent.mkdir()
    shutil.copyfile(dbs["v1"], p)
    return p


def _release(file: Path, reg: Path, **kw: object) -> Release:
    return release_db(file, reg, now=NOW, user="tester", **kw).release  # type: ignore[arg-type]


def test_release_mirrors_registry_schema() -> None:
    assert [f.name for f in dataclasses.fields(Release)] == RELEASES.column_names


def test_release_happy_path(db: Path, tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    digest, mtime = sha256_file(db), db.stat().st_mtime_ns
    r = _release(db, reg, note="first cut")
    target = reg / "2026.10.sqlite"
    assert r.db_version == "2026.10" and r.file == target.name and r.sha256 == digest
    assert r.released_at == "2026-11-01T09:30:00Z" and r.released_by == "tester" and r.schema_version == SCHEMA_VERSION
    assert r.source_file == str(db.resolve()) and r.note == "first cut"
    assert sha256_file(target) == digest  # byte-identical copy
    assert stat.S_IMODE(target.stat().st_mode) == 0o444
    assert (reg / "2026.10.sha256").read_text() == f"{digest}  2026.10.sqlite\n"
    assert sha256_file(db) == digest and db.stat().st_mtime_ns == mtime  # input untouched
    assert list_releases(reg) == [r]
    assert sorted(p.name for p in reg.iterdir()) == ["2026.10.sha256", "2026.10.sqlite", REGISTRY_FILE]
    report = verify_releases(reg)
    assert report.ok and report.findings == [] and [c.db_version for c in report.checked] == ["2026.10"]


def test_release_twice_is_refused(dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    _release(dbs["v1"], reg)
    with pytest.raises(RefusedError, match=r"already released .* as this same file"):
        _release(dbs["v1"], reg)
    with pytest.raises(RefusedError, match="as a different file"):
        _release(dbs["v1b"], reg)
    _release(dbs["v2"], reg)
    assert [r.db_version for r in list_releases(reg)] == ["2026.10", "2026.11"]
    assert sha256_file(reg / "2026.10.sqlite") == sha256_file(dbs["v1"])


def test_unregistered_file_in_the_way_is_refused(dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    reg.mkdir()
    (reg / "2026.10.sqlite").write_bytes(b"debris")
    with pytest.raises(RefusedError, match="not registered"):
        _release(dbs["v1"], reg)
    assert (reg / "2026.10.sqlite").read_bytes() == b"debris"
    assert list_releases(reg) == []
    findings = verify_releases(reg).findings
    assert [f.rule for f in findings] == ["release.unregistered"]


def test_failed_release_leaves_nothing(db: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def boom(*_: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(release_mod, "registry_insert", boom)
    reg = tmp_path / "reg"
    with pytest.raises(OSError, match="disk full"):
        _release(db, reg)
    assert sorted(p.name for p in reg.iterdir()) == [REGISTRY_FILE]
    assert list_releases(reg) == []


def test_release_refused_when_validation_fails(db: Path, tmp_path: Path) -> None:
    with sqlite3.connect(db) as conn:  # hand edit: the content hash in meta no longer matches
        conn.execute("UPDATE balises SET km_actual_m = 601 WHERE balise_id = 'B005'")
    conn.close()
    reg = tmp_path / "reg"
    with pytest.raises(FindingsError) as exc:
        _release(db, reg)
    assert any(f.rule == "db.content_hash" for f in exc.value.findings)
    assert not reg.exists()


def test_release_refuses_unusable_version(tmp_path: Path, dbs: dict[str, Path]) -> None:
    bad = tmp_path / "bad.sqlite"
    _set_version(dbs["v1"], bad, "../evil")
    with pytest.raises(RefusedError, match="cannot name a released file"):
        _release(bad, tmp_path / "reg")


def test_release_of_unreadable_file(tmp_path: Path) -> None:
    junk = tmp_path / "junk.sqlite"
    junk.write_text("hello")
    with pytest.raises(InputError, match="not an SQLite database"):
        _release(junk, tmp_path / "reg")
    with pytest.raises(InputError, match="no such file"):
        _release(tmp_path / "missing.sqlite", tmp_path / "reg")


def test_tampered_release_is_detected(dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    _release(dbs["v1"], reg)
    _release(dbs["v2"], reg)
    target = reg / "2026.11.sqlite"
    target.chmod(0o644)
    with sqlite3.connect(target) as conn:
        conn.execute("UPDATE gis SET lat = lat + 0.001 WHERE km_m = 0")
    conn.close()
    report = verify_releases(reg)
    assert not report.ok
    assert not report.failed("2026.10") and report.failed("2026.11")
    rules = {(f.rule, str(f.severity)) for f in report.findings}
    assert ("release.sha256", "error") in rules
    assert ("db.content_hash", "error") in rules
    assert ("release.writable", "warning") in rules
    assert verify_releases(reg, "2026.10").ok
    assert not verify_releases(reg, "2026.11").ok


def test_missing_file_and_bad_manifest(dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    _release(dbs["v1"], reg)
    _release(dbs["v2"], reg)
    (reg / "2026.10.sqlite").unlink()
    manifest = reg / "2026.11.sha256"
    manifest.chmod(0o644)
    manifest.write_text(f"{'0' * 64}  2026.11.sqlite\n")
    report = verify_releases(reg)
    by = {(f.keys["db_version"], f.rule) for f in report.findings}
    assert by == {("2026.10", "release.missing_file"), ("2026.11", "release.manifest")}


def test_corrupt_or_missing_registry(dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    _release(dbs["v1"], reg)
    (reg / REGISTRY_FILE).write_bytes(b"garbage that is not sqlite" * 10)
    for call in (lambda: list_releases(reg), lambda: verify_releases(reg), lambda: _release(dbs["v2"], reg)):
        with pytest.raises(InputError, match="not an SQLite database"):
            call()
    with pytest.raises(InputError, match="no such registry folder"):
        list_releases(tmp_path / "nowhere")
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="nothing released yet"):
        list_releases(tmp_path / "empty")


def test_unknown_version(dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    _release(dbs["v1"], reg)
    with pytest.raises(UsageError, match="2099 is not in the registry"):
        verify_releases(reg, "2099")


# ------------------------------------------------------------------ issue 32: integrity


def _wal_db(db: Path, version: str) -> tuple[sqlite3.Connection, sqlite3.Connection]:
    """``db`` switched to WAL mode with an uncheckpointed change in its -wal (meta
    db_version → ``version``; meta is outside the content hash, so both states are valid
    DBs). Two connections stay open: the WAL is not checkpointed until they close."""
    writer = sqlite3.connect(db, isolation_level=None)
    assert writer.execute("PRAGMA journal_mode=WAL").fetchone()[0] == "wal"
    writer.execute("PRAGMA wal_autocheckpoint=0")
    reader = sqlite3.connect(db)
    reader.execute("SELECT COUNT(*) FROM meta").fetchone()
    writer.execute("UPDATE meta SET value = ? WHERE key = 'db_version'", (version,))
    writer.execute("UPDATE meta SET value = 'from the WAL' WHERE key = 'note'")
    wal = db.with_name(db.name + "-wal")
    assert wal.stat().st_size > 0
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as probe:  # the main file alone is the old version
        assert probe.execute("SELECT value FROM meta WHERE key = 'db_version'").fetchone()[0] == version
    return writer, reader


def test_wal_db_releases_exactly_what_was_validated(db: Path, tmp_path: Path) -> None:
    """Issue 32.1: a WAL-mode DB with uncheckpointed changes: the release is a snapshot of
    what SQLite reads (WAL included), in rollback-journal mode; the user's DB and -wal are
    left byte for byte as they were."""
    writer, reader = _wal_db(db, "2026.12")
    wal = db.with_name(db.name + "-wal")
    try:
        before = (sha256_file(db), sha256_file(wal))
        reg = tmp_path / "reg"
        r = _release(db, reg)
        assert (sha256_file(db), sha256_file(wal)) == before  # never checkpointed or modified
        assert r.db_version == "2026.12"
        target = reg / "2026.12.sqlite"
        assert sha256_file(target) == r.sha256
        assert target.read_bytes()[18:20] == b"\x01\x01"  # rollback journal: readers need no -wal/-shm
        with sqlite3.connect(f"file:{target}?mode=ro", uri=True) as conn:
            assert dict(conn.execute("SELECT key, value FROM meta").fetchall())["note"] == "from the WAL"
        conn.close()
        report = verify_releases(reg)
        assert report.ok and report.findings == [], report.findings
    finally:
        reader.close()
        writer.close()


def test_released_wal_db_is_read_on_a_read_only_folder(db: Path, tmp_path: Path) -> None:
    """Issue 32.1: reading a release creates nothing in the registry (no -wal/-shm), so a
    read-only registry folder (a read-only mount) is read as it is."""
    writer, reader = _wal_db(db, "2026.12")
    try:
        reg = tmp_path / "reg"
        _release(db, reg)
    finally:
        reader.close()
        writer.close()
    names = sorted(p.name for p in reg.iterdir())
    reg.chmod(0o555)
    try:
        from dbtools.database import read_network

        net = read_network(reg / "2026.12.sqlite")
        assert net.meta["db_version"] == "2026.12"
        assert verify_releases(reg).ok
        assert sorted(p.name for p in reg.iterdir()) == names  # no -wal, no -shm
    finally:
        reg.chmod(0o755)


def test_a_failed_snapshot_leaves_no_registry_folder(db: Path, tmp_path: Path) -> None:
    """A release refused by validation of its snapshot writes nothing, not even the folder."""
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE balises SET km_actual_m = 601 WHERE balise_id = 'B005'")
    conn.close()
    reg = tmp_path / "new" / "reg"
    with pytest.raises(FindingsError):
        _release(db, reg)
    assert not reg.exists()


_CRASH = """
import os, sys
from pathlib import Path
import dbtools.release as rel
from schemas.registry import RELEASES

real = rel.registry_insert

def insert(conn, row, table=RELEASES):
    if table is RELEASES:  # files published, registration not committed: killed
        os._exit(9)
    real(conn, row, table)

rel.registry_insert = insert
rel.release_db(Path(sys.argv[1]), Path(sys.argv[2]), user="tester")
"""


def _crash_release(db: Path, reg: Path) -> None:
    """``db release`` killed (``os._exit``) after it published its files, before its commit."""
    import subprocess
    import sys

    from tests.fresh import ROOT

    proc = subprocess.run([sys.executable, "-c", _CRASH, str(db), str(reg)], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 9, proc.stderr


def test_release_killed_before_its_commit_is_recovered(dbs: dict[str, Path], tmp_path: Path) -> None:
    """Issue 32.3: the files a killed release published are known as its own debris:
    verify-release says so, and the next release removes them and releases the version."""
    reg = tmp_path / "reg"
    _crash_release(dbs["v1"], reg)
    assert (reg / "2026.10.sqlite").is_file() and list_releases(reg) == []  # published, not registered
    findings = verify_releases(reg).findings
    assert {f.rule for f in findings} == {"release.unregistered"} and len(findings) == 2
    assert all("interrupted" in f.message and "next db release removes it" in f.message for f in findings)
    r = _release(dbs["v1b"], reg)  # the same version, rebuilt: not burned
    assert r.sha256 == sha256_file(dbs["v1b"]) == sha256_file(reg / "2026.10.sqlite")
    report = verify_releases(reg)
    assert report.ok and report.findings == []
    assert sorted(p.name for p in reg.iterdir()) == ["2026.10.sha256", "2026.10.sqlite", REGISTRY_FILE]


def test_re_release_after_a_kill_through_the_cli(dbs: dict[str, Path], tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from cli.main import app

    reg = tmp_path / "reg"
    _crash_release(dbs["v1"], reg)
    res = CliRunner().invoke(app, ["db", "release", str(dbs["v1"]), "--registry", str(reg)])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(app, ["db", "verify-release", "--registry", str(reg)])
    assert res.exit_code == 0 and "not registered" not in res.output, res.output


def test_debris_changed_since_the_kill_is_kept(dbs: dict[str, Path], tmp_path: Path) -> None:
    """A file an interrupted release recorded but whose content changed since is not its
    own any more: kept, and the release is refused (exit 3) naming it."""
    reg = tmp_path / "reg"
    _crash_release(dbs["v1"], reg)
    manifest = reg / "2026.10.sha256"
    manifest.chmod(0o644)
    manifest.write_text("someone's notes\n")
    with pytest.raises(RefusedError, match=r"2026\.10\.sha256 already exists .* not registered"):
        _release(dbs["v1"], reg)
    assert manifest.read_text() == "someone's notes\n"
    assert not (reg / "2026.10.sqlite").exists()  # what was still the release's own is gone


def test_a_release_in_progress_is_not_taken_for_debris(dbs: dict[str, Path], tmp_path: Path) -> None:
    import json
    import os
    import socket

    from dbtools.database import registry_insert, registry_transaction
    from schemas.registry import PENDING

    reg = tmp_path / "reg"
    reg.mkdir()
    with registry_transaction(reg / REGISTRY_FILE) as conn:
        row = {"db_version": "2026.10", "files": json.dumps({"2026.10.sqlite": "0" * 64}), "pid": os.getppid()}
        registry_insert(conn, {**row, "host": socket.gethostname(), "started_at": "2026-12-05T03:00:00Z"}, PENDING)
    with pytest.raises(RefusedError, match="is being released by process"):
        _release(dbs["v1"], reg)
    _release(dbs["v2"], reg)  # another version is not held up
    assert [r.db_version for r in list_releases(reg)] == ["2026.11"]


def test_identical_debris_without_an_intent_is_written_again(dbs: dict[str, Path], tmp_path: Path) -> None:
    """Files an older trainpos left (no intent recorded) that hold exactly the bytes this
    release writes are no obstacle; a different file still is."""
    reg = tmp_path / "reg"
    reg.mkdir()
    digest = sha256_file(dbs["v1"])
    shutil.copyfile(dbs["v1"], reg / "2026.10.sqlite")
    (reg / "2026.10.sha256").write_text(f"{digest}  2026.10.sqlite\n")
    r = _release(dbs["v1"], reg)
    assert r.sha256 == digest and verify_releases(reg).findings == []
    (reg / "2026.11.sqlite").write_bytes(b"someone else's")
    with pytest.raises(RefusedError, match="not registered"):
        _release(dbs["v2"], reg)
    assert (reg / "2026.11.sqlite").read_bytes() == b"someone else's"
