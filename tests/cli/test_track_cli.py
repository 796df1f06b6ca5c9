"""``trainpos track match`` end to end on tp-lib's RINF Kongsvinger network (Apache-2.0,
tests/data/tp-lib) with its 149 GNSS points imported by ``logs import`` — as a GeoJSON point
trace and as a vendor CSV of local time stamps without quality columns
(tests/data/trackmatch) — in every output format, and the documented exit codes."""

from __future__ import annotations

import json
from pathlib import Path

import pandas as pd
import pytest
from typer.testing import CliRunner, Result

from cli.main import app
from dbtools.build import build_db
from dbtools.interchange.rtm_import import import_rtm_geojson
from fieldlogs.runs.handle import read_run

DATA = Path(__file__).resolve().parents[1] / "data"
KVG = DATA / "tp-lib" / "rinf-kvg"
TM = DATA / "trackmatch"


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


@pytest.fixture(scope="module")
def kvg_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    tmp = tmp_path_factory.mktemp("kvg")
    import_rtm_geojson(KVG / "network.geojson", tmp / "src")
    build_db(tmp / "src", tmp / "kvg.sqlite")
    return tmp / "kvg.sqlite"


@pytest.fixture(scope="module")
def geojson_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs") / "kvg-geojson"
    res = invoke("logs", "import", KVG / "gnss.geojson", "--vehicle", TM / "road_rail.toml", "--out", out,
                 "--time-zone", "Europe/Oslo")  # fmt: skip
    assert res.exit_code == 0, res.output
    return out


def test_geojson_trace_imports_as_a_gps_stream(geojson_run: Path) -> None:
    run = read_run(geojson_run)
    gps = run.stream("gps")
    assert gps is not None and len(gps) == 149 and gps["t"].is_monotonic_increasing
    assert (gps["fix"] == 1).all() and gps["nsat"].isna().all() and gps["hdop"].isna().all()
    # the features are listed newest first; local 13:06:47 CEST = 11:06:47 UTC
    assert run.meta is not None and run.meta.start_time.startswith("2026-05-25T11:06:47")
    assert gps["t"].iloc[-1] == pytest.approx(148.0)


def test_vendor_csv_with_local_time_and_no_quality(tmp_path: Path) -> None:
    out = tmp_path / "vendor"
    res = invoke("logs", "import", TM / "vendor_trace.csv", "--mapping", TM / "vendor_trace.toml",
                 "--vehicle", TM / "road_rail.toml", "--out", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    run = read_run(out)
    gps = run.stream("gps")
    assert gps is not None and len(gps) == 149
    assert run.meta is not None and run.meta.start_time.startswith("2026-05-25T11:06:47")
    # mixed precision: every third stamp carries .400 s
    assert list(gps["t"].iloc[:4].round(3)) == [0.0, 1.4, 2.0, 3.0]
    assert (gps["fix"] == 1).all() and gps["nsat"].isna().all()


def test_offset_less_stamps_without_a_time_zone_are_refused(tmp_path: Path) -> None:
    res = invoke("logs", "import", KVG / "gnss.geojson", "--vehicle", TM / "road_rail.toml", "--out", tmp_path / "r")
    assert res.exit_code == 2 and "no UTC offset" in res.output and "feature 0" in res.output
    assert not (tmp_path / "r").exists()
    mapping = tmp_path / "m.toml"
    mapping.write_text((TM / "vendor_trace.toml").read_text().replace('timezone = "Europe/Oslo"', ""))
    res = invoke("logs", "import", TM / "vendor_trace.csv", "--mapping", mapping, "--vehicle", TM / "road_rail.toml",
                 "--out", tmp_path / "r")  # fmt: skip
    assert res.exit_code == 2 and "no UTC offset" in res.output and "vendor_trace.csv:2, column 'Time'" in res.output


def test_json(geojson_run: Path, kvg_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "m.json"
    res = invoke("track", "match", geojson_run, "--db", kvg_db, "--format", "json", "--out", out)
    assert res.exit_code == 0, res.output
    doc = json.loads(out.read_text())
    s = doc["summary"]
    assert (s["fixes"], s["matched"], s["chains"], s["run_id"]) == (149, 149, 1, "gnss")
    assert set(doc["path"][0]) == {"chain", "track_id", "probability", "t_from", "t_to", "fixes"}
    assert doc["path"][0]["track_id"].startswith("_netelement_")  # verbatim ids
    f = doc["fixes"][0]
    assert {"t", "track_id", "offset_m", "distance_m", "km_m", "probability", "status"} <= set(f)
    assert f["km_m"] is None  # the imported tracks lie along no line km
    assert sum(p["fixes"] for p in doc["path"]) == 149


def test_geojson_csv_table_and_the_output_rule(geojson_run: Path, kvg_db: Path, tmp_path: Path) -> None:
    gj = tmp_path / "m.geojson"
    assert invoke("track", "match", geojson_run, "--db", kvg_db, "--format", "geojson", "--out", gj).exit_code == 0
    doc = json.loads(gj.read_text())
    layers = pd.Series([f["properties"]["layer"] for f in doc["features"]]).value_counts().to_dict()
    assert doc["type"] == "FeatureCollection" and layers["fix"] == 149 and layers["path"] >= 5
    assert {f["geometry"]["type"] for f in doc["features"] if f["properties"]["layer"] == "path"} == {"LineString"}
    csv = tmp_path / "m.csv"
    assert invoke("track", "match", geojson_run, "--db", kvg_db, "--format", "csv", "--out", csv).exit_code == 0
    frame = pd.read_csv(csv)
    assert len(frame) == 149 and list(frame.columns)[:5] == ["t", "lat", "lon", "status", "track_id"]
    res = invoke("track", "match", geojson_run, "--db", kvg_db)
    assert res.exit_code == 0 and "Track match" in res.output and "Path" in res.output
    res = invoke("track", "match", geojson_run, "--db", kvg_db, "--format", "csv", "--out", csv)
    assert res.exit_code == 3
    assert (
        invoke("track", "match", geojson_run, "--db", kvg_db, "--format", "csv", "--out", csv, "--force").exit_code == 0
    )


def test_exit_codes_without_gps_or_without_a_match(geojson_run: Path, kvg_db: Path, tmp_path: Path) -> None:
    empty = tmp_path / "nogps"
    empty.mkdir()
    (empty / "run.json").write_text((geojson_run / "run.json").read_text())
    res = invoke("track", "match", empty, "--db", kvg_db)
    assert res.exit_code == 2 and "no gps stream" in res.output
    far = tmp_path / "far"
    far.mkdir()
    (far / "run.json").write_text((geojson_run / "run.json").read_text())
    gps = pd.read_parquet(geojson_run / "gps.parquet")
    gps.assign(lat=gps["lat"] - 0.1).to_parquet(far / "gps.parquet")  # 11 km south of every track
    res = invoke("track", "match", far, "--db", kvg_db)
    assert res.exit_code == 1 and "none of the 149 fixes" in res.output


def test_tp_lib_teaching_trace_with_offsets(tmp_path: Path) -> None:
    out = tmp_path / "sample"
    res = invoke("logs", "import", DATA / "tp-lib" / "sample_gnss.geojson", "--vehicle", TM / "road_rail.toml",
                 "--out", out)  # fmt: skip
    assert res.exit_code == 0, res.output
    run = read_run(out)
    gps = run.stream("gps")
    assert gps is not None and list(gps["t"]) == [0.0, 5.0, 10.0]
    assert list(gps["speed_mps"].round(3)) == [round(v / 3.6, 3) for v in (120, 122, 118)]
    assert run.meta is not None and run.meta.start_time.startswith("2024-01-15T09:30:00")  # 10:30 at +01:00
