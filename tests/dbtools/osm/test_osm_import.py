"""OSM import (SPEC §8.1): exact outputs on the hand-made junction, plausible counts on the
real VDE 8.2 and Cologne extracts (© OpenStreetMap contributors, ODbL 1.0), and the
workflow db import → db build → db validate."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st

from dbtools.interchange.osm_import import import_osm
from dbtools.interchange.osm_km import KmModel, _fit, km_chains, parse_position
from schemas.errors import FindingsError, InputError, RefusedError

DATA = Path(__file__).resolve().parents[2] / "data" / "osm"
JUNCTION = DATA / "junction.osm"
VDE = DATA / "vde8.2-rail.osm.pbf"
COLOGNE = DATA / "cologne-railway.osm.pbf"


def _read(folder: Path, name: str) -> pd.DataFrame:
    return pd.read_csv(folder / f"{name}.csv", dtype={"line_code": str, "track": str, "name": str})


@pytest.fixture(scope="module")
def junction(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("osm") / "junction"
    import_osm(JUNCTION, out)
    return out


@pytest.fixture(scope="module")
def vde(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("osm") / "vde"
    import_osm(VDE, out)
    return out


@pytest.mark.parametrize(
    ("text", "metres"),
    [
        ("12.3", 12300.0),
        ("12,3", 12300.0),
        ("km 12.3", 12300.0),
        ("12.3 km", 12300.0),
        ("12+345", 12345.0),
        ("-0.2", -200.0),
        ("0+050", 50.0),
        ("12.345", 12345.0),
    ],
)
def test_positions_are_read_in_their_usual_forms(text: str, metres: float) -> None:
    assert parse_position(text) == pytest.approx(metres)


@pytest.mark.parametrize("text", [None, "", "mi:12.3", "12.3;4.5", "abc"])
def test_other_positions_are_not_read(text: str | None) -> None:
    assert parse_position(text) is None


def test_tracks_are_split_at_switches_with_traceable_ids(junction: Path) -> None:
    t = _read(junction, "tracks").set_index("track_id")
    assert sorted(t.index) == ["w101_1", "w101_2", "w101_3", "w102", "w103_1", "w103_2", "w104"]
    # lengths: the local metres (geodesic vs UTM grid at E 650 000: scale 0.99988)
    expect = {"w101_1": 500, "w101_2": 300, "w101_3": 200, "w103_1": 700, "w103_2": 300, "w104": np.hypot(100, 5)}
    for tid, length in expect.items():
        assert t.loc[tid, "length_m"] == pytest.approx(length, abs=0.15)
    assert t.loc["w102", "length_m"] == pytest.approx(np.hypot(100, 30) + np.hypot(200, 50), abs=0.1)
    kinds = t["kind"].to_dict()
    assert kinds["w101_1"] == "station" and kinds["w103_1"] == "main"  # track_ref without service → station
    assert kinds["w102"] == "siding" and kinds["w104"] == "crossover"
    assert t.loc["w101_1", "line_code"] == "6340" and t.loc["w101_1", "track"] == "1"
    assert pd.isna(t.loc["w102", "line_code"])
    assert t["end_buffer_stop"].to_dict()["w102"] is True or t.loc["w102", "end_buffer_stop"] == 1
    assert t["end_buffer_stop"].isna().sum() == 6 and t["begin_buffer_stop"].isna().all()


def test_switch_ports_sides_and_navigability(junction: Path) -> None:
    sw = _read(junction, "switches").set_index("switch_id")
    ports = {s: tuple(sw.loc[s, [f"{p}_{c}" for p in ("a1", "b1", "b2") for c in ("track", "end")]]) for s in sw.index}
    # n2 at x=500: toe from the west, the siding leaves north = left seen eastwards
    assert ports["n2"] == ("w101_1", "end", "w102", "begin", "w101_2", "begin")
    # n4 at x=800: the crossover arrives from the south-west: toe is the east track, seen
    # westwards south is on the left → the crossover is B1
    assert ports["n4"] == ("w101_3", "begin", "w104", "end", "w101_2", "end")
    # n9 at x=700 on the parallel track: the crossover leaves north-east = left seen eastwards
    assert ports["n9"] == ("w103_1", "end", "w104", "begin", "w103_2", "begin")
    assert sw.loc["n2", "diverging_side"] == "left" and sw.loc["n2", "name"] == "W1"
    assert sw.loc["n2", "diverging_radius_m"] == 500 and sw.loc["n2", "diverging_speed_kmh"] == 60
    assert sw.loc["n4", "diverging_side"] == "left" and sw.loc["n9", "diverging_side"] == "left"  # guessed
    assert sw.loc["n2", "line_code"] == "6340" and sw.loc["n2", "km_m"] == pytest.approx(1400, abs=0.2)
    c = _read(junction, "connections")
    nav = {(r.track_a, r.end_a, r.track_b, r.end_b): (r.navigability, r.switch_id) for r in c.itertuples()}
    assert nav[("w101_1", "end", "w102", "begin")] == ("both", "n2")
    assert nav[("w101_1", "end", "w101_2", "begin")] == ("both", "n2")
    assert nav[("w102", "begin", "w101_2", "begin")] == ("none", "n2")
    assert nav[("w104", "end", "w101_2", "end")] == ("none", "n4")
    assert len(c) == 9 and (c["navigability"] == "none").sum() == 3


def test_km_is_interpolated_between_posts_and_breaks_are_reported(junction: Path) -> None:
    tp = _read(junction, "track_points")
    own = tp[tp["track_id"] == "w101_1"].set_index("pos_m")["km_m"]
    assert list(own.index[:3]) == [0.0, 20.0, 40.0] and own.index[-1] == pytest.approx(500.06, abs=0.01)
    # posts 1.0 km at 100 m, 1.2 at 300, (0.7 at 400 dropped), 1.35 at 450; 1 m/m beyond
    for pos, km in ((0, 900), (100, 1000), (200, 1100), (300, 1200), (400, 1300), (440, 1340), (480, 1380)):
        assert own[float(pos)] == pytest.approx(km, abs=0.2)
    # the parallel track of the same line (5 m away) takes the posts too, extrapolated beyond
    par = tp[tp["track_id"] == "w103_1"].set_index("pos_m")["km_m"]
    assert par[200.0] == pytest.approx(1100, abs=0.3) and par[600.0] == pytest.approx(1500, abs=0.3)
    # the crossover w104 (line 6340, no post of its own, on no through route) runs from switch
    # n9 (x = 700 on w103: km 1.6) to n4 (x = 800 on w101: km 1.7): anchored at both ends
    cross = tp[tp["track_id"] == "w104"]["km_m"].to_numpy()
    assert cross[0] == pytest.approx(1600, abs=0.3) and cross[-1] == pytest.approx(1700, abs=0.3)
    # the km runs on along the line: through the switch n2 (toe → through branch w101_2),
    # the plain route on through n4 (toe w101_3 → through w101_2) and n9 on the other track
    t = _read(junction, "tracks").set_index("track_id")
    for tid, (k0, k1) in {"w101_2": (1400, 1700), "w101_3": (1700, 1900), "w103_2": (1600, 1900)}.items():
        assert (t.loc[tid, "km_begin_m"], t.loc[tid, "km_end_m"]) == (
            pytest.approx(k0, abs=0.3),
            pytest.approx(k1, abs=0.3),
        )
    report = json.loads((junction / "import_report.json").read_text())
    breaks = [f for f in report["findings"] if f["rule"] == "osm.km_break"]
    assert {f["keys"]["element"] for f in breaks} == {"node/13"} and len(breaks) == 2
    assert t.loc["w101_1", "km_begin_m"] == pytest.approx(900, abs=0.2)
    assert t.loc["w101_1", "km_end_m"] == pytest.approx(1400, abs=0.2)


def test_a_km_jump_between_posts_is_reported() -> None:
    model = KmModel()
    _fit(model, 0, "t", [(0.0, 1000.0, 1, 0.0), (200.0, 1200.0, 2, 0.0), (400.0, 3400.0, 3, 0.0)])
    assert [f.keys["element"] for f in model.findings] == ["node/2,node/3"]
    assert model.at(np.array([0]), np.array([300.0]))[0] == pytest.approx(2300.0)


def test_balise_groups_with_an_identity_become_g_rows(junction: Path) -> None:
    b = _read(junction, "balises")
    assert list(b["balise_id"]) == ["BG1_0", "BG1_1"] and set(b["kind"]) == {"G"}
    assert list(b["n_pig"]) == [0, 1] and set(b["n_total"]) == {2}
    assert set(b["nid_c"]) == {80} and set(b["nid_bg"]) == {1234} and set(b["track_id"]) == {"w101_1"}
    assert b["km_actual_m"].to_numpy() == pytest.approx([1100, 1100], abs=0.2)
    report = json.loads((junction / "import_report.json").read_text())
    rules = {f["rule"]: f for f in report["findings"]}
    assert rules["osm.balise_group"]["keys"]["element"] == "node/16"
    assert rules["osm.excluded"]["keys"]["element"] == "way/105"
    assert (junction / "network.toml").read_text().startswith('metric_crs = "EPSG:32632"')


def test_lines_come_from_line_relations_before_way_refs(junction: Path) -> None:
    lines = _read(junction, "lines")
    # relation 201 (route=railway, ref 6340) names the line; relation 202 (route=train) is a service
    assert lines.to_dict("records") == [{"line_code": "6340", "name": "Testbahn (relation)"}]
    report = json.loads((junction / "import_report.json").read_text())
    guesses = [f["message"] for f in report["findings"] if f["rule"] == "osm.line_guess"]
    assert guesses == ["2 way(s) in no line relation: line from the way's ref"]  # ways 101 and 104


def test_vde_switches_are_all_accounted_for(vde: Path) -> None:
    """908 railway=switch nodes: each is a switch row n<id> or named in a finding."""
    import osmium

    switch_nodes = {
        o.id
        for o in osmium.FileProcessor(str(VDE))
        if isinstance(o, osmium.osm.Node) and o.tags.get("railway") == "switch"
    }
    assert len(switch_nodes) == 908
    sw = _read(vde, "switches")
    rows = {int(s[1:]) for s in sw["switch_id"]}
    report = json.loads((vde / "import_report.json").read_text())
    named = {
        int(e.split("/")[1])
        for f in report["findings"]
        for e in f["keys"].get("element", "").split(",")
        if e.startswith("node/")
    }
    assert switch_nodes <= rows | named
    assert 780 <= len(sw) <= 908  # 799: the rest lie at the extract's edge (2 tracks) or join 4 tracks
    ports = sw[["a1_track", "a1_end"]].astype(str).agg(":".join, axis=1)
    for p in ("b1", "b2"):
        other = sw[[f"{p}_track", f"{p}_end"]].astype(str).agg(":".join, axis=1)
        assert (ports != other).all()
    assert (sw["b1_track"] + sw["b1_end"] != sw["b2_track"] + sw["b2_end"]).all()


def test_vde_switches_checked_by_hand(vde: Path) -> None:
    """Two real switches read off the track points by hand (20 m grid, 40 m from the node):
    * n1291046400 (ref 25, turnout_side=left, 51.39088 N 11.94282 E): the toe track runs
      south-east; seen north-westwards (from the toe) the branch w218917747 at bearing 150.3° (math
      angle, lon scaled by cos φ) lies counter-clockwise of the one at 147.7°, which is
      straight on (toe direction 147.8°): B1 is the left, diverging branch.
    * n1258637704 (ref 92W292, turnout_side=right): the toe runs north; seen southwards the
      branch 11.995212 E lies east (= left) of 11.995202 E; the other turns west (right).
    """
    sw = _read(vde, "switches").set_index("switch_id")
    a = sw.loc["n1291046400"]
    assert (a["a1_track"], a["b1_track"], a["b2_track"]) == ("w218782129_2", "w218917747", "w212812301_2")
    assert a["diverging_side"] == "left" and a["name"] == "25"
    b = sw.loc["n1258637704"]
    assert (b["a1_track"], b["b1_track"], b["b2_track"]) == ("w265277501", "w386699015", "w110108862")
    assert b["diverging_side"] == "right"


def test_vde_counts_and_km(vde: Path) -> None:
    t = _read(vde, "tracks")
    assert len(t) == 2451 and t["track_id"].is_unique  # ways 927446286, 935171552: building outlines, not tracks
    c = _read(vde, "connections")
    assert 3500 <= len(c) <= 3800
    known = set(t["track_id"])
    assert set(c["track_a"]) <= known and set(c["track_b"]) <= known
    # 1,162 of the 1,327 tracks with a line get a km: 473 of their 507 km (the km runs on
    # through plain joints and switches' through branches, a track joining its line at both
    # ends takes the km there; posts are sparse in OSM)
    with_km = t["km_begin_m"].notna()
    assert with_km.sum() >= 1150 and t.loc[with_km, "length_m"].sum() > 470_000
    # along a track the km changes by its length (1 m per m), give or take the posts' spacing
    change = (t["km_end_m"] - t["km_begin_m"]).abs()[with_km]
    assert (np.abs(change - t.loc[with_km, "length_m"]) < 0.1 * t.loc[with_km, "length_m"] + 60).mean() > 0.95
    tp = _read(vde, "track_points")
    steps = tp.groupby("track_id")["pos_m"].diff().dropna()
    assert (steps <= 20.0 + 1e-9).all() and (steps > 0).all()
    ends = tp.groupby("track_id")["pos_m"].max()
    assert np.allclose(ends.reindex(t["track_id"]).to_numpy(), t["length_m"].to_numpy())
    assert t["end_buffer_stop"].notna().sum() + t["begin_buffer_stop"].notna().sum() >= 38


def _switch_nodes(path: Path) -> set[int]:
    import osmium

    return {
        o.id
        for o in osmium.FileProcessor(str(path))
        if isinstance(o, osmium.osm.Node) and o.tags.get("railway") == "switch"
    }


def _rail_nodes(path: Path) -> set[int]:
    import osmium

    return {
        n.ref
        for o in osmium.FileProcessor(str(path))
        if isinstance(o, osmium.osm.Way) and o.tags.get("railway") == "rail"
        for n in o.nodes
    }


def _named_nodes(findings: list[dict[str, Any]]) -> set[int]:
    return {
        int(e.split("/")[1]) for f in findings for e in f["keys"].get("element", "").split(",") if e.startswith("node/")
    }


def test_cologne_imports_and_accounts_for_every_switch(tmp_path: Path) -> None:
    res = import_osm(COLOGNE, tmp_path / "k")
    nodes = _switch_nodes(COLOGNE)
    assert len(nodes) == 3657
    # 2,982 switch rows (19 of them railway=switch nodes where two tracks cross, taken as
    # double slips): the others are on light rail and tram ways (excluded, reported as
    # unplaced), at the extract's edge or where 4 tracks meet in no slip's shape
    assert res.rows["switches"] == 2982
    assert sum(f.rule == "osm.switch_inferred" for f in res.findings) == 19
    sw = pd.read_csv(tmp_path / "k" / "switches.csv")
    rows = {int(s[1:]) for s in sw["switch_id"]}
    report = json.loads((tmp_path / "k" / "import_report.json").read_text())
    unplaced = [f for f in report["findings"] if f["rule"] == "osm.unplaced" and "railway=switch" in f["message"]]
    assert len(unplaced) == 1 and unplaced[0]["value"] > 300  # listed ids are capped: the count is exact
    listed = _named_nodes(report["findings"])
    on_rail = _rail_nodes(COLOGNE)
    assert unplaced[0]["value"] == len(nodes - on_rail)  # switches on no railway=rail way
    assert nodes - rows - listed <= nodes - on_rail  # every other switch is a row or named
    excluded = [f for f in res.findings if f.rule == "osm.excluded"]
    assert any("railway=tram" in f.message for f in excluded)
    assert set(sw["type"]) <= {"point", "crossing", "single_slip", "double_slip"}


def test_refusals_and_errors(tmp_path: Path, junction: Path) -> None:
    with pytest.raises(RefusedError):
        import_osm(JUNCTION, junction)
    no_rail = tmp_path / "tram.osm"
    no_rail.write_text(
        '<osm version="0.6"><node id="1" lat="51" lon="11"/><node id="2" lat="51.001" lon="11"/>'
        '<way id="5"><nd ref="1"/><nd ref="2"/><tag k="railway" v="tram"/></way></osm>'
    )
    with pytest.raises(FindingsError) as err:
        import_osm(no_rail, tmp_path / "o1")
    assert err.value.exit_code == 1 and not (tmp_path / "o1").exists()
    cut = tmp_path / "cut.osm"
    cut.write_text(
        '<osm version="0.6"><node id="1" lat="51" lon="11"/><way id="7"><nd ref="1"/><nd ref="9"/>'
        '<tag k="railway" v="rail"/></way></osm>'
    )
    with pytest.raises(FindingsError) as err2:
        import_osm(cut, tmp_path / "o2")
    assert any(f.keys.get("element") == "way/7" for f in err2.value.findings)
    bad = tmp_path / "bad.osm.pbf"
    bad.write_bytes(b"not a pbf")
    with pytest.raises(InputError):
        import_osm(bad, tmp_path / "o3")


def test_km_chains_follow_links_through_reversed_ways() -> None:
    # 0 → 1 (drawn the other way: end meets end) → 2 (begin meets 1's begin); 3 has another line
    links = {(0, "end"): (1, "end"), (1, "end"): (0, "end"), (1, "begin"): (2, "begin"), (2, "begin"): (1, "begin")}
    links |= {(2, "end"): (3, "begin"), (3, "begin"): (2, "end")}
    chains = km_chains(4, ["L", "L", "L", "M"], links)
    assert chains == [[(0, True), (1, False), (2, True)], [(3, True)]]
    # met first in its middle (track 0 lies between 1 and 2), the chain is found whole, from its start
    mid = {(1, "end"): (0, "begin"), (0, "begin"): (1, "end"), (0, "end"): (2, "begin"), (2, "begin"): (0, "end")}
    assert km_chains(3, ["L", "L", "L"], mid) == [[(1, True), (0, True), (2, True)]]


@given(st.integers(0, 999), st.integers(0, 999))
def test_km_plus_metres_and_decimal_km_agree(km: int, m: int) -> None:
    assert parse_position(f"{km}+{m:03d}") == parse_position(f"{km}.{m:03d}") == pytest.approx(km * 1000 + m)
    assert parse_position(f"km {km},{m:03d}") == pytest.approx(km * 1000 + m)


@given(st.floats(0, 2 * np.pi), st.floats(1.0, 20.0), st.booleans(), st.permutations([0, 1, 2]))
def test_point_switch_ports_do_not_depend_on_rotation_or_order(
    theta: float, angle_deg: float, diverge_left: bool, order: list[int]
) -> None:
    """A turnout rotated anywhere, its ends listed in any order: the toe is A1, the branch
    turning counter-clockwise (seen from the toe) is B1, and the guessed diverging side is
    the branch that turns."""
    from dbtools.interchange.osm_switches import Junctions, _point

    a = np.radians(angle_deg) * (1 if diverge_left else -1)

    def end(name: str, phi: float) -> tuple[str, str, float, float]:
        return (name, "begin", float(np.cos(phi)), float(np.sin(phi)))

    ends = [end("toe", theta + np.pi), end("through", theta), end("diverging", theta + a)]
    j = Junctions()
    _point(j, 1, {}, [ends[i] for i in order], 0.0, 0.0)
    (row,) = j.switches
    left, right = ("diverging", "through") if diverge_left else ("through", "diverging")
    assert (row["a1_track"], row["b1_track"], row["b2_track"]) == ("toe", left, right)
    assert row["diverging_side"] == ("left" if diverge_left else "right")
    nav = {(c["track_a"], c["track_b"]): c["navigability"] for c in j.connections}
    assert nav == {("toe", left): "both", ("toe", right): "both", (left, right): "none"}
