"""docs/howto/track-match.md stays runnable: every ``trainpos`` command of its ``sh`` blocks
runs, in order, in a scratch folder (paths under ``tests/data/`` point at the repository's),
and exits 0; the numbers the page states are checked on the results."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.database import read_network
from dbtools.topology import topology
from tests.howto import page_commands

ROOT = Path(__file__).resolve().parents[2]
PAGE = ROOT / "docs" / "howto" / "track-match.md"


def commands() -> list[list[str]]:
    return page_commands(PAGE)


def test_the_page_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    calls = commands()
    assert len(calls) == 8
    for argv in calls:
        r = CliRunner().invoke(app, argv, env={"COLUMNS": "200"})
        assert r.exit_code == 0, (argv, r.output)
    doc = json.loads((tmp_path / "kvg-match.json").read_text(encoding="utf-8"))
    s = doc["summary"]
    assert (s["fixes"], s["matched"], s["chains"], s["path_tracks"], s["crs_epsg"]) == (149, 149, 1, 14, 32633)
    assert round(s["mean_abs_offset_m"], 2) == 1.50
    first = doc["path"][0]
    assert first["track_id"] == "_netelement_94cd1b3d-9ef1-42dc-b7f6-32932adf7d6f_0.12594356"
    assert (round(first["probability"], 3), first["t_from"], first["t_to"]) == (0.972, 0.0, 18.0)
    assert all(f["km_m"] is None for f in doc["fixes"])
    topo = topology(read_network(tmp_path / "kvg.sqlite"))
    for a, b in zip(doc["path"][:-1], doc["path"][1:], strict=True):
        assert b["track_id"] in {x.track_id for d in (1, -1) for x in topo.next_tracks(a["track_id"], d)}
    layers = [f["properties"]["layer"] for f in json.loads((tmp_path / "kvg-match.geojson").read_text())["features"]]
    assert layers.count("path") == 14 and layers.count("fix") == 149
    vendor = pd.read_csv(tmp_path / "vendor-fixes.csv")
    assert list(vendor["track_id"].drop_duplicates()) == [p["track_id"] for p in doc["path"] if p["fixes"]]
