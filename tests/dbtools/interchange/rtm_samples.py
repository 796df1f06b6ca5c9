"""Hand-made RailTopoModel GeoJSON networks (tp-lib's format) for the rtm-geojson tests."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

TP_LIB = Path(__file__).resolve().parents[2] / "data" / "tp-lib"
SAMPLE = TP_LIB / "sample_network.geojson"
KVG = TP_LIB / "rinf-kvg" / "network.geojson"

#: A turnout in ETRS89 / UTM 32N (EPSG:25832), metres: the toe track T runs east along
#: northing 6,000,000 from easting 500,000 (the zone's central meridian, 9° E) to the node at
#: 500,100; the straight branch S goes on east 100 m, the branch L leaves it to the north
#: (the left side seen from the toe), 11 m north after 100 m (about 1:9).
E0, N0 = 500_000.0, 6_000_000.0


def element(ident: Any, coords: list[list[float]], **props: Any) -> dict[str, Any]:
    geom = {"type": "LineString", "coordinates": coords}
    return {"type": "Feature", "geometry": geom, "properties": {"id": ident, **props}}


def relation(ident: str, a: str, pa: Any, b: str, pb: Any, nav: Any, **extra: Any) -> dict[str, Any]:
    props = {
        "type": "netrelation",
        "id": ident,
        "netelementA": a,
        "netelementB": b,
        "positionOnA": pa,
        "positionOnB": pb,
        "navigability": nav,
        **extra,
    }
    return {"type": "Feature", "geometry": None, "properties": props}


def turnout_features() -> list[dict[str, Any]]:
    return [
        element("T", [[E0, N0], [E0 + 50, N0], [E0 + 100, N0]]),
        element("S", [[E0 + 100, N0], [E0 + 200, N0]]),
        element("L", [[E0 + 100, N0], [E0 + 150, N0 + 2.75], [E0 + 200, N0 + 11]]),
        relation("r1", "T", 1, "S", 0, "both"),
        relation("r2", "L", 0, "T", 1, "Both"),  # the case tp-lib accepts, A and B swapped
        relation("r3", "S", 0, "L", 0, "none"),
    ]


def collection(features: list[dict[str, Any]], crs: str | None = "EPSG:25832") -> dict[str, Any]:
    out: dict[str, Any] = {"type": "FeatureCollection", "features": features}
    if crs is not None:
        out["crs"] = {"type": "name", "properties": {"name": crs}}
    return out


def write(path: Path, data: Any) -> Path:
    path.write_text(json.dumps(data), encoding="utf-8")
    return path
