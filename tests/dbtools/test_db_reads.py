"""DB reads that meet a value of the wrong storage class, and databases locked by another
process: clear messages and documented exit codes, never "internal error" nor "corrupt"
(issue 32 item 8)."""

from __future__ import annotations

import shutil
import sqlite3
from collections.abc import Iterator
from contextlib import closing, contextmanager
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools import audit_db, database
from dbtools.audit_db import open_audit_db
from dbtools.database import read_network, registry_transaction
from schemas.errors import EXIT_REFUSED, BusyError, InputError
from tests.fieldlogs.make_runs import make_run


@pytest.fixture
def damaged(tmp_path: Path, sample_db: Path) -> Path:
    """A copy of the sample DB with text in a REAL column (balises.km_actual_m)."""
    db = tmp_path / "bad.sqlite"
    shutil.copyfile(sample_db, db)
    with closing(sqlite3.connect(db)) as conn, conn:
        conn.execute("UPDATE balises SET km_actual_m = 'abc' WHERE rowid = 3")
    return db


def test_text_in_a_real_column_names_table_column_and_row(damaged: Path) -> None:
    with pytest.raises(InputError) as info:
        read_network(damaged, verify=False)
    msg = str(info.value)
    assert info.value.column == "km_actual_m" and "'balises' row 3" in msg and "'abc'" in msg and "REAL" in msg


def test_a_fraction_in_an_integer_column_is_named(tmp_path: Path, sample_db: Path) -> None:
    db = tmp_path / "bad.sqlite"
    shutil.copyfile(sample_db, db)
    with closing(sqlite3.connect(db)) as conn, conn:
        conn.execute("UPDATE feature_points SET seq = 2.5 WHERE rowid = 1")
    with pytest.raises(InputError) as info:
        read_network(db, verify=False)
    assert info.value.column == "seq" and "real 2.5" in str(info.value)


@pytest.mark.parametrize("command", ["validate", "diff", "run"])
def test_commands_exit_2_on_a_wrong_storage_class(tmp_path: Path, sample_db: Path, damaged: Path, command: str) -> None:
    args = {
        "validate": ["db", "validate", str(damaged)],
        "diff": ["db", "diff", str(sample_db), str(damaged)],
        "run": [
            "run",
            str(make_run(tmp_path / "r", 3)),
            "--db",
            str(damaged),
            "--out",
            str(tmp_path / "o"),
            "--no-verify-hash",
        ],
    }[command]
    res = CliRunner().invoke(app, args, env={"COLUMNS": "300"})
    assert res.exit_code == 2, res.output
    assert "km_actual_m" in res.output and "internal error" not in res.output


@contextmanager
def _locked(path: Path) -> Iterator[None]:
    """Another process's write lock on the SQLite file ``path``."""
    conn = sqlite3.connect(path, isolation_level=None)
    try:
        conn.execute("BEGIN EXCLUSIVE")
        yield
        conn.execute("ROLLBACK")
    finally:
        conn.close()


def test_a_locked_registry_is_in_use_not_corrupt(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(database, "REGISTRY_LOCK_WAIT_S", 0.05)
    registry = tmp_path / "registry.sqlite"
    with registry_transaction(registry):
        pass  # created
    with _locked(registry), pytest.raises(BusyError) as info, registry_transaction(registry):
        pass
    assert info.value.exit_code == EXIT_REFUSED
    assert "in use by another trainpos process" in str(info.value) and "corrupt" not in str(info.value)


def test_a_second_concurrent_audit_is_told_the_db_is_in_use(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(audit_db, "AUDIT_LOCK_WAIT_S", 0.05)
    path = tmp_path / "audit.sqlite"
    with open_audit_db(path):
        pass
    with _locked(path), pytest.raises(BusyError) as info, open_audit_db(path):
        pass
    assert "in use by another trainpos process" in str(info.value) and "unreadable" not in str(info.value)
