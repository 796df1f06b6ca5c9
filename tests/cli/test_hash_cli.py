"""Every command that loads an onboard DB refuses a modified one (exit 2, one line naming
the DB, nothing written) unless --no-verify-hash, which uses it and names it in a warning."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner, Result

from cli.main import app
from tests.dbtools.test_integrity import bit_flipped

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "fieldlogs" / "sample_logs"
TRAIN = SAMPLE_LOGS / "sim-d-evening"
ROAD_RAIL = SAMPLE_LOGS / "sim-road-rail"
PLAN = SAMPLE_LOGS / "possessions.csv"


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


@pytest.fixture(scope="module")
def bad_db(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return bit_flipped(sample_db, tmp_path_factory.mktemp("hash") / "flipped.sqlite")


#: command line with DB, GOOD (a clean DB) and OUT placeholders; whether it writes OUT
COMMANDS = {
    "run": (["run", TRAIN, "--db", "DB", "--out", "OUT"], True),
    "simulate": (["simulate", "--db", "DB", "--out", "OUT", "--seed", "3"], True),
    "logs check": (["logs", "check", TRAIN, "--db", "DB"], False),
    "possession check": (["possession", "check", ROAD_RAIL, "--db", "DB", "--plan", PLAN, "--out", "OUT"], True),
    "gis verify": (["gis", "verify", "DB", TRAIN, "--out", "OUT", "--workers", "1"], True),
    "survey": (["survey", TRAIN, "--db", "DB", "--out", "OUT", "--workers", "1"], True),
    "audit": (["audit", TRAIN, "--db", "DB", "--out", "OUT", "--workers", "1"], True),
    "db export": (["db", "export", "DB", "--format", "geojson", "--out", "OUT"], True),
    "db impact (new)": (["db", "impact", "GOOD", "DB", TRAIN, "--out", "OUT"], True),
    "db impact (old)": (["db", "impact", "DB", "GOOD", TRAIN, "--out", "OUT"], True),
    "gnss position": (["gnss", "position", TRAIN, "--db", "DB", "--line", "0420", "--track", "D"], False),
}


def _argv(cmd: list[object], db: Path, good: Path, out: Path) -> list[object]:
    return [{"DB": db, "GOOD": good, "OUT": out}.get(a, a) if isinstance(a, str) else a for a in cmd]


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_a_modified_db_is_refused(name: str, bad_db: Path, sample_db: Path, tmp_path: Path) -> None:
    cmd, _ = COMMANDS[name]
    out = tmp_path / "out"
    res = invoke(*_argv(cmd, bad_db, sample_db, out))
    assert res.exit_code == 2, res.output
    assert "Traceback" not in res.output and "internal error" not in res.output
    assert f"error: {bad_db}: content hash" in " ".join(res.stderr.split()), res.stderr
    assert not out.exists()  # nothing written


@pytest.mark.parametrize("name", ["run", "db export", "logs check"])
def test_no_verify_hash_uses_it_and_says_so(name: str, bad_db: Path, sample_db: Path, tmp_path: Path) -> None:
    cmd, writes = COMMANDS[name]
    out = tmp_path / "out"
    res = invoke(*_argv(cmd, bad_db, sample_db, out), "--no-verify-hash")
    assert res.exit_code in (0, 1), res.output
    stderr = " ".join(res.stderr.split())
    assert f"warning: {bad_db}: content hash" in stderr and "used anyway (--no-verify-hash)" in stderr
    assert stderr.count("used anyway") == 1
    assert out.exists() == writes
    good = invoke(*_argv(cmd, sample_db, sample_db, tmp_path / "good"), "--no-verify-hash")
    assert "used anyway" not in good.stderr  # a DB that matches is not named


def test_every_command_loading_a_db_has_the_option() -> None:
    """The one opt-out is the same option everywhere (README: Exit codes)."""
    for cmd, _ in COMMANDS.values():
        path = [str(a) for a in cmd[: 2 if cmd[0] in ("logs", "possession", "gis", "db", "gnss") else 1]]
        res = invoke(*path, "--help")
        assert "--no-verify-hash" in res.output, path


def test_db_diff_shows_the_mismatch(bad_db: Path, sample_db: Path) -> None:
    res = invoke("db", "diff", sample_db, bad_db)
    assert res.exit_code == 0, res.output
    flat = " ".join(res.stdout.split())
    assert "MODIFIED" in flat and "content does not match its stored content_hash" in flat
    assert "content hashes differ" in flat
    doc = json.loads(invoke("db", "diff", sample_db, bad_db, "--format", "json").stdout)
    assert doc["new"]["content_verified"] is False and doc["old"]["content_verified"] is True
    assert "actual_content_hash" not in doc["meta"]
