"""Errors of the machine while an output is written (disk full, read-only, file too large)
are reported against the user's ``--out`` path with the reason, never as an internal
error, without a path or against a temporary file (issue 32 item 8)."""

from __future__ import annotations

import errno
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest

from dbtools.atomic import atomic_file, atomic_folder, machine_errno
from dbtools.sample_network import sample_source_dir
from schemas.errors import InputError
from tests.fieldlogs.make_runs import make_run

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT / "tests" / "data"


@pytest.mark.parametrize(
    "error",
    [
        OSError(errno.ENOSPC, "No space left on device"),
        sqlite3.OperationalError("database or disk is full"),
        sqlite3.IntegrityError("gis: INTERNAL: failed to execute: database or disk is full"),
    ],
)
@pytest.mark.parametrize("kind", ["file", "folder"])
def test_disk_full_names_the_output(tmp_path: Path, error: Exception, kind: str) -> None:
    out = tmp_path / "out"
    writer = atomic_file if kind == "file" else atomic_folder
    with pytest.raises(OSError) as info, writer(out):
        raise error
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(out)
    assert not out.exists() and os.listdir(tmp_path) == []


def test_a_temporary_file_is_never_named(tmp_path: Path) -> None:
    out = tmp_path / "out.sqlite"
    with pytest.raises(OSError) as info, atomic_file(out) as tmp:
        raise PermissionError(errno.EACCES, "Permission denied", str(tmp))
    assert info.value.filename == str(out) and info.value.errno == errno.EACCES


def test_errors_about_other_files_pass_unchanged(tmp_path: Path) -> None:
    src = tmp_path / "input.csv"
    with pytest.raises(PermissionError) as info, atomic_file(tmp_path / "out"):
        raise PermissionError(errno.EACCES, "Permission denied", str(src))
    assert info.value.filename == str(src)
    with pytest.raises(sqlite3.IntegrityError), atomic_file(tmp_path / "out2"):
        raise sqlite3.IntegrityError("UNIQUE constraint failed")
    assert machine_errno(ValueError("x")) is None
    with pytest.raises(InputError), atomic_file(tmp_path / "out3"):  # an input's error keeps its path
        raise InputError("cannot open database: unable to open database file", path=src)


def _limited(limit: int, args: list[str], cwd: Path) -> subprocess.CompletedProcess[str]:
    """The CLI in a subprocess whose files may not grow beyond ``limit`` bytes
    (RLIMIT_FSIZE: writes fail with EFBIG, as on a full disk)."""
    code = (
        "import resource, sys\n"
        f"resource.setrlimit(resource.RLIMIT_FSIZE, ({limit}, {limit}))\n"
        "sys.argv = ['trainpos', *sys.argv[1:]]\n"
        "from cli.main import app\n"
        "app()\n"
    )
    env = {**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "200"}
    return subprocess.run(
        [sys.executable, "-c", code, *args], cwd=cwd, env=env, capture_output=True, text=True, timeout=300
    )


@pytest.mark.parametrize("command", ["db build", "db export", "run", "logs import", "db import", "db release"])
def test_a_full_disk_names_the_out_path_and_exits_2(tmp_path: Path, sample_db: Path, command: str) -> None:
    out = tmp_path / "o" / "out"
    args = {
        "db build": ["db", "build", str(sample_source_dir()), "--out", str(out), "--version", "1"],
        "db export": ["db", "export", str(sample_db), "--format", "gpkg", "--out", str(out)],
        "run": ["run", str(make_run(tmp_path / "r", 20)), "--db", str(sample_db), "--out", str(out)],
        "logs import": [
            "logs",
            "import",
            str(DATA / "recorders" / "sample.nmea"),
            "--vehicle",
            str(DATA / "recorders" / "vehicle.toml"),
            "--out",
            str(out),
        ],
        "db import": [
            "db",
            "import",
            str(DATA / "railml" / "Track-007_28-47.railml.xml"),
            "--format",
            "railml",
            "--out",
            str(out),
        ],
        "db release": ["db", "release", str(sample_db), "--registry", str(out)],
    }[command]
    res = _limited(4096, args, tmp_path)
    assert res.returncode == 2, res.stderr
    message = " ".join(res.stderr.split())
    assert f"{out}:" in message and "internal error" not in message, message
    assert "trainpos-tmp" not in message
    assert not out.exists()
