"""The one output rule (issue 15): --force never replaces a registry, an input, a folder
trainpos did not write, or a file by a folder; outputs honour the umask; stale temporary
files of a killed process are swept."""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.atomic import MARKER, REGISTRY_FILE, atomic_file, atomic_folder, write_text
from schemas.errors import RefusedError
from tests.fresh import fresh_python


def test_existing_output_needs_force(tmp_path: Path) -> None:
    out = tmp_path / "a.txt"
    write_text(out, "one")
    with pytest.raises(RefusedError, match="output exists; use --force"):
        write_text(out, "two")
    write_text(out, "two", force=True)
    assert out.read_text() == "two"


def test_a_registry_is_never_written_into(tmp_path: Path) -> None:
    reg = tmp_path / "releases"
    reg.mkdir()
    (reg / REGISTRY_FILE).write_bytes(b"")
    (reg / "2026.11.sqlite").write_bytes(b"released")
    for target in (reg / "2026.11.sqlite", reg / "new.sqlite", reg / "sub" / "x.json"):
        with pytest.raises(RefusedError, match="release registry"):
            write_text(target, "x", force=True)
    with pytest.raises(RefusedError, match="release registry"), atomic_folder(reg, force=True):
        pass
    assert (reg / "2026.11.sqlite").read_bytes() == b"released"


@pytest.mark.parametrize("rel", ["in.sqlite", ".", "in.sqlite/x"])
def test_an_input_of_the_command_is_never_replaced(tmp_path: Path, rel: str) -> None:
    src = tmp_path / "in.sqlite"
    src.write_bytes(b"input")
    with pytest.raises(RefusedError, match="would replace an input"):
        write_text(tmp_path / rel, "x", force=True, inputs=[src])
    assert src.read_bytes() == b"input"


def test_force_replaces_only_a_folder_trainpos_wrote(tmp_path: Path) -> None:
    mine = tmp_path / "mine"
    with atomic_folder(mine) as tmp:
        (tmp / "a").write_text("1")
    assert (mine / MARKER).is_file()
    with atomic_folder(mine, force=True) as tmp:
        (tmp / "b").write_text("2")
    assert not (mine / "a").exists() and (mine / "b").exists()
    theirs = tmp_path / "Documents"
    theirs.mkdir()
    (theirs / "thesis.tex").write_text("years of work")
    with pytest.raises(RefusedError, match="replaces only a folder trainpos wrote"), atomic_folder(theirs, force=True):
        pass
    assert (theirs / "thesis.tex").read_text() == "years of work"
    empty = tmp_path / "empty"
    empty.mkdir()
    with atomic_folder(empty, force=True) as tmp:
        (tmp / "c").write_text("3")
    assert (empty / "c").exists()


def test_never_a_file_by_a_folder_or_a_folder_by_a_file(tmp_path: Path) -> None:
    f = tmp_path / "f"
    f.write_text("x")
    with pytest.raises(RefusedError, match="is a file"), atomic_folder(f, force=True):
        pass
    d = tmp_path / "d"
    d.mkdir()
    with pytest.raises(RefusedError, match="is a folder"), atomic_file(d, force=True):
        pass


def test_outputs_honour_the_umask(tmp_path: Path) -> None:
    code = (
        "import os, sys; os.umask(0o022); from pathlib import Path; "
        "from dbtools.atomic import write_text, atomic_folder; "
        f"write_text(Path({str(tmp_path / 'f.txt')!r}), 'x'); "
        f"cm = atomic_folder(Path({str(tmp_path / 'dir')!r})); t = cm.__enter__(); (t / 'a').write_text('y'); "
        "cm.__exit__(None, None, None)"
    )
    fresh_python(code)
    assert stat.S_IMODE((tmp_path / "f.txt").stat().st_mode) == 0o644
    assert stat.S_IMODE((tmp_path / "dir").stat().st_mode) == 0o755
    assert stat.S_IMODE((tmp_path / "dir" / "a").stat().st_mode) == 0o644


def test_temporary_files_of_a_killed_process_are_swept(tmp_path: Path) -> None:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    pid = int(dead.stdout)
    stale = tmp_path / f".net.sqlite.{pid}.abcd.tmp"
    stale.write_bytes(b"half a DB")
    live = tmp_path / f".net.sqlite.{os.getppid()}.efgh.tmp"  # a live process's: kept
    live.write_bytes(b"in progress")
    write_text(tmp_path / "net.sqlite", "x")
    assert not stale.exists() and live.exists()


# ------------------------------------------------------------------------------ commands
def test_report_out_is_refused_without_force_and_never_its_own_input(tmp_path: Path) -> None:
    from fieldlogs.audit.store import open_audit

    db = tmp_path / "audit.sqlite"
    with open_audit(db):
        pass
    runner = CliRunner()
    out = tmp_path / "r.txt"
    out.write_text("keep me")
    res = runner.invoke(app, ["report", str(db), "--out", str(out)])
    assert res.exit_code == 3 and "use --force" in res.output and out.read_text() == "keep me"
    assert runner.invoke(app, ["report", str(db), "--out", str(out), "--force"]).exit_code == 0
    before = db.read_bytes()
    res = runner.invoke(app, ["report", str(db), "--format", "csv", "--out", str(db), "--force"])
    assert res.exit_code == 3 and "input of this command" in res.output and db.read_bytes() == before


def test_db_build_never_replaces_a_released_db(tiny_sources: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    reg = tmp_path / "releases"
    reg.mkdir()
    (reg / REGISTRY_FILE).write_bytes(b"")
    released = reg / "2026.11.sqlite"
    released.write_bytes(b"released")
    res = runner.invoke(app, ["db", "build", str(tiny_sources), "--out", str(released), "--force"])
    assert res.exit_code == 3, res.output
    assert "release registry" in res.output and released.read_bytes() == b"released"


def test_run_out_file_is_not_replaced_by_a_folder(sample_db: Path, tmp_path: Path) -> None:
    f = tmp_path / "out.txt"
    f.write_text("x")
    args = ["run", "fieldlogs/sample_logs/sim-d-slips", "--db", str(sample_db), "--out", str(f), "--force"]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 3, res.output
    assert "is a file" in res.output and f.read_text() == "x"


def test_permission_denied_is_an_environment_error_not_a_bug(tiny_sources: Path, tmp_path: Path) -> None:
    if os.geteuid() == 0:
        pytest.skip("root ignores directory permissions")
    locked = tmp_path / "locked"
    locked.mkdir()
    locked.chmod(0o500)
    res = CliRunner().invoke(app, ["db", "build", str(tiny_sources), "--out", str(locked / "x.sqlite")])
    assert res.exit_code == 2 and "Permission denied" in res.output and "internal error" not in res.output


@pytest.mark.parametrize(
    ("exc", "expected"),
    [
        (PermissionError(13, "Permission denied", "/data/out.sqlite"), "/data/out.sqlite: Permission denied"),
        (OSError(28, "No space left on device", "/data/out.sqlite"), "No space left on device (free some space"),
    ],
)
def test_environment_errors_exit_2_with_a_clear_line(exc: OSError, expected: str) -> None:
    import typer

    from cli.errors import cli_command

    mini = typer.Typer()

    @mini.command()
    @cli_command
    def boom() -> None:
        raise exc

    res = CliRunner().invoke(mini, [])
    assert res.exit_code == 2
    assert expected in res.output and "internal error" not in res.output
