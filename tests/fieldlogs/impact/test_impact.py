"""``db impact`` (issue 19): the sample DB against a hand-edited copy with one balise moved
30 m, through the library and the CLI, and ``db release --impact``."""

from __future__ import annotations

import csv
import json
import os
import shutil
import stat
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.release import impact_file_name, list_impacts, verify_releases
from dbtools.sample_network import sample_source_dir
from fieldlogs.impact.replay import RunFigures
from fieldlogs.impact.report import FIGURES, changed_corrections
from fieldlogs.impact.runner import impact_runs
from tests.pages import check_page

SAMPLE_LOGS = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"
LINE_RUNS = sorted(p for p in SAMPLE_LOGS.iterdir() if (p / "run.json").is_file() and not p.name.startswith("sim-net-"))
MOVED = "0420-D-C001"
MOVE_M = 30.0


@pytest.fixture(scope="module")
def moved_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample sources with balise 0420-D-C001 (a C balise on track D) 30 m further on."""
    root = tmp_path_factory.mktemp("impact")
    src = root / "src"
    shutil.copytree(sample_source_dir(), src)
    path = src / "balises.csv"
    with open(path, newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    for r in rows:
        if r["balise_id"] == MOVED:
            for col in ("km_actual_m", "km_equipment_m"):
                r[col] = str(float(r[col]) + MOVE_M)
    with open(path, "w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    db = root / "moved.sqlite"
    build_db(src, db, db_version="sample-moved")
    return db


@pytest.fixture(scope="module")
def report(sample_db: Path, moved_db: Path) -> dict:
    # the line runs: the sim-net-* runs ride the network source set (the station, crossovers, junction)
    r = impact_runs(sample_db, moved_db, LINE_RUNS, plan=SAMPLE_LOGS / "possessions.csv")
    return r.to_dict()


def test_moved_balise_changes_its_correction_by_the_move(report: dict) -> None:
    runs = {r["run_id"]: r for r in report["runs"]}
    assert report["totals"]["runs"] == len(LINE_RUNS) == 6 and report["totals"]["runs_failed"] == {"old": 0, "new": 0}
    passing = [r for r in runs.values() if any(c["row"] == MOVED for c in r["changed_corrections"])]
    assert len(passing) >= 2
    for r in passing:
        at = next(c for c in r["changed_corrections"] if c["row"] == MOVED)
        # correction = computed km − DB km: the DB km is 30 m larger, the correction 30 m smaller
        assert at["delta_m"] == pytest.approx(-MOVE_M, abs=0.01)
        assert at["new_pct"] > at["old_pct"]
        assert r["delta"]["balise_mean_pct"] > 0 and r["delta"]["n_balise"] == 0
    # runs on the other track never meet the balise: nothing changes for them
    for r in runs.values():
        if r["track"] == "U":
            assert r["changed_corrections"] == [] and all(v in (None, 0, 0.0) for v in r["delta"].values())


def test_route_figures_are_over_the_route_corrections(report: dict) -> None:
    routes = {(r["line_code"], r["track"], r["direction"]): r for r in report["routes"]}
    d = routes[("0420", "D", "down")]
    assert set(d["old"]) == set(FIGURES)
    assert d["new"]["n_balise"] == d["old"]["n_balise"] and d["delta"]["balise_max_pct"] > 5
    # refusals by diagnostic: the route's runs summed, per version
    summed: dict[str, int] = {}
    for r in report["runs"]:
        if (r["line_code"], r["track"], r["direction"]) == ("0420", "D", "down"):
            for diag, n in r["refusals"]["old"].items():
                summed[diag] = summed.get(diag, 0) + n
    assert d["refusals"]["old"] == summed and sum(summed.values()) >= d["old"]["n_refused"] > 0
    rr = next(r for r in report["runs"] if r["vehicle_kind"] == "road_rail")
    assert rr["alarms"]["old"] is not None and rr["new"]["n_alarms"] == rr["old"]["n_alarms"]


def test_same_content_changes_nothing(sample_db: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy.sqlite"
    shutil.copyfile(sample_db, copy)
    d = impact_runs(sample_db, copy, [SAMPLE_LOGS / "sim-u-evening"]).to_dict()
    assert d["same_content"] and d["totals"]["runs_changed"] == 0 and d["totals"]["corrections_changed"] == 0


def test_changed_corrections_by_hand() -> None:
    def figs(*rows: tuple[str, str, float, float | None]) -> RunFigures:
        cols = ("type", "row", "t", "correction_m")
        return RunFigures(
            True, corrections=[{**dict(zip(cols, r, strict=True)), "km_m": 0.0, "correction_pct": 0.1} for r in rows]
        )

    old = figs(("balise_correction", "B1", 10.0, 0.4), ("balise_correction", "B2", 50.0, 0.2))
    new = figs(("balise_correction", "B1", 10.0, 0.405), ("feature_correction", "F1", 30.0, 1.0))
    ch = {c["row"]: c for c in changed_corrections(old, new)}
    assert set(ch) == {"B2", "F1"}  # B1 moved 5 mm: below the tolerance
    assert ch["B2"]["new_m"] is None and ch["F1"]["old_m"] is None and ch["F1"]["delta_m"] is None


def test_cli_json_html_and_refusals(runner: CliRunner, sample_db: Path, moved_db: Path, tmp_path: Path) -> None:
    run = str(SAMPLE_LOGS / "sim-d-evening")
    res = runner.invoke(app, ["db", "impact", str(sample_db), str(moved_db), run, "--format", "json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout[res.stdout.index("{") :])
    assert data["totals"]["corrections_changed"] >= 1
    page = tmp_path / "impact.html"
    res = runner.invoke(
        app, ["db", "impact", str(sample_db), str(moved_db), run, "--format", "html", "--out", str(page)]
    )
    assert res.exit_code == 0, res.output
    html = page.read_text(encoding="utf-8")
    assert "Impact of a new DB version" in html and MOVED in html and "data:image/png;base64" in html
    res = runner.invoke(app, ["db", "impact", str(sample_db), str(moved_db), run, "--out", str(page)])
    assert res.exit_code == 3
    res = runner.invoke(app, ["db", "impact", str(sample_db), str(moved_db), run, "--format", "html"])
    assert res.exit_code == 2 and "--out" in res.output
    res = runner.invoke(app, ["db", "impact", str(sample_db), str(tmp_path / "none.sqlite"), run])
    assert res.exit_code == 2


def test_release_with_impact(runner: CliRunner, sample_db: Path, moved_db: Path, tmp_path: Path) -> None:
    reg = tmp_path / "releases"
    run = str(SAMPLE_LOGS / "sim-d-evening")
    res = runner.invoke(app, ["db", "release", str(moved_db), "--registry", str(reg), "--impact", run])
    assert res.exit_code == 2 and "needs a release in the registry" in res.output  # nothing to compare with
    assert runner.invoke(app, ["db", "release", str(sample_db), "--registry", str(reg)]).exit_code == 0
    assert list_impacts(reg) == {}  # a registry without impact reports reads as before
    res = runner.invoke(app, ["db", "release", str(moved_db), "--registry", str(reg), "--impact", run])
    assert res.exit_code == 0, res.output
    path = reg / impact_file_name("sample-moved")
    assert stat.S_IMODE(path.stat().st_mode) == 0o444
    stored = json.loads(path.read_text(encoding="utf-8"))
    assert stored["old"]["db_version"] == "sample-test" and stored["new"]["db_version"] == "sample-moved"
    row = list_impacts(reg)["sample-moved"]
    assert row["against_version"] == "sample-test" and row["runs"] == 1 and row["runs_changed"] == 1
    assert verify_releases(reg).ok
    os.chmod(path, 0o644)
    path.write_text("{}", encoding="utf-8")
    report = verify_releases(reg)
    assert not report.ok and report.failed("sample-moved")
    assert any(f.rule == "release.impact" for f in report.findings)


def test_page_standard_in_the_browser(
    runner: CliRunner, sample_db: Path, moved_db: Path, browser: Any, tmp_path: Path
) -> None:
    """The rendering standard (tests/pages.py) on the impact page: verdict first, no sideways
    scroll, sticky headers, the bar chart's axes named with units."""
    page = tmp_path / "impact.html"
    runs = [str(SAMPLE_LOGS / "sim-d-evening")]
    res = runner.invoke(
        app, ["db", "impact", str(sample_db), str(moved_db), *runs, "--format", "html", "--out", str(page)]
    )
    assert res.exit_code == 0, res.output
    seen = check_page(browser, page, tmp_path / "shots")
    assert seen["verdict"].startswith("Changes: ") and seen["plots"] == 1
