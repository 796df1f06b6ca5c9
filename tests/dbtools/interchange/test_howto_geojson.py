"""docs/howto/import-geojson.md stays runnable: every ``trainpos`` command of its ``sh``
blocks runs, in order, in a scratch folder (paths under ``tests/data/`` point at the
repository's), and exits 0; the numbers the page states are checked on the results."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from tests.howto import page_commands

ROOT = Path(__file__).resolve().parents[3]
PAGE = ROOT / "docs" / "howto" / "import-geojson.md"


def commands() -> list[list[str]]:
    return page_commands(PAGE)


def test_the_page_runs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    calls = commands()
    assert len(calls) == 10
    for argv in calls:
        r = CliRunner().invoke(app, argv, env={"COLUMNS": "200"})
        if argv[:2] == ["db", "validate"]:  # the RINF extract's own errors, as the page says
            assert r.exit_code == 1, (argv, r.output)
            assert {"topology.gap", "topology.switch_overlap", "topology.multiple_connections"} <= set(
                r.output.replace("\n", " ").split()
            ), r.output
            continue
        assert r.exit_code == 0, (argv, r.output)
    src = tmp_path / "kvg-src"
    assert len(pd.read_csv(src / "tracks.csv")) == 99 and len(pd.read_csv(src / "track_points.csv")) == 1757
    assert round(pd.read_csv(src / "tracks.csv")["length_m"].sum() / 1000, 2) == 32.13
    sw = pd.read_csv(src / "switches.csv")
    assert sw["diverging_side"].value_counts().to_dict() == {"left": 32, "right": 21}
    assert sw["type"].value_counts().to_dict() == {"point": 53, "double_slip": 2}
    assert 'metric_crs = "EPSG:32633"' in (src / "network.toml").read_text(encoding="utf-8")
    report = json.loads((src / "import_report.json").read_text(encoding="utf-8"))
    assert report["rows"]["connections"] == 182 and report["inferred"]["switches"] == 55
    a = pd.read_csv(src / "tracks.csv").set_index("track_id")["length_m"]
    b = pd.read_csv(tmp_path / "kvg-back" / "tracks.csv").set_index("track_id")["length_m"]
    assert list(a.index) == list(b.index) and round((a - b).abs().max(), 3) == 0.172
    assert pd.read_csv(src / "connections.csv").equals(pd.read_csv(tmp_path / "kvg-back" / "connections.csv"))
    assert {p.name for p in (tmp_path / "kvg-layers").glob("*.geojson")} == {
        "tracks.geojson",
        "switches.geojson",
        "connections.geojson",
    }
    import pyogrio

    chosen = tmp_path / "kvg-tracks.gpkg"
    assert {str(n) for n, _ in pyogrio.list_layers(chosen)} == {"tracks", "switches"}
    assert pyogrio.read_info(chosen, layer="tracks")["crs"] == "EPSG:25833"
