"""OSM import against the topology rules (dbtools/rules/topology*.py): the importer bugs the
VDE 8.2 file showed, each on a small hand-made network (nodes in local metres, x east, y north
from UTM 32N E 650000 N 5650000, converted with pyproj as in make_junction.py)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from pyproj import Transformer

from dbtools.interchange.osm_import import import_osm
from dbtools.interchange.osm_switches import two_sides

Nodes = dict[int, tuple[float, float, dict[str, str]]]
Ways = dict[int, tuple[list[int], dict[str, str]]]


def _write(path: Path, nodes: Nodes, ways: Ways) -> Path:
    tr = Transformer.from_crs(32632, 4326, always_xy=True)
    out = ['<?xml version="1.0" encoding="UTF-8"?>', '<osm version="0.6" generator="test">']
    for i, (x, y, tags) in nodes.items():
        lon, lat = tr.transform(650000.0 + x, 5650000.0 + y)
        out.append(f'  <node id="{i}" version="1" lat="{lat:.8f}" lon="{lon:.8f}">')
        out += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        out.append("  </node>")
    for i, (nds, tags) in ways.items():
        out.append(f'  <way id="{i}" version="1">')
        out += [f'    <nd ref="{n}"/>' for n in nds]
        out += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        out.append("  </way>")
    out.append("</osm>")
    path.write_text("\n".join(out) + "\n")
    return path


def _import(tmp_path: Path, nodes: Nodes, ways: Ways) -> tuple[Path, list[dict[str, Any]]]:
    out = tmp_path / "src"
    import_osm(_write(tmp_path / "net.osm", nodes, ways), out)
    return out, json.loads((out / "import_report.json").read_text())["findings"]


def _tracks(folder: Path) -> pd.DataFrame:
    return pd.read_csv(folder / "tracks.csv", dtype={"line_code": str}).set_index("track_id")


LINE = {"railway": "rail", "ref": "6340"}
SWITCH_LEFT = {"railway": "switch", "railway:switch": "default", "railway:turnout_side": "left"}


def test_a_closed_building_tagged_rail_is_not_a_track(tmp_path: Path) -> None:
    """VDE 8.2 ways 927446286 and 935171552: building=yes + railway=rail outlines of 7.6 and
    10.9 m became ring tracks whose track_points start and end at one point
    (topology.track_length: centreline 0.0 m)."""
    nodes: Nodes = {1: (0, 0, {}), 2: (200, 0, {}), 3: (50, 10, {}), 4: (53, 10, {}), 5: (53, 12, {}), 6: (50, 12, {})}
    ways: Ways = {1: ([1, 2], LINE), 2: ([3, 4, 5, 6, 3], {"railway": "rail", "building": "yes"})}
    out, findings = _import(tmp_path, nodes, ways)
    assert list(_tracks(out).index) == ["w1"]
    area = [f for f in findings if f["rule"] == "osm.area"]
    assert len(area) == 1 and area[0]["keys"]["element"] == "way/2"


def _x(angle_deg: float) -> tuple[float, float]:
    import math

    return 100 * math.cos(math.radians(angle_deg)), 100 * math.sin(math.radians(angle_deg))


def test_a_switch_node_where_two_ways_cross_is_a_double_slip(tmp_path: Path) -> None:
    """VDE 8.2 node 1289546773 and 11 others: railway=switch (railway:switch=default or
    none) where two ways cross at ≈ 6°; joined without a switch row, every end had 3
    connections (topology.multiple_connections)."""
    (ax, ay), (bx, by) = _x(3.0), _x(-3.0)
    nodes: Nodes = {
        1: (-ax, -ay, {}),
        2: (ax, ay, {}),
        3: (-bx, -by, {}),
        4: (bx, by, {}),
        9: (0, 0, {"railway": "switch", "railway:switch": "default"}),
    }
    ways: Ways = {1: ([1, 9, 2], {"railway": "rail"}), 2: ([3, 9, 4], {"railway": "rail"})}
    out, findings = _import(tmp_path, nodes, ways)
    sw = pd.read_csv(out / "switches.csv")
    assert list(sw["switch_id"]) == ["n9"] and list(sw["type"]) == ["double_slip"]
    con = pd.read_csv(out / "connections.csv")
    assert len(con) == 6 and set(con["switch_id"]) == {"n9"}
    west = {"w1_1", "w2_1"}  # the two ends on the west side: their pair is no route
    none = con[con["navigability"] == "none"]
    assert {frozenset((a, b)) for a, b in zip(none["track_a"], none["track_b"], strict=True)} == {
        frozenset(west),
        frozenset({"w1_2", "w2_2"}),
    }
    assert [f["keys"]["element"] for f in findings if f["rule"] == "osm.switch_inferred"] == ["node/9"]
    assert not [f for f in findings if f["rule"] == "osm.node_degree"]


def test_a_switch_node_where_ways_meet_at_right_angles_stays_unresolved(tmp_path: Path) -> None:
    """Not two sides of two ends: no guess (the generic joint and its report stay)."""
    nodes: Nodes = {1: (-100, 0, {}), 2: (100, 0, {}), 3: (0, -100, {}), 4: (0, 100, {})}
    nodes[9] = (0, 0, {"railway": "switch"})
    ways: Ways = {1: ([1, 9, 2], {"railway": "rail"}), 2: ([3, 9, 4], {"railway": "rail"})}
    out, findings = _import(tmp_path, nodes, ways)
    assert not (out / "switches.csv").exists()  # no switch row: the table is not written
    assert [f["rule"] for f in findings if f["rule"] in ("osm.node_degree", "osm.switch_inferred")] == [
        "osm.node_degree"
    ]


@pytest.mark.parametrize(
    ("dirs", "expected"),
    [
        ([(1, 0), (1, 0.1), (-1, 0), (-1, -0.1)], True),
        ([(1, 0), (-1, 0), (0, 1), (0, -1)], False),
        ([(1, 0), (1, 0.1), (1, -0.1), (-1, 0)], False),  # a three-way switch: 3 against 1
    ],
)
def test_two_sides(dirs: list[tuple[float, float]], expected: bool) -> None:
    import math

    ends = [("t", "begin", x / math.hypot(x, y), y / math.hypot(x, y)) for x, y in dirs]
    assert two_sides(ends) is expected


def test_km_runs_on_along_a_way_that_takes_the_diverging_branch(tmp_path: Path) -> None:
    """VDE 8.2 way 110108839 (line 6343): the way, with its line, leaves switch n1259867279
    by the diverging branch; the through branch is a way without a line. The km chain stopped
    at the switch, the piece after it was fitted alone: 7k442.0 → 7k468.8 (topology.km_jump).
    Here: posts 1.1 and 1.3 km before the switch (x = 500), 1.62 and 2.02 km after it. Fitted
    apart, the piece before ends at 1.5 km and the one after begins at 1.62 − 0.1044 ≈ 1.5156
    km; along one chain the switch lies between the posts 1.3 (x = 300) and 1.62 (200 m +
    √(100² + 30²) = 304.403 m further): 1300 + 320 · 200 / 304.403 = 1510.245 m on both."""
    nodes: Nodes = {
        1: (0, 0, {}),
        2: (100, 0, {"railway": "milestone", "railway:position": "1.1"}),
        3: (300, 0, {"railway": "milestone", "railway:position": "1.3"}),
        4: (500, 0, SWITCH_LEFT),
        5: (600, 30, {"railway": "milestone", "railway:position": "1.62"}),
        6: (1000, 80, {"railway": "milestone", "railway:position": "2.02"}),
        7: (1000, 0, {}),
    }
    ways: Ways = {20: ([1, 2, 3, 4, 5, 6], LINE), 21: ([4, 7], {"railway": "rail", "service": "siding"})}
    out, _ = _import(tmp_path, nodes, ways)
    t = _tracks(out)
    assert t.loc["w20_1", "km_end_m"] == pytest.approx(1510.245, abs=0.05)  # UTM scale: geodesic ≈ grid
    assert t.loc["w20_2", "km_begin_m"] == pytest.approx(t.loc["w20_1", "km_end_m"], abs=1e-6)
    assert t.loc["w20_2", "km_end_m"] == pytest.approx(2020.0, abs=0.05)


def test_a_diverging_branch_of_the_line_starts_at_the_switch_km(tmp_path: Path) -> None:
    """VDE 8.2 switch n1908724021 (line 5919): toe, through and diverging branch all carry the
    line; the diverging branch, a chain of its own, was fitted on its own posts only and
    began 57.9 m of km away from its toe (topology.km_jump). Its km is anchored at the switch:
    here posts 0.62 and 1.02 km on the branch would put its begin at ≈ 0.5156 km, the switch
    is at 0.5 km on the main track."""
    nodes: Nodes = {
        1: (0, 0, {}),
        2: (100, 0, {"railway": "milestone", "railway:position": "0.1"}),
        3: (500, 0, SWITCH_LEFT),
        4: (900, 0, {"railway": "milestone", "railway:position": "0.9"}),
        5: (1000, 0, {}),
        6: (600, 30, {"railway": "milestone", "railway:position": "0.62"}),
        7: (1000, 30, {"railway": "milestone", "railway:position": "1.02"}),
    }
    ways: Ways = {30: ([1, 2, 3, 4, 5], LINE), 31: ([3, 6, 7], LINE)}
    out, _ = _import(tmp_path, nodes, ways)
    t = _tracks(out)
    assert t.loc["w30_1", "km_end_m"] == pytest.approx(500.0, abs=0.05)
    assert t.loc["w31", "km_begin_m"] == pytest.approx(t.loc["w30_1", "km_end_m"], abs=1e-6)
    assert t.loc["w31", "km_end_m"] == pytest.approx(1020.0, abs=0.05)  # its own last post counts
