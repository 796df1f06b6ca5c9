"""``trainpos logs …`` end to end: exit codes, JSON shapes, no tracebacks on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.tabular import sha256_file
from tests.conftest import DATA
from tests.fieldlogs.make_runs import make_run
from tests.fieldlogs.quality.test_checks import DAMAGES, clean_copy, damage_run


@pytest.fixture(scope="module")
def tiny_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("db") / "tiny.sqlite"
    build_db(DATA / "tiny_sources", out, db_version="t1")
    return out


def invoke(runner: CliRunner, *args: object) -> tuple[int, str, str]:
    res = runner.invoke(app, [str(a) for a in args], env={"COLUMNS": "250"})
    assert res.exception is None or isinstance(res.exception, SystemExit), res.exception
    assert "Traceback" not in res.output
    return res.exit_code, res.stdout, res.stderr


def test_check_clean_run(runner: CliRunner, tmp_path: Path, tiny_db: Path) -> None:
    run = make_run(tmp_path / "r", 3)
    code, out, _ = invoke(runner, "logs", "check", run, "--db", tiny_db)
    assert code == 0 and "0 error(s), 0 warning(s)" in out
    code, out, _ = invoke(runner, "logs", "check", run, "--format", "json")
    assert code == 0 and json.loads(out) == {"ok": True, "runs": [{"run": str(run), "ok": True, "findings": []}]}


def test_check_several_runs_json(runner: CliRunner, tmp_path: Path) -> None:
    good = make_run(tmp_path / "good", 3)
    bad = make_run(tmp_path / "bad", 3, fmt="parquet")
    (bad / "imu.parquet").unlink()
    code, out, _ = invoke(runner, "logs", "check", good, bad, "--format", "json")
    report = json.loads(out)
    assert code == 1 and report["ok"] is False
    assert [r["ok"] for r in report["runs"]] == [True, False]
    (f,) = report["runs"][1]["findings"]
    assert f["rule"] == "log.missing_stream" and f["file"] == str(bad) and f["severity"] == "error"
    assert set(f) >= {"rule", "severity", "table", "keys", "value", "limit", "message", "file"}


def test_check_tables_and_exit_codes(runner: CliRunner, tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 3)
    (run / "tacho.csv").write_text("t,pulses\n0,5\n0.1,2\n", encoding="utf-8")
    code, out, _ = invoke(runner, "logs", "check", run)
    assert code == 1 and f"Check of {run}" in out and "log.pulse_reset" in out and "tacho.csv:3" in out

    code, _, err = invoke(runner, "logs", "check", run, tmp_path / "missing")
    assert code == 2 and "not a run folder" in err and "missing" in err

    code, out, _ = invoke(runner, "logs", "check", tmp_path / "missing", "--format", "json")
    report = json.loads(out)
    assert code == 2 and report["runs"][0]["ok"] is False and "not a run folder" in report["runs"][0]["error"]

    (tmp_path / "not.sqlite").write_text("hello", encoding="utf-8")
    code, _, err = invoke(runner, "logs", "check", run, "--db", tmp_path / "not.sqlite")
    assert code == 2 and "not an SQLite database" in err


def test_check_strict_fails_on_warnings(runner: CliRunner, tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 3)
    (run / "notes.csv").write_text("x\n", encoding="utf-8")
    assert invoke(runner, "logs", "check", run)[0] == 0
    assert invoke(runner, "logs", "check", run, "--strict")[0] == 1


def test_info(runner: CliRunner, tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 10, fmt="parquet")
    code, out, _ = invoke(runner, "logs", "info", run, "--format", "json")
    (info,) = json.loads(out)["runs"]
    assert code == 0
    assert (info["run_id"], info["vehicle_id"], info["vehicle_kind"]) == ("R001", "V01", "train")
    assert info["duration_s"] == pytest.approx(9.99)
    assert info["distance_m"] == pytest.approx(0.25 * 9.9**2, abs=0.05)  # 0.5 m/s² for 9.9 s
    streams = {s["name"]: s for s in info["streams"]}
    assert streams["imu"]["rows"] == 1000 and streams["imu"]["measured_rate_hz"] == pytest.approx(100.0)
    assert streams["balise"]["measured_rate_hz"] is None and streams["tacho"]["format"] == "parquet"
    assert info["gps"] == {"rows": 10, "fix_share": 1.0, "dgps_share": 0.8}
    code, out, _ = invoke(runner, "logs", "info", run)
    assert code == 0 and "R001" in out and "80.0%" in out and "imu" in out
    assert invoke(runner, "logs", "info", tmp_path / "missing")[0] == 2


def test_convert(runner: CliRunner, tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 2)
    code, out, _ = invoke(runner, "logs", "convert", run, "--to", "parquet", "--out", tmp_path / "pq")
    assert code == 0 and (tmp_path / "pq" / "imu.parquet").exists() and "Converted" in out
    code, _, err = invoke(runner, "logs", "convert", run, "--to", "parquet", "--out", tmp_path / "pq")
    assert code == 3 and "--force" in err
    assert invoke(runner, "logs", "convert", run, "--to", "csv", "--out", tmp_path / "pq", "--force")[0] == 0
    assert (tmp_path / "pq" / "imu.csv").exists() and not (tmp_path / "pq" / "imu.parquet").exists()
    assert invoke(runner, "logs", "convert", run, "--to", "csv", "--out", run, "--force")[0] == 3
    assert invoke(runner, "logs", "convert", run, "--to", "xml", "--out", tmp_path / "x")[0] == 2


def test_repair(runner: CliRunner, tmp_path: Path) -> None:
    run = make_run(tmp_path / "r", 3)
    lines = (run / "tacho.csv").read_text(encoding="utf-8").splitlines()
    lines[5], lines[6] = lines[6], lines[5]
    (run / "tacho.csv").write_text("\n".join([*lines, lines[-1]]) + "\n", encoding="utf-8")
    before = {p.name: sha256_file(p) for p in run.iterdir()}
    code, out, _ = invoke(runner, "logs", "repair", run, "--out", tmp_path / "fixed")
    assert code == 0 and "sort_by_t" in out and "drop_duplicate_rows" in out and "0 error(s)" in out
    assert {p.name: sha256_file(p) for p in run.iterdir()} == before
    assert invoke(runner, "logs", "check", tmp_path / "fixed")[0] == 0
    code, _, err = invoke(runner, "logs", "repair", run, "--out", tmp_path / "fixed")
    assert code == 3 and "--force" in err
    code, out, _ = invoke(runner, "logs", "repair", run, "--out", tmp_path / "fixed", "--force", "--format", "json")
    assert code == 0 and json.loads(out)["streams"][0]["actions"][0]["action"] == "sort_by_t"
    assert invoke(runner, "logs", "repair", run, "--out", run, "--force")[0] == 3
    assert invoke(runner, "logs", "repair", tmp_path / "missing", "--out", tmp_path / "x")[0] == 2


def test_repair_exits_1_and_writes_nothing_when_problems_remain(runner: CliRunner, tmp_path: Path) -> None:
    from tests.fieldlogs.quality.test_repair import _with_a_small_pulse_drop

    run = make_run(tmp_path / "r", 10)
    line = _with_a_small_pulse_drop(run)
    code, out, err = invoke(runner, "logs", "repair", run, "--out", tmp_path / "fixed")
    flat = " ".join(err.split())
    assert code == 1 and not (tmp_path / "fixed").exists(), out + err
    assert "log.pulse_decrease" in flat and f"tacho.csv:{line}" in flat and "nothing was written" in flat
    assert "Traceback" not in err
    code, out, _ = invoke(runner, "logs", "repair", run, "--out", tmp_path / "fixed", "--format", "json")
    assert code == 1 and out == ""
    clean = make_run(tmp_path / "c", 3)
    code, out, _ = invoke(runner, "logs", "repair", clean, "--out", tmp_path / "copy", "--strict")
    assert code == 0 and "0 error(s), 0 warning(s)" in out


def test_every_command_has_help(runner: CliRunner) -> None:
    for cmd in ("check", "info", "convert", "repair"):
        code, out, _ = invoke(runner, "logs", cmd, "--help")
        assert code == 0 and "Example: trainpos logs" in out


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    damage=st.sampled_from((*DAMAGES, "run_json")),
    stream=st.sampled_from(["tacho", "imu", "gps", "balise", "cab"]),
    fmt=st.sampled_from(["csv", "parquet"]),
    data=st.data(),
)
def test_damaged_runs_never_crash_the_cli(
    runner: CliRunner, tmp_path_factory: pytest.TempPathFactory, damage: str, stream: str, fmt: str, data: st.DataObject
) -> None:
    folder = clean_copy(tmp_path_factory.mktemp("cli") / "run", fmt)
    if damage == "run_json":
        raw = (folder / "run.json").read_bytes()
        (folder / "run.json").write_bytes(raw[: data.draw(st.integers(0, len(raw) - 1), label="cut")])
        path = folder / "run.json"
    else:
        path = damage_run(folder, damage, stream, data)
    code, out, _ = invoke(runner, "logs", "check", folder, "--format", "json")
    assert code in (0, 1, 2)
    report = json.loads(out)
    assert report["ok"] is (code == 0)
    findings = report["runs"][0]["findings"]
    assert all("file" in f for f in findings)
    if code == 2:
        assert str(path.parent) in report["runs"][0]["error"]
    for cmd in (["info"], ["repair", "--out", folder.parent / "fixed"]):
        code, _, _ = invoke(runner, "logs", *cmd, folder)
        assert code in (0, 1, 2)
