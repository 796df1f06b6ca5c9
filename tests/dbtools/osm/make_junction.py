"""Writes tests/data/osm/junction.osm (run once: ``python tests/dbtools/osm/make_junction.py``):
the hand-made network of the OSM import tests, nodes placed in local metres (x east, y north
from UTM 32N E 650000 N 5650000) and converted to WGS 84 with pyproj."""

from pathlib import Path

from pyproj import Transformer


def main() -> None:
    """Write the file."""
    tr = Transformer.from_crs(32632, 4326, always_xy=True)
    E0, N0 = 650000.0, 5650000.0
    nodes = {  # id: (x, y, tags)
        1: (0, 0, {}),
        11: (100, 0, {"railway": "milestone", "railway:position": "1.0"}),
        15: (
            200,
            0,
            {
                "railway": "balise_group",
                "railway:etcs:nid_c": "80",
                "railway:etcs:nid_bg": "1234",
                "balise_count": "2",
                "ref": "BG1",
            },
        ),
        12: (300, 0, {"railway": "milestone", "railway:position": "1,2"}),
        13: (400, 0, {"railway": "milestone", "railway:position": "0.7"}),
        14: (450, 0, {"railway": "milestone", "railway:position": "1+350"}),
        2: (
            500,
            0,
            {
                "railway": "switch",
                "railway:switch": "default",
                "railway:turnout_side": "left",
                "ref": "W1",
                "railway:radius": "500",
                "railway:maxspeed:diverging": "60",
            },
        ),
        16: (600, 0, {"railway": "balise_group", "balise_count": "2"}),
        3: (650, 0, {}),
        4: (800, 0, {"railway": "switch"}),
        5: (1000, 0, {}),
        6: (600, 30, {}),
        7: (800, 80, {"railway": "buffer_stop"}),
        8: (0, -5, {}),
        9: (700, -5, {"railway": "switch"}),
        10: (1000, -5, {}),
    }
    ways = {
        101: (
            [1, 11, 15, 12, 13, 14, 2, 16, 3, 4, 5],
            {"railway": "rail", "ref": "6340", "name": "Test line", "railway:track_ref": "1", "usage": "main"},
        ),
        102: ([2, 6, 7], {"railway": "rail", "service": "siding"}),
        103: ([8, 9, 10], {"railway": "rail", "ref": "6340", "name": "Test line"}),
        104: ([9, 4], {"railway": "rail", "service": "crossover", "ref": "6340"}),
        105: ([1, 8], {"railway": "tram"}),
    }
    out = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        "<!-- hand-made test network: see tests/data/osm/README.md"
        " (local x east, y north in metres from UTM 32N E 650000 N 5650000) -->",
        '<osm version="0.6" generator="hand">',
    ]
    for i, (x, y, tags) in nodes.items():
        lon, lat = tr.transform(E0 + x, N0 + y)
        if not tags:
            out.append(f'  <node id="{i}" version="1" lat="{lat:.8f}" lon="{lon:.8f}"/>')
        else:
            out.append(f'  <node id="{i}" version="1" lat="{lat:.8f}" lon="{lon:.8f}">')
            out += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
            out.append("  </node>")
    for i, (nds, tags) in ways.items():
        out.append(f'  <way id="{i}" version="1">')
        out += [f'    <nd ref="{n}"/>' for n in nds]
        out += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        out.append("  </way>")
    relations = {
        201: ([103], {"type": "route", "route": "railway", "ref": "6340", "name": "Testbahn (relation)"}),
        202: ([101], {"type": "route", "route": "train", "ref": "RE 1", "name": "a service, not a line"}),
    }
    for i, (members, tags) in relations.items():
        out.append(f'  <relation id="{i}" version="1">')
        out += [f'    <member type="way" ref="{m}" role=""/>' for m in members]
        out += [f'    <tag k="{k}" v="{v}"/>' for k, v in tags.items()]
        out.append("  </relation>")
    out.append("</osm>")
    (Path(__file__).resolve().parents[2] / "data" / "osm" / "junction.osm").open("w").write("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
