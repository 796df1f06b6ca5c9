"""``trainpos db diff / release / releases / verify-release`` through the CLI: output, exit codes."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest
from click.testing import Result
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from schemas.registry import REGISTRY_FILE
from schemas.tables import SCHEMA_VERSION
from tests.dbtools.release_sources import write_sources


@pytest.fixture(scope="module")
def dbs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("cli")
    out = {"src1": write_sources(root / "src1"), "v1": root / "v1.sqlite", "v2": root / "v2.sqlite"}
    build_db(out["src1"], out["v1"], db_version="2026.10")
    build_db(write_sources(root / "src2", c_km=612.0), out["v2"], db_version="2026.11")
    return out


def _run(runner: CliRunner, args: list[str]) -> Result:
    """Invoke with a wide terminal so that Rich does not wrap messages."""
    return runner.invoke(app, args, env={"COLUMNS": "400"})


def _one_line_error(result: Result, *needles: str) -> None:
    """The error is one line on stderr, no traceback."""
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for n in needles:
        assert n in lines[0]


@pytest.mark.parametrize("command", ["diff", "release", "releases", "verify-release"])
def test_commands_have_help(runner: CliRunner, command: str) -> None:
    result = _run(runner, ["db", command, "--help"])
    assert result.exit_code == 0
    assert "Example: trainpos db" in result.stdout


def test_diff_table_and_json(runner: CliRunner, dbs: dict[str, Path]) -> None:
    result = _run(runner, ["db", "diff", str(dbs["v1"]), str(dbs["v2"])])
    assert result.exit_code == 0, result.output
    assert "balise B005 (C, 0420 01 D) moved +12.0 m (km_actual 0k600.0 → 0k612.0)" in result.stdout
    assert "db_version 2026.10 → 2026.11" in result.stdout
    result = _run(runner, ["db", "diff", str(dbs["v1"]), str(dbs["v2"]), "--format", "json"])
    assert result.exit_code == 0
    out = json.loads(result.stdout)
    assert out["tables"]["balises"]["changed"] == 1
    assert out["schema_version"] == {"old": SCHEMA_VERSION, "new": SCHEMA_VERSION}


def test_diff_without_differences_exits_0(runner: CliRunner, dbs: dict[str, Path]) -> None:
    result = _run(runner, ["db", "diff", str(dbs["src1"]), str(dbs["v1"])])
    assert result.exit_code == 0
    assert "no content differences" in result.stdout


def test_diff_unreadable_input_exits_2(runner: CliRunner, dbs: dict[str, Path], tmp_path: Path) -> None:
    bad = tmp_path / "bad.sqlite"
    bad.write_text("nope")
    result = _run(runner, ["db", "diff", str(dbs["v1"]), str(bad)])
    assert result.exit_code == 2
    _one_line_error(result, str(bad), "not an SQLite database")
    result = _run(runner, ["db", "diff", str(tmp_path / "missing.sqlite"), str(dbs["v1"])])
    assert result.exit_code == 2
    _one_line_error(result, "missing.sqlite", "no such file")


def test_release_list_verify(runner: CliRunner, dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    result = _run(runner, ["db", "release", str(dbs["v1"]), "--registry", str(reg), "--note", "first"])
    assert result.exit_code == 0, result.output
    assert "2026.10" in result.stdout
    assert _run(runner, ["db", "release", str(dbs["v2"]), "--registry", str(reg)]).exit_code == 0

    again = _run(runner, ["db", "release", str(dbs["v1"]), "--registry", str(reg)])
    assert again.exit_code == 3
    _one_line_error(again, "db_version 2026.10 was already released")

    listed = _run(runner, ["db", "releases", "--registry", str(reg), "--format", "json"])
    assert listed.exit_code == 0
    out = json.loads(listed.stdout)
    assert [r["db_version"] for r in out["releases"]] == ["2026.10", "2026.11"]
    assert out["releases"][0]["note"] == "first"
    assert set(out["releases"][0]) == {
        "db_version",
        "file",
        "sha256",
        "content_hash",
        "schema_version",
        "released_at",
        "released_by",
        "note",
        "source_file",
    }
    table = _run(runner, ["db", "releases", "--registry", str(reg)])
    assert table.exit_code == 0 and "2 release(s)" in table.stdout

    ok = _run(runner, ["db", "verify-release", "--registry", str(reg)])
    assert ok.exit_code == 0, ok.output
    assert "2 of 2 release(s) intact" in ok.stdout

    target = reg / "2026.11.sqlite"
    target.chmod(0o644)
    with target.open("r+b") as fh:  # flip bytes well inside the file
        fh.seek(5000)
        fh.write(b"\x00tampered\x00")
    bad = _run(runner, ["db", "verify-release", "--registry", str(reg), "--format", "json"])
    assert bad.exit_code == 1
    report = json.loads(bad.stdout)
    assert report["ok"] is False
    assert report["checked"] == [
        {"db_version": "2026.10", "file": "2026.10.sqlite", "ok": True},
        {"db_version": "2026.11", "file": "2026.11.sqlite", "ok": False},
    ]
    assert any(f["rule"] == "release.sha256" for f in report["findings"])
    one = _run(runner, ["db", "verify-release", "2026.10", "--registry", str(reg)])
    assert one.exit_code == 0
    unknown = _run(runner, ["db", "verify-release", "2099", "--registry", str(reg)])
    assert unknown.exit_code == 2
    _one_line_error(unknown, "2099 is not in the registry")


def test_release_refused_on_validation_error(runner: CliRunner, dbs: dict[str, Path], tmp_path: Path) -> None:
    edited = tmp_path / "edited.sqlite"
    edited.write_bytes(dbs["v1"].read_bytes())
    with sqlite3.connect(edited) as conn:
        conn.execute("UPDATE balises SET km_equipment_m = 1 WHERE balise_id = 'B001'")
    conn.close()
    result = _run(runner, ["db", "release", str(edited), "--registry", str(tmp_path / "reg")])
    assert result.exit_code == 1
    lines = result.stderr.splitlines()
    assert "db.content_hash" in result.stderr and "1 error(s), 0 warning(s)" in lines  # the findings table
    assert lines[-1] == f"error: {edited}: 1 validation error(s); not released"
    assert not (tmp_path / "reg").exists()


def test_corrupt_registry_exits_2(runner: CliRunner, dbs: dict[str, Path], tmp_path: Path) -> None:
    reg = tmp_path / "reg"
    assert _run(runner, ["db", "release", str(dbs["v1"]), "--registry", str(reg)]).exit_code == 0
    (reg / REGISTRY_FILE).write_bytes(b"\x00" * 4096)
    for args in (["releases"], ["verify-release"], ["release", str(dbs["v2"])]):
        result = _run(runner, ["db", *args, "--registry", str(reg)])
        assert result.exit_code == 2, args
        _one_line_error(result, REGISTRY_FILE, "not an SQLite database")
    missing = _run(runner, ["db", "releases", "--registry", str(tmp_path / "nowhere")])
    assert missing.exit_code == 2
    _one_line_error(missing, "no such registry folder")


def test_diff_source_set_with_errors_exits_1(runner: CliRunner, dbs: dict[str, Path], tmp_path: Path) -> None:
    src = write_sources(tmp_path / "src")
    (src / "gis.csv").unlink()
    result = _run(runner, ["db", "diff", str(src), str(dbs["v1"])])
    assert result.exit_code == 1
    assert result.stderr.splitlines()[-1] == f"error: {src}: 1 error(s) in the source set; cannot diff it"


def test_build_says_when_the_db_would_fail_validation(tmp_path: Path) -> None:
    """Issue 32 item 14: `db build` wrote a DB that fails `db validate` without a word. It now
    prints the validation summary (exit 0, DB written), and --strict refuses (exit 1, nothing)."""
    src = tmp_path / "src"
    shutil.copytree(Path(__file__).resolve().parents[1] / "data" / "tiny_sources", src)
    text = (src / "balises.csv").read_text().replace("B002,I2,0420,01,D,,10,10,", "B002,I2,0420,01,D,,13,13,")
    (src / "balises.csv").write_text(text)  # I1–I2 8 m apart: balise.pair_spacing
    runner = CliRunner()
    r = _run(runner, ["db", "build", str(src), "--out", str(tmp_path / "a.sqlite")])
    assert r.exit_code == 0, r.output
    assert "validation: 1 error(s)" in r.stdout and "trainpos db validate" in r.stdout
    assert (tmp_path / "a.sqlite").exists()
    r = _run(runner, ["db", "build", str(src), "--out", str(tmp_path / "b.sqlite"), "--strict"])
    assert r.exit_code == 1 and "balise.pair_spacing" in r.output
    assert not (tmp_path / "b.sqlite").exists()
    r = _run(runner, ["db", "build", str(src), "--out", str(tmp_path / "c.sqlite"), "--no-validate"])
    assert r.exit_code == 0 and "validation:" not in r.stdout
