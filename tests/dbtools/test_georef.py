"""Any railway (issue 22): operating area, metric CRS and height datum — declared in
network.toml or derived — in Japan, Europe, the southern hemisphere, west of Greenwich and
across a UTM zone border; reference values of the projections; the sample network unchanged."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.diff import diff_paths
from dbtools.gis.geometry import Projector
from dbtools.gis.georef import JAPAN, derive, utm_epsg
from dbtools.gis.index import grid_index
from dbtools.gis.matching import track_index_for
from dbtools.network import Network
from dbtools.sources import read_source_set, write_source_set
from dbtools.validate import validate_network, validate_path
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.simulate.networks.alignment import Alignment, Curve
from fieldlogs.simulate.networks.synthetic import LineSpec, Station, build_network, demo_line
from schemas.enums import Severity
from schemas.errors import FindingsError, InputError

SAMPLE = Path(__file__).resolve().parents[2] / "dbtools" / "sample_network" / "sources"

#: WGS 84 ellipsoid.
A_WGS84, F_WGS84 = 6378137.0, 1 / 298.257223563


def test_gsi_worked_example_zone_ix() -> None:
    """GSI's worked example for JGD2011 plane rectangular zone IX (X is GSI's northing)."""
    x, y = Projector(9).to_xy(140.08785504166664, 36.103774791666666)
    assert float(y[()]) == pytest.approx(11543.6883, abs=5e-4)  # GSI X (northing)
    assert float(x[()]) == pytest.approx(22916.2436, abs=5e-4)  # GSI Y (easting)
    lon, lat = Projector(9).to_lonlat(x, y)
    assert float(lat[()]) == pytest.approx(36.103774791666666, abs=1e-10)
    assert float(lon[()]) == pytest.approx(140.08785504166664, abs=1e-10)


def _meridian_arc(lat_deg: float) -> float:
    """Meridian arc length from the equator on WGS 84, by numerical integration of the
    meridional radius M(φ) = a(1 − e²)/(1 − e² sin²φ)^{3/2} (independent of PROJ)."""
    e2 = F_WGS84 * (2 - F_WGS84)
    phi = np.linspace(0.0, math.radians(lat_deg), 20001)
    m = A_WGS84 * (1 - e2) / (1 - e2 * np.sin(phi) ** 2) ** 1.5
    return float(np.sum(0.5 * (m[1:] + m[:-1]) * np.diff(phi)))


@pytest.mark.parametrize(("lat", "zone"), [(45.0, 32), (-33.9, 56), (41.9, 16), (60.2, 35)])
def test_utm_on_the_central_meridian_is_the_scaled_meridian_arc(lat: float, zone: int) -> None:
    """On a UTM central meridian: easting 500 000 m, northing 0.9996 × meridian arc (plus
    10 000 000 m in the south) — hand-computed, not from PROJ."""
    epsg = (32600 if lat >= 0 else 32700) + zone
    cm = -183.0 + 6.0 * zone
    x, y = Projector.from_epsg(epsg).to_xy(cm, lat)
    arc = 0.9996 * _meridian_arc(abs(lat))
    assert float(x[()]) == pytest.approx(500_000.0, abs=1e-6)
    assert float(y[()]) == pytest.approx(arc if lat >= 0 else 10_000_000.0 - arc, abs=1e-3)
    assert utm_epsg(lat, cm) == epsg


@pytest.mark.parametrize(
    ("lat", "lon", "epsg"),
    [
        (35.68, 139.77, 6677),  # Tokyo: zone IX
        (43.06, 141.35, 6680),  # Sapporo: zone XII
        (33.59, 130.40, 6670),  # Fukuoka: zone II
        (45.44, 12.32, 32633),  # Venice
        (45.07, 7.69, 32632),  # Turin
        (-33.87, 151.21, 32756),  # Sydney
        (41.88, -87.63, 32616),  # Chicago
        (-0.18, -78.47, 32717),  # Quito: just south of the equator
        (60.17, 24.94, 32635),  # Helsinki
    ],
)
def test_derived_crs(lat: float, lon: float, epsg: int) -> None:
    g = derive([lat, lat + 0.01], [lon, lon + 0.01])
    assert g is not None and g.crs_epsg == epsg
    assert (g.area == JAPAN) == (epsg < 32600)


def _straight(length_m: float, x0: float, y0: float, heading: float = 0.0) -> Alignment:
    return Alignment(length_m, [Curve(3000.0, 80.0, 400.0, 900.0, True)], x0=x0, y0=y0, heading0=heading)


def _network(epsg: int, x0: float, y0: float, *, straight_m: float | None = None) -> Network:
    if straight_m is None:
        spec = demo_line(x0=x0, y0=y0)
    else:
        a = _straight(straight_m, x0, y0)
        spec = LineSpec("0700", "across", a, [Station("01", "A", 1000.0), Station("02", "B", straight_m - 1000.0)])
    return build_network([spec], Projector.from_epsg(epsg))


def _offset_fixes(net: Network, track: str, offset_m: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Points ``offset_m`` left of the track (perpendicular in the network's plane)."""
    idx = track_index_for(net)
    g = net.gis[net.gis["track"] == track].sort_values("km_m").iloc[100:400:20]
    x, y = idx.to_xy(g["lat"].to_numpy(), g["lon"].to_numpy())
    xa, ya = idx.to_xy(net.gis.loc[g.index + 1, "lat"].to_numpy(), net.gis.loc[g.index + 1, "lon"].to_numpy())
    h = np.arctan2(ya - y, xa - x)
    lon, lat = idx.projector.to_lonlat(x - offset_m * np.sin(h), y + offset_m * np.cos(h))
    return lat, lon, g["km_m"].to_numpy()


@pytest.mark.parametrize(
    ("where", "epsg", "x0", "y0"),
    [
        ("europe", 32632, 500_000.0, 5_000_000.0),  # northern Italy
        ("south", 32756, 330_000.0, 6_250_000.0),  # Sydney
        ("west", 32616, 440_000.0, 4_640_000.0),  # Chicago (negative longitudes)
        ("japan", 6677, 0.0, 0.0),  # zone IX origin
    ],
)
def test_network_anywhere_builds_validates_and_matches(
    where: str, epsg: int, x0: float, y0: float, tmp_path: Path
) -> None:
    net = _network(epsg, x0, y0)
    lat = net.gis["lat"].to_numpy()
    lon = net.gis["lon"].to_numpy()
    assert (lat < 0).all() if where == "south" else (lat > 0).all()
    assert (lon < 0).all() if where == "west" else (lon > 0).all()
    assert validate_network(net) == []
    src = write_source_set(net, tmp_path / "src")
    assert validate_path(src) == []
    build_db(src, tmp_path / "net.sqlite")
    assert validate_path(tmp_path / "net.sqlite") == []
    db = read_network(tmp_path / "net.sqlite")
    assert db.meta["metric_crs"] == f"EPSG:{epsg}" and db.meta["metric_crs_source"] == "declared"
    assert db.meta["area_source"] == "derived" and db.meta["height_datum"] == "ellipsoidal"
    assert grid_index(db).projector == Projector.from_epsg(epsg)
    # 1.5 m left of D: matched on D at the grid km, offset +1.5 (left of increasing km)
    flat, flon, km = _offset_fixes(db, "D", 1.5)
    m = track_index_for(db).match(flat, flon, track="D")
    assert len(m) == len(km)
    assert m["offset_m"].to_numpy() == pytest.approx(1.5, abs=1e-3)
    assert m["km_m"].to_numpy() == pytest.approx(km, abs=0.1)  # off a vertex of a curve: a few cm
    # dead-reckoning metric: geodesic track length, within 0.2 % of the km on this line
    tm = track_metric(db, "0900", "D")
    assert np.all(np.diff(tm.c) > 0)
    assert (tm.c[-1] - tm.c[0]) / (tm.km[-1] - tm.km[0]) == pytest.approx(1.0, abs=2e-3)


def test_network_straddling_a_utm_zone_border(tmp_path: Path) -> None:
    """A 20 km line across 12° E (zones 32 and 33): derived in its median's zone or
    declared in the other, it validates clean and matches the same fixes alike."""
    net = _network(32632, 712_000.0, 5_300_000.0, straight_m=20_000.0)
    lon = net.gis["lon"].to_numpy()
    assert lon.min() < 12.0 < lon.max()
    results = {}
    for name, meta in (("derived", {}), ("declared", {"metric_crs": "EPSG:32633", "metric_crs_source": "declared"})):
        other = Network(dict(net.tables), origin=name, meta=dict(meta))
        src = write_source_set(other, tmp_path / name)
        assert (src / "network.toml").exists() == bool(meta)
        build_db(src, tmp_path / f"{name}.sqlite")
        assert validate_path(tmp_path / f"{name}.sqlite") == []
        db = read_network(tmp_path / f"{name}.sqlite")
        results[name] = db
    assert (
        results["derived"].meta["metric_crs"]
        == f"EPSG:{utm_epsg(float(np.median(net.gis.lat)), float(np.median(lon)))}"
    )
    assert results["declared"].meta["metric_crs"] == "EPSG:32633"
    flat, flon, _ = _offset_fixes(results["derived"], "U", -2.0)
    a = track_index_for(results["derived"]).match(flat, flon, track="U")
    b = track_index_for(results["declared"]).match(flat, flon, track="U")
    assert a["km_m"].to_numpy() == pytest.approx(b["km_m"].to_numpy(), abs=5e-3)
    assert a["offset_m"].to_numpy() == pytest.approx(b["offset_m"].to_numpy(), abs=5e-3)
    assert a["offset_m"].to_numpy() == pytest.approx(-2.0, abs=5e-3)
    # geodesic track length does not depend on the plane at all
    ca = track_metric(results["derived"], "0700", "D").c
    cb = track_metric(results["declared"], "0700", "D").c
    assert np.array_equal(ca, cb)
    rows = diff_paths(tmp_path / "derived.sqlite", tmp_path / "declared.sqlite").summary
    assert any(r.startswith("metric CRS EPSG:") and "(derived) → EPSG:32633 (declared)" in r for r in rows), rows


def _europe_source(tmp_path: Path, toml: str) -> Path:
    src = write_source_set(_network(32632, 500_000.0, 5_000_000.0), tmp_path / "src")
    (src / "network.toml").write_text(toml, encoding="utf-8")
    return src


BOX = "\n[area]\nlat_min = 45.15\nlat_max = 45.26\nlon_min = 8.96\nlon_max = 9.01\n"


def test_declared_area_near_and_far_outside(tmp_path: Path) -> None:
    src = _europe_source(tmp_path, 'metric_crs = "EPSG:32632"\n' + BOX)
    assert validate_path(src) == []
    gis = pd.read_csv(src / "gis.csv", dtype={"line_code": str})
    gis.loc[10, "lat"] = 45.15 - 0.005  # ~560 m south of the box: warning, used
    gis.loc[20, "lon"] = -gis.loc[20, "lon"]  # a lost sign: ~1400 km away, error
    gis.to_csv(src / "gis.csv", index=False)
    found = validate_path(src)
    near = [f for f in found if f.rule == "gis.outside_area"]
    far = [f for f in found if f.rule == "schema.range"]
    assert [(f.severity, f.row, f.column) for f in near] == [(Severity.WARNING, 12, "lat")]
    assert [(f.severity, f.row, f.column) for f in far] == [(Severity.ERROR, 22, "lon")]
    assert " m outside the declared operating area" in near[0].message
    assert " km outside the declared operating area" in far[0].message
    with pytest.raises(FindingsError):
        build_db(src, tmp_path / "net.sqlite")


def test_derived_area_keeps_a_far_point_out(tmp_path: Path) -> None:
    """Derived outside Japan, the area is the extent of the points within 1,000 km of the
    median: a point with a lost sign is not absorbed into it."""
    net = _network(32616, 440_000.0, 4_640_000.0)
    g = net.gis.copy()
    g.loc[7, "lon"] = -g.loc[7, "lon"]  # Chicago → Mongolia
    net.tables["gis"] = g
    net.meta = {}
    found = validate_network(net)
    assert [f.rule for f in found if f.severity == Severity.ERROR][:1] == ["schema.range"]
    assert any(f.rule == "gis.km_step" for f in found)  # the point is left out of the grid


def test_heights_declared_and_shown_in_diff(tmp_path: Path) -> None:
    plain = write_source_set(_network(32632, 500_000.0, 5_000_000.0), tmp_path / "plain")
    build_db(plain, tmp_path / "a.sqlite")
    src = _europe_source(
        tmp_path, 'metric_crs = "EPSG:32632"\nheight_datum = "orthometric"\ngeoid_model = "ITALGEO2005"\n'
    )
    build_db(src, tmp_path / "b.sqlite")
    meta = read_network(tmp_path / "b.sqlite").meta
    assert (meta["height_datum"], meta["geoid_model"]) == ("orthometric", "ITALGEO2005")
    assert (
        "height datum ellipsoidal → orthometric (ITALGEO2005)"
        in diff_paths(tmp_path / "a.sqlite", tmp_path / "b.sqlite").summary
    )
    net, _ = read_source_set(src)
    assert write_source_set(net, tmp_path / "again").joinpath("network.toml").read_text().count("ITALGEO2005") == 1


@pytest.mark.parametrize(
    ("toml", "says"),
    [
        ('metric_crs = "EPSG:4326"\n', "not a projected CRS in metres"),
        ('metric_crs = "EPSG:999999"\n', "not an EPSG code"),
        ('height_datum = "orthometric"\n', "needs geoid_model"),
        ('height_datum = "normal"\n', "neither"),
        ("crs = 32632\n", "unknown key"),
        ("[area]\nlat_min = 46\nlat_max = 45\nlon_min = 8\nlon_max = 9\n", "min < max"),
        ("[area]\nlat_min = 45\n", "missing"),
        ("metric_crs = [\n", "not valid TOML"),
    ],
)
def test_bad_declarations_are_one_line_input_errors(tmp_path: Path, toml: str, says: str) -> None:
    src = _europe_source(tmp_path, toml)
    with pytest.raises(InputError, match=says) as err:
        read_source_set(src)
    assert "network.toml" in str(err.value.path) and "\n" not in str(err.value)


def test_sample_network_figures_unchanged(tmp_path: Path) -> None:
    """The sample network in Japan: derived zone IX and the JGD2011 box, and the grid
    figures of the index as computed before areas and CRSs could be declared."""
    net, findings = read_source_set(SAMPLE)
    assert findings == [] and validate_network(net, schema_checks=False) == []
    gi = grid_index(net)
    assert gi.projector == Projector(9)
    assert gi.georef is not None and gi.georef.area == JAPAN
    assert (float(gi.x[0]), float(gi.y[0])) == (-31526.871639973608, -10379.404333131379)
    assert track_index_for(net).n_vertices == 1500
    shape = gi.shape(20.0, 1e-3)
    assert float(np.nansum(np.abs(shape.kappa))) == pytest.approx(0.46259015412703386, rel=1e-12)
    assert float(np.nanmax(np.abs(shape.turn))) == pytest.approx(0.067821680924117, rel=1e-12)
    for track, length, rail in (
        ("D", 14975.569486778033, 14975.978533971516),
        ("U", 14986.565007804697, 14986.97567912706),
    ):
        t = gi.track_id("0420", track)
        assert t is not None
        assert float(gi.dist[gi.start[t] : gi.end[t] - 1].sum()) == pytest.approx(length, rel=1e-12)  # geodesic
        tm = track_metric(net, "0420", track)
        # the 3-D rail (issue 19): + rail height 55–95 m 0.169 m, + arcs over chords 0.156 m,
        # + gradients ≤ 5.3 ‰ 0.084 m
        assert float(tm.c[-1] - tm.c[0]) == pytest.approx(rail, rel=1e-12)
    shutil.copytree(SAMPLE, tmp_path / "src")
    build_db(tmp_path / "src", tmp_path / "net.sqlite")
    meta = read_network(tmp_path / "net.sqlite").meta
    assert meta["metric_crs"] == "EPSG:6677" and meta["metric_crs_source"] == "derived"
    assert json.loads(meta["area"]) == {"lat_min": 20.0, "lat_max": 46.0, "lon_min": 122.0, "lon_max": 154.0}


def test_declared_polygon_area(tmp_path: Path) -> None:
    """A polygon area: a point inside its bounding box but ~1.4 km beyond its slanted edge
    is a warning, the same point 25 km out an error; the polygon survives db build and a
    rewrite of the source set."""
    poly = "[[8.9, 45.1], [9.1, 45.1], [9.1, 45.3], [8.9, 45.3], [8.9, 45.2]]"
    src = _europe_source(tmp_path, f"[area]\npolygon = {poly}\n")
    assert validate_path(src) == []
    gis = pd.read_csv(src / "gis.csv", dtype={"line_code": str})
    gis.loc[3, ["lat", "lon"]] = [45.2, 8.9 - 0.018]  # 1.4 km west of the western edge
    gis.loc[4, ["lat", "lon"]] = [45.2, 8.9 - 0.32]  # 25 km west
    gis.to_csv(src / "gis.csv", index=False)
    found = {(f.rule, f.row) for f in validate_path(src) if f.rule in ("schema.range", "gis.outside_area")}
    assert found == {("gis.outside_area", 5), ("schema.range", 6)}
    gis.drop(index=[3, 4]).to_csv(src / "gis.csv", index=False)
    build_db(src, tmp_path / "net.sqlite")
    db = read_network(tmp_path / "net.sqlite")
    assert json.loads(db.meta["area"])["polygon"][0] == [8.9, 45.1] and db.meta["area_source"] == "declared"
    again = write_source_set(db, tmp_path / "again")
    assert read_source_set(again)[0].meta["area"] == db.meta["area"]
