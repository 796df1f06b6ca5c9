"""Fail-safe holes the damage property test found (issue 15, tests/test_damage.py): a tacho that
is not one counter, a time base that does not fit the run — refused by the usability rule
(``logs check`` and ``run`` alike), never positioned, never an internal error."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import build_cycles
from fieldlogs.pipeline.odometry.streams import align_streams
from fieldlogs.quality.checks import check_run
from fieldlogs.quality.tacho import MAX_ROWS_BELOW, counter_problem
from fieldlogs.quality.usability import Purpose, time_span_problem, time_unit_problem, usability_findings
from fieldlogs.runs.handle import read_run

LOGS = Path(__file__).resolve().parents[3] / "fieldlogs" / "sample_logs"
K = 0.01  # metres per pulse of the hand-made counters below


def _tacho(tmp_path: Path, edit: str) -> Path:
    run = tmp_path / "run"
    shutil.copytree(LOGS / "sim-d-slips", run)
    f = pd.read_parquet(run / "tacho.parquet")
    n = len(f)
    if edit == "partly_ms":  # the recorder switched to milliseconds two thirds in
        f.loc[f.index[2 * n // 3 :], "t"] = f["t"].iloc[2 * n // 3 :] * 1000.0
    elif edit == "ns":  # three times ×1000 (the property test's 'milliseconds' ×3)
        f["t"] = f["t"] * 1e9
    elif edit == "shuffled_reset":  # the property test's shuffle then reset at half the file
        f = f.sample(frac=1.0, random_state=1).reset_index(drop=True)
        f.loc[n // 2 :, "pulses"] = f["pulses"].iloc[n // 2 :] - f["pulses"].iloc[n // 2 - 1]
    elif edit == "sparse":  # the property test's shuffle, then 11 % of the rows kept: 0.6 s apart
        f = f.sample(frac=0.111, random_state=2).sort_values("t")
    elif edit == "reset_then_back":  # a reset, later the count steps back 500 and stays back
        p = f["pulses"].to_numpy(dtype=np.int64).copy()
        p[n // 2 :] -= p[n // 2 - 1]
        p[3 * n // 4 :] -= 500
        f["pulses"] = p
    f.to_parquet(run / "tacho.parquet", index=False)
    return run


def _imu(tmp_path: Path, edit: str) -> Path:
    run = tmp_path / "run"
    shutil.copytree(LOGS / "sim-d-slips", run)
    f = pd.read_parquet(run / "imu.parquet")
    cols = ["ax", "ay", "az"] if edit == "g" else ["wx", "wy", "wz"]
    f[cols] = f[cols] / 9.80665 if edit == "g" else np.degrees(f[cols])
    f.to_parquet(run / "imu.parquet", index=False)
    return run


def _refused(run: Path, db: Path, tmp_path: Path, column: str, words: str, stream: str = "tacho") -> None:
    problems = usability_findings(read_run(run), Purpose.POSITIONING)
    assert [(p.table, p.column) for p in problems] == [(stream, column)], problems
    assert words in problems[0].message, problems[0].message
    res = CliRunner().invoke(app, ["run", str(run), "--db", str(db), "--out", str(tmp_path / "out")])
    assert res.exit_code == 1, res.output
    assert f"{stream}.parquet column {column}" in res.output and words in res.output, res.output
    assert "internal error" not in res.output and not (tmp_path / "out").exists()
    # logs check fails it too: the same message, or (values out of range) its range findings on that column
    found = check_run(run)
    assert any(f.rule == "run.unusable" and words in f.message for f in found) or any(
        f.rule == "schema.range" and (f.table, f.column) == (stream, column) for f in found
    ), found[:5]


@pytest.mark.parametrize(
    ("edit", "column", "words"),
    [
        ("ns", "t", "t looks like nanoseconds: rows 1e+08 apart for a 10 Hz stream"),
        ("partly_ms", "t", "part of t not in seconds"),
        ("shuffled_reset", "pulses", "pulses is negative at"),
        ("reset_then_back", "pulses", "step back below an earlier count and stay back"),
        ("sparse", "t", "apart, not a 10 Hz stream (0.05–0.2 s;"),
    ],
)
def test_a_tacho_the_pipeline_cannot_trust_is_refused(
    edit: str, column: str, words: str, sample_db: Path, tmp_path: Path
) -> None:
    _refused(_tacho(tmp_path, edit), sample_db, tmp_path, column, words)


@pytest.mark.parametrize(
    ("edit", "column", "words"),
    [
        ("g", "az", "median |a| 1.01, gravity is about 9.81 m/s² (looks like g: multiply by 9.80665)"),
        ("deg", "wz", "99 % of the angular rates below 2.86, over 1 rad/s (deg/s? divide by 57.3)"),
    ],
)
def test_an_imu_in_other_units_is_refused(edit: str, column: str, words: str, sample_db: Path, tmp_path: Path) -> None:
    """Gyro in deg/s: once 95 % of the determined cycles within margin, exit 0."""
    run = _imu(tmp_path, edit)
    if edit == "g":  # logs check states it as log.unit_suspect already (not twice)
        problems = usability_findings(read_run(run), Purpose.POSITIONING)
        assert [(p.table, p.column, words in p.message) for p in problems] == [("imu", column, True)]
        res = CliRunner().invoke(app, ["run", str(run), "--db", str(sample_db), "--out", str(tmp_path / "out")])
        assert res.exit_code == 1 and words in res.output and not (tmp_path / "out").exists(), res.output
        assert any(f.rule == "log.unit_suspect" for f in check_run(run))
    else:
        _refused(run, sample_db, tmp_path, column, words, stream="imu")


def test_a_counter_by_hand() -> None:
    t = np.arange(100) * 0.1
    p = np.arange(100.0) * 10.0  # 10 pulses per 0.1 s: 1 m/s at 1 cm per pulse
    assert counter_problem(t, p, K) is None
    shuffled = np.random.default_rng(0).permutation(100)
    assert counter_problem(t[shuffled], p[shuffled], K) is None  # the pipeline sorts by t
    reset = p.copy()
    reset[50:] -= reset[49]  # a real reset: restarts at 10, bridged to the same count
    assert counter_problem(t, reset, K) is None
    glitch = p.copy()
    glitch[30] = 5.0  # one low sample that recovers: the dead reckoning holds one cycle
    assert counter_problem(t, glitch, K) is None
    back = p.copy()
    back[80:] -= 300.0  # steps back 300 pulses (not below half: no reset) and stays: 20 rows below
    assert "at 20 rows (first row 82)" in (counter_problem(t, back, K) or "")
    assert MAX_ROWS_BELOW < 20
    step = p.copy()
    step[40:] -= 105.0  # steps back 105 pulses for 10 rows: 1.05 m lost
    assert "(first row 42): the dead reckoning would lose 1.05 m" in (counter_problem(t, step, K) or "")
    step[40:] += 10.0  # 0.95 m: within MAX_LOST_M
    assert counter_problem(t, step, K) is None
    neg = p - 50.0
    assert "negative at 5 rows (first row 2)" in (counter_problem(t, neg, K) or "")
    false_bridge = p.copy()
    false_bridge[90:92] = 1.0  # two low samples read as a reset: 890 pulses bridged in
    big = 0.2  # m per pulse: 20 m/s, and the bridge adds 178 m within a second
    msg = counter_problem(t, false_bridge, big) or ""
    assert "198 m/s by pulses after bridging 1 counter reset(s) at row 94" in msg, msg
    assert counter_problem(t, false_bridge, None) is None  # no wheel: the wheel rule speaks
    jump = p.copy()
    jump[70:] += 20_000  # 200 m in 0.1 s at row 72: 201 m/s over the 1 s window
    assert "201 m/s by pulses at row 72, over 120 m/s" in (counter_problem(t, jump, K) or "")


def test_time_base_by_hand() -> None:
    t = np.arange(0, 100.0, 0.1)
    assert time_unit_problem(t, 10.0) is None
    assert "nanoseconds" in (time_unit_problem(t * 1e9, 10.0) or "")
    assert "not a 10 Hz stream" in (time_unit_problem(t * 100.0, 10.0) or "")  # no known unit
    assert "not a 10 Hz stream" in (time_unit_problem(t / 100.0, 10.0) or "")
    assert time_unit_problem(t * 2.0, 10.0) is None  # a slow stream is a rate problem, not a unit
    dup = np.repeat(t, 3)  # rows repeated (the pipeline drops repeated t): still 0.1 s apart
    assert time_unit_problem(dup, 10.0) is None and time_span_problem(dup, 10.0) is None
    assert time_span_problem(t[: t.size // 2], 10.0) is None  # truncated: covers its span
    gap = np.concatenate([t, t[-1] + 60.0 + t])  # a minute without rows in 200 s: covered
    assert time_span_problem(gap, 10.0) is None
    partly = np.concatenate([t, t[: t.size // 2] * 1000.0 + 1e5])  # a third of the rows in ms
    assert "part of t not in seconds" in (time_span_problem(partly, 10.0) or "")


def test_pulse_delay_search_never_fails_on_a_long_cycle() -> None:
    """Cycles longer than the delay search's high-pass window (t in nanoseconds, issue 15):
    the SPEC delay, no IndexError (``hp`` was 0)."""
    n = 400
    t = np.arange(n) * 1e8
    tacho = pd.DataFrame({"t": t, "pulses": np.arange(n) * 30})
    imu = pd.DataFrame({"t": t, "ax": 0.0, "ay": 0.0, "az": 9.8, "wx": 0.0, "wy": 0.0, "wz": 0.0})
    cycles = build_cycles(tacho=tacho, imu=imu, cab=None, wheel_diameter_m=0.86, teeth=90, cycle_s=0.1)
    cfg = OdometryConfig()
    assert cfg.pulse_delay_search_cycles > 0
    s = align_streams(cycles, cfg)
    assert s.delay == cfg.pulse_delay_cycles
