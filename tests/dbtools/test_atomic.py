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
from dbtools.atomic import MARKER, OLD_TAG, REGISTRY_FILE, TEMP_RE, TEMP_TAG, atomic_file, atomic_folder, write_text
from schemas.errors import RefusedError
from tests.fresh import ROOT, fresh_python


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


def _dead_pid() -> int:
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    return int(dead.stdout)


def test_temporary_files_of_a_killed_process_are_swept(tmp_path: Path) -> None:
    pid = _dead_pid()
    stale = tmp_path / f".net.sqlite.{TEMP_TAG}.{pid}.0123456789abcdef"
    stale.write_bytes(b"half a DB")
    journal = tmp_path / f".net.sqlite.{TEMP_TAG}.{pid}.fedcba9876543210-journal"  # SQLite's, beside a temp DB
    journal.write_bytes(b"journal")
    live = tmp_path / f".net.sqlite.{TEMP_TAG}.{os.getppid()}.0123456789abcdef"  # a live process's: kept
    live.write_bytes(b"in progress")
    write_text(tmp_path / "net.sqlite", "x")
    assert not stale.exists() and not journal.exists() and live.exists()


def test_temporaries_carry_the_signature(tmp_path: Path) -> None:
    seen: list[str] = []
    with atomic_file(tmp_path / "net.sqlite") as tmp:
        seen.append(tmp.name)
    with atomic_folder(tmp_path / "out") as tmp:
        seen.append(tmp.name)
    assert [TEMP_RE.match(n) is not None for n in seen] == [True, True]
    assert [m.group("name") for m in map(TEMP_RE.match, seen) if m] == ["net.sqlite", "out"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["net.sqlite", "out"]


def test_the_sweep_keeps_user_files_that_look_like_temporaries(tiny_sources: Path, tmp_path: Path) -> None:
    """Issue 32.2: a hidden backup beside the DB, a notes folder beside the output folder —
    named like the old temporaries (``.NAME.<number>.…``) — survive ``--force`` writes."""
    runner = CliRunner()
    db = tmp_path / "net.sqlite"
    backups = [tmp_path / ".net.sqlite.20261205.bak", tmp_path / f".net.sqlite.{_dead_pid()}.x.tmp"]
    for b in backups:
        b.write_text("my backup")
    for _ in range(2):
        res = runner.invoke(app, ["db", "build", str(tiny_sources), "--out", str(db), "--force"])
        assert res.exit_code == 0, res.output
    assert all(b.read_text() == "my backup" for b in backups)
    out = tmp_path / "out-sim"
    notes = [tmp_path / ".out-sim.2026.notes", tmp_path / ".out-sim.20261205.notes"]
    for n in notes:
        n.mkdir()
        (n / "todo.txt").write_text("notes")
    for _ in range(2):
        with atomic_folder(out, force=True) as tmp:
            (tmp / "summary.json").write_text("{}")
    assert all((n / "todo.txt").read_text() == "notes" for n in notes)


def test_run_out_force_keeps_a_notes_folder_beside_the_output(sample_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "out-sim"
    notes = tmp_path / ".out-sim.20261205.notes"
    notes.mkdir()
    (notes / "todo.txt").write_text("notes")
    args = ["run", "fieldlogs/sample_logs/sim-d-slips", "--db", str(sample_db), "--out", str(out), "--force"]
    for _ in range(2):
        res = CliRunner().invoke(app, args)
        assert res.exit_code == 0, res.output
    assert (notes / "todo.txt").read_text() == "notes"


_KILLED_REPLACE = """
import os, sys
from pathlib import Path
import dbtools.atomic as atomic

target = Path(sys.argv[1])
real = os.replace

def replace(src, dst):
    if Path(dst) == target:  # the old copy is aside, the new one not yet in place: killed
        os._exit(9)
    real(src, dst)

atomic.os.replace = replace
with atomic.atomic_folder(target, force=True) as tmp:
    (tmp / "result.txt").write_text("new")
"""


def test_a_folder_replace_killed_between_its_renames_keeps_the_old_copy(tmp_path: Path) -> None:
    """Issue 32.2: killed between the two renames of a --force replace, the output is
    missing; the old copy is kept aside and the next write to it puts it back."""
    out = tmp_path / "out"
    with atomic_folder(out) as tmp:
        (tmp / "result.txt").write_text("old")
    proc = subprocess.run([sys.executable, "-c", _KILLED_REPLACE, str(out)], cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 9, proc.stderr
    assert not out.exists()
    aside = [p for p in tmp_path.iterdir() if (p / "result.txt").is_file() and (p / "result.txt").read_text() == "old"]
    assert len(aside) == 1  # recoverable by hand meanwhile
    with pytest.raises(RefusedError, match="output exists; use --force"), atomic_folder(out) as tmp:
        (tmp / "result.txt").write_text("newer")
    assert (out / "result.txt").read_text() == "old" and (out / MARKER).is_file()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # the killed write's new copy is swept
    with atomic_folder(out, force=True) as tmp:
        (tmp / "result.txt").write_text("newer")
    assert (out / "result.txt").read_text() == "newer"


def test_a_failed_second_rename_puts_the_old_copy_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    import dbtools.atomic as atomic

    out = tmp_path / "out"
    with atomic_folder(out) as tmp:
        (tmp / "result.txt").write_text("old")
    real = os.replace

    def replace(src: object, dst: object) -> None:
        if Path(str(dst)) == out:
            raise OSError(5, "Input/output error")
        real(src, dst)  # type: ignore[arg-type]

    monkeypatch.setattr(atomic.os, "replace", replace)
    with pytest.raises(OSError, match="Input/output"), atomic_folder(out, force=True) as tmp:
        (tmp / "result.txt").write_text("new")
    assert (out / "result.txt").read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_an_old_copy_left_after_a_finished_replace_is_swept(tmp_path: Path) -> None:
    out = tmp_path / "out"
    with atomic_folder(out) as tmp:
        (tmp / "result.txt").write_text("new")
    old = tmp_path / f".out.{OLD_TAG}.{_dead_pid()}.0123456789abcdef"
    old.mkdir()
    (old / "result.txt").write_text("old")
    with atomic_folder(out, force=True) as tmp:
        (tmp / "result.txt").write_text("newer")
    assert not old.exists() and sorted(p.name for p in tmp_path.iterdir()) == ["out"]


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


def _registry(folder: Path) -> Path:
    """A release registry folder with one released file (what makes it one: its registry file)."""
    folder.mkdir()
    (folder / REGISTRY_FILE).write_bytes(b"")
    (folder / "2026.11.sqlite").write_bytes(b"released")
    return folder


def test_audit_never_writes_into_a_registry(sample_db: Path, tmp_path: Path) -> None:
    """Issue 32.4: ``audit --out`` (an output resumed in place, not replaced) passes the same
    registry check as every other output: exit 3, nothing written, before any run is read."""
    reg = _registry(tmp_path / "releases")
    link = tmp_path / "link"
    link.symlink_to(reg)
    runner = CliRunner()
    for out in (reg / "audit.sqlite", reg / "sub" / "audit.sqlite", link / "audit.sqlite", reg):
        args = ["audit", "fieldlogs/sample_logs/sim-d-slips", "--db", str(sample_db), "--out", str(out)]
        res = runner.invoke(app, args)
        assert res.exit_code == 3, res.output
        assert "release registry" in res.output and "never written into" in res.output
    assert sorted(p.name for p in reg.iterdir()) == ["2026.11.sqlite", REGISTRY_FILE]


def test_other_outputs_never_go_into_a_registry(sample_db: Path, tmp_path: Path) -> None:
    """Issue 32.4: the same refusal (exit 3) for the other commands' --out: a report, the demo
    folder, a run's output folder, a grid."""
    from fieldlogs.audit.store import open_audit

    reg = _registry(tmp_path / "releases")
    audit_db = tmp_path / "audit.sqlite"
    with open_audit(audit_db):
        pass
    runner = CliRunner()
    commands = [
        ["report", str(audit_db), "--format", "html", "--out", str(reg / "report.html")],
        ["demo", "--out", str(reg / "demo")],
        ["demo", "--out", str(reg)],
        ["run", "fieldlogs/sample_logs/sim-d-slips", "--db", str(sample_db), "--out", str(reg / "run")],
        ["db", "export", str(sample_db), "--format", "geojson", "--out", str(reg / "net.geojson")],
    ]
    for args in commands:
        res = runner.invoke(app, args)
        assert res.exit_code == 3, (args, res.output)
        assert "release registry" in res.output, res.output
    assert sorted(p.name for p in reg.iterdir()) == ["2026.11.sqlite", REGISTRY_FILE]
