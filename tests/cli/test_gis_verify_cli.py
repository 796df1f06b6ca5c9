"""``trainpos gis verify`` through the CLI: defects → exit 1, proposal → db build → db diff,
JSON/HTML/table output, usage errors and refusals."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cli.main import app
from schemas.units import parse_km
from tests.dbtools.gis_verify_data import DEFECT_KM, DEFECT_TRACK, LINE, VerifyData, verify_data
from tests.pages import check_page


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> VerifyData:
    return verify_data(tmp_path_factory)


def invoke(runner: CliRunner, *args: str):  # type: ignore[no-untyped-def]
    return runner.invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


def test_defect_html_proposal_build_and_diff(runner: CliRunner, data: VerifyData, tmp_path: Path) -> None:
    html, prop = tmp_path / "gis.html", tmp_path / "src-fixed"
    r = invoke(
        runner, "gis", "verify", data.surveyed_db, data.logs, "--format", "html", "--out", html, "--propose", prop
    )
    assert r.exit_code == 1, r.output  # defects found
    text = html.read_text(encoding="utf-8")
    assert "data:image/png;base64," in text and "<h2>Defects</h2>" in text and "http" not in text.split("<body>")[1]
    assert f"proposed source set written to {prop}" in r.output

    new_db = tmp_path / "fixed.sqlite"
    b = invoke(runner, "db", "build", prop, "--out", new_db, "--version", "fixed")
    assert b.exit_code == 0, b.output
    d = invoke(runner, "db", "diff", data.surveyed_db, new_db)
    assert d.exit_code == 0, d.output
    moved = re.findall(rf"GIS {LINE} {DEFECT_TRACK} km (\S+)–(\S+): (\d+) points moved", d.output)
    assert len(moved) == 1, d.output  # one stretch moved, nothing else
    lo, hi, _n = moved[0]
    assert abs(parse_km(lo) - DEFECT_KM[0]) <= 40 and abs(parse_km(hi) - DEFECT_KM[1]) <= 40

    # the corrected DB verifies clean
    again = invoke(runner, "gis", "verify", new_db, data.logs, "--format", "json")
    assert again.exit_code == 0, again.output
    assert json.loads(again.stdout)["defects"] == []


def test_json_shape_on_correct_grid(runner: CliRunner, data: VerifyData) -> None:
    runs = data.runs[:2] + data.runs[-2:]
    r = invoke(runner, "gis", "verify", data.truth_db, *runs, "--format", "json")
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert {"db", "db_version", "evidence", "runs", "config", "counts", "km_residual", "coverage", "defects"} <= set(
        out
    )
    assert {"proposal", "cells"} <= set(out)
    assert out["db_version"] == "truth" and len(out["runs"]) == 4 and out["defects"] == []
    cov = {(c["line_code"], c["track"]): c for c in out["coverage"]}
    assert set(cov) == {(LINE, "D"), (LINE, "U")}
    for c in cov.values():
        total = c["verified_km"] + c["unverified_km"] + c["defect_km"]
        assert total == pytest.approx(c["length_km"])
    statuses = {c["status"] for c in out["cells"]}
    assert statuses <= {"verified", "unverified"}


def test_table_with_too_few_runs_is_unverified(runner: CliRunner, data: VerifyData) -> None:
    r = invoke(runner, "gis", "verify", data.surveyed_db, data.runs[0], data.runs[1])
    assert r.exit_code == 0, r.output  # two runs cannot show a defect
    assert "Coverage" in r.output and "GIS verification" in r.output
    assert "unverified" in r.output and "Defects" not in r.output


def test_html_of_a_mostly_unverified_grid_is_not_green(runner: CliRunner, data: VerifyData, tmp_path: Path) -> None:
    """Issue 15: "No defect found" never shows in green while most of the line is unverified."""
    html = tmp_path / "gis.html"
    r = invoke(runner, "gis", "verify", data.surveyed_db, data.runs[0], data.runs[1], "--format", "html", "--out", html)
    assert r.exit_code == 0, r.output
    text = html.read_text(encoding="utf-8")
    assert "class='verdict ok'" not in text
    assert "<p id='verdict' class='verdict caution'>Mostly unverified: no defect found where the evidence" in text
    assert f"line {LINE}: " in text and "km unverified" in text


def test_usage_errors_and_refusals(runner: CliRunner, data: VerifyData, tmp_path: Path) -> None:
    r = invoke(runner, "gis", "verify", data.truth_db, data.runs[0], "--format", "html")
    assert r.exit_code == 2 and "--format html needs --out" in r.output
    r = invoke(runner, "gis", "verify", tmp_path / "none.sqlite", data.runs[0])
    assert r.exit_code == 2
    empty = tmp_path / "empty"
    empty.mkdir()
    r = invoke(runner, "gis", "verify", data.truth_db, empty)
    assert r.exit_code == 2 and "no run folders" in r.output
    broken = tmp_path / "logs" / "broken"
    shutil.copytree(data.runs[0], broken)
    (broken / "run.json").write_text('{"run_id": "broken"}', encoding="utf-8")  # no vehicle, wheel, …
    r = invoke(runner, "gis", "verify", data.truth_db, data.runs[1], tmp_path / "logs")
    assert r.exit_code == 2 and "broken" in r.output and "run cannot be used" in r.output  # not 1 (= defects)
    busy = tmp_path / "busy"
    busy.mkdir()
    (busy / "gis.csv").write_text("x\n")
    r = invoke(runner, "gis", "verify", data.truth_db, data.runs[0], "--propose", busy)
    assert r.exit_code == 3 and "--force" in r.output
    assert (busy / "gis.csv").read_text() == "x\n"


def test_help_documents_exit_codes_and_json() -> None:
    r = CliRunner().invoke(app, ["gis", "verify", "--help"], env={"COLUMNS": "200"})
    assert r.exit_code == 0
    assert "Exit codes" in r.output and "coverage" in r.output and "Example" in r.output


def test_options_default_to_the_config_and_override_it(runner: CliRunner, data: VerifyData, tmp_path: Path) -> None:
    """[gis_verify] of --config sets the thresholds; an option on the command line wins."""
    runs = data.runs[:2] + data.runs[-2:]
    cfg = tmp_path / "suite.toml"
    cfg.write_text("[gis_verify]\nmin_runs = 40\nscan = false\n[odometry]\nta_kmh_s = 1.23\n", encoding="utf-8")
    r = invoke(runner, "gis", "verify", data.truth_db, *runs, "--format", "json", "--config", cfg)
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["config"]["min_runs"] == 40 and out["config"]["scan"] is False
    assert {c["reason"] for c in out["cells"]} == {"fewer than 40 runs"}
    r = invoke(runner, "gis", "verify", data.truth_db, *runs, "--format", "json", "--config", cfg, "--min-runs", "2")
    assert json.loads(r.stdout)["config"]["min_runs"] == 2
    bad = tmp_path / "bad.toml"
    bad.write_text("[gis_verify]\nscan_correction = 'max'\n", encoding="utf-8")
    r = invoke(runner, "gis", "verify", data.truth_db, *runs, "--config", bad)
    assert r.exit_code == 2 and "'gis_verify.scan_correction' = 'max' is not one of" in r.output
    r = invoke(runner, "config", "show", "--section", "gis_verify")
    assert r.exit_code == 0 and "scan_windows_m = [100.0, 140.0, 200.0, 300.0, 400.0, 500.0]" in r.output


def test_page_standard_in_the_browser(runner: CliRunner, data: VerifyData, browser: Any, tmp_path: Path) -> None:
    """The rendering standard (tests/pages.py) on the GIS-verify page: verdict first, no
    sideways scroll, sticky headers (the long cells table scrolls under its header), every
    plot's axes named with units."""
    html = tmp_path / "gis.html"
    r = invoke(runner, "gis", "verify", data.surveyed_db, data.logs, "--format", "html", "--out", html)
    assert r.exit_code == 1, r.output
    seen = check_page(browser, html, tmp_path / "shots")
    assert seen["verdict"].startswith("Failed: ") and seen["plots"] >= 1
