"""Random damage to recorder files and to onboard DBs (issue 32, property tests): never a
traceback or an internal error (exit 4), never a modified input, and a release is exactly what
was validated.

Recorder files (the bundled NMEA, UBX and RINEX samples) are cut, have bytes flipped, lines
repeated or dropped, are gzipped, or are replaced by a small gzip that decompresses beyond a
tiny ``[input] max_decompressed_mb`` (a bomb in miniature: the limit, not the machine's
memory, must speak), then given to ``logs import``. DBs (the bundled sample built) have a page
flipped, are truncated, have a REAL cell turned into text, a row deleted, or are put in WAL
mode with a change left in the write-ahead log; then ``db validate``, ``db info`` and
``db release`` run on them, and a release that succeeds must verify."""

from __future__ import annotations

import gzip
import hashlib
import shutil
import sqlite3
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner, Result

from cli.main import app

DATA = Path(__file__).resolve().parent / "data" / "recorders"
RECORDERS = ("sample.nmea", "sample.ubx", "sample_v211.obs")
RECORDER_OPS = ("truncate", "flip", "repeat_lines", "drop_lines", "gzip", "bomb")
DB_OPS = ("flip_page", "truncate", "text_in_real", "delete_row", "wal_pending")


def _digest(folder: Path) -> dict[str, str]:
    """Every file's hash; a WAL DB's ``-shm`` left out: it is SQLite's shared-memory index,
    which every reader of a WAL database writes (the DB and its ``-wal`` must not change)."""
    return {
        p.name: hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(folder.iterdir())
        if p.is_file() and not p.name.endswith("-shm")
    }


def _clean(r: Result, what: object) -> None:
    assert "Traceback" not in r.output and "internal error" not in r.output, (what, r.output)
    assert r.exception is None or isinstance(r.exception, SystemExit), (what, repr(r.exception))
    assert r.exit_code in (0, 1, 2, 3), (what, r.exit_code, r.output)


def _damage_recorder(path: Path, op: str, frac: float) -> Path:
    raw = path.read_bytes()
    if op == "truncate":
        path.write_bytes(raw[: int(len(raw) * frac)])
    elif op == "flip":
        i = int(len(raw) * frac) % max(len(raw), 1)
        path.write_bytes(raw[:i] + bytes([raw[i] ^ 0xFF]) + raw[i + 1 :] if raw else raw)
    elif op in ("repeat_lines", "drop_lines"):
        lines = raw.split(b"\n")
        k = int(len(lines) * frac)
        lines = (
            lines[:k] + lines[k : k + 5] * 3 + lines[k + 5 :] if op == "repeat_lines" else lines[:k] + lines[k + 5 :]
        )
        path.write_bytes(b"\n".join(lines))
    elif op == "gzip":
        gz = path.with_name(path.name + ".gz")
        gz.write_bytes(gzip.compress(raw))
        path.unlink()
        return gz
    elif op == "bomb":  # 2 MB of one repeated line in a few kB: beyond the 1 MB limit the test sets
        gz = path.with_name(path.name + ".gz")
        gz.write_bytes(
            gzip.compress((raw.split(b"\n", 1)[0] + b"\n") * (2_000_000 // max(len(raw.split(b"\n", 1)[0]), 1)))
        )
        path.unlink()
        return gz
    return path


@pytest.mark.slow
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    name=st.sampled_from(RECORDERS),
    ops=st.lists(st.tuples(st.sampled_from(RECORDER_OPS), st.floats(0.05, 0.95)), min_size=1, max_size=2),
)
def test_damaged_recorder_files_never_crash(
    name: str, ops: list[tuple[str, float]], tmp_path_factory: pytest.TempPathFactory
) -> None:
    work = tmp_path_factory.mktemp("rec")
    src = work / "in"
    src.mkdir()
    path = src / name
    shutil.copyfile(DATA / name, path)
    if name.endswith(".obs"):
        shutil.copyfile(DATA / "sample_v2.nav", src / "sample_v2.nav")
    for op, frac in ops:
        if path.exists() and path.suffix != ".gz":
            path = _damage_recorder(path, op, frac)
    cfg = work / "limits.toml"
    cfg.write_text("[input]\nmax_decompressed_mb = 1\n", encoding="utf-8")
    before = _digest(src)
    sources = [str(p) for p in sorted(src.iterdir())]
    args = ["logs", "import", *sources, "--out", str(work / "run"), "--config", str(cfg)]
    r = CliRunner().invoke(app, [*args, "--vehicle", str(DATA / "vehicle.toml")])
    _clean(r, (name, ops))
    assert _digest(src) == before, "an input was modified"
    if any(op == "bomb" for op, _ in ops) and path.suffix == ".gz" and r.exit_code == 2:
        assert "max_decompressed_mb" in r.output.replace("\n", " ") or "decompress" in r.output, r.output


def _damage_db(db: Path, op: str, frac: float) -> None:
    if op == "flip_page":
        raw = bytearray(db.read_bytes())
        page = 4096
        i = page + int((len(raw) - page) * frac)  # never the header page: the file stays SQLite
        raw[i : i + 64] = bytes(b ^ 0x5A for b in raw[i : i + 64])
        db.write_bytes(bytes(raw))
        return
    if op == "truncate":
        raw = db.read_bytes()
        db.write_bytes(raw[: max(100, int(len(raw) * frac))])
        return
    conn = sqlite3.connect(db)
    try:
        if op == "text_in_real":
            conn.execute("UPDATE gis SET lat = 'north' WHERE rowid = (SELECT MIN(rowid) FROM gis)")
        elif op == "delete_row":
            conn.execute("DELETE FROM balises WHERE rowid = (SELECT MAX(rowid) FROM balises)")
        conn.commit()
    finally:
        conn.close()


def _wal_pending(db: Path) -> sqlite3.Connection:
    """The DB in WAL mode with a change in its -wal, held there by a reader kept open."""
    writer = sqlite3.connect(db)
    writer.execute("PRAGMA journal_mode=WAL")
    reader = sqlite3.connect(db)
    reader.execute("BEGIN")
    reader.execute("SELECT COUNT(*) FROM meta").fetchone()
    writer.execute("PRAGMA wal_autocheckpoint=0")
    writer.execute("UPDATE meta SET value = value || ' (edited)' WHERE key = 'note'")
    writer.commit()
    writer.close()
    return reader


@pytest.mark.slow
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(op=st.sampled_from(DB_OPS), frac=st.floats(0.05, 0.95))
def test_damaged_dbs_never_crash_and_releases_verify(
    op: str, frac: float, sample_db: Path, tmp_path_factory: pytest.TempPathFactory
) -> None:
    work = tmp_path_factory.mktemp("db")
    db = work / "net.sqlite"
    shutil.copyfile(sample_db, db)
    held = _wal_pending(db) if op == "wal_pending" else None
    try:
        if held is None:
            _damage_db(db, op, frac)
        before = _digest(work)
        runner = CliRunner()
        for args in (["db", "validate", str(db)], ["db", "info", str(db)]):
            _clean(runner.invoke(app, args), (op, args))
        reg = work.parent / f"{work.name}-releases"
        rel = runner.invoke(app, ["db", "release", str(db), "--registry", str(reg)])
        _clean(rel, (op, "release"))
        assert _digest(work) == before, "an input was modified"
        if rel.exit_code == 0:  # what the registry holds is what was validated
            check = runner.invoke(app, ["db", "verify-release", "--registry", str(reg)])
            assert check.exit_code == 0, (op, check.output)
        elif op in ("flip_page", "truncate", "text_in_real", "delete_row"):
            assert rel.exit_code in (1, 2), (op, rel.output)  # damaged content is never released
    finally:
        if held is not None:
            held.close()
