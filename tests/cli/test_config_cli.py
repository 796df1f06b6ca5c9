"""``trainpos config show``: every setting documented; its output is a config that changes nothing."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from fieldlogs.config import SuiteConfig, section_names
from fieldlogs.pipeline.config import PipelineConfig
from schemas.settings import undocumented


def test_every_setting_has_a_meaning() -> None:
    assert undocumented(SuiteConfig()) == []


def test_show_fed_back_changes_nothing(runner: CliRunner, tmp_path: Path) -> None:
    res = runner.invoke(app, ["config", "show"])
    assert res.exit_code == 0, res.output
    path = tmp_path / "all.toml"
    path.write_text(res.output, encoding="utf-8")
    assert SuiteConfig.from_toml(path) == SuiteConfig()
    assert PipelineConfig.from_toml(path) == PipelineConfig()
    data = tomllib.loads(res.output)
    assert set(section_names(SuiteConfig())) <= set(data)
    # every setting appears, with a comment line above it naming its meaning
    lines = res.output.splitlines()
    for i, line in enumerate(lines):
        if " = " in line and not line.startswith("#"):
            assert lines[i - 1].startswith("# "), line


def test_a_shown_non_default_config_reads_back_identically(runner: CliRunner, tmp_path: Path) -> None:
    src = tmp_path / "mine.toml"
    src.write_text("[odometry]\nta_kmh_s = 1.5\n[gps]\nwindows_s = [5, 20]\nrms_threshold_m = [2.4, 1.7]\n")
    res = runner.invoke(app, ["config", "show", "--config", str(src)])
    assert res.exit_code == 0, res.output
    back = tmp_path / "back.toml"
    back.write_text(res.output, encoding="utf-8")
    assert SuiteConfig.from_toml(back) == SuiteConfig.from_toml(src)
    assert PipelineConfig.from_toml(back).odometry.ta_kmh_s == 1.5


def test_one_section_as_toml_and_json(runner: CliRunner) -> None:
    res = runner.invoke(app, ["config", "show", "--section", "balise"])
    assert res.exit_code == 0
    assert tomllib.loads(res.output) == {
        "balise": {"pair_max_travel_m": 10.0, "id_window_m": 500.0, "fix_uncertainty_m": 1.0, "latency_budget_s": 0.1}
    }
    assert "# C-balise identification window around dist_from_initial_m ([m], > 0)" in res.output
    res = runner.invoke(app, ["config", "show", "--section", "odometry", "--format", "json"])
    data = json.loads(res.output)
    assert data["odometry"]["ta_kmh_s"] == {
        "value": 1.23,
        "unit": "km/h/s",
        "meaning": "detection threshold Ta on |a_x − A_p|, eq. 1 (gravity of 35 ‰)",
        "range": "> 0",
    }


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--section", "odometri"], "no config section 'odometri' (known: odometry"),
        (["--config", "missing.toml"], "no such config file"),
    ],
)
def test_bad_usage_is_exit_2(runner: CliRunner, args: list[str], message: str) -> None:
    res = runner.invoke(app, ["config", "show", *args])
    assert res.exit_code == 2
    assert message in res.output


def test_out_of_range_config_is_refused_by_run(runner: CliRunner, tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[odometry]\nta_kmh_s = -1\n")
    res = runner.invoke(
        app,
        ["run", str(tmp_path), "--db", str(tmp_path / "x.sqlite"), "--out", str(tmp_path / "o"), "--config", str(cfg)],
    )
    assert res.exit_code == 2
    assert "'odometry.ta_kmh_s' = -1.0 km/h/s is out of range (allowed: > 0)" in res.output
