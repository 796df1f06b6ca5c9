"""``db export --layers/--crs`` and a GeoPackage every GDAL reads without a warning (issue 33):
GDAL (pyogrio) reads with its warnings as errors; reprojection checked against pyproj."""

from __future__ import annotations

import json
import shutil
import sqlite3
import warnings
import zipfile
from pathlib import Path

import pyogrio
import pytest
from pyogrio.raw import read
from pyproj import Transformer
from typer.testing import CliRunner

from cli.main import app
from dbtools.interchange.export import EXPORT_LAYERS, ExportFormat, GisOptions, export_network
from dbtools.interchange.gpkg import USER_VERSION
from dbtools.interchange.reproject import parse_crs, reproject
from schemas.errors import UsageError

#: JGD2011 / Japan Plane Rectangular CS IX: the sample network (Tokyo) in metres.
PLANE = 6677
#: GDAL 3.6 (ogr/ogrsf_frmts/gpkg/ogrgeopackagedriver.cpp) opens a GeoPackage silently when its
#: user_version is in one of these ranges (102xx, 103xx); 104xx gets "may only be partially supported".
GDAL_3_6_SILENT = (range(10200, 10299), range(10300, 10399))


def _gdal_warnings(path: Path) -> tuple[dict[str, str], list[str]]:
    """Every layer opened and read by GDAL: layer → geometry type, and GDAL's warnings (pyogrio
    passes them on as Python warnings; raised from its C error handler they would be lost)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        layers = {str(n): str(k) for n, k in pyogrio.list_layers(path)}
        for name in layers:
            pyogrio.read_info(path, layer=name)
            read(path, layer=name)
    return layers, [str(w.message) for w in caught]


def _gdal_reads_silently(path: Path) -> dict[str, str]:
    """Every layer read by GDAL, GDAL's warnings taken as errors; layer → geometry type."""
    layers, said = _gdal_warnings(path)
    assert not said, said
    return layers


@pytest.fixture(scope="module")
def gpkg(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("gis") / "net.gpkg"
    export_network(sample_db, out, ExportFormat.gpkg)
    return out


def test_the_geopackage_is_a_version_gdal_3_6_reads_without_a_warning(gpkg: Path, tmp_path: Path) -> None:
    con = sqlite3.connect(gpkg)
    try:
        assert con.execute("PRAGMA user_version").fetchone()[0] == USER_VERSION
    finally:
        con.close()
    assert any(USER_VERSION in r for r in GDAL_3_6_SILENT)
    assert set(_gdal_reads_silently(gpkg)) >= {"balises", "tracks", "gis_points"}  # the newest GDAL: no warning
    newer = tmp_path / "newer.gpkg"  # the check itself can fail: a version GDAL does not know warns
    shutil.copy(gpkg, newer)
    con = sqlite3.connect(newer)
    con.execute("PRAGMA user_version = 10900")
    con.commit()
    con.close()
    _, said = _gdal_warnings(newer)
    assert said and "partially supported" in said[0]


def test_layers_choose_the_tables_and_files(sample_db: Path, tmp_path: Path) -> None:
    counts = export_network(
        sample_db, tmp_path / "two.gpkg", ExportFormat.gpkg, gis=GisOptions(layers=("tracks", "balises"))
    )
    assert set(counts) == {"tracks", "balises"}
    assert set(_gdal_reads_silently(tmp_path / "two.gpkg")) == {"tracks", "balises"}
    export_network(sample_db, tmp_path / "one.zip", ExportFormat.geojson, gis=GisOptions(layers=("km_posts",)))
    assert zipfile.ZipFile(tmp_path / "one.zip").namelist() == ["km_posts.geojson"]
    export_network(sample_db, tmp_path / "grid.parquet", ExportFormat.geoparquet, gis=GisOptions(layers=("gis_lines",)))


@pytest.mark.parametrize(
    ("fmt", "options", "message"),
    [
        (ExportFormat.gpkg, GisOptions(layers=("tracks", "signals")), "no layer signals"),
        (ExportFormat.geoparquet, GisOptions(layers=("tracks",)), "no layer tracks"),
        (ExportFormat.railml, GisOptions(crs=PLANE), "not --format railml"),
        (ExportFormat.rtm_geojson, GisOptions(layers=("tracks",)), "not --format rtm-geojson"),
    ],
)
def test_wrong_layers_or_formats_are_refused_before_any_work(
    sample_db: Path, tmp_path: Path, fmt: ExportFormat, options: GisOptions, message: str
) -> None:
    with pytest.raises(UsageError, match=message):
        export_network(sample_db, tmp_path / "x.out", fmt, gis=options)
    assert not (tmp_path / "x.out").exists()
    assert set(EXPORT_LAYERS) >= {"tracks", "switches", "connections", "balise_groups", "km_posts", "gis_points"}


def _first_balise(gpkg_path: Path) -> tuple[float, float]:
    import shapely

    _, _, geoms, fields = read(gpkg_path, layer="balises", columns=["balise_id"])
    order = sorted(range(len(fields[0])), key=lambda i: str(fields[0][i]))
    g = shapely.from_wkb(geoms[order[0]])
    return g.x, g.y


def test_crs_reprojects_the_geopackage_and_records_it(gpkg: Path, sample_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "plane.gpkg"
    export_network(sample_db, out, ExportFormat.gpkg, gis=GisOptions(crs=PLANE))
    assert _gdal_reads_silently(out)
    assert pyogrio.read_info(out, layer="tracks")["crs"] == f"EPSG:{PLANE}"
    lon, lat = _first_balise(gpkg)
    x, y = _first_balise(out)
    ex, ey = Transformer.from_crs(6668, PLANE, always_xy=True).transform(lon, lat)
    assert (x, y) == pytest.approx((ex, ey), abs=1e-6) and abs(x) < 100_000 and abs(y) < 100_000
    con = sqlite3.connect(out)
    try:
        assert {r[0] for r in con.execute("SELECT srs_id FROM gpkg_spatial_ref_sys")} == {4326, -1, 0, PLANE}
        assert {r[0] for r in con.execute("SELECT DISTINCT srs_id FROM gpkg_contents")} == {PLANE}
        min_x, max_x = con.execute("SELECT min_x, max_x FROM gpkg_contents WHERE table_name='balises'").fetchone()
        assert min_x <= x <= max_x
    finally:
        con.close()


def test_geojson_in_another_crs_names_it_and_gdal_reads_it(sample_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "plane"
    export_network(sample_db, out, ExportFormat.geojson, gis=GisOptions(crs=PLANE, layers=("balises", "tracks")))
    doc = json.loads((out / "balises.geojson").read_text(encoding="utf-8"))
    assert doc["crs"] == {"type": "name", "properties": {"name": f"urn:ogc:def:crs:EPSG::{PLANE}"}}
    x, y = doc["features"][0]["geometry"]["coordinates"][:2]
    assert abs(x) < 100_000 and abs(y) < 100_000  # metres from the zone's origin, not degrees
    assert pyogrio.read_info(out / "tracks.geojson")["crs"] == f"EPSG:{PLANE}"
    single = tmp_path / "wgs84.geojson"
    export_network(sample_db, single, ExportFormat.geojson, gis=GisOptions(crs=4326))
    doc = json.loads(single.read_text(encoding="utf-8"))
    assert "crs" not in doc  # RFC 7946: WGS 84 needs no member
    lon, lat = doc["features"][0]["geometry"]["coordinates"][:2]
    assert 139 < lon < 140 and 35 < lat < 36


def test_crs_of_geoparquet(sample_db: Path, tmp_path: Path) -> None:
    import pyarrow.parquet as pq

    out = tmp_path / "plane.parquet"
    export_network(sample_db, out, ExportFormat.geoparquet, gis=GisOptions(crs=PLANE))
    geo = json.loads(pq.read_table(out).schema.metadata[b"geo"])
    assert geo["columns"]["geometry"]["crs"]["id"] == {"authority": "EPSG", "code": PLANE}
    assert abs(geo["columns"]["geometry"]["bbox"][0]) < 100_000


@pytest.mark.parametrize(
    ("text", "code"), [("EPSG:3067", 3067), ("epsg:4326", 4326), ("urn:ogc:def:crs:EPSG::6677", 6677), ("4258", 4258)]
)
def test_parse_crs(text: str, code: int) -> None:
    assert parse_crs(text) == code


@pytest.mark.parametrize("text", ["WGS84", "EPSG:999999", "EPSG:"])
def test_parse_crs_refuses(text: str) -> None:
    with pytest.raises(UsageError, match="--crs"):
        parse_crs(text)


def test_reproject_keeps_heights_and_nulls_and_refuses_what_the_crs_cannot_hold() -> None:
    feats = [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [139.4, 35.9, 42.0]}, "properties": {}},
        {"type": "Feature", "geometry": None, "properties": {}},
        {
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": [[139.4, 35.9], [139.41, 35.91]]},
            "properties": {"layer": "x"},
        },
    ]
    out = reproject(feats, 4326, 3857)
    assert out[0]["geometry"]["coordinates"][2] == 42.0 and out[1]["geometry"] is None
    assert out[2]["geometry"]["coordinates"][1][0] == pytest.approx(139.41 * 20_037_508.342789244 / 180, abs=0.01)
    assert feats[0]["geometry"]["coordinates"][0] == 139.4  # the input is not changed
    assert reproject(feats, 4326, 4326) == feats
    bad = [{"type": "Feature", "geometry": {"type": "Point", "coordinates": [0.0, 91.0]}, "properties": {}}]
    with pytest.raises(UsageError, match="outside"):
        reproject(bad, 4326, 3857)


def test_cli_layers_and_crs(sample_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "cli.gpkg"
    args = ["db", "export", str(sample_db), "--format", "gpkg", "--out", str(out)]
    r = CliRunner().invoke(app, [*args, "--layers", "tracks, km_posts", "--crs", f"EPSG:{PLANE}"])
    assert r.exit_code == 0, r.output
    assert set(_gdal_reads_silently(out)) == {"tracks", "km_posts"}
    assert pyogrio.read_info(out, layer="km_posts")["crs"] == f"EPSG:{PLANE}"
    r = CliRunner().invoke(app, [*args[:-1], str(tmp_path / "bad.gpkg"), "--crs", "EPSG:999999"])
    assert r.exit_code == 2 and not (tmp_path / "bad.gpkg").exists()
