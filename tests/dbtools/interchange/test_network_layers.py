"""``db export --format gpkg|geojson``: the network layers (tracks, switches, connections,
balise_groups, km_posts) as GDAL reads them (pyogrio, as QGIS would)."""

from __future__ import annotations

import json
import warnings
import zipfile
from pathlib import Path

import pandas as pd
import pyogrio
import pytest
import shapely

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.interchange.export import ExportFormat, export_network
from dbtools.interchange.rtm_import import import_rtm_geojson
from schemas.errors import RefusedError
from tests.dbtools.interchange.rtm_samples import KVG

NE_01FA = "_netelement_01fadff1-852a-4137-b141-867cfc91d09a_0.0"
#: Two balises of one ETCS group (NID_C 76, NID_BG 1001) on a track without km: their km is
#: the distance from the track's begin.
G_BALISES = (
    "balise_id,kind,line_code,station_code,track,signal_type,km_actual_m,km_equipment_m,dist_from_initial_m,"
    "track_id,nid_c,nid_bg,n_pig,n_total,link_group,link_distance_m\n"
    f"BG1-0,G,,,,,10.0,10.0,,{NE_01FA},76,1001,0,2,,\n"
    f"BG1-1,G,,,,,13.0,13.0,,{NE_01FA},76,1001,1,2,,\n"
)


@pytest.fixture(scope="module")
def kvg_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("layers")
    import_rtm_geojson(KVG, d / "src")
    (d / "src" / "balises.csv").write_text(G_BALISES, encoding="utf-8")
    build_db(d / "src", d / "kvg.sqlite", db_version="kvg")
    return d / "kvg.sqlite"


def _frame(path: Path, layer: str) -> pd.DataFrame:
    """A layer's attributes and shapely geometry, read by GDAL (pyogrio without geopandas)."""
    from pyogrio.raw import read

    meta, _, geoms, fields = read(path, layer=layer)
    frame = pd.DataFrame({str(n): f for n, f in zip(meta["fields"], fields, strict=True)})
    frame["geometry"] = [None if g is None else shapely.from_wkb(g) for g in geoms]
    return frame


def _read_all(path: Path) -> dict[str, tuple[str, int]]:
    """Every layer of a file with its geometry type and feature count; any GDAL warning fails."""
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name, kind in pyogrio.list_layers(path):
            info = pyogrio.read_info(path, layer=name)
            frame = _frame(path, str(name))
            assert len(frame) == info["features"] and info["crs"] == "EPSG:4326"
            out[str(name)] = (str(kind), int(info["features"]))
    return out


def test_geopackage_layers(kvg_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "kvg.gpkg"
    counts = export_network(kvg_db, out, ExportFormat.gpkg)
    layers = _read_all(out)
    assert layers == {
        "tracks": ("LineString", 99),
        "switches": ("Point", 55),
        "connections": ("Point", 182),
        "balise_groups": ("Point", 2),
        "balises": ("Point", 2),
    }
    assert counts == {k: v[1] for k, v in layers.items()}
    sw = _frame(out, "switches")
    assert {"switch_id", "type", "switch_number", "diverging_side", "km_m"} <= set(sw.columns)
    assert set(sw["diverging_side"].dropna()) <= {"left", "right"}
    info = pyogrio.read_info(out, layer="switches")
    types = dict(zip(info["fields"], info["dtypes"], strict=True))
    assert types["switch_number"] == "float64" and types["diverging_radius_m"] == "float64"  # all null, still REAL
    conns = _frame(out, "connections")
    assert {"track_a", "end_a", "track_b", "end_b", "navigability", "switch_id"} <= set(conns.columns)


def test_connection_and_switch_points_lie_at_the_node(kvg_db: Path, tmp_path: Path) -> None:
    """A switch's point is its toe; a connection's is track A's end: the same point where
    track A is the toe (RINF's track ends at a node lie up to a few metres apart)."""
    out = tmp_path / "layers"
    export_network(kvg_db, out, ExportFormat.geojson)
    sw = json.loads((out / "switches.geojson").read_text(encoding="utf-8"))["features"]
    conns = json.loads((out / "connections.geojson").read_text(encoding="utf-8"))["features"]
    toe = {f["properties"]["switch_id"]: f for f in sw}
    n = 0
    for c in conns:
        p = c["properties"]
        s = toe.get(p["switch_id"])
        if s is not None and (p["track_a"], p["end_a"]) == (s["properties"]["a1_track"], s["properties"]["a1_end"]):
            n += 1
            assert c["geometry"]["coordinates"] == s["geometry"]["coordinates"]
    assert n > 0


def test_balise_group_on_a_track_without_km(kvg_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "layers"
    export_network(kvg_db, out, ExportFormat.geojson)
    bg = json.loads((out / "balise_groups.geojson").read_text(encoding="utf-8"))["features"]
    assert [f["properties"]["group"] for f in bg] == ["76:1001", "76:1001"]
    assert [f["properties"]["n_pig"] for f in bg] == [0, 1]
    net = read_network(kvg_db)
    tp = net.track_points[net.track_points["track_id"] == NE_01FA].sort_values("pos_m")
    # 10 m from the begin: halfway between the grid points at 0 and 20 m
    lon, lat = bg[0]["geometry"]["coordinates"]
    assert lon == pytest.approx((tp["lon"].iloc[0] + tp["lon"].iloc[1]) / 2, abs=1e-9)
    assert lat == pytest.approx((tp["lat"].iloc[0] + tp["lat"].iloc[1]) / 2, abs=1e-9)


def test_geojson_folder_zip_and_single_file(kvg_db: Path, tmp_path: Path) -> None:
    folder = tmp_path / "layers"
    counts = export_network(kvg_db, folder, ExportFormat.geojson)
    names = {p.name for p in folder.glob("*.geojson")}
    assert names == {f"{k}.geojson" for k in counts} and counts["tracks"] == 99
    for name in names:
        assert _read_all(folder / name) == {name.removesuffix(".geojson"): _read_all(folder / name)[name[:-8]]}
    z = tmp_path / "layers.zip"
    export_network(kvg_db, z, ExportFormat.geojson)
    with zipfile.ZipFile(z) as zf:
        assert set(zf.namelist()) == names
        tracks = json.loads(zf.read("tracks.geojson"))
    assert tracks["type"] == "FeatureCollection" and len(tracks["features"]) == 99
    one = tmp_path / "one.geojson"
    export_network(kvg_db, one, ExportFormat.geojson)
    layers = pd.Series([f["properties"]["layer"] for f in json.loads(one.read_text())["features"]]).value_counts()
    assert layers.to_dict() == counts
    with pytest.raises(RefusedError):
        export_network(kvg_db, folder, ExportFormat.geojson)


def test_km_posts_of_a_line_grid(sample_db: Path, tmp_path: Path) -> None:
    """The sample's lines run km 16.000–30.980 on U and D: a post at km 16 … 30 on each,
    the km 16 post at the grid point of km 16.000."""
    out = tmp_path / "s.gpkg"
    export_network(sample_db, out, ExportFormat.gpkg)
    posts = _frame(out, "km_posts")
    assert len(posts) == 30 and sorted(set(posts["km"])) == [float(k) for k in range(16, 31)]
    net = read_network(sample_db)
    g = net.gis[(net.gis["track"] == "D") & (net.gis["km_m"] == 16000.0)].iloc[0]
    p = posts[(posts["track"] == "D") & (posts["km"] == 16.0)].geometry.iloc[0]
    assert (p.x, p.y) == pytest.approx((g["lon"], g["lat"]), abs=1e-12)
    tracks = _frame(out, "tracks")
    assert sorted(tracks["track_id"]) == ["0420:D", "0420:U"] and set(tracks["implied"]) == {1}
    assert set(tracks["length_m"]) == {14980.0}
