"""Whole-number columns: one typed path turns non-finite, huge and fractional values into
findings naming file, row, column and value — never a crash of the cast (issue 32 item 8)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.sample_network import sample_source_dir
from fieldlogs.runs.handle import read_run
from schemas.frames import coerce_frame
from schemas.logs import LOG_STREAMS
from schemas.tables import FEATURE_POINTS
from tests.fieldlogs.make_runs import make_run

BAD = ["inf", "-inf", "1e308", "1e400", "-1e19", "2.5", "9.3e18"]


@pytest.mark.parametrize("value", BAD)
@pytest.mark.parametrize("as_numbers", [False, True])
def test_bad_whole_numbers_are_findings(value: str, as_numbers: bool) -> None:
    cells: list[object] = ["1", value, ""]
    raw = pd.DataFrame({"t": ["0", "0.1", "0.2"], "pulses": cells})
    if as_numbers:  # as the typed CSV reader hands them over
        raw = raw.apply(lambda s: pd.to_numeric(s.replace("", np.nan)))
    co = coerce_frame(LOG_STREAMS["tacho"], raw, file="tacho.csv")
    assert co.frame["pulses"].tolist()[0] == 1
    assert co.frame["pulses"].isna().tolist() == [False, True, True]
    [f] = co.findings
    assert (f.rule, f.file, f.row, f.column) == ("schema.type", "tacho.csv", 3, "pulses")
    assert "whole number" in f.message


@pytest.mark.parametrize("value", ["inf", "1e308", "1e400"])
def test_db_build_names_a_bad_seq(tmp_path: Path, value: str) -> None:
    src = tmp_path / "src"
    shutil.copytree(sample_source_dir(), src)
    fp = src / "feature_points.csv"
    frame = pd.read_csv(fp, dtype=str, keep_default_na=False)
    if "seq" not in frame.columns:
        frame.insert(3, "seq", "")
    frame.loc[0, "seq"] = value
    frame.to_csv(fp, index=False)
    res = CliRunner().invoke(app, ["db", "build", str(src), "--out", str(tmp_path / "o.sqlite"), "--version", "1"])
    assert res.exit_code == 1, res.output
    assert "feature_points.csv:2" in res.output and "'seq'" in res.output
    assert FEATURE_POINTS.name in res.output


@pytest.mark.parametrize(("stream", "column"), [("tacho", "pulses"), ("gps", "fix"), ("gps", "nsat")])
@pytest.mark.parametrize("value", ["inf", "1e308"])
def test_run_streams_with_bad_whole_numbers_are_read(tmp_path: Path, stream: str, column: str, value: str) -> None:
    folder = make_run(tmp_path / "r", 3)
    path = folder / f"{stream}.csv"
    frame = pd.read_csv(path, dtype=str, keep_default_na=False)
    frame.loc[1, column] = value
    frame.to_csv(path, index=False)
    run = read_run(folder)
    typed = run.stream(stream)
    assert typed is not None and pd.isna(typed[column].iat[1])
    assert any(f.rule == "schema.type" and f.row == 3 and f.column == column for f in run.findings)
