"""``trainpos audit``, ``trainpos report`` and ``trainpos demo`` (thin CLI over fieldlogs.audit.runner/report)."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner, Result

import cli.demo as demo_mod
from cli.main import app
from tests.fieldlogs.audit.audit_data import RUNS, AuditData, audit_data

N = len(RUNS)


@pytest.fixture(scope="session")
def data(tmp_path_factory: pytest.TempPathFactory) -> AuditData:
    return audit_data(tmp_path_factory)


@pytest.fixture(scope="module")
def audited(data: AuditData, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("cli-audit") / "audit.sqlite"
    res = invoke("audit", data.logs, "--db", data.db, "--out", out, "--workers", "1")
    assert res.exit_code == 0, res.output
    return out


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args])


def test_commands_are_registered_with_help() -> None:
    res = invoke("--help")
    for name in ("run", "audit", "report", "demo"):
        assert name in res.output
        sub = invoke(name, "--help")
        assert sub.exit_code == 0 and "Example:" in sub.output


def test_audit_prints_progress_and_summary_and_exits_1_on_failed_runs(data: AuditData, tmp_path: Path) -> None:
    logs = data.copy_logs(tmp_path / "logs")
    bad = logs / "broken"
    shutil.copytree(logs / RUNS[0][0], bad)
    (bad / "run.json").write_text("[1, 2", encoding="utf-8")
    out = tmp_path / "audit.sqlite"
    res = invoke("audit", logs, "--db", data.db, "--out", out, "-j", "2")
    assert res.exit_code == 1, res.output
    assert "Traceback" not in res.output + res.stderr
    assert "runs/s" in res.stderr and f"{N + 1}/{N + 1}" in res.stderr  # Rich bar: count, rate, ETA
    assert "audited" in res.stdout and "runs/min" in res.stdout
    assert f"failed: {bad.resolve()}" in res.stderr and "run.json" in res.stderr
    shutil.rmtree(bad)
    res = invoke("audit", logs, "--db", data.db, "--out", out, "-j", "2")
    assert res.exit_code == 0, res.output
    assert "skipped (unchanged)" in res.stdout and f"│ {N} " in res.stdout
    assert "Traceback" not in res.output + res.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--db", "{tmp}/missing.sqlite"], "missing.sqlite"),
        (["--db", "{db}", "--config", "{tmp}/nope.toml"], "no such config file"),
        (["--db", "{logs}"], "logs"),
    ],
)
def test_audit_unreadable_inputs_exit_2_with_one_line(
    data: AuditData, tmp_path: Path, args: list[str], message: str
) -> None:
    fill = {"tmp": str(tmp_path), "db": str(data.db), "logs": str(data.logs)}
    res = invoke("audit", data.logs, "--out", tmp_path / "a.sqlite", *[a.format(**fill) for a in args])
    assert res.exit_code == 2, res.output
    assert message in res.stderr and "Traceback" not in res.stderr
    res = invoke("audit", tmp_path / "no-logs", "--db", data.db, "--out", tmp_path / "a.sqlite")
    assert res.exit_code == 2 and "no such folder" in res.stderr


def test_report_formats(audited: Path, tmp_path: Path) -> None:
    res = invoke("report", audited, "--format", "json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    assert {r["track"] for r in data["routes"]} == {"D", "U"}
    assert len(data["runs"]) == N and data["failed_runs"] == []
    assert sum(r["n_runs"] for r in data["routes"]) == N
    res = invoke("report", audited, "--format", "json", "--target-pct", "0.1", "--out", tmp_path / "r.json")
    assert res.exit_code == 0 and json.loads((tmp_path / "r.json").read_text())["target_pct"] == 0.1

    res = invoke("report", audited, "--format", "csv", "--by", "run")
    assert res.exit_code == 0
    lines = res.stdout.strip().splitlines()
    assert (
        lines[0].startswith("run_path,run_id,vehicle_id,unit,track_id,line_code,track,direction")
        and len(lines) == N + 1
    )

    res = invoke("report", audited, "--by", "vehicle")
    assert res.exit_code == 0 and "EMU-01" in res.stdout and "EMU-02" in res.stdout
    res = invoke("report", audited)
    assert res.exit_code == 0 and "Position correction by route" in res.stdout and "down" in res.stdout
    res = invoke("report", audited, "--out", tmp_path / "r.txt")
    assert res.exit_code == 0 and "Slips, feature points" in (tmp_path / "r.txt").read_text(encoding="utf-8")

    res = invoke("report", audited, "--format", "html")
    assert res.exit_code == 2 and "--out" in res.stderr
    res = invoke("report", audited, "--format", "html", "--out", tmp_path / "r.html")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "r.html").read_text(encoding="utf-8").count("data:image/png;base64,") >= 5


def test_report_refuses_what_is_not_an_audit_db(data: AuditData, tmp_path: Path) -> None:
    res = invoke("report", data.db)
    assert res.exit_code == 2 and "not a trainpos audit database" in res.stderr
    res = invoke("report", tmp_path / "nope.sqlite")
    assert res.exit_code == 2 and "no such audit database" in res.stderr


def test_demo_on_fixture_network_and_logs(data: AuditData, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(demo_mod, "sample_logs_dir", lambda: data.logs)
    monkeypatch.setattr(demo_mod, "sample_source_dir", lambda: data.sources)
    out = tmp_path / "demo"
    for _ in range(2):  # a second demo replaces the first one's outputs
        res = invoke("demo", "--out", out, "-j", "1")
        assert res.exit_code == 0, res.output + res.stderr
        assert f"audited {N} runs (0 failed)" in res.stdout
        assert "Position correction by route" in res.stdout and "HTML report" in res.stdout
        legend = res.stdout.split("What the columns mean", 1)[1]  # every term, one line each (issue 33)
        assert "share above target" in legend and "GPS trusted share" in legend and "share [%]" not in legend
    assert (out / "sample-network.sqlite").is_file() and (out / "audit.sqlite").is_file()
    assert (out / "report.html").read_text(encoding="utf-8").count("<img") >= 5

    monkeypatch.setattr(demo_mod, "sample_logs_dir", lambda: tmp_path / "missing")
    res = invoke("demo", "--out", out)
    assert res.exit_code == 2 and "sample logs are missing" in res.stderr


@pytest.mark.parametrize("columns", ["80", None])
def test_report_table_piped_at_80_columns(audited: Path, columns: str | None) -> None:
    """``trainpos report`` piped (not a terminal), at 80 columns or with no width given: every
    table keeps its borders or is printed as records, the columns under their labels with
    units, the shares as %, and every figure of the JSON report printed whole."""
    env = {"COLUMNS": columns} if columns else {}
    res = CliRunner().invoke(app, ["report", str(audited), "--by", "run"], env=env)
    assert res.exit_code == 0, res.output
    text = res.stdout
    for line in text.splitlines():
        assert len(line) <= 80, line
        if line.startswith(("│", "┃")):
            assert line.rstrip().endswith(("│", "┃")), line
    assert "mean correction [%]" in text and "GPS trusted share:" in text
    assert "share [%]" not in text and "_pct" not in text
    csv = invoke("report", audited, "--format", "csv", "--by", "run").stdout  # the same rows, machine names
    runs = pd.read_csv(io.StringIO(csv)).to_dict("records")
    words = {w for line in text.splitlines() for w in line.replace("│", " ").replace("┃", " ").split()}
    for r in runs:
        assert r["run_id"] in words and f"{round(r['mean_correction_pct'], 3):.4g}" in words, r["run_id"]
        assert f"{100 * round(r['gps_trusted_share'], 3):.1f}" in words
