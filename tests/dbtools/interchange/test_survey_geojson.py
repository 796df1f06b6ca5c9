"""``survey_geojson``: a hand-made survey report on a straight hand-made grid gives the
features, positions and collection members worked out by hand."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import numpy as np
import pandas as pd
import pytest

from dbtools.interchange.geojson import survey_geojson, write_geojson
from dbtools.network import Network

NAN = float("nan")
LON0, LAT0, DLON = 139.0, 35.0, 1e-5
"""The grid: line L1 track D, km 0 … 1000 every 20 m at lon = LON0 + km · DLON, lat = LAT0."""


def _lon(km: float) -> float:
    return LON0 + km * DLON


def _network() -> Network:
    km = np.arange(0.0, 1001.0, 20.0)
    gis = pd.DataFrame({"line_code": "L1", "track": "D", "km_m": km, "lon": _lon(km), "lat": LAT0})  # type: ignore[arg-type]
    return Network({"gis": gis})


def _report(gis: Any = None) -> SimpleNamespace:
    balises = pd.DataFrame(
        {
            "balise_id": ["B1", "B2", "B3", "B4"],
            "line_code": "L1",
            "track": "D",
            "km_db_m": [100.0, 200.0, 300.0, 5000.0],
            "status": ["ok", "moved", "missed", "unverified"],
            "residual_m": [0.1, 3.0, NAN, NAN],
            "ci95_m": [0.3, 0.4, NAN, NAN],
            "km_surveyed_m": [99.9, 197.0, NAN, NAN],
        }
    )
    candidates = pd.DataFrame(
        {
            "candidate_id": ["X1"],
            "kind": ["C"],
            "line_code": ["L1"],
            "track": ["D"],
            "km_m": [400.5],
            "confirmed": [True],
        }
    )
    features = pd.DataFrame(
        {
            "line_code": "L1",
            "track": "D",
            "feature_id": ["F1", None, "F3"],
            "curve_id": ["c1", "c2", None],
            "status": ["moved", "new", "not seen"],
            "entry_km_db_m": [500.0, NAN, 800.0],
            "exit_km_db_m": [560.0, NAN, 850.0],
            "entry_km_m": [505.0, 700.0, NAN],
            "exit_km_m": [565.0, 760.0, NAN],
        }
    )
    wheels = pd.DataFrame({"vehicle_id": ["EMU-A"], "diameter_m": [0.8592], "status": ["alert"]})
    wheel_runs = pd.DataFrame({"vehicle_id": ["EMU-A"], "run_id": ["R1"], "diameter_m": [0.8592]})
    return SimpleNamespace(
        db="net.sqlite",
        db_version="t1",
        balises=balises,
        candidates=candidates,
        features=features,
        wheels=wheels,
        wheel_runs=wheel_runs,
        failed_runs=pd.DataFrame({"run": [], "error": []}),
        gis=gis,
        gis_note="",
        summary=lambda: {"balises": {"moved": 1, "ok": 1}, "runs": 3},
    )


def _gis() -> SimpleNamespace:
    return SimpleNamespace(
        defects=pd.DataFrame(
            {"defect_id": ["D1"], "line_code": "L1", "track": "D", "km_from_m": 610.0, "km_to_m": 650.0}
        ),
        cells=pd.DataFrame(
            {"line_code": "L1", "track": "D", "km_from_m": [0.0], "km_to_m": [20.0], "offset_mean_m": 0.2}
        ),
        km_defects=pd.DataFrame(
            {"km_defect_id": ["K1"], "line_code": "L1", "track": "D", "km_from_m": 900.0, "km_to_m": 940.0}
        ),
        proposal=pd.DataFrame(
            {"defect_id": ["D1"], "lon": [_lon(620)], "lat": [LAT0], "lon_new": [_lon(620)], "lat_new": [LAT0 + 1e-6]}
        ),
    )


def _layer(gj: dict[str, Any], name: str) -> list[dict[str, Any]]:
    return [f for f in gj["features"] if f["properties"]["layer"] == name]


def _along(geom: dict[str, Any], *kms: float) -> bool:
    """The geometry is the LineString along the grid through these km."""
    want = [[_lon(k), LAT0] for k in kms]
    got = geom["coordinates"]
    return geom["type"] == "LineString" and len(got) == len(want) and bool(np.allclose(got, want, rtol=0, atol=1e-9))


@pytest.fixture(scope="module")
def gj(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    out: Path = tmp_path_factory.mktemp("survey-geojson") / "s.geojson"
    write_geojson(out, survey_geojson(_network(), _report(_gis())))
    data: dict[str, Any] = json.loads(out.read_text(encoding="utf-8"))  # strict JSON (no NaN) as written
    return data


def test_balises_at_their_db_km_with_status_and_residual(gj: dict[str, Any]) -> None:
    b = {f["properties"]["balise_id"]: f for f in _layer(gj, "balises")}
    assert [b[k]["properties"]["status"] for k in ("B1", "B2", "B3", "B4", "X1")] == [
        "ok",
        "moved",
        "missed",
        "unverified",
        "candidate",
    ]
    assert b["B2"]["geometry"] == {"type": "Point", "coordinates": [pytest.approx(_lon(200)), LAT0]}
    assert b["B2"]["id"] == "B2" and b["B2"]["properties"]["residual_m"] == 3.0
    assert b["B2"]["properties"]["ci95_m"] == 0.4
    assert b["B2"]["properties"]["lon_surveyed"] == pytest.approx(_lon(197))  # DB km − residual
    assert b["B3"]["properties"]["residual_m"] is None and b["B3"]["properties"]["lon_surveyed"] is None
    assert b["B4"]["geometry"] is None  # beyond the grid
    assert b["X1"]["geometry"]["coordinates"] == [pytest.approx(_lon(400.5)), LAT0]
    (move,) = _layer(gj, "balise_moves")
    assert move["properties"]["balise_id"] == "B2"
    assert _along(move["geometry"], 197, 200)


def test_curves_at_the_db_and_as_the_runs_place_them(gj: dict[str, Any]) -> None:
    feats = _layer(gj, "features")
    assert [f["properties"]["status"] for f in feats] == ["moved", "new", "not seen"]
    assert _along(feats[0]["geometry"], 500, 520, 540, 560)
    assert _along(feats[1]["geometry"], 700, 720, 740, 760)  # new: the runs'
    assert _along(feats[2]["geometry"], 800, 820, 840, 850)
    proposals = _layer(gj, "feature_proposals")
    assert [f["properties"]["curve_id"] for f in proposals] == ["c1", "c2"]
    assert _along(proposals[0]["geometry"], 505, 520, 540, 560, 565)


def test_gis_layers_like_gis_verify(gj: dict[str, Any]) -> None:
    (defect,) = _layer(gj, "defects")
    assert _along(defect["geometry"], 610, 620, 640, 650)
    assert _layer(gj, "cells")[0]["properties"]["offset_mean_m"] == 0.2
    assert _along(_layer(gj, "km_defects")[0]["geometry"], 900, 920, 940)
    (moved,) = _layer(gj, "proposal_moves")
    assert moved["geometry"]["coordinates"][1] == pytest.approx([_lon(620), LAT0 + 1e-6])


def test_wheels_and_summary_are_collection_members(gj: dict[str, Any]) -> None:
    assert gj["type"] == "FeatureCollection" and gj["name"] == "survey" and "crs" not in gj
    assert gj["wheels"]["vehicles"] == [{"vehicle_id": "EMU-A", "diameter_m": 0.8592, "status": "alert"}]
    assert gj["wheels"]["runs"][0]["run_id"] == "R1"
    assert gj["db"] == "net.sqlite" and gj["db_version"] == "t1" and gj["summary"]["runs"] == 3
    assert gj["failed_runs"] == []
    assert all(f["properties"]["layer"] != "wheels" for f in gj["features"])


def test_no_gis_no_features() -> None:
    rep = _report()
    rep.features = rep.features.iloc[0:0]
    gj = survey_geojson(_network(), rep)
    assert {f["properties"]["layer"] for f in gj["features"]} == {"balises", "balise_moves"}
