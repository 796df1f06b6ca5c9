"""The interchange commands through the CLI: exit codes and messages of ``db import`` and
``db export``, and ``--format geojson`` of ``gis verify`` and ``possession check``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from cli.main import app
from tests.dbtools.gis_verify_data import DEFECT_KM, DEFECT_TRACK, VerifyData, verify_data
from tests.dbtools.interchange.railml_samples import MAP24, RAILML24, balise3, railml3

FINLAND = Path(__file__).resolve().parents[2] / "data" / "railml" / "Track-007_28-47.railml.xml"


def invoke(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "300"})


def test_import_exit_codes(tmp_path: Path) -> None:
    r = invoke("db", "import", FINLAND, "--format", "railml", "--out", tmp_path / "fi")
    assert r.exit_code == 0, r.output
    assert "balises in the file" in r.output and "76" in r.output and "railml.balise_identity" in r.output
    m0 = tmp_path / "pairs.toml"
    m0.write_text('[initial_pairs]\n"none" = "00"\n', encoding="utf-8")
    r = invoke("db", "import", FINLAND, "--format", "railml", "--out", tmp_path / "fi0", "--line-code", m0)
    assert r.exit_code == 1 and "railml.nothing_imported" in r.output and not (tmp_path / "fi0").exists()
    again = invoke("db", "import", FINLAND, "--format", "railml", "--out", tmp_path / "fi")
    assert again.exit_code == 3 and "--force" in again.output
    bad = tmp_path / "bad.railml"
    bad.write_text(railml3(balise3("b1", ne="nowhere")), encoding="utf-8")
    r = invoke("db", "import", bad, "--format", "railml", "--out", tmp_path / "bad")
    assert r.exit_code == 1 and "railml.undefined_track" in r.output and not (tmp_path / "bad").exists()
    bad.write_text(RAILML24[:500], encoding="utf-8")
    r = invoke("db", "import", bad, "--format", "railml", "--out", tmp_path / "bad")
    assert r.exit_code == 2 and "malformed XML" in r.output and f"{bad}:" in r.output
    m = tmp_path / "map.toml"
    m.write_text('[lines.L1]\ntrack = "D"\n', encoding="utf-8")
    bad.write_text(RAILML24, encoding="utf-8")
    r = invoke("db", "import", bad, "--format", "railml", "--out", tmp_path / "bad", "--line-code", m)
    assert r.exit_code == 2 and "needs line_code" in r.output
    m.write_text(MAP24, encoding="utf-8")
    r = invoke("db", "import", bad, "--format", "railml", "--out", tmp_path / "ok", "--line-code", m)
    assert r.exit_code == 0, r.output
    assert invoke("db", "build", tmp_path / "ok", "--out", tmp_path / "ok.sqlite").exit_code == 0


def test_export_exit_codes(sample_db: Path, tmp_path: Path) -> None:
    r = invoke("db", "export", sample_db, "--format", "kml", "--out", tmp_path / "x.kml")
    assert r.exit_code == 2 and "railml, geojson, gpkg, geoparquet" in r.output
    r = invoke("db", "export", sample_db, "--format", "geojson", "--out", tmp_path / "n.geojson")
    assert (
        r.exit_code == 0
        and json.loads((tmp_path / "n.geojson").read_text(encoding="utf-8"))["type"] == "FeatureCollection"
    )
    assert invoke("db", "export", sample_db, "--format", "geojson", "--out", tmp_path / "n.geojson").exit_code == 3
    assert (
        invoke("db", "export", tmp_path / "missing.sqlite", "--format", "gpkg", "--out", tmp_path / "m.gpkg").exit_code
        == 2
    )


@pytest.fixture(scope="module")
def data(tmp_path_factory: pytest.TempPathFactory) -> VerifyData:
    return verify_data(tmp_path_factory)


def test_gis_verify_geojson(data: VerifyData, tmp_path: Path) -> None:
    out = tmp_path / "verify.geojson"
    r = invoke("gis", "verify", data.surveyed_db, data.logs, "--format", "geojson", "--out", out)
    assert r.exit_code == 1, r.output  # defects found
    gj = json.loads(out.read_text(encoding="utf-8"))
    layers = {f["properties"]["layer"] for f in gj["features"]}
    assert {"defects", "cells", "proposal", "proposal_moves"} <= layers
    (defect,) = [f for f in gj["features"] if f["properties"]["layer"] == "defects"]
    assert defect["geometry"]["type"] == "LineString" and defect["properties"]["track"] == DEFECT_TRACK
    assert (
        DEFECT_KM[0] - 40 <= defect["properties"]["km_from_m"] <= defect["properties"]["km_to_m"] <= DEFECT_KM[1] + 40
    )
    assert all("offset_mean_m" in f["properties"] for f in gj["features"] if f["properties"]["layer"] == "cells")
    assert invoke("gis", "verify", data.surveyed_db, data.logs, "--format", "geojson").exit_code == 2  # needs --out


def test_possession_geojson(tmp_path: Path) -> None:
    from dbtools.build import build_db
    from dbtools.gis.geometry import Projector
    from dbtools.sources import write_source_set
    from fieldlogs.simulate.networks.synthetic import build_network, demo_line
    from fieldlogs.simulate.possession import make_case

    net = build_network([demo_line()], Projector(9))
    write_source_set(net, tmp_path / "src")
    build_db(tmp_path / "src", tmp_path / "net.sqlite", db_version="t")
    run, plan = make_case(net, "overrun", 31).write(tmp_path, fmt="csv")
    out = tmp_path / "pz.geojson"
    r = invoke(
        "possession", "check", run, "--db", tmp_path / "net.sqlite", "--plan", plan, "--format", "geojson", "--out", out
    )
    assert r.exit_code == 1, r.output
    gj = json.loads(out.read_text(encoding="utf-8"))
    alarms = [f for f in gj["features"] if f["properties"]["layer"] == "alarms"]
    sections = [f for f in gj["features"] if f["properties"]["layer"] == "possessions"]
    assert alarms and all(a["properties"]["type"] == "overrun" for a in alarms)
    assert all(a["geometry"]["type"] == "Point" for a in alarms) and sections[0]["geometry"]["type"] == "LineString"
    assert alarms[0]["properties"]["work_no"] == "W00031"
