"""``trainpos db validate`` and ``db build`` on the hand-made networks (tests/data/networks):
clean as source sets and as built DBs; a broken copy fails with exit 1 and a SARIF result
naming the topology rule, file and line."""

from __future__ import annotations

import json
import shutil
import sqlite3
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app

NETWORKS = Path(__file__).resolve().parents[1] / "data" / "networks"


def _run(args: list[str]) -> tuple[int, str]:
    r = CliRunner().invoke(app, args, env={"COLUMNS": "400"})
    return r.exit_code, r.output


@pytest.mark.parametrize("name", ["junction", "crossover", "station4", "double_slip"])
def test_built_network_validates_clean(tmp_path: Path, name: str) -> None:
    db = tmp_path / f"{name}.sqlite"
    code, out = _run(["db", "build", str(NETWORKS / name), "--out", str(db)])
    assert code == 0, out
    with sqlite3.connect(db) as con:
        assert con.execute("SELECT count(*) FROM switches").fetchone()[0] >= 1
    code, out = _run(["db", "validate", str(db), "--format", "json"])
    assert code == 0, out
    assert json.loads(out)["findings"] == []


def test_broken_network_sarif(tmp_path: Path) -> None:
    src = tmp_path / "junction"
    shutil.copytree(NETWORKS / "junction", src)
    text = (src / "tracks.csv").read_text().replace("A2,9001,S,main,400,1000,600,", "A2,9001,S,main,400,1000,590,")
    (src / "tracks.csv").write_text(text)
    code, out = _run(["db", "validate", str(src), "--format", "sarif"])
    assert code == 1
    results = json.loads(out)["runs"][0]["results"]
    assert [r["ruleId"] for r in results] == ["topology.track_length"]
    region = results[0]["locations"][0]["physicalLocation"]["region"]
    assert text.splitlines()[region["startLine"] - 1].startswith("A2,")
