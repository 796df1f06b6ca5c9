"""``db validate --format sarif|junit``: SARIF validated against the OASIS SARIF 2.1.0 JSON
schema (tests/data/sarif, with attribution), locations for source sets and DBs, JUnit XML."""

from __future__ import annotations

import json
import shutil
import sqlite3
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import jsonschema
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.interchange.ci import db_source_files, rule_descriptor, sarif
from dbtools.rules.catalogue import plain, rule_catalogue
from dbtools.sample_network import sample_source_dir
from schemas.enums import Severity
from schemas.findings import Finding

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


def _sarif(*args: object) -> dict[str, Any]:
    code, out = _run("db", "validate", *args, "--format", "sarif")
    assert code in (0, 1), out
    log: dict[str, Any] = json.loads(out)
    jsonschema.Draft4Validator(SCHEMA).validate(log)
    return log


def test_sarif_describes_every_rule_from_the_catalogue(broken_sources: Path) -> None:
    run = _sarif(broken_sources)["runs"][0]
    rules = run["tool"]["driver"]["rules"]
    catalogue = rule_catalogue()
    assert {r["id"] for r in rules} >= {"schema.enum", "balise.dist_from_initial"}
    for r in rules:
        doc = catalogue[r["id"]]
        assert r["shortDescription"]["text"] == doc.summary
        assert r["fullDescription"]["text"] and "Fix" not in r["fullDescription"]["text"]
        assert "**Fix:**" in r["help"]["markdown"] and "``" not in r["help"]["markdown"]
        assert r["help"]["text"].endswith(plain(doc.fix))
        assert r["helpUri"] == f"docs/reference/rules.md#{r['id']}"
    balise = [r["shortDescription"]["text"] for r in rules if r["id"].startswith("balise.")]
    assert len(balise) == len(set(balise)) >= 1
    assert "informationUri" not in run["tool"]["driver"]  # absolute only


def test_every_balise_rule_has_its_own_description() -> None:
    descriptors = [rule_descriptor(r) for r in rule_catalogue() if r.startswith("balise.")]
    assert len({d["shortDescription"]["text"] for d in descriptors}) == len(descriptors) > 10
    assert all(d["defaultConfiguration"]["level"] in ("error", "warning") for d in descriptors)


def test_help_uri_base_from_the_option_and_the_environment(broken_sources: Path, monkeypatch: Any) -> None:
    run = _sarif(broken_sources, "--help-uri-base", "https://example.org/trainpos/blob/main")["runs"][0]
    uris = {r["helpUri"] for r in run["tool"]["driver"]["rules"]}
    assert "https://example.org/trainpos/blob/main/docs/reference/rules.md#schema.enum" in uris
    assert run["tool"]["driver"]["informationUri"] == "https://example.org/trainpos/blob/main/docs/reference/rules.md"
    monkeypatch.setenv("TRAINPOS_HELP_URI_BASE", "https://docs.example.org/")
    run = _sarif(broken_sources)["runs"][0]
    assert run["tool"]["driver"]["rules"][0]["helpUri"].startswith("https://docs.example.org/docs/reference/rules.md#")


def _artifacts(run: dict[str, Any]) -> list[dict[str, Any]]:
    return [loc["physicalLocation"]["artifactLocation"] for r in run["results"] for loc in r["locations"]]


def test_uris_are_relative_to_a_declared_base(broken_sources: Path, tmp_path: Path, monkeypatch: Any) -> None:
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # the source set lies outside the working folder
    run = _sarif(broken_sources)["runs"][0]
    artifacts = _artifacts(run)
    assert len(artifacts) == len(run["results"])  # every result located
    assert artifacts and all(a["uriBaseId"] == "TARGETROOT" and ":" not in a["uri"] for a in artifacts)
    assert "balises.csv" in {a["uri"] for a in artifacts}
    assert run["originalUriBaseIds"] == {"TARGETROOT": {"uri": broken_sources.resolve().as_uri() + "/"}}
    monkeypatch.chdir(tmp_path)  # now inside it
    run = _sarif(broken_sources)["runs"][0]
    assert {a["uriBaseId"] for a in _artifacts(run)} == {"%SRCROOT%"}
    assert "src/balises.csv" in {a["uri"] for a in _artifacts(run)}
    assert run["originalUriBaseIds"] == {"%SRCROOT%": {"uri": tmp_path.resolve().as_uri() + "/"}}


def test_a_whole_network_finding_of_a_source_set_names_the_table_file(tmp_path: Path) -> None:
    f = Finding("topology.gap", Severity.ERROR, "connections", "far apart", keys={"connection_id": "C1"})
    (tmp_path / "connections.csv").write_text("connection_id\nC1\n", encoding="utf-8")
    loc = sarif([f], target=tmp_path, cwd=tmp_path)["runs"][0]["results"][0]["locations"][0]
    assert loc["physicalLocation"]["artifactLocation"] == {"uri": "connections.csv", "uriBaseId": "%SRCROOT%"}
    assert loc["logicalLocations"][0]["name"] == "connections/connection_id=C1"


def test_a_db_finding_is_located_in_the_db_and_its_source_file(sample_db: Path, tmp_path: Path) -> None:
    db = tmp_path / "edited.sqlite"
    shutil.copy(sample_db, db)
    con = sqlite3.connect(db)
    con.execute("UPDATE balises SET km_actual_m = km_actual_m + 15 WHERE balise_id = '0420-02-D-I2'")
    con.commit()
    con.close()
    run = _sarif(db)["runs"][0]
    assert run["results"] and all("physicalLocation" in r["locations"][0] for r in run["results"])
    pair = next(r for r in run["results"] if r["ruleId"].startswith("balise.pair"))
    assert pair["locations"][0]["physicalLocation"]["artifactLocation"] == {
        "uri": "edited.sqlite",
        "uriBaseId": "TARGETROOT",
    }
    assert pair["locations"][0]["logicalLocations"][0]["name"].startswith("balises/")
    (related,) = pair["relatedLocations"]
    assert related["physicalLocation"]["artifactLocation"] == {"uri": "balises.csv", "uriBaseId": "SOURCESET"}
    assert db_source_files(db)["balises"] == "balises.csv"
    assert db_source_files(tmp_path / "missing.sqlite") == {}
