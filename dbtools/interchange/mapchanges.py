"""What a DB change moved, placed on the map (pure): the data of the review page's change layer
(:mod:`dbtools.interchange.leaflet_map`).

Balises and feature points are placed on the GIS grids by their (line, track, km) — the old
ones on OLD's grid, the new ones on NEW's — and GIS points by their own lon/lat. Each change
is added, removed or moved (old and new place, and the shift in metres: km difference for
balises and feature points, geodesic distance for GIS points). Track lines of OLD that NEW
no longer has are kept as ``removed_lines``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from dbtools.interchange.geojson import GridLocator
from dbtools.network import Network


@dataclass
class Change:
    """One changed thing: kind (added/removed/moved), what (balise, feature point, GIS point),
    label, old and new lon/lat (None when absent) and the shift [m] of a move."""

    kind: str
    what: str
    label: str
    old: tuple[float, float] | None
    new: tuple[float, float] | None
    shift_m: float | None = None


@dataclass
class MapData:
    """The grid lines (label "LINE TRACK", lon/lat points) of OLD's line tracks that NEW
    lacks, and the changes."""

    removed_lines: list[tuple[str, list[tuple[float, float]]]] = field(default_factory=list)
    changes: list[Change] = field(default_factory=list)


def map_data(old: Network, new: Network, diff: Any) -> MapData:
    """What changed, placed on the grids (balises and feature points by their km)."""
    lo, ln = GridLocator(old), GridLocator(new)
    removed = [
        (f"{k[0]} {k[1]}", list(zip(v[1].tolist(), v[2].tolist(), strict=True)))
        for k, v in lo.tracks.items()
        if k not in ln.tracks
    ]
    data = MapData(removed)
    _balise_changes(data, diff.tables["balises"], lo, ln)
    _feature_changes(data, diff.tables["feature_points"], lo, ln)
    _gis_changes(data, diff.tables["gis"])
    return data


def _at(loc: GridLocator, r: dict[str, Any], km: str) -> tuple[float, float] | None:
    return loc.at(r["line_code"], r["track"], r[km])


def _balise_changes(data: MapData, td: Any, lo: GridLocator, ln: GridLocator) -> None:
    for r in td.added.to_dict("records"):
        data.changes.append(Change("added", "balise", str(r["balise_id"]), None, _at(ln, r, "km_actual_m")))
    for r in td.removed.to_dict("records"):
        data.changes.append(Change("removed", "balise", str(r["balise_id"]), _at(lo, r, "km_actual_m"), None))
    for o, n in zip(td.old.to_dict("records"), td.new.to_dict("records"), strict=True):
        a, b = _at(lo, o, "km_actual_m"), _at(ln, n, "km_actual_m")
        shift = abs(float(n["km_actual_m"]) - float(o["km_actual_m"]))
        kind = "moved" if a and b and shift > 0 else "added"
        data.changes.append(Change(kind, "balise", str(n["balise_id"]), a, b, shift))


def _feature_changes(data: MapData, td: Any, lo: GridLocator, ln: GridLocator) -> None:
    def label(r: dict[str, Any]) -> str:
        return f"{r['feature_id']} row {r['seq']} ({r['line_code']} {r['track']})"

    for r in td.added.to_dict("records"):
        data.changes.append(Change("added", "feature point", label(r), None, _at(ln, r, "km_m")))
    for r in td.removed.to_dict("records"):
        data.changes.append(Change("removed", "feature point", label(r), _at(lo, r, "km_m"), None))
    for o, n in zip(td.old.to_dict("records"), td.new.to_dict("records"), strict=True):
        a, b = _at(lo, o, "km_m"), _at(ln, n, "km_m")
        shift = abs(float(n["km_m"]) - float(o["km_m"]))
        if a and b and shift > 0:
            data.changes.append(Change("moved", "feature point", label(n), a, b, shift))


def _gis_changes(data: MapData, td: Any) -> None:
    from dbtools.gis.geometry import GEOD

    def label(r: dict[str, Any]) -> str:
        return f"{r['line_code']} {r['track']} km {float(r['km_m']):.0f}"

    for r in td.added.to_dict("records"):
        data.changes.append(Change("added", "GIS point", label(r), None, (float(r["lon"]), float(r["lat"]))))
    for r in td.removed.to_dict("records"):
        data.changes.append(Change("removed", "GIS point", label(r), (float(r["lon"]), float(r["lat"])), None))
    for o, n in zip(td.old.to_dict("records"), td.new.to_dict("records"), strict=True):
        a, b = (float(o["lon"]), float(o["lat"])), (float(n["lon"]), float(n["lat"]))
        if a != b:
            shift = float(GEOD.inv(a[0], a[1], b[0], b[1])[2])
            data.changes.append(Change("moved", "GIS point", label(n), a, b, shift))
