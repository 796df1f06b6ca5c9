"""Topology and balise-group rules (``dbtools.rules.topology``, ``dbtools.rules.balise_groups``):
the hand-made networks validate clean; a copy broken in one place fails exactly the rule
that guards it."""

from __future__ import annotations

import shutil
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import Network, canonical, empty_frame
from dbtools.rules.common import Locator
from dbtools.rules.config import ValidationConfig
from dbtools.rules.topology import check_topology
from dbtools.validate import validate_path
from schemas.findings import Finding
from schemas.tables import DB_TABLES
from tests.dbtools.test_networks_data import generator as _generator

NETWORKS = Path(__file__).resolve().parents[1] / "data" / "networks"
NAMES = ("junction", "crossover", "station4", "double_slip")
Tables = dict[str, pd.DataFrame]
#: Lat/lon offset of 5 m north [deg] (1° of latitude ≈ 111.4 km at 60°N).
FIVE_M_NORTH = 5.0 / 111_412.0


@pytest.mark.parametrize("name", NAMES)
def test_hand_made_networks_are_clean(name: str) -> None:
    assert validate_path(NETWORKS / name) == []


def broken(tmp_path: Path, name: str, edit: Callable[[Tables], None]) -> list[Finding]:
    """Validate a copy of network ``name`` whose CSV tables ``edit`` changed (as text)."""
    dst = tmp_path / name
    shutil.copytree(NETWORKS / name, dst)
    tables = {
        p.stem: pd.read_csv(p, dtype=str, keep_default_na=False)
        for p in dst.glob("*.csv")
        if p.stem != "feature_points"
    }
    edit(tables)
    for stem, frame in tables.items():
        frame.to_csv(dst / f"{stem}.csv", index=False, lineterminator="\n")
    return validate_path(dst)


def rules(findings: list[Finding]) -> set[str]:
    return {f.rule for f in findings}


def add(frame: pd.DataFrame, **row: str) -> pd.DataFrame:
    return pd.concat([frame, pd.DataFrame([{c: row.get(c, "") for c in frame.columns}])], ignore_index=True)


def where(frame: pd.DataFrame, **eq: str) -> pd.Series:
    m = pd.Series(True, index=frame.index)
    for k, v in eq.items():
        m &= frame[k] == v
    assert m.any(), eq
    return m


def test_invalid_reference_names_file_and_line(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        tp = t["track_points"]
        tp.loc[where(tp, track_id="X1", pos_m="20"), "track_id"] = "X9"

    f = broken(tmp_path, "crossover", edit)
    assert rules(f) == {"topology.invalid_reference"}
    assert f[0].file and f[0].file.endswith("track_points.csv") and f[0].row is not None and "X9" in f[0].message


def test_invalid_reference_balise_track(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        b = t["balises"]
        b.loc[where(b, balise_id="BG1.0"), "track_id"] = "nowhere"

    assert rules(broken(tmp_path, "junction", edit)) == {"topology.invalid_reference"}


def test_switch_port_used_twice(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        s = t["switches"]
        s.loc[where(s, switch_id="W1"), ["b2_track", "b2_end"]] = ["B1", "begin"]

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.switch_port"}
    assert any("two ports" in x.message for x in f) and any("none of its ports" in x.message for x in f)


def test_switch_port_missing_a2_of_double_slip(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        s = t["switches"]
        s.loc[where(s, switch_id="DS1"), ["a2_track", "a2_end"]] = ["", ""]

    f = broken(tmp_path, "double_slip", edit)
    assert "topology.switch_port" in rules(f)
    assert any("needs port A2" in x.message for x in f)


def test_navigability_branch_to_branch(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        c = t["connections"]
        c.loc[where(c, navigability="none"), "navigability"] = "both"

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.navigability"}
    assert f[0].column == "navigability"


def test_navigability_route_not_navigable(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        c = t["connections"]
        c.loc[where(c, track_a="P1", track_b="Q2"), "navigability"] = "none"

    assert rules(broken(tmp_path, "double_slip", edit)) == {"topology.navigability"}


def test_multiple_connections_without_switch(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        t["connections"] = add(
            t["connections"], track_a="A2", end_a="begin", track_b="A1", end_b="end", navigability="both"
        )

    assert rules(broken(tmp_path, "junction", edit)) == {"topology.multiple_connections"}


def test_switch_overlap_shared_port(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        s, c = t["switches"], t["connections"]
        w9 = s[where(s, switch_id="W1")].assign(switch_id="W9")
        t["switches"] = pd.concat([s, w9], ignore_index=True)
        mine = c[where(c, switch_id="W1")]
        flipped = mine.rename(columns={"track_a": "track_b", "end_a": "end_b", "track_b": "track_a", "end_b": "end_a"})
        t["connections"] = pd.concat([c, flipped[c.columns].assign(switch_id="W9")], ignore_index=True)

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.switch_overlap"}
    assert "W1, W9" in f[0].message


def test_gap_at_connection(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        g = t["gis"]
        on = where(g, line_code="9002")
        g.loc[on, "lat"] = [f"{float(x) + FIVE_M_NORTH:.9f}" for x in g.loc[on, "lat"]]

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.gap"}
    assert all(4.5 < x.value < 5.5 for x in f)


def test_km_jump_and_km_break(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        tr = t["tracks"]
        tr.loc[where(tr, track_id="3"), "km_begin_m"] = "230"

    f = broken(tmp_path, "station4", edit)
    assert rules(f) == {"topology.km_jump"}
    assert f[0].value == pytest.approx(30.0)

    def explained(t: Tables) -> None:
        edit(t)
        t["km_breaks"] = pd.DataFrame([{"line_code": "9004", "track": "U", "km_from_m": "200", "km_to_m": "230"}])

    assert "topology.km_jump" not in rules(broken(tmp_path / "b", "station4", explained))


def test_track_length(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        tr = t["tracks"]
        tr.loc[where(tr, track_id="A2"), "length_m"] = "590"

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.track_length"}
    assert f[0].limit == pytest.approx(600.0, abs=0.01)


def test_track_length_within_tolerance(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        tr = t["tracks"]
        tr.loc[where(tr, track_id="A2"), "length_m"] = "595"  # 1 % of 600 m is 6 m

    assert broken(tmp_path, "junction", edit) == []


def test_crossover_angle(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        s = t["switches"]
        s.loc[where(s, switch_id="W1"), "switch_number"] = "20"

    f = broken(tmp_path, "crossover", edit)
    assert rules(f) == {"topology.crossover_angle"}
    assert [x.keys["switch_id"] for x in f] == ["W1"]
    assert f[0].value == pytest.approx(5.71, abs=0.05)  # atan(1/10): the geometry is 1:10


def test_open_end(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        tr = t["tracks"]
        tr.loc[where(tr, track_id="B1"), ["km_end_m", "length_m"]] = ["580", "580"]

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.open_end"}
    assert "B1" in f[0].message and "end has no connection" in f[0].message


def test_a_buffer_stop_closes_an_open_end(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        tr = t["tracks"]
        tr.loc[where(tr, track_id="B1"), ["km_end_m", "length_m"]] = ["580", "580"]
        tr["end_buffer_stop"] = ""
        tr.loc[where(tr, track_id="B1"), "end_buffer_stop"] = "1"

    assert not rules(broken(tmp_path, "junction", edit))


def test_a_branch_leading_out_of_the_db_is_a_warning(tmp_path: Path) -> None:
    """An extract's edge (the Finnish railML switches): the port left empty is said, not an error."""

    def edit(t: Tables) -> None:
        s = t["switches"]
        s.loc[where(s, switch_id="W1"), ["b1_track", "b1_end"]] = ["", ""]
        c = t["connections"]
        t["connections"] = c[~((c["track_a"] == "B1") | (c["track_b"] == "B1"))]
        t["tracks"] = t["tracks"][t["tracks"]["track_id"] != "B1"]
        b = t["balises"]
        t["balises"] = b[b["track_id"] != "B1"]

    f = broken(tmp_path, "junction", edit)
    assert {x.rule for x in f if x.severity == "error"} == set(), [str(x) for x in f]
    assert [x.rule for x in f if x.rule.startswith("topology.switch")] == ["topology.switch_open_port"]


def test_isolated_track(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        tr, tp = t["tracks"], t["track_points"]
        t["tracks"] = add(tr, track_id="Z1", kind="siding", length_m="20")
        tp = add(tp, track_id="Z1", pos_m="0", lat="60.2005", lon="24.905")
        t["track_points"] = add(tp, track_id="Z1", pos_m="20", lat="60.2005", lon="24.905360")

    f = broken(tmp_path, "station4", edit)
    assert rules(f) == {"topology.isolated_track"}


def test_group_fields(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        t["balises"] = add(
            t["balises"], balise_id="GX", kind="G", km_actual_m="100", km_equipment_m="100", track_id="A1"
        )

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"balise.group_fields"}
    assert f[0].column == "nid_c"


def test_group_members(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        b = t["balises"]
        b.loc[where(b, balise_id="BG1.1"), "n_pig"] = "0"

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"balise.group_members"}
    assert "share one N_PIG" in f[0].message


def test_group_duplicate_far_apart(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        b = t["balises"]
        b.loc[b["balise_id"].str.startswith("BG5."), "nid_bg"] = "4"  # B1 km 400 vs A2 km 800: 800 m by route

    assert rules(broken(tmp_path, "junction", edit)) == {"balise.group_duplicate"}


def test_group_ambiguous_along_route(tmp_path: Path) -> None:
    """A1 km 300 and B1 km 40 are 140 m apart through the switch: the same identity on both is
    ambiguous; A2 km 440 and B1 km 40 are not connected by a route (branch to branch)."""

    def edit(t: Tables) -> None:
        b = t["balises"]
        b.loc[b["balise_id"].str.startswith("BG3."), "nid_bg"] = "1"

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.balise_ambiguous"}
    assert f[0].value == pytest.approx(140.0, abs=0.5)

    def no_route(t: Tables) -> None:
        b = t["balises"]
        b.loc[b["balise_id"].str.startswith("BG3."), "nid_bg"] = "2"

    assert rules(broken(tmp_path / "b", "junction", no_route)) == {"balise.group_duplicate"}


def test_c_balises_ambiguous_along_route(tmp_path: Path) -> None:
    """Same signal type after two different pairs, 250 m apart via the junction."""

    def edit(t: Tables) -> None:
        b = t["balises"]
        for bid, kind, line, station, km, sig, dist in (
            ("P1", "I1", "9001", "01", "100", "", ""),
            ("P2", "I2", "9001", "01", "105", "", ""),
            ("C1", "C", "9001", "01", "300", "H", "200"),
            ("Q1", "I1", "9002", "02", "100", "", ""),
            ("Q2", "I2", "9002", "02", "105", "", ""),
            ("C2", "C", "9002", "02", "150", "H", "50"),
        ):
            b = add(b, balise_id=bid, kind=kind, line_code=line, station_code=station, track="S", km_actual_m=km)
            b.loc[b.index[-1], ["km_equipment_m", "signal_type", "dist_from_initial_m"]] = [km, sig, dist]
        t["balises"] = b

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"topology.balise_ambiguous"}
    assert f[0].value == pytest.approx(250.0, abs=0.5)
    assert {f[0].keys["balise_id"], f[0].keys["other_balise_id"]} == {"C1", "C2"}


def test_window_is_configurable(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        b = t["balises"]
        b.loc[b["balise_id"].str.startswith("BG3."), "nid_bg"] = "1"

    broken(tmp_path, "junction", edit)
    f = validate_path(tmp_path / "junction", config=ValidationConfig(id_window_m=100.0))
    assert rules(f) == {"balise.group_duplicate"}


def test_balise_position_off_track(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        b = t["balises"]
        b.loc[where(b, balise_id="BG1.0"), ["km_actual_m", "km_equipment_m"]] = ["900", "900"]  # track A1: km 0–400

    f = broken(tmp_path, "junction", edit)
    assert "topology.balise_position" in rules(f)
    assert "A1" in next(x for x in f if x.rule == "topology.balise_position").message


def test_initial_pair_needs_key_fields(tmp_path: Path) -> None:
    def edit(t: Tables) -> None:
        b = t["balises"]
        b = add(b, balise_id="P1", kind="I1", line_code="9001", track="S", km_actual_m="100", km_equipment_m="100")
        t["balises"] = add(
            b, balise_id="P2", kind="I2", line_code="9001", track="S", km_actual_m="105", km_equipment_m="105"
        )

    f = broken(tmp_path, "junction", edit)
    assert rules(f) == {"balise.key_fields"}
    assert {x.column for x in f} == {"station_code"}


def test_sarif_describes_topology_rules_and_points_at_the_line(tmp_path: Path) -> None:
    from dbtools.interchange.ci import FAMILIES, sarif
    from dbtools.rules.catalogue import rule_catalogue

    def edit(t: Tables) -> None:
        c = t["connections"]
        c.loc[where(c, navigability="none"), "navigability"] = "both"

    log = sarif(broken(tmp_path, "junction", edit))
    run = log["runs"][0]
    (descriptor,) = run["tool"]["driver"]["rules"]
    assert descriptor["shortDescription"]["text"] == rule_catalogue()["topology.navigability"].summary
    assert descriptor["properties"]["family"] == FAMILIES["topology"]
    region = run["results"][0]["locations"][0]["physicalLocation"]["region"]
    lines = (tmp_path / "junction" / "connections.csv").read_text().splitlines()
    assert {"A2", "B1", "both", "W1"} <= set(lines[region["startLine"] - 1].split(","))  # the branch↔branch row
    assert region["startColumn"] > 1


def test_switch_overlap_by_a_short_track() -> None:
    """X1 and X2 (60 m) each join two switches: with a 100 m minimum spacing they overlap."""
    f = validate_path(NETWORKS / "crossover", config=ValidationConfig(switch_min_spacing_m=100.0))
    assert rules(f) == {"topology.switch_overlap"}
    assert sorted(x.message.split(" are joined")[0] for x in f) == ["switches W1, W2", "switches W3, W4"]


@settings(max_examples=15, database=None)
@given(n=st.floats(8.0, 18.5), d=st.floats(3.8, 5.0))
def test_crossover_angle_property(tmp_path_factory: pytest.TempPathFactory, n: float, d: float) -> None:
    """A crossover drawn with 1:n turnouts (R = 25·n m, typical of 1:9 at 190 m … 1:18.5 at
    500 m) between tracks d apart passes with switch number n and fails with 1.8·n or n/1.8.
    (The crossover's far end is left open in this one-switch network: ``topology.open_end``.)"""
    gen = _generator()
    path = gen.crossover_path(0.0, 0.0, d, n, 25.0 * n, left=True)
    length = path.length
    pos = [*(p for p in range(0, int(length), 20) if length - p >= 1.0), length]
    points = pd.DataFrame({"track_id": "X", "pos_m": pos})
    xy = [path.at(p) for p in pos]
    lat_lon = [gen.latlon(x, y) for x, y, _ in xy]
    points["lat"], points["lon"] = [a for a, _ in lat_lon], [b for _, b in lat_lon]
    found = {}
    for label, number in (("right", n), ("high", 1.8 * n), ("low", n / 1.8)):
        net = _crossover_network(gen, points, length, xy[-1][0], number)
        found[label] = [
            f.rule for f in check_topology(net, ValidationConfig(), Locator()) if f.rule != "topology.open_end"
        ]
    assert found == {"right": [], "high": ["topology.crossover_angle"], "low": ["topology.crossover_angle"]}


def _crossover_network(gen: ModuleType, points: pd.DataFrame, length: float, x_end: float, number: float) -> Network:
    """Line L: D at y = 0 and U where the crossover ends (both straight east, km = x), D split
    at km 0 by switch W1 whose diverging branch is crossover X (``points``) up to U at x_end."""
    tables = {t.name: empty_frame(t) for t in DB_TABLES}
    y_u = (float(points["lat"].iloc[-1]) - gen.LAT0) * 111_412.0
    km = [20.0 * i for i in range(-10, 21)]
    gis = [("L", "D", k, *gen.latlon(k, 0.0)) for k in km] + [("L", "U", k, *gen.latlon(k, y_u)) for k in km]
    tracks = [
        ("D1", "L", "D", "main", -200.0, 0.0, 200.0),
        ("D2", "L", "D", "main", 0.0, 400.0, 400.0),
        ("X", None, None, "crossover", None, None, length),
    ]
    ports = ["switch_id", "type", "a1_track", "a1_end", "b1_track", "b1_end", "b2_track", "b2_end", "switch_number"]
    conns = [("D1", "end", "X", "begin", "both", "W1"), ("D1", "end", "D2", "begin", "both", "W1")]
    frames = {
        "gis": pd.DataFrame(gis, columns=["line_code", "track", "km_m", "lat", "lon"]),
        "tracks": pd.DataFrame(
            tracks, columns=["track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m"]
        ),
        "switches": pd.DataFrame([("W1", "point", "D1", "end", "X", "begin", "D2", "begin", number)], columns=ports),
        "connections": pd.DataFrame(
            [*conns, ("X", "begin", "D2", "begin", "none", "W1")],
            columns=["track_a", "end_a", "track_b", "end_b", "navigability", "switch_id"],
        ),
        "track_points": points,
    }
    for t in DB_TABLES:
        if t.name in frames:
            tables[t.name] = canonical(t, frames[t.name])
    return Network(tables, origin="test")


NETWORK_FILES = ("tracks", "connections", "switches", "track_points", "balises")
JUNK = ("", "x", "-5", "1e9", "begin", "A1", "nan", "W1", "none", "both", "point")


@settings(max_examples=20, database=None)
@given(
    name=st.sampled_from(NAMES),
    cuts=st.lists(
        st.tuples(st.sampled_from(NETWORK_FILES), st.integers(0, 60), st.integers(0, 20), st.sampled_from(JUNK)),
        min_size=1,
        max_size=4,
    ),
)
def test_damaged_networks_give_findings_never_a_traceback(
    tmp_path_factory: pytest.TempPathFactory, name: str, cuts: list[tuple[str, int, int, str]]
) -> None:
    def edit(t: Tables) -> None:
        for table, row, col, junk in cuts:
            f = t.get(table)
            if f is not None and len(f):
                f.iloc[row % len(f), col % len(f.columns)] = junk

    broken(tmp_path_factory.mktemp("damaged"), name, edit)  # raises on a bug
