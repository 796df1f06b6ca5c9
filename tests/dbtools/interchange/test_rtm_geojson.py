"""``db import --format rtm-geojson`` and ``db export --format rtm-geojson``: tp-lib's
RailTopoModel GeoJSON (tests/data/tp-lib, Apache-2.0) and hand-made networks."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

import pandas as pd
import pytest
from pyproj import Geod

from dbtools.build import build_db
from dbtools.interchange.export import ExportFormat, export_network
from dbtools.interchange.rtm_import import import_rtm_geojson
from dbtools.validate import validate_path
from schemas.enums import Severity, SwitchType
from schemas.errors import FindingsError, InputError, RefusedError
from schemas.network import SWITCH_ROUTES
from tests.dbtools.interchange.rtm_samples import (
    E0,
    KVG,
    N0,
    SAMPLE,
    collection,
    element,
    relation,
    turnout_features,
    write,
)

GEOD = Geod(ellps="WGS84")
K0 = 0.9996  # UTM scale factor on the central meridian
NE_00B6 = "_netelement_00b6f74b-7ca0-428e-a2d2-c2f5f5452310_0.0"
NE_0FA9 = "_netelement_0fa90553-f256-4ef2-ad39-f27ef2de68a5_0.11291494"
NE_01FA = "_netelement_01fadff1-852a-4137-b141-867cfc91d09a_0.0"
NE_F9C4 = "_netelement_f9c4d558-c756-469d-a9f9-f6ce4c4506c2_0.13198151"
NE_FF1F = "_netelement_ff1fd959-89d3-4ff4-abe1-6564e4fca9dc_0.0"
NE_01FA_2 = "_netelement_01fadff1-852a-4137-b141-867cfc91d09a_0.11093652"


def csv(folder: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(folder / f"{name}.csv", dtype={"track_id": str, "track_a": str, "track_b": str})


@pytest.fixture(scope="module")
def kvg(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("kvg") / "src"
    import_rtm_geojson(KVG, out)
    return out


def test_tp_lib_sample_network(tmp_path: Path) -> None:
    r = import_rtm_geojson(SAMPLE, tmp_path / "src")
    assert r.findings == [] and r.netelements_seen == 2 and r.netrelations_seen == 0 and r.crs == "EPSG:4326"
    tracks = csv(tmp_path / "src", "tracks").set_index("track_id")
    assert list(tracks.index) == ["NE001", "NE002"] and list(tracks["name"]) == ["Track 1", "Track 2"]
    # NE001 (4.3510, 50.8500) → (4.3530, 50.8510): 0.001° of latitude ≈ 111.2 m north and
    # 0.002° of longitude ≈ 0.002 · 111.3 km · cos 50.85° ≈ 140.5 m east: ≈ 179.2 m
    ne001 = GEOD.inv(4.3510, 50.8500, 4.3530, 50.8510)[2]
    assert tracks.loc["NE001", "length_m"] == pytest.approx(ne001, abs=1e-3)
    assert ne001 == pytest.approx((111.2**2 + 140.5**2) ** 0.5, abs=0.5)
    pts = csv(tmp_path / "src", "track_points")
    ne1 = pts[pts["track_id"] == "NE001"]
    assert list(ne1["pos_m"])[:-1] == [20.0 * i for i in range(9)]  # 0 … 160 m, then the end
    assert ne1["pos_m"].iloc[-1] == pytest.approx(ne001, abs=1e-3)
    assert (ne1["lon"].iloc[-1], ne1["lat"].iloc[-1]) == (4.3530, 50.8510)
    assert len(pts) == 10 + 7  # NE002 is ≈ 105 m long: 0 … 100 m and its end
    for name in ("gis", "balises", "feature_points"):  # header only
        assert (tmp_path / "src" / f"{name}.csv").read_text(encoding="utf-8").count("\n") == 1
    report = json.loads((tmp_path / "src" / "import_report.json").read_text(encoding="utf-8"))
    assert report["format"] == "rtm-geojson" and report["inferred"]["switches"] == 0


def test_rinf_kvg_counts_ids_and_lengths(kvg: Path) -> None:
    tracks, conns, sw = csv(kvg, "tracks"), csv(kvg, "connections"), csv(kvg, "switches")
    assert len(tracks) == 99 and tracks["track_id"].str.startswith("_netelement_").all()
    # 364 netrelations, each listed from both of its sides: 182 connections
    assert len(conns) == 182 and set(conns["navigability"]) == {"both", "none"}
    report = json.loads((kvg / "import_report.json").read_text(encoding="utf-8"))
    assert report["features"] == {"netelements": 99, "netrelations": 364} and report["relations_listed_twice"] == 182
    # the first netelement: two vertices (11.98732, 60.190313) → (11.987807, 60.190143);
    # by hand 0.00017° south ≈ 18.9 m, 0.000487° east ≈ 0.000487 · 111.3 km · cos 60.19° ≈ 26.9 m
    own = GEOD.inv(11.98732, 60.190313, 11.987807, 60.190143)[2]
    assert tracks.set_index("track_id").loc[NE_00B6, "length_m"] == pytest.approx(own, abs=1e-3)
    assert own == pytest.approx((18.9**2 + 26.9**2) ** 0.5, abs=0.3)
    # _netrelation_539ca81d…: A = 00b6… positionOnA 1, B = 0fa9… positionOnB 0, both
    c = conns.set_index(["track_a", "end_a", "track_b", "end_b"])
    assert c.loc[(NE_00B6, "end", NE_0FA9, "begin"), "navigability"] == "both"
    # _netrelation_not_navigable_…01fadff1…_f9c4d558…: both at position 0, none
    assert c.loc[(NE_01FA, "begin", NE_F9C4, "begin"), "navigability"] == "none"
    assert sw["type"].value_counts().to_dict() == {"point": 53, "double_slip": 2}
    # by hand at the end of 01fadff1…_0.0 (12.003491, 60.187778): its last segment heads
    # (0.000273° · cos 60.19°, 0.000008°); ff1fd959…'s first turns 2.89° counter-clockwise
    # from that (left, diverging), 01fadff1…_0.11093652's first 0.06° clockwise (through)
    s = sw.set_index("switch_id").loc[f"switch:{NE_01FA}:end"]
    assert (s["b1_track"], s["b1_end"], s["diverging_side"]) == (NE_FF1F, "begin", "left")
    assert (s["b2_track"], s["b2_end"]) == (NE_01FA_2, "begin")
    # the node at the end of 6ffafb60…: four ends, each of one side joined to both of the
    # other (both), the two of a side joined by none: a double slip, not a point switch
    d = sw.set_index("switch_id").loc["switch:_netelement_6ffafb60-df00-4dba-805b-c460839400d8_0.0:end"]
    assert d["type"] == "double_slip" and d["a2_track"] == "_netelement_d5b44b60-686f-465f-b044-f7ca3acb0362_0.0"
    assert report["findings"] == []
    # every inferred switch: the connections among its ports carry its id — a point switch
    # toe ↔ branches navigable and none between the branches, a double slip four and two
    for s in sw.to_dict("records"):
        mine = conns[conns["switch_id"] == s["switch_id"]]
        want = ["both", "both", "none"] if s["type"] == "point" else ["both"] * 4 + ["none"] * 2
        assert sorted(mine["navigability"]) == want
        ends = {(s[f"{p}_track"], s[f"{p}_end"]) for p in ("a1", "b1", "b2", "a2")}
        assert {(r["track_a"], r["end_a"]) for r in mine.to_dict("records")} <= ends


def test_rinf_kvg_builds_and_validates(kvg: Path, tmp_path: Path) -> None:
    db = tmp_path / "kvg.sqlite"
    build_db(kvg, db, db_version="kvg")
    findings = validate_path(db)
    # the RINF extract's own errors (docs/howto/import-geojson.md): a 2 m "-link" netelement
    # between two switches, two nodes of three ends without the `none` relation of a switch
    errors = Counter(f.rule for f in findings if f.severity == Severity.ERROR)
    assert errors == {"topology.gap": 4, "topology.multiple_connections": 4, "topology.switch_overlap": 2}, errors
    (gis,) = [f for f in findings if f.rule == "schema.empty_table" and f.table == "gis"]
    assert gis.severity == Severity.WARNING and "own centrelines (track_points)" in gis.message


def test_projected_crs_turnout_and_inferred_switch(tmp_path: Path) -> None:
    src = write(tmp_path / "t.geojson", collection(turnout_features()))
    r = import_rtm_geojson(src, tmp_path / "out")
    assert r.findings == [] and r.crs == "EPSG:25832"
    pts = csv(tmp_path / "out", "track_points")
    t0 = pts[(pts["track_id"] == "T") & (pts["pos_m"] == 0.0)].iloc[0]
    # easting 500 000 is the central meridian of UTM 32: 9° E exactly; there the northing is
    # k0 · the meridian arc from the equator (measured here on the ellipsoid, not through PROJ)
    assert t0["lon"] == pytest.approx(9.0, abs=1e-9)
    assert K0 * GEOD.inv(9.0, 0.0, 9.0, t0["lat"])[2] == pytest.approx(N0, abs=0.01)
    tracks = csv(tmp_path / "out", "tracks").set_index("track_id")
    assert tracks.loc["T", "length_m"] == pytest.approx(100.0 / K0, abs=2e-3)  # 100 grid metres
    sw = csv(tmp_path / "out", "switches").iloc[0]
    assert (sw["switch_id"], sw["a1_track"], sw["a1_end"]) == ("switch:T:end", "T", "end")
    assert (sw["b1_track"], sw["b2_track"], sw["diverging_side"]) == ("L", "S", "left")
    conns = csv(tmp_path / "out", "connections")
    assert set(conns["switch_id"]) == {"switch:T:end"}
    assert ("L", "begin", "T", "end", "both") in set(
        conns[["track_a", "end_a", "track_b", "end_b", "navigability"]].itertuples(index=False, name=None)
    )
    assert (tmp_path / "out" / "network.toml").read_text(encoding="utf-8").startswith('metric_crs = "EPSG:25832"')


def test_mirrored_turnout_diverges_right(tmp_path: Path) -> None:
    feats = turnout_features()
    feats[2] = element("L", [[E0 + 100, N0], [E0 + 150, N0 - 2.75], [E0 + 200, N0 - 11]])  # to the south
    r = import_rtm_geojson(write(tmp_path / "t.geojson", collection(feats)), tmp_path / "out")
    sw = csv(tmp_path / "out", "switches").iloc[0]
    assert r.switches_inferred == 1 and (sw["b1_track"], sw["b2_track"], sw["diverging_side"]) == ("S", "L", "right")


def test_bad_features_are_skipped_with_findings(tmp_path: Path) -> None:
    feats = [
        *turnout_features(),
        element(None, [[E0, N0 + 50], [E0 + 10, N0 + 50]]),  # 6: no id
        element("T", [[E0, N0 + 60], [E0 + 10, N0 + 60]]),  # 7: the id again
        relation("r4", "T", 0, "nowhere", 0, "both"),  # 8
        relation("r5", "T", 2, "S", 1, "both"),  # 9
        relation("r6", "T", 0, "S", 1, "sideways"),  # 10
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [E0, N0]}, "properties": {"id": "P"}},
        relation("r7", "S", 1.0, "L", "1", "ab"),  # 12: 1.0, "1" and "ab" accepted; ends 11 m apart
        relation("r8", "T", 0, "S", 1, "both"),  # 13: 200 m apart
    ]
    r = import_rtm_geojson(write(tmp_path / "t.geojson", collection(feats)), tmp_path / "out")
    by_rule = {(f.rule, f.keys.get("feature")): f for f in r.findings}
    assert set(by_rule) == {
        ("rtm.missing_id", 6),
        ("rtm.duplicate_id", 7),
        ("rtm.unknown_netelement", 8),
        ("rtm.position", 9),
        ("rtm.navigability", 10),
        ("rtm.geometry", 11),
        ("rtm.gap", 12),  # 11 m: reported, kept
        ("rtm.gap", 13),
    }
    assert "lie 200.1 m apart" in by_rule[("rtm.gap", 13)].message  # 200 grid metres / k0
    f = by_rule[("rtm.unknown_netelement", 8)]
    assert "feature 8 (id 'r4')" in f.message and "'nowhere'" in f.message and f.column == "netelementB"
    assert "positionOnA is 2, not 0 or 1" in by_rule[("rtm.position", 9)].message
    assert all(f.severity == Severity.WARNING and f.file == str(tmp_path / "t.geojson") for f in r.findings)
    conns = csv(tmp_path / "out", "connections")
    assert len(conns) == 5 and ("S", "end", "L", "end", "AB") in set(
        conns[["track_a", "end_a", "track_b", "end_b", "navigability"]].itertuples(index=False, name=None)
    )


def test_files_that_cannot_be_imported(tmp_path: Path) -> None:
    out = tmp_path / "out"
    bad = tmp_path / "bad.geojson"
    bad.write_text('{"type": "FeatureCollection", "features": [', encoding="utf-8")
    with pytest.raises(InputError, match="invalid JSON"):
        import_rtm_geojson(bad, out)
    write(bad, {"type": "Feature", "geometry": None, "properties": {}})
    with pytest.raises(FindingsError, match="not a GeoJSON FeatureCollection"):
        import_rtm_geojson(bad, out)
    write(bad, collection(turnout_features(), crs="EPSG:999999"))
    with pytest.raises(FindingsError, match="unknown CRS 'EPSG:999999'") as e:
        import_rtm_geojson(bad, out)
    assert [f.rule for f in e.value.findings] == ["rtm.crs"]
    write(bad, collection([element("A", [[E0, N0]]), element(None, [[E0, N0], [E0 + 1, N0]])]))
    with pytest.raises(FindingsError, match="none of the 2 netelement") as e:
        import_rtm_geojson(bad, out)
    assert [f.rule for f in e.value.findings] == ["rtm.geometry", "rtm.missing_id", "rtm.no_netelement"]
    assert not out.exists()
    import_rtm_geojson(SAMPLE, out)
    with pytest.raises(RefusedError):
        import_rtm_geojson(SAMPLE, out)


def test_feature_crs_property_and_rfc7946_default(tmp_path: Path) -> None:
    """No crs member: WGS 84 lon/lat; a feature's own crs property (as RINF writes) wins."""
    feats = [
        element("W", [[9.0, 54.0], [9.001, 54.0]]),
        element("U", [[E0, N0], [E0 + 10, N0]], crs="EPSG:25832"),
        element("X", [[9.0, 54.0], [190.0, 54.0]]),  # longitude beyond 180°
    ]
    r = import_rtm_geojson(write(tmp_path / "t.geojson", collection(feats, crs=None)), tmp_path / "out")
    (f,) = r.findings
    assert (
        f.rule == "rtm.geometry" and "feature 2 (id 'X'): vertex 1 [190.0, 54.0] does not lie on the earth" in f.message
    )
    pts = csv(tmp_path / "out", "track_points").set_index(["track_id", "pos_m"])
    assert pts.loc[("W", 0.0), "lon"] == 9.0 and pts.loc[("U", 0.0), "lon"] == pytest.approx(9.0, abs=1e-9)


def test_round_trip_import_build_export_import(kvg: Path, tmp_path: Path) -> None:
    db = tmp_path / "kvg.sqlite"
    build_db(kvg, db, db_version="kvg")
    out = tmp_path / "kvg.rtm.geojson"
    counts = export_network(db, out, ExportFormat.rtm_geojson)
    assert counts == {"netelements": 99, "netrelations": 182, "tracks_without_geometry": 0, "connections_left_out": 0}
    gj = json.loads(out.read_text(encoding="utf-8"))
    assert gj["crs"]["properties"]["name"] == "EPSG:4326"
    rel = next(f for f in gj["features"] if f["properties"]["type"] == "netrelation")
    assert rel["geometry"]["type"] == "Point" and set(rel["properties"]) >= {
        "netelementA",
        "netelementB",
        "positionOnA",
        "positionOnB",
        "navigability",
    }
    back = tmp_path / "back"
    r = import_rtm_geojson(out, back)
    first = json.loads((kvg / "import_report.json").read_text(encoding="utf-8"))["findings"]
    assert r.findings == [] and first == []
    a, b = csv(kvg, "tracks").set_index("track_id"), csv(back, "tracks").set_index("track_id")
    assert list(a.index) == list(b.index)
    assert (a["length_m"] - b["length_m"]).abs().max() < 0.5
    assert csv(kvg, "connections").equals(csv(back, "connections"))
    cols = [
        "switch_id",
        "type",
        "diverging_side",
        *(f"{p}_{x}" for p in ("a1", "b1", "b2", "a2") for x in ("track", "end")),
    ]
    assert csv(kvg, "switches")[cols].equals(csv(back, "switches")[cols])


def test_tp_lib_sample_round_trip(tmp_path: Path) -> None:
    import_rtm_geojson(SAMPLE, tmp_path / "src")
    build_db(tmp_path / "src", tmp_path / "s.sqlite", db_version="s")
    export_network(tmp_path / "s.sqlite", tmp_path / "s.geojson", ExportFormat.rtm_geojson)
    import_rtm_geojson(tmp_path / "s.geojson", tmp_path / "back")
    a, b = csv(tmp_path / "src", "tracks"), csv(tmp_path / "back", "tracks")
    assert list(a["track_id"]) == list(b["track_id"]) == ["NE001", "NE002"]
    assert (a["length_m"] - b["length_m"]).abs().max() < 0.5


def _slip_features(joins: tuple[tuple[str, str], ...]) -> list[dict[str, object]]:
    """A slip in UTM 32 metres at node (E0 + 100, N0): P comes from the west-south-west and
    Q from the west-north-west; X leaves to the east-north-east (P → X straight on), Y to
    the east-south-east (Q → Y straight on). ``joins``: the navigable ones of P–X, P–Y,
    Q–X, Q–Y; P–Q and X–Y are joined by none."""
    node = [E0 + 100, N0]
    feats: list[dict[str, object]] = [
        element("P", [[E0, N0 - 10], node]),
        element("Q", [[E0, N0 + 10], node]),
        element("X", [node, [E0 + 200, N0 + 10]]),
        element("Y", [node, [E0 + 200, N0 - 10]]),
        relation("pq", "P", 1, "Q", 1, "none"),
        relation("xy", "X", 0, "Y", 0, "none"),
    ]
    pos = {"P": 1, "Q": 1, "X": 0, "Y": 0}
    feats += [relation(a + b, a, pos[a], b, pos[b], "both") for a, b in joins]
    return feats


def test_inferred_double_and_single_slip(tmp_path: Path) -> None:
    both = (("P", "X"), ("P", "Y"), ("Q", "X"), ("Q", "Y"))
    import_rtm_geojson(write(tmp_path / "d.geojson", collection(_slip_features(both))), tmp_path / "d")
    (sw,) = csv(tmp_path / "d", "switches").to_dict("records")
    ports = {p: sw[f"{p}_track"] for p in ("a1", "b1", "a2", "b2")}
    # A1 = P (sorts first), A1–B1 the straight route P → X, A2 = Q, B2 = Y
    assert (sw["type"], sw["switch_id"], ports) == (
        "double_slip",
        "switch:P:end",
        {"a1": "P", "b1": "X", "a2": "Q", "b2": "Y"},
    )
    assert (csv(tmp_path / "d", "connections")["switch_id"] == "switch:P:end").sum() == 6
    # without Q–X: a single slip whose A1 (two routes) is P and A2 = Q with its one route to B2 = Y
    single = (("P", "X"), ("P", "Y"), ("Q", "Y"))
    import_rtm_geojson(write(tmp_path / "s.geojson", collection(_slip_features(single))), tmp_path / "s")
    (sw,) = csv(tmp_path / "s", "switches").to_dict("records")
    ports = {p: sw[f"{p}_track"] for p in ("a1", "b1", "a2", "b2")}
    assert (sw["type"], ports) == ("single_slip", {"a1": "P", "b1": "X", "a2": "Q", "b2": "Y"})
    # the routes of a single slip (schemas.network.SWITCH_ROUTES) are exactly the navigable joins
    routes = {frozenset((ports[u], ports[v])) for u, v in SWITCH_ROUTES[SwitchType.SINGLE_SLIP]}
    assert routes == {frozenset(j) for j in single}
