"""``trainpos db info`` and ``db show`` through the CLI: what they print, exit codes, and that
they never modify the DB (a ``--where`` can only read)."""

from __future__ import annotations

import csv
import hashlib
import io
import json
import shutil
import sqlite3
from pathlib import Path

import pytest
from click.testing import Result
from typer.testing import CliRunner

from cli.main import app
from schemas.tables import DB_TABLES, SCHEMA_VERSION

TABLES = [*(t.name for t in DB_TABLES), "meta"]
NEWER = SCHEMA_VERSION + 1


def _run(runner: CliRunner, args: list[str], columns: int = 400) -> Result:
    return runner.invoke(app, args, env={"COLUMNS": str(columns)})


def _count(db: Path, sql: str) -> int:
    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as conn:
        return int(conn.execute(sql).fetchone()[0])


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _one_line_error(result: Result, *needles: str) -> None:
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.stderr
    for n in needles:
        assert n in lines[0], (n, lines[0])


@pytest.fixture
def db_copy(sample_db: Path, tmp_path: Path) -> Path:
    """A copy of the sample DB in a folder of its own (safe to edit; nothing else beside it)."""
    folder = tmp_path / "db"
    folder.mkdir()
    return Path(shutil.copy(sample_db, folder / "net.sqlite"))


def _bordered(text: str, width: int) -> None:
    """Every line fits ``width`` and every table row keeps its left and right border."""
    for line in text.splitlines():
        assert len(line) <= width, line
        if line.startswith(("│", "┃")):
            assert line.rstrip().endswith(("│", "┃")), line


@pytest.mark.parametrize("command", ["info", "show"])
def test_commands_have_help(runner: CliRunner, command: str) -> None:
    result = _run(runner, ["db", command, "--help"])
    assert result.exit_code == 0
    assert "Example: trainpos db" in result.stdout


def test_info_json_describes_the_db(runner: CliRunner, sample_db: Path) -> None:
    result = _run(runner, ["db", "info", str(sample_db), "--format", "json"])
    assert result.exit_code == 0, result.output
    d = json.loads(result.stdout)
    assert d["db_version"] == "sample-test" and d["schema_version"] == SCHEMA_VERSION and d["schema_supported"]
    assert d["application_id"] == "0x54504f53"
    assert d["size_bytes"] == sample_db.stat().st_size
    assert list(d["tables"]) == TABLES
    assert d["tables"] == {t: _count(sample_db, f"SELECT COUNT(*) FROM {t}") for t in TABLES}
    assert d["content_hash"]["verified"] is True
    assert d["content_hash"]["actual"] == d["content_hash"]["stored"] == d["meta"]["content_hash"]
    assert set(d["source_sha256"]) == {"balises.csv", "feature_points.csv", "gis.csv", "lines.csv"}
    assert d["source_sha256"]["gis.csv"] == d["meta"]["source_sha256:gis.csv"]
    assert len(d["meta"]) == _count(sample_db, "SELECT COUNT(*) FROM meta")
    assert d["georef"]["metric_crs"].startswith("EPSG:") and {"lat_min", "lon_max"} <= set(d["georef"]["area"])


def test_info_table_at_80_columns(runner: CliRunner, sample_db: Path) -> None:
    result = _run(runner, ["db", "info", str(sample_db)], columns=80)
    assert result.exit_code == 0, result.output
    out = result.stdout
    for needle in ("sample-test", "matches", "0x54504f53 (TPOS)", "operating area", "metric CRS", "Source files"):
        assert needle in out, (needle, out)
    n_gis = _count(sample_db, "SELECT COUNT(*) FROM gis")
    assert any(line.split() == ["│", "gis", "│", f"{n_gis:,}", "│"] for line in out.splitlines()), out
    _bordered(out, 80)


def test_info_of_a_modified_db_says_so(runner: CliRunner, db_copy: Path) -> None:
    with sqlite3.connect(db_copy) as conn:
        conn.execute("UPDATE gis SET lat = lat + 0.001 WHERE rowid = 1")
    conn.close()
    result = _run(runner, ["db", "info", str(db_copy), "--format", "json"])
    assert result.exit_code == 0, result.output  # a report
    check = json.loads(result.stdout)["content_hash"]
    assert check["verified"] is False and check["actual"] != check["stored"]
    assert "does not match" in check["status"]
    assert "MODIFIED" in _run(runner, ["db", "info", str(db_copy)]).stdout


def test_info_of_a_newer_schema_counts_its_new_tables(runner: CliRunner, db_copy: Path) -> None:
    with sqlite3.connect(db_copy) as conn:
        conn.execute("CREATE TABLE speed_limits (line_code TEXT, km_from_m REAL, kmh INTEGER)")
        conn.executemany("INSERT INTO speed_limits VALUES (?, ?, ?)", [("0420", k * 100.0, 80) for k in range(3)])
        conn.execute(f"PRAGMA user_version = {NEWER}")
    conn.close()
    result = _run(runner, ["db", "info", str(db_copy), "--format", "json"])
    assert result.exit_code == 0, result.output
    d = json.loads(result.stdout)
    assert d["tables"]["speed_limits"] == 3 and list(d["tables"]) == [*TABLES, "speed_limits"]
    assert d["schema_version"] == NEWER and d["schema_supported"] is False
    assert d["content_hash"]["verified"] is None and f"schema version {NEWER}" in d["content_hash"]["status"]
    shown = _run(runner, ["db", "show", str(db_copy), "speed_limits", "--format", "json"])
    assert json.loads(shown.stdout)["matched"] == 3


def test_info_quick_skips_the_content_check(runner: CliRunner, sample_db: Path) -> None:
    result = _run(runner, ["db", "info", str(sample_db), "--quick", "--format", "json"])
    assert result.exit_code == 0, result.output
    check = json.loads(result.stdout)["content_hash"]
    assert check["verified"] is None and check["actual"] is None and check["stored"]
    assert "not checked (--quick)" in _run(runner, ["db", "info", str(sample_db), "--quick"]).stdout


@pytest.mark.parametrize("command", [["info"], ["show", "gis"]])
def test_not_an_onboard_db_exits_2(runner: CliRunner, tmp_path: Path, command: list[str]) -> None:
    bad = tmp_path / "bad.sqlite"
    bad.write_text("nope")
    result = _run(runner, ["db", command[0], str(bad), *command[1:]])
    assert result.exit_code == 2
    _one_line_error(result, str(bad), "not an SQLite database")


def test_show_table_says_how_many_rows_match(runner: CliRunner, sample_db: Path) -> None:
    n = _count(sample_db, "SELECT COUNT(*) FROM gis")
    result = _run(runner, ["db", "show", str(sample_db), "gis", "--limit", "3"])
    assert result.exit_code == 0, result.output
    assert f"3 of {n:,} row(s) in gis shown" in result.stdout
    first = _count(sample_db, "SELECT km_m FROM gis ORDER BY rowid LIMIT 1")
    assert f"{float(first)!r}" in result.stdout
    assert sum(line.startswith("│") for line in result.stdout.splitlines()) == 3


def test_show_where_as_json(runner: CliRunner, sample_db: Path) -> None:
    where = "kind = 'C' AND km_actual_m > 1000"
    result = _run(runner, ["db", "show", str(sample_db), "balises", "--where", where, "--format", "json"])
    assert result.exit_code == 0, result.output
    d = json.loads(result.stdout)
    n = _count(sample_db, f"SELECT COUNT(*) FROM balises WHERE {where}")
    assert n > 0 and d["matched"] == n and d["table"] == "balises" and d["where"] == where
    assert len(d["rows"]) == min(n, 20) and all(r["kind"] == "C" and r["km_actual_m"] > 1000 for r in d["rows"])
    assert list(d["rows"][0]) == d["columns"]


def test_show_csv_parses_and_counts_on_stderr(runner: CliRunner, sample_db: Path) -> None:
    result = _run(runner, ["db", "show", str(sample_db), "gis", "--limit", "5", "--format", "csv"])
    assert result.exit_code == 0, result.output
    rows = list(csv.DictReader(io.StringIO(result.stdout)))
    assert len(rows) == 5 and list(rows[0]) == ["line_code", "track", "km_m", "lat", "lon", "height_m"]
    assert all(float(r["lat"]) for r in rows)
    assert "5 of" in result.stderr and "row(s) in gis shown" in result.stderr


def test_show_limit_0_only_counts(runner: CliRunner, sample_db: Path) -> None:
    result = _run(runner, ["db", "show", str(sample_db), "lines", "--limit", "0"])
    assert result.exit_code == 0, result.output
    n = _count(sample_db, "SELECT COUNT(*) FROM lines")
    assert result.stdout.strip() == f"0 of {n:,} row(s) in lines shown (--limit N shows more)"


def test_show_wide_rows_keep_every_column_at_80_columns(runner: CliRunner, sample_db: Path) -> None:
    for table in ("balises", "gis", "feature_points", "meta"):
        result = _run(runner, ["db", "show", str(sample_db), table, "--limit", "4"], columns=80)
        assert result.exit_code == 0, result.output
        _bordered(result.stdout, 80)
    flat = " ".join(_run(runner, ["db", "show", str(sample_db), "balises"], columns=80).stdout.split())
    assert "balise_id:" in flat and "km_equipment_m:" in flat  # a record per row where a table cannot fit


def test_show_unknown_table_lists_the_tables(runner: CliRunner, sample_db: Path) -> None:
    result = _run(runner, ["db", "show", str(sample_db), "balise"])
    assert result.exit_code == 2
    _one_line_error(result, "no table 'balise'", "tables: " + ", ".join(TABLES))


@pytest.mark.parametrize(
    ("where", "needle"),
    [
        ("no_such_column = 1", "no such column: no_such_column"),
        ("kind = ", "syntax error"),
        ("   ", "--where is empty"),
    ],
)
def test_show_bad_where_exits_2(runner: CliRunner, sample_db: Path, where: str, needle: str) -> None:
    result = _run(runner, ["db", "show", str(sample_db), "balises", "--where", where])
    assert result.exit_code == 2
    _one_line_error(result, needle)
    if where.strip():
        assert "columns: balise_id, kind, line_code" in result.stderr


@pytest.mark.parametrize(
    "where",
    [
        "1; DROP TABLE gis",
        "1); DROP TABLE gis; --",
        "1)\n; DELETE FROM gis; --",
        "1); PRAGMA user_version = 9; --",
        "1) /*",
    ],
)
def test_show_where_cannot_run_a_second_statement(runner: CliRunner, db_copy: Path, where: str) -> None:
    before, files = _sha(db_copy), sorted(db_copy.parent.iterdir())
    result = _run(runner, ["db", "show", str(db_copy), "gis", "--where", where])
    assert result.exit_code == 2, result.output
    _one_line_error(result, "--where", "on table 'gis'")
    assert _sha(db_copy) == before
    assert sorted(db_copy.parent.iterdir()) == files  # no -journal, -wal or -shm beside it
    assert _count(db_copy, "SELECT COUNT(*) FROM gis") > 0


@pytest.mark.parametrize(
    "where",
    [
        "(SELECT count(*) FROM pragma_table_info('gis')) > 0",
        "load_extension('x') IS NULL",
        "EXISTS (WITH RECURSIVE c(x) AS (SELECT 1 UNION ALL SELECT x + 1 FROM c) SELECT 1 FROM c)",
    ],
)
def test_show_where_may_only_read(runner: CliRunner, db_copy: Path, where: str) -> None:
    """The authorizer refuses what a single expression could still do besides reading rows."""
    before = _sha(db_copy)
    result = _run(runner, ["db", "show", str(db_copy), "gis", "--where", where])
    assert result.exit_code == 2, result.output
    _one_line_error(result, "only a read is allowed")
    assert _sha(db_copy) == before


def test_show_where_may_read_other_tables(runner: CliRunner, sample_db: Path) -> None:
    where = "line_code IN (SELECT line_code FROM balises WHERE kind = 'C')"
    result = _run(runner, ["db", "show", str(sample_db), "lines", "--where", where, "--format", "json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["matched"] == _count(sample_db, f"SELECT COUNT(*) FROM lines WHERE {where}")


def test_show_where_may_end_in_a_comment(runner: CliRunner, sample_db: Path) -> None:
    """The expression sits on lines of its own: a trailing comment cannot eat the closing parenthesis."""
    where = "kind = 'C' -- the C balises only"
    result = _run(runner, ["db", "show", str(sample_db), "balises", "--where", where, "--format", "json"])
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout)["matched"] == _count(sample_db, "SELECT COUNT(*) FROM balises WHERE kind = 'C'")


def test_info_and_show_leave_the_db_as_it_was(runner: CliRunner, db_copy: Path) -> None:
    before, files = _sha(db_copy), sorted(db_copy.parent.iterdir())
    db_copy.chmod(0o444)  # a released DB is read-only: both commands read it all the same
    try:
        for args in (["info", str(db_copy)], ["show", str(db_copy), "gis", "--where", "lat > 0"]):
            result = _run(runner, ["db", *args])
            assert result.exit_code == 0, result.output
    finally:
        db_copy.chmod(0o644)
    assert _sha(db_copy) == before
    assert sorted(db_copy.parent.iterdir()) == files


def test_info_of_a_db_without_a_content_hash(runner: CliRunner, db_copy: Path) -> None:
    with sqlite3.connect(db_copy) as conn:
        conn.execute("DELETE FROM meta WHERE key = 'content_hash'")
    conn.close()
    check = json.loads(_run(runner, ["db", "info", str(db_copy), "--format", "json"]).stdout)["content_hash"]
    assert check["stored"] is None and check["verified"] is False and "no content hash" in check["status"]
    out = _run(runner, ["db", "info", str(db_copy)]).stdout
    assert "cannot be verified" in out and "MODIFIED" not in out


def test_a_file_name_with_uri_characters_is_read_as_named(runner: CliRunner, db_copy: Path) -> None:
    """'#', '?' and '%' are percent-encoded in the read-only URI: the DB named is the DB read
    (unencoded, ``net #1`` would be opened read-write and created, an empty DB)."""
    odd = db_copy.rename(db_copy.parent / "net #1%20?.sqlite")
    files = sorted(odd.parent.iterdir())
    d = json.loads(_run(runner, ["db", "info", str(odd), "--format", "json"]).stdout)
    assert d["content_hash"]["verified"] is True and d["tables"]["gis"] > 0
    shown = _run(runner, ["db", "show", str(odd), "lines", "--format", "json"])
    assert shown.exit_code == 0 and json.loads(shown.stdout)["matched"] == d["tables"]["lines"]
    assert sorted(odd.parent.iterdir()) == files


@pytest.mark.parametrize(
    ("area", "shown"),
    [
        ('{"polygon": [[139.0, 35.0], [140.0, 35.0], [140.0, 36.5]]}', "polygon of 3 vertices, lat 35…36.5°"),
        ('{"lat_min": "south"}', '{"lat_min": "south"}'),
        ("[fix] not JSON", "[fix] not JSON"),
    ],
)
def test_info_shows_the_area_as_it_is_stored(runner: CliRunner, db_copy: Path, area: str, shown: str) -> None:
    with sqlite3.connect(db_copy) as conn:
        conn.execute("UPDATE meta SET value = ? WHERE key = 'area'", (area,))
    conn.close()
    result = _run(runner, ["db", "info", str(db_copy), "--quick"])
    assert result.exit_code == 0, result.output
    assert shown in result.stdout
