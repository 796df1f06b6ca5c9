"""``trainpos gnss position``: JSON and table output on a simulated run, the track from the
pipeline or given, the paper's sky mask, and the documented exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner, Result

from cli.main import app
from dbtools.build import build_db
from dbtools.database import read_network
from fieldlogs.runs.handle import read_run
from tests.fieldlogs.gnss.runs import simulate_gnss_run

SAMPLE_LOGS = Path(__file__).resolve().parents[2] / "fieldlogs" / "sample_logs"


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


@pytest.fixture(scope="module")
def run_dir(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return simulate_gnss_run(read_network(sample_db), tmp_path_factory.mktemp("cli") / "run", seed=8, length_m=2500.0)


def test_json_on_the_pipelines_track(run_dir: Path, sample_db: Path) -> None:
    res = invoke("gnss", "position", run_dir, "--db", sample_db, "--format", "json")
    assert res.exit_code == 0, res.output
    doc = json.loads(res.output)
    assert (doc["line_code"], doc["track"], doc["track_source"]) == ("0420", "D", "pipeline")
    assert (doc["facing"], doc["facing_source"]) == ("increasing_km", "pipeline")
    a = doc["availability"]
    assert a["constrained"] > 0.95 and set(a["by_receiver"]) == {"rx1", "rx2"}
    e = doc["epochs"][0]
    for key in ("t", "receiver", "status", "km_m", "uncertainty_m", "residual_rms_m", "used", "excluded", "not_used",
                "lsq_available", "lsq_pdop", "lsq_offset_m"):  # fmt: skip
        assert key in e
    truth = read_run(run_dir).stream("truth")
    assert truth is not None
    ok = [x for x in doc["epochs"] if x["available"]]
    err = np.array([x["km_m"] for x in ok]) - np.interp([x["t"] for x in ok], truth["t"], truth["km_m"])
    assert np.median(np.abs(err)) < 1.5


def test_the_west_half_blocked_constrained_beats_unconstrained(run_dir: Path, sample_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "west.json"
    res = invoke("gnss", "position", run_dir, "--db", sample_db, "--line", "0420", "--track", "D",
                 "--sky-mask", "west-half", "--systems", "G", "--format", "json", "--out", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    assert doc["track_source"] == "given" and doc["sky_mask"] == "west-half" and doc["systems"] == ["G"]
    a = doc["availability"]
    assert a["constrained"] > a["unconstrained"]
    not_used = [(sat, why) for x in doc["epochs"] for sat, why in x["not_used"].items()]
    assert all("system_not_selected" in why for sat, why in not_used if sat[0] != "G")
    assert sum("sky_mask" in why for sat, why in not_used if sat[0] == "G") > len(doc["epochs"])
    assert all(s.startswith("G") for x in doc["epochs"] for s in x["used"])
    # the output exists: refused without --force, replaced with it
    assert invoke("gnss", "position", run_dir, "--db", sample_db, "--out", out).exit_code == 3
    assert invoke("gnss", "position", run_dir, "--db", sample_db, "--out", out, "--force").exit_code == 0
    assert "constrained available" in out.read_text()


def test_table_output(run_dir: Path, sample_db: Path) -> None:
    res = invoke("gnss", "position", run_dir, "--db", sample_db, "--line", "0420", "--track", "D")
    assert res.exit_code == 0, res.output
    assert "constrained available" in res.output and "16k" in res.output


def test_exit_codes(run_dir: Path, sample_db: Path, tiny_sources: Path, tmp_path: Path) -> None:
    assert invoke("gnss", "position", run_dir, "--db", sample_db, "--line", "0420").exit_code == 2
    assert invoke("gnss", "position", run_dir, "--db", sample_db, "--systems", "G,X").exit_code == 2
    bad_mask = tmp_path / "mask.csv"
    bad_mask.write_text("azimuth_deg,elevation_deg\n0,95\n")
    res = invoke("gnss", "position", run_dir, "--db", sample_db, "--sky-mask", bad_mask)
    assert res.exit_code == 2 and "elevation_deg" in res.output
    # a run without raw observations
    res = invoke("gnss", "position", SAMPLE_LOGS / "sim-d-slips", "--db", sample_db)
    assert res.exit_code == 2 and "gnss_obs" in res.output
    # a DB whose GIS grid has no heights (the tiny source set has none)
    db = tmp_path / "tiny.sqlite"
    build_db(tiny_sources, db, db_version="t")
    res = invoke("gnss", "position", run_dir, "--db", db, "--line", "0420", "--track", "D")
    assert res.exit_code == 1 and "height_m is empty" in res.output
