"""DB versions are checked where they are made (db build) and where they name a file (db release)."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.release import release_db
from schemas.errors import RefusedError, UsageError
from schemas.registry import DB_VERSION_MAX_LENGTH, db_version_problem

GOOD = ["2026.11", "2026.11.1", "v3", "sample-1", "2026.11-rc1", "20261201.093000", "V_3", "1", "a" * 100]
BAD = {
    "": "is empty",
    "2026 11": "has a space",
    "2026/11": "has '/'",
    "../x": "has '/'",
    "2026.11.": "at its start or end",
    ".2026": "at its start or end",
    "-v3": "at its start or end",
    "2026..11": "two of them in a row",
    "版3": "has '版'",
    "v3\n": "has '\\n'",
    "a" * 101: "101 characters long",
}


@pytest.mark.parametrize("version", GOOD)
def test_good_versions(version: str) -> None:
    assert db_version_problem(version) is None


@pytest.mark.parametrize("version", sorted(BAD))
def test_bad_versions_say_why(version: str) -> None:
    assert BAD[version] in (db_version_problem(version) or "")


@given(st.text(max_size=120))
def test_a_valid_version_is_a_plain_file_name(version: str) -> None:
    if db_version_problem(version) is None:
        assert 0 < len(version) <= DB_VERSION_MAX_LENGTH and version not in (".", "..")
        assert Path(f"{version}.sqlite").name == f"{version}.sqlite" and version.isascii()
        assert version[0].isalnum() and version[-1].isalnum() and ".." not in version


@pytest.mark.parametrize("version", ["2026 11", "../evil", "2026.11.", ""])
def test_db_build_refuses_a_bad_version_before_reading_or_writing(
    tiny_sources: Path, tmp_path: Path, version: str
) -> None:
    out = tmp_path / "net.sqlite"
    with pytest.raises(UsageError, match="a DB version is letters and digits"):
        build_db(tiny_sources, out, db_version=version)
    res = CliRunner().invoke(app, ["db", "build", str(tiny_sources), "--out", str(out), "--version", version])
    assert res.exit_code == 2 and f"error: version '{version}'" in res.stderr, res.output
    assert not out.exists() and list(tmp_path.iterdir()) == [tiny_sources]
    good = CliRunner().invoke(app, ["db", "build", str(tiny_sources), "--out", str(out), "--version", "v3"])
    assert good.exit_code == 0


def test_db_release_refuses_a_version_that_cannot_name_a_file(tiny_sources: Path, tmp_path: Path) -> None:
    db = tmp_path / "net.sqlite"
    build_db(tiny_sources, db, db_version="2026.11")
    bad = tmp_path / "bad.sqlite"
    shutil.copy(db, bad)
    with sqlite3.connect(bad) as conn:  # a DB built by an older trainpos, before versions were checked
        conn.execute("UPDATE meta SET value = '2026..11' WHERE key = 'db_version'")
    conn.close()
    with pytest.raises(RefusedError, match="two of them in a row: it cannot name a released file"):
        release_db(bad, tmp_path / "reg")
    assert not (tmp_path / "reg").exists()
    assert release_db(db, tmp_path / "reg").release.db_version == "2026.11"
