"""``db validate --format sarif|junit``: SARIF validated against the OASIS SARIF 2.1.0 JSON
schema (tests/data/sarif, with attribution), locations for source sets and DBs, JUnit XML."""

from __future__ import annotations

import json
import shutil
import sqlite3
import xml.etree.ElementTree as ET
from pathlib import Path

import jsonschema
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.sample_network import sample_source_dir

SCHEMA = json.loads(
    (Path(__file__).resolve().parents[2] / "data" / "sarif" / "sarif-schema-2.1.0.json").read_text(encoding="utf-8")
)


def _run(*args: object) -> tuple[int, str]:
    r = CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "400"})
    return r.exit_code, r.stdout


@pytest.fixture
def broken_sources(tmp_path: Path) -> Path:
    src = tmp_path / "src"
    shutil.copytree(sample_source_dir(), src)
    path = src / "balises.csv"
    lines = path.read_text(encoding="utf-8").splitlines()
    lines[1] = lines[1].replace(",I1,", ",X9,")  # file line 2: an unknown kind
    lines[3] = lines[3].replace("18485.0,18485.0", "18495.0,18495.0")  # file line 4: pair 15 m apart
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return src


def test_sarif_of_a_source_set_validates_and_points_at_file_line_column(broken_sources: Path) -> None:
    code, out = _run("db", "validate", broken_sources, "--format", "sarif")
    assert code == 1
    log = json.loads(out)
    jsonschema.Draft4Validator(SCHEMA).validate(log)
    run = log["runs"][0]
    rules = [r["id"] for r in run["tool"]["driver"]["rules"]]
    results = run["results"]
    assert all(rules[r["ruleIndex"]] == r["ruleId"] for r in results)
    kind = next(r for r in results if r["ruleId"] == "schema.enum")
    assert kind["level"] == "error" and kind["properties"]["column"] == "kind"
    region = kind["locations"][0]["physicalLocation"]["region"]
    uri = kind["locations"][0]["physicalLocation"]["artifactLocation"]["uri"]
    assert uri.endswith("balises.csv") and region["startLine"] == 2
    line = (broken_sources / "balises.csv").read_text(encoding="utf-8").splitlines()[1]
    assert line[region["startColumn"] - 1 : region["endColumn"] - 1] == "X9"
    assert {r["level"] for r in results} <= {"error", "warning"}


def test_sarif_of_a_db_uses_logical_locations(sample_db: Path, tmp_path: Path) -> None:
    db = tmp_path / "edited.sqlite"
    shutil.copy(sample_db, db)
    con = sqlite3.connect(db)
    con.execute("UPDATE balises SET km_actual_m = km_actual_m + 15 WHERE balise_id = '0420-02-D-I2'")
    con.commit()
    con.close()
    code, out = _run("db", "validate", db, "--format", "sarif")
    assert code == 1
    log = json.loads(out)
    jsonschema.Draft4Validator(SCHEMA).validate(log)
    results = log["runs"][0]["results"]
    assert any(r["ruleId"] == "db.content_hash" for r in results)
    pair = next(r for r in results if r["ruleId"].startswith("balise.pair"))
    loc = pair["locations"][0]
    assert loc["physicalLocation"]["artifactLocation"]["uri"].endswith("edited.sqlite")
    assert loc["logicalLocations"][0]["name"].startswith("balises/")


def test_sarif_of_a_clean_db_validates(sample_db: Path) -> None:
    code, out = _run("db", "validate", sample_db, "--format", "sarif")
    assert code == 0
    log = json.loads(out)
    jsonschema.Draft4Validator(SCHEMA).validate(log)
    assert log["runs"][0]["results"] == []


def test_junit(broken_sources: Path, sample_db: Path) -> None:
    code, out = _run("db", "validate", broken_sources, "--format", "junit")
    assert code == 1
    suite = ET.fromstring(out).find("testsuite")
    assert suite is not None
    cases = suite.findall("testcase")
    failures = [c for c in cases if c.find("failure") is not None]
    assert int(suite.get("tests", "0")) == len(cases) and int(suite.get("failures", "0")) == len(failures) > 1
    assert any("balises.csv:2" in (c.find("failure").text or "") for c in failures)  # type: ignore[union-attr]
    code, out = _run("db", "validate", sample_db, "--format", "junit")
    suite = ET.fromstring(out).find("testsuite")
    assert code == 0 and suite is not None and suite.get("failures") == "0"
