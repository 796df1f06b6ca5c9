"""``db import --format rtm-geojson`` and ``db export --format rtm-geojson`` through the CLI:
exit codes and messages."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

from cli.main import app
from tests.dbtools.interchange.rtm_samples import KVG, SAMPLE, collection, element, turnout_features, write


def invoke(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "300"})


def test_import_exit_codes(tmp_path: Path) -> None:
    r = invoke("db", "import", KVG, "--format", "rtm-geojson", "--out", tmp_path / "kvg")
    assert r.exit_code == 0, r.output
    assert "switches inferred" in r.output and "│ 55" in r.output and "warning" not in r.output
    again = invoke("db", "import", KVG, "--format", "rtm-geojson", "--out", tmp_path / "kvg")
    assert again.exit_code == 3 and "--force" in again.output
    bad = tmp_path / "bad.geojson"
    bad.write_text("{", encoding="utf-8")
    r = invoke("db", "import", bad, "--format", "rtm-geojson", "--out", tmp_path / "bad")
    assert r.exit_code == 2 and "invalid JSON" in r.output and f"{bad}:1" in r.output
    write(bad, collection([element(None, [[0.0, 0.0], [1.0, 0.0]])]))
    r = invoke("db", "import", bad, "--format", "rtm-geojson", "--out", tmp_path / "bad")
    assert r.exit_code == 1 and "rtm.missing_id" in r.output and "feature 0" in r.output
    assert not (tmp_path / "bad").exists()
    write(bad, collection(turnout_features(), crs="urn:ogc:def:crs:EPSG::0"))
    r = invoke("db", "import", bad, "--format", "rtm-geojson", "--out", tmp_path / "bad")
    assert r.exit_code == 1 and "rtm.crs" in r.output and "unknown CRS" in r.output
    r = invoke("db", "import", SAMPLE, "--format", "rtm-geojson", "--out", tmp_path / "s", "--line-code", bad)
    assert r.exit_code == 2 and "railML only" in r.output


def test_export_rtm_geojson(tmp_path: Path) -> None:
    assert invoke("db", "import", SAMPLE, "--format", "rtm-geojson", "--out", tmp_path / "src").exit_code == 0
    assert invoke("db", "build", tmp_path / "src", "--out", tmp_path / "s.sqlite").exit_code == 0
    r = invoke("db", "export", tmp_path / "s.sqlite", "--format", "rtm-geojson", "--out", tmp_path / "s.geojson")
    assert r.exit_code == 0, r.output
    gj = json.loads((tmp_path / "s.geojson").read_text(encoding="utf-8"))
    assert [f["properties"]["id"] for f in gj["features"]] == ["NE001", "NE002"]
    r = invoke("db", "export", tmp_path / "s.sqlite", "--format", "rtm-geojson", "--out", tmp_path / "s.geojson")
    assert r.exit_code == 3
    r = invoke("db", "export", tmp_path / "s.sqlite", "--format", "geojson", "--out", tmp_path / "layers")
    assert r.exit_code == 0 and (tmp_path / "layers" / "tracks.geojson").is_file()
