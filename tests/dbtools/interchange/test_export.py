"""``db export``: railML 3.2 (structure, round trip), GeoJSON (RFC 7946), GeoPackage
(read back with sqlite3 and shapely), GeoParquet (pyarrow, geo metadata)."""

from __future__ import annotations

import json
import sqlite3
import struct
from pathlib import Path

import pytest
import shapely

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.diff import diff_paths
from dbtools.interchange.export import ExportFormat, export_network
from dbtools.interchange.importer import import_railml
from dbtools.interchange.xmltree import TPOS_NS
from schemas.errors import RefusedError

R = "{https://www.railml.org/schemas/3.2}"


@pytest.fixture(scope="module")
def exported(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("export")
    out = {}
    for f in ExportFormat:
        out[f.value] = d / f"net.{f.value}"
        export_network(sample_db, out[f.value], f)
    return out


def test_round_trip_railml_import_build_diff_has_no_content_difference(
    sample_db: Path, exported: dict[str, Path], tmp_path: Path
) -> None:
    src = tmp_path / "src"
    r = import_railml(exported["railml"], src)
    assert not [f for f in r.findings if f.rule == "railml.unmapped"], [str(f) for f in r.findings]
    build_db(src, tmp_path / "back.sqlite", db_version="back")
    d = diff_paths(sample_db, tmp_path / "back.sqlite")
    assert not d.has_changes and any("no content differences" in s for s in d.summary), d.summary
    assert d.old["content_hash"] == d.new["content_hash"]


def test_railml_structure(exported: dict[str, Path], sample_db: Path) -> None:
    """Structural checks in place of XSD validation (the railML 3.2 XSDs are not available
    offline): the element hierarchy, required attributes, unique ids, resolvable refs."""
    from lxml import etree

    root = etree.parse(str(exported["railml"])).getroot()
    assert root.tag == f"{R}railML" and root.get("version") == "3.2"
    assert [c.tag for c in root] == [f"{R}metadata", f"{R}common", f"{R}infrastructure"]
    ids = [e.get("id") for e in root.iter() if e.get("id")]
    assert len(ids) == len(set(ids))
    ids_set = set(ids)
    for attr in ("netElementRef", "positioningSystemRef", "ref"):
        refs = {e.get(attr) for e in root.iter() if e.get(attr)}
        assert refs <= ids_set, (attr, refs - ids_set)
    infra = root.find(f"{R}infrastructure")
    assert [c.tag for c in infra] == [f"{R}topology", f"{R}geometry", f"{R}functionalInfrastructure"]
    net = read_network(sample_db)
    nes = infra.findall(f"{R}topology/{R}netElements/{R}netElement")
    assert len(nes) == 2 and all(float(n.get("length")) > 14_000 for n in nes)
    ics = root.findall(f".//{R}intrinsicCoordinate")
    assert len(ics) == len(net.gis)
    assert all(0.0 <= float(ic.get("intrinsicCoord")) <= 1.0 for ic in ics)
    assert all(
        ic.find(f"{R}linearCoordinate") is not None and ic.find(f"{R}geometricCoordinate") is not None for ic in ics
    )
    balises = infra.findall(f"{R}functionalInfrastructure/{R}balises/{R}balise")
    assert len(balises) == len(net.balises)
    for b in balises:
        loc = b.find(f"{R}spotLocation")
        assert loc.get("applicationDirection") in ("normal", "reverse") and loc.find(f"{R}linearCoordinate") is not None
        assert b.get(f"{{{TPOS_NS}}}kind") in ("I1", "I2", "C")
    curves = infra.findall(f"{R}geometry/{R}horizontalCurves/{R}horizontalCurve")
    assert {c.get("curveType") for c in curves} == {"straight", "clothoide", "arc"}
    arcs = [c for c in curves if c.get("curveType") == "arc"]
    assert len(arcs) == len(net.feature_points) // 6 and all(float(c.get("radius")) != 0 for c in arcs)
    lps = root.findall(f"{R}common/{R}positioning/{R}linearPositioningSystems/{R}linearPositioningSystem")
    assert [p.get("units") for p in lps] == ["m"]


def test_geojson_is_rfc7946(exported: dict[str, Path], sample_db: Path) -> None:
    gj = json.loads(exported["geojson"].read_text(encoding="utf-8"))
    assert gj["type"] == "FeatureCollection"
    layers: dict[str, int] = {}
    for f in gj["features"]:
        assert f["type"] == "Feature" and {"geometry", "properties"} <= set(f)
        layers[f["properties"]["layer"]] = layers.get(f["properties"]["layer"], 0) + 1
        g = f["geometry"]
        pts = [g["coordinates"]] if g["type"] == "Point" else g["coordinates"]
        for p in pts:  # lon, lat order: the sample lies near 139.5° E, 35.9° N
            assert 139.3 < p[0] < 139.6 and 35.8 < p[1] < 36.0
    net = read_network(sample_db)
    assert layers == {
        "balises": 31,
        "feature_points": len(net.feature_points),
        "gis_points": len(net.gis),
        "gis_lines": 2,
        "tracks": 2,  # the implied tracks 420:D and 420:U (a line-only DB: no switches, no connections)
        "km_posts": 2 * 15,  # km 16, 17 … 30 on a grid from km 16.000 to 30.980 on each track
    }


def test_geopackage_tables_and_binary_geometry(exported: dict[str, Path]) -> None:
    con = sqlite3.connect(exported["gpkg"])
    try:
        assert con.execute("PRAGMA application_id").fetchone()[0] == 0x47504B47
        assert con.execute("PRAGMA user_version").fetchone()[0] == 10300
        assert {r[0] for r in con.execute("SELECT srs_id FROM gpkg_spatial_ref_sys")} == {4326, 6668, -1, 0}
        contents = {
            r[0]: r[1:] for r in con.execute("SELECT table_name, data_type, srs_id, min_x, max_x FROM gpkg_contents")
        }
        assert set(contents) == {"balises", "feature_points", "gis_points", "gis_lines", "tracks", "km_posts"}
        assert all(v[0] == "features" and v[1] == 6668 and 139 < v[2] < v[3] < 140 for v in contents.values())
        types = dict(con.execute("SELECT table_name, geometry_type_name FROM gpkg_geometry_columns"))
        assert types == {
            "balises": "POINT",
            "feature_points": "POINT",
            "gis_points": "POINT",
            "gis_lines": "LINESTRING",
            "tracks": "LINESTRING",
            "km_posts": "POINT",
        }
        blob, bid, km = con.execute(
            "SELECT geom, balise_id, km_actual_m FROM balises ORDER BY balise_id LIMIT 1"
        ).fetchone()
        assert blob[:2] == b"GP" and blob[2] == 0 and blob[3] & 1 == 1
        assert struct.unpack("<i", blob[4:8])[0] == 6668
        minx, maxx, miny, maxy = struct.unpack("<4d", blob[8:40])
        geom = shapely.from_wkb(bytes(blob[40:]))
        assert geom.geom_type == "Point" and minx == maxx == geom.x and miny == maxy == geom.y
        assert bid == "0420-01-U-I1" and km == 16350.0
        line = shapely.from_wkb(bytes(con.execute("SELECT geom FROM gis_lines LIMIT 1").fetchone()[0][40:]))
        assert line.geom_type == "LineString" and len(line.coords) == 750
    finally:
        con.close()


def test_gdal_reads_the_geopackage_and_geojson_as_qgis_would(exported: dict[str, Path]) -> None:
    import pyogrio
    from pyogrio.raw import read

    layers = {str(name): str(kind) for name, kind in pyogrio.list_layers(exported["gpkg"])}
    assert layers == {
        "balises": "Point",
        "feature_points": "Point",
        "gis_points": "Point Z",
        "gis_lines": "LineString",
        "tracks": "LineString",
        "km_posts": "Point",
    }
    info = pyogrio.read_info(exported["gpkg"], layer="balises")
    assert info["crs"] == "EPSG:6668" and info["features"] == 31 and "station_code" in list(info["fields"])
    _, _, geoms, fields = read(exported["gpkg"], layer="feature_points", columns=["feature_id", "km_m"])
    assert len(geoms) == 108 and all(shapely.from_wkb(g).geom_type == "Point" for g in geoms)
    assert sorted(set(fields[0].tolist()))[:2] == ["F001", "F002"] and float(fields[1].max()) > 29_000
    gj = pyogrio.read_info(exported["geojson"])
    assert gj["features"] == 31 + 108 + 1500 + 2 + 2 + 30 and gj["crs"] == "EPSG:4326"


def test_geoparquet_metadata_and_wkb(exported: dict[str, Path]) -> None:
    import pyarrow.parquet as pq

    t = pq.read_table(exported["geoparquet"])
    geo = json.loads(t.schema.metadata[b"geo"])
    assert geo["version"] == "1.1.0" and geo["primary_column"] == "geometry"
    col = geo["columns"]["geometry"]
    assert col["encoding"] == "WKB" and set(col["geometry_types"]) == {"Point", "Point Z", "LineString"}
    assert col["crs"]["id"] == {"authority": "EPSG", "code": 6668}
    frame = t.to_pandas()
    assert len(frame) == 31 + 108 + 1500 + 2
    g = shapely.from_wkb(frame.loc[frame["layer"] == "gis_points", "geometry"].iloc[0])
    assert g.has_z and 139 < g.x < 140 and col["bbox"][0] <= g.x <= col["bbox"][2]


def test_existing_output_refused(exported: dict[str, Path], sample_db: Path) -> None:
    with pytest.raises(RefusedError):
        export_network(sample_db, exported["gpkg"], ExportFormat.gpkg)
