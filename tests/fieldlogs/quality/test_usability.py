"""One usability rule for runs (issue 15): never a confident wrong position from a run that
cannot support one; fields required only where they apply."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.database import read_network
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.quality.checks import check_run
from fieldlogs.quality.usability import Purpose, time_unit_problem, usability_findings
from fieldlogs.runs.handle import read_run
from schemas.errors import FindingsError

LOGS = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"


def _copy(name: str, tmp_path: Path) -> Path:
    dst = tmp_path / name
    shutil.copytree(LOGS / name, dst)
    return dst


def _edit_json(run: Path, **changes: object) -> None:
    data = json.loads((run / "run.json").read_text())
    for k, v in changes.items():
        if v is None:
            data.pop(k, None)
        else:
            data[k] = v
    (run / "run.json").write_text(json.dumps(data))


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        ("imu", "no imu stream (without it slips and slides can be neither detected nor bounded)"),
        ("tacho", "no tacho stream (the position is dead-reckoned on the wheel)"),
        ("ms", "t looks like milliseconds: rows 100 apart for a 10 Hz stream"),
        ("wheel", "wheel_diameter_m 1e+308 m is not a train's wheel (0.5–1.3 m)"),
    ],
)
def test_a_run_that_cannot_be_positioned_honestly_is_refused(
    damage: str, message: str, sample_db: Path, tmp_path: Path
) -> None:
    run = _copy("sim-d-slips", tmp_path)
    if damage in ("imu", "tacho"):
        (run / f"{damage}.parquet").unlink()
    elif damage == "ms":
        t = pd.read_parquet(run / "tacho.parquet")
        t["t"] *= 1000.0
        t.to_parquet(run / "tacho.parquet", index=False)
    else:
        _edit_json(run, wheel_diameter_m=1e308)
    with pytest.raises(FindingsError) as exc:
        run_pipeline(read_run(run), read_network(sample_db))
    assert any(message in f.message for f in exc.value.findings), [f.message for f in exc.value.findings]
    res = CliRunner().invoke(app, ["run", str(run), "--db", str(sample_db), "--out", str(tmp_path / "out")])
    assert res.exit_code == 1 and "unusable run for positioning" in res.output and "internal error" not in res.output
    assert not (tmp_path / "out").exists()
    # logs check says the same (the rate and wheel rules it adds beside its stream checks)
    if damage in ("ms", "wheel"):
        assert any(message in f.message for f in check_run(run))


def test_a_counter_reset_is_bridged_not_a_kilometre_correction(sample_db: Path, tmp_path: Path) -> None:
    """An un-repaired pulse-counter reset once gave 2,779 m of error and a 566 % 'correction'."""
    run = _copy("sim-d-slips", tmp_path)
    t = pd.read_parquet(run / "tacho.parquet")
    i = len(t) // 2
    t.loc[i:, "pulses"] = t.loc[i:, "pulses"] - t["pulses"].iloc[i - 1]
    t.to_parquet(run / "tacho.parquet", index=False)
    res = run_pipeline(read_run(run), read_network(sample_db))
    repaired = res.events[res.events["type"] == "input_repaired"]
    assert any(json.loads(d).get("counter_resets") == 1 for d in repaired["detail"])
    assert res.summary["truth"]["within_margin_share"] >= 0.999
    assert res.summary["max_correction_pct"] < 1.0


def test_wheel_fields_are_required_only_where_they_apply(sample_db: Path, tmp_path: Path) -> None:
    # a road-rail vehicle without a tacho needs no wheel: the possession check reads it
    rr = _copy("sim-road-rail", tmp_path)
    (rr / "tacho.parquet").unlink()
    _edit_json(rr, wheel_diameter_m=None, teeth=None)
    r = read_run(rr)
    assert r.meta is not None and r.meta.wheel_diameter_m is None
    assert usability_findings(r, Purpose.POSSESSION) == []
    plan = LOGS / "possessions.csv"
    res = CliRunner().invoke(app, ["possession", "check", str(rr), "--db", str(sample_db), "--plan", str(plan)])
    assert res.exit_code in (0, 1) and "wheel_diameter_m" not in res.output, res.output
    # … but it cannot be positioned (no wheel to dead-reckon on)
    assert [f.table for f in usability_findings(r, Purpose.POSITIONING)] == ["tacho"]
    # a train without its wheel, or any run with a tacho stream but no wheel, is refused
    train = _copy("sim-d-slips", tmp_path)
    _edit_json(train, wheel_diameter_m=None)
    t = read_run(train)
    assert t.meta is None
    assert any("wheel_diameter_m" in f.message and "missing" in f.message for f in t.findings)
    rr2 = _copy("sim-road-rail", tmp_path / "b")
    _edit_json(rr2, teeth=None)
    assert read_run(rr2).meta is None


def test_time_unit_detection_by_hand() -> None:
    t = np.arange(0, 100.0, 0.1)
    assert time_unit_problem(t, 10.0) is None
    assert "milliseconds" in (time_unit_problem(t * 1000.0, 10.0) or "")
    assert "microseconds" in (time_unit_problem(t * 1e6, 10.0) or "")
    assert time_unit_problem(t * 2.0, 10.0) is None  # a slow stream is a rate problem, not a unit


def test_audit_records_the_same_refusal(sample_db: Path, tmp_path: Path) -> None:
    run = _copy("sim-d-slips", tmp_path / "logs")
    (run / "imu.parquet").unlink()
    res = CliRunner().invoke(
        app, ["audit", str(tmp_path / "logs"), "--db", str(sample_db), "--out", str(tmp_path / "a.sqlite")]
    )
    assert res.exit_code == 1
    from fieldlogs.audit.store import read_table

    runs = read_table(tmp_path / "a.sqlite", "audit_runs")
    assert runs["status"].tolist() == ["error"] and "no imu stream" in runs["error"].iloc[0]
