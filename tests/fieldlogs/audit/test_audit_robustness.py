"""Audits that are killed, interrupted, or given an edited DB or an old audit DB (issue 15).

* ``kill -9`` of an audit: the audit DB can be reported and resumed (its identity is in the
  file header, not only in the write-ahead log), a new audit into another DB works, and the
  fork server, the workers and the resource tracker die with the coordinating process;
* Ctrl-C (SIGINT to the process group, as a terminal sends it): exit 130, finished runs
  kept, no process left;
* a hand-edited DB (a balise moved 30 m, meta left as it was) is a new context: every run
  is audited again, with a warning;
* an audit DB of schema 1 is refused with a clear message.
"""

from __future__ import annotations

import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import closing, contextmanager
from pathlib import Path

import psutil
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.database import read_meta as read_db_meta
from dbtools.database import read_network
from dbtools.integrity import ContentHashError, hash_policy
from dbtools.network import content_hash
from fieldlogs.audit.runner import audit
from fieldlogs.audit.store import open_audit, read_table
from fieldlogs.reports.report import build_report
from schemas.audit import AUDIT_APPLICATION_ID, AUDIT_SCHEMA_VERSION
from schemas.errors import InputError
from tests.fieldlogs.audit.audit_data import RUNS, AuditData, audit_data

N = len(RUNS)
COPIES = 10  # 40 runs: the audit is still running when it is interrupted


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> AuditData:
    return audit_data(tmp_path_factory)


@pytest.fixture(scope="module")
def many_logs(data: AuditData, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("many-logs")
    for k in range(COPIES):
        for name, *_ in RUNS:
            dst = root / f"{name}-{k}"
            dst.mkdir()
            for f in (data.logs / name).iterdir():
                os.link(f, dst / f.name)
    return root


@contextmanager
def audit_process(logs: Path, db: Path, out: Path) -> Iterator[subprocess.Popen[bytes]]:
    """``trainpos audit`` in its own process group (a terminal's foreground job); killed
    and reaped at the end whatever happened."""
    code = (
        "import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "  # as in a terminal
        "from cli.main import app; sys.argv[0] = 'trainpos'; app()"
    )
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    root = Path(__file__).resolve().parents[3]
    args = ["audit", str(logs), "--db", str(db), "--out", str(out), "-j", "2"]
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *args],
        cwd=root,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        start_new_session=True,
    )
    try:
        yield proc
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=60)


def stored_runs(out: Path) -> int:
    """Runs committed so far (read as another process would, WAL included)."""
    try:
        with closing(sqlite3.connect(f"file:{out}?mode=ro", uri=True)) as conn:
            return int(conn.execute("SELECT COUNT(*) FROM audit_runs").fetchone()[0])
    except sqlite3.Error:
        return 0


def freeze_when_running(proc: subprocess.Popen[bytes], out: Path, timeout_s: float = 240.0) -> set[int]:
    """Once at least one run is stored and the pool runs, stop the whole job (SIGSTOP to
    its process group, as a terminal's Ctrl-Z) and return the coordinator's descendants.

    Stopping first makes the interruption deterministic: however loaded the machine, the
    audit cannot finish between "it is running" and the signal under test (a bare poll
    lost that race once in CI). Signals sent while stopped stay pending; ``resume`` lets
    them be delivered."""
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        assert proc.poll() is None, "the audit finished before it could be interrupted"
        kids = {p.pid for p in psutil.Process(proc.pid).children(recursive=True)}
        if stored_runs(out) >= 1 and len(kids) >= 2:  # the workers (forked: no server, no tracker)
            os.killpg(proc.pid, signal.SIGSTOP)
            assert proc.poll() is None, "the audit finished before it could be stopped"
            return kids
        time.sleep(0.05)
    raise AssertionError("the audit did not start its pool in time")


def resume(proc: subprocess.Popen[bytes]) -> None:
    """SIGCONT to the job's process group: pending signals are delivered now."""
    try:
        os.killpg(proc.pid, signal.SIGCONT)
    except ProcessLookupError:  # the group is already gone
        pass


def assert_gone(pids: set[int], timeout_s: float = 30.0) -> None:
    procs = []
    for pid in pids:
        try:
            procs.append(psutil.Process(pid))
        except psutil.NoSuchProcess:
            continue
    _, alive = psutil.wait_procs(procs, timeout=timeout_s)
    assert not alive, [(p.pid, " ".join(p.cmdline())[:120]) for p in alive]


def test_audit_killed_with_sigkill_can_be_reported_and_resumed_and_leaves_no_process(
    data: AuditData, many_logs: Path, tmp_path: Path
) -> None:
    out = tmp_path / "audit.sqlite"
    with audit_process(many_logs, data.db, out) as proc:
        kids = freeze_when_running(proc, out)
        os.kill(proc.pid, signal.SIGKILL)
        resume(proc)  # the orphaned workers wake up to find their parent gone
        proc.communicate(timeout=30)
    assert_gone(kids)  # no worker survives
    kept = stored_runs(out)
    assert 1 <= kept < N * COPIES
    assert out.read_bytes()[68:72] == AUDIT_APPLICATION_ID.to_bytes(4, "big")  # in the header itself

    rep = build_report(out)  # read-only: the runs committed before the kill
    assert int(rep.routes["n_runs"].sum()) == kept
    stats = audit([many_logs], data.db, out, workers=1)
    assert (stats.skipped, stats.audited, stats.failed) == (kept, N * COPIES - kept, 0)
    assert len(read_table(out, "audit_runs")) == N * COPIES
    assert not Path(f"{out}-wal").exists()
    fresh = audit([data.logs], data.db, tmp_path / "second.sqlite", workers=2)  # a second audit, new DB
    assert (fresh.audited, fresh.failed) == (N, 0)


def test_audit_interrupted_with_ctrl_c_exits_130_keeps_runs_and_leaves_no_process(
    data: AuditData, many_logs: Path, tmp_path: Path
) -> None:
    out = tmp_path / "audit.sqlite"
    with audit_process(many_logs, data.db, out) as proc:
        kids = freeze_when_running(proc, out)
        os.killpg(proc.pid, signal.SIGINT)  # what a terminal does on Ctrl-C
        resume(proc)
        _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err.decode()
    assert b"interrupted" in err and b"Traceback" not in err
    assert_gone(kids)
    kept = stored_runs(out)
    assert kept >= 1 and not Path(f"{out}-wal").exists(), err.decode()
    assert audit([many_logs], data.db, out, workers=1).skipped == kept


def test_hand_edited_db_is_refused_or_audited_again_with_a_warning(data: AuditData, tmp_path: Path) -> None:
    db = tmp_path / "net.sqlite"
    shutil.copy(data.db, db)
    out = tmp_path / "audit.sqlite"
    assert audit([data.logs], db, out, workers=1).audited == N
    unchanged = audit([data.logs], db, out, workers=1)
    assert (unchanged.skipped, unchanged.warnings) == (N, [])
    meta_before = read_db_meta(db)
    with sqlite3.connect(db) as conn:  # a balise moved 30 m by hand; meta left as it was
        bid = conn.execute("SELECT balise_id FROM balises WHERE kind = 'C' ORDER BY balise_id").fetchone()[0]
        conn.execute("UPDATE balises SET km_actual_m = km_actual_m + 30 WHERE balise_id = ?", (bid,))
    assert read_db_meta(db)["content_hash"] == meta_before["content_hash"]
    with pytest.raises(ContentHashError, match="modified afterwards"):  # refused on loading
        audit([data.logs], db, out, workers=1)
    res = CliRunner().invoke(app, ["audit", str(data.logs), "--db", str(db), "--out", str(out), "-j", "1"])
    assert res.exit_code == 2 and "does not match the one stored" in res.stderr and "Traceback" not in res.stderr
    with hash_policy(verify=False) as policy:  # the user's explicit opt-out: used, with a warning
        edited = audit([data.logs], db, out, workers=1)
    assert len(policy.used_unverified) == 1 and str(db) in policy.used_unverified[0]
    assert (edited.audited, edited.skipped) == (N, 0)
    assert len(edited.warnings) == 1 and "modified after it was built" in edited.warnings[0]
    meta = read_table(out, "audit_meta").set_index("key")["value"]
    assert meta["db_content_hash"] == content_hash(read_network(db, verify=False).tables) != meta_before["content_hash"]
    res = CliRunner().invoke(
        app, ["audit", str(data.logs), "--db", str(db), "--out", str(out), "-j", "1", "--no-verify-hash"]
    )
    assert res.exit_code == 0 and "modified after it was built" in res.stderr
    assert "used anyway (--no-verify-hash)" in res.stderr


def old_audit_db(path: Path) -> Path:
    """An audit DB as schema 1 wrote it (its DDL, abridged)."""
    with sqlite3.connect(path) as conn:
        conn.execute(f"PRAGMA application_id={AUDIT_APPLICATION_ID}")
        conn.execute("PRAGMA user_version=1")
        conn.execute("CREATE TABLE runs (run_path TEXT PRIMARY KEY, fingerprint TEXT NOT NULL, status TEXT)")
        conn.execute("CREATE TABLE audit_meta (key TEXT PRIMARY KEY, value TEXT)")
    return path


def test_audit_db_of_schema_1_is_refused_with_a_clear_message(data: AuditData, tmp_path: Path) -> None:
    old = old_audit_db(tmp_path / "old.sqlite")
    raw = old.read_bytes()
    with pytest.raises(InputError, match=rf"schema 1 is older than this tool's \({AUDIT_SCHEMA_VERSION}: "):
        build_report(old)
    with pytest.raises(InputError, match="audit the runs again into a new audit database"), open_audit(old):
        pass
    runner = CliRunner()
    for args in (["report", str(old)], ["audit", str(data.logs), "--db", str(data.db), "--out", str(old)]):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and "older than this tool's" in res.stderr and "Traceback" not in res.stderr
    assert old.read_bytes() == raw  # never modified


def test_audit_tables_refuse_an_unknown_status(tmp_path: Path) -> None:
    with open_audit(tmp_path / "a.sqlite") as conn, pytest.raises(sqlite3.IntegrityError, match="status"):
        conn.store_run({"run_path": "x", "fingerprint": "", "status": "done", "audited_at": "now"}, [], None)


def test_schema_show_lists_the_audit_tables() -> None:
    res = CliRunner().invoke(app, ["schema", "show", "--format", "json"])
    names = {t["name"]: t for t in __import__("json").loads(res.stdout)}
    assert {"audit_runs", "audit_events", "audit_traces", "audit_meta", "route_summary"} <= set(names)
    assert names["audit_runs"]["kind"] == "audit" and names["audit_runs"]["primary_key"] == ["run_path"]
    res = CliRunner().invoke(app, ["schema", "show", "audit_traces"])
    assert res.exit_code == 0 and "bytes" in res.stdout


def test_audit_db_whose_identity_is_still_in_the_wal_is_recognised(tmp_path: Path) -> None:
    """What schema 1 left after a kill -9: application id written in WAL mode, never
    checkpointed, so the file header still says 0. The probe asks SQLite, not the header."""
    src = tmp_path / "live.sqlite"
    conn = sqlite3.connect(src)
    try:
        conn.execute("PRAGMA journal_mode=WAL")
        conn.execute(f"PRAGMA application_id={AUDIT_APPLICATION_ID}")
        conn.execute("PRAGMA user_version=1")
        conn.execute("CREATE TABLE runs (run_path TEXT PRIMARY KEY)")
        conn.commit()
        dst = tmp_path / "killed.sqlite"
        for suffix in ("", "-wal"):  # the files as a killed process leaves them
            shutil.copy(f"{src}{suffix}", f"{dst}{suffix}")
    finally:
        conn.close()
    assert dst.read_bytes()[68:72] == b"\0\0\0\0"
    with pytest.raises(InputError, match="schema 1 is older") as err:
        build_report(dst)
    assert "not a trainpos audit database" not in str(err.value)
