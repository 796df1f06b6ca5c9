"""``trainpos survey --format geojson`` on the survey data (the bundled sample network with
known errors, runs simulated on it): the file is RFC 7946 and lies on the network."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from cli.main import app
from tests.fieldlogs.survey.survey_data import MOVED, REMOVED_BALISE, SurveyData, survey_data


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> SurveyData:
    return survey_data(tmp_path_factory)


def _coords(geom: dict[str, Any]) -> list[list[float]]:
    return [geom["coordinates"]] if geom["type"] == "Point" else list(geom["coordinates"])


def test_survey_geojson_lies_on_the_network(data: SurveyData, tmp_path: Path, runner: CliRunner) -> None:
    out = tmp_path / "survey.geojson"
    args = ["survey", str(data.logs), "--db", str(data.db), "-j", "1", "--format", "geojson", "--out", str(out)]
    res = runner.invoke(app, args)
    assert res.exit_code == 1, res.output  # flagged, as in every other format
    gj = json.loads(out.read_text(encoding="utf-8"))
    assert gj["type"] == "FeatureCollection" and "crs" not in gj
    gis = data.truth.gis
    lon0, lon1, lat0, lat1 = gis["lon"].min(), gis["lon"].max(), gis["lat"].min(), gis["lat"].max()
    placed = [f for f in gj["features"] if f["geometry"] is not None]
    assert len(placed) > 0.9 * len(gj["features"])
    for f in placed:  # [lon, lat] in WGS 84, inside the network's area
        for lon, lat in _coords(f["geometry"]):
            assert lon0 - 1e-6 <= lon <= lon1 + 1e-6 and lat0 - 1e-6 <= lat <= lat1 + 1e-6
    balises = {f["properties"]["balise_id"]: f for f in gj["features"] if f["properties"]["layer"] == "balises"}
    (bid,) = MOVED
    assert balises[bid]["properties"]["status"] == "moved" and balises[bid]["geometry"]["type"] == "Point"
    moves = [f for f in gj["features"] if f["properties"]["layer"] == "balise_moves"]
    assert [f["properties"]["balise_id"] for f in moves] == [bid]
    assert any(p["properties"]["status"] == "candidate" for p in balises.values())
    assert REMOVED_BALISE not in balises
    layers = {f["properties"]["layer"] for f in gj["features"]}
    assert {"features", "feature_proposals", "cells"} <= layers
    assert {w["vehicle_id"] for w in gj["wheels"]["vehicles"]} == {"EMU-A", "EMU-B"}
    assert gj["summary"]["balises"]["moved"] == 1
    res = runner.invoke(app, ["survey", str(data.logs), "--db", str(data.db), "--format", "geojson"])
    assert res.exit_code == 2 and "--out" in res.output
