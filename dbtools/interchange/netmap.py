"""The network as map layers for the review page's interactive map (pure; no HTML here).

What is drawn (all positions lat/lon in the DB's geodetic datum — JGD2011 or WGS 84, the
same within centimetres at map scales):

* **tracks** — every row of :func:`dbtools.topology.all_tracks` (declared and implied line
  tracks, so a line-only DB shows its ``LINE:TRACK`` tracks) with its
  :func:`~dbtools.topology.centreline`, simplified by Douglas–Peucker in the network's metric
  CRS with :data:`TOLERANCE_M` (shapely ``simplify``: kept vertices are original vertices,
  and no dropped vertex lies farther than the tolerance from the simplified line).
  Coordinates are integers of :data:`COORD_SCALE` (1e-6 deg ≈ 0.11 m), delta-encoded
  ``[lat0, lon0, dlat1, dlon1, …]`` to keep a national DB's page small;
* **switches** — at their surveyed lat/lon, else at the toe end (port A1) of their
  centreline; type, switch number 1:n, diverging side, radius and speed for the tooltip;
* **connections** — one marker per place where track ends meet (rounded to the coordinate
  unit), listing every connection there with its navigability and switch;
* **balise groups** — ``balises`` rows of kind G grouped by (NID_C, NID_BG), at the mean of
  their balises placed on the grid by (line, track, km) or on their track's km;
* **km ticks** — every :data:`KM_TICK_M` of line km along tracks that carry km.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from dbtools.gis.geometry import Projector
from dbtools.gis.georef import projector_for_points
from dbtools.network import Network
from dbtools.topology import Centreline, all_tracks, centreline

#: Douglas–Peucker tolerance of the drawn centrelines [m].
TOLERANCE_M = 0.5
#: Coordinates are drawn as integers of this many degrees (≈ 0.11 m north–south).
COORD_SCALE = 1e6
#: Spacing of the km ticks [m of line km].
KM_TICK_M = 1000.0


def _clean(v: Any) -> Any:
    """A JSON-safe scalar (None for missing, plain int/float/str)."""
    if v is None or v is pd.NA or (isinstance(v, float | np.floating) and not np.isfinite(v)):
        return None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.floating):
        return float(v)
    return v if isinstance(v, int | float | str | bool) else str(v)


def map_projector(net: Network) -> Projector | None:
    """The metric CRS of the network (its georef), else one chosen for its track points."""
    from dbtools.gis.index import network_georef

    g = network_georef(net)
    if g is not None:
        return Projector.from_epsg(g.crs_epsg)
    tp = net.track_points
    if tp.empty:
        return None
    return projector_for_points(tp["lat"].to_numpy(float), tp["lon"].to_numpy(float))


def simplify(lat: np.ndarray, lon: np.ndarray, projector: Projector, tolerance_m: float = TOLERANCE_M) -> np.ndarray:
    """Indices of the vertices Douglas–Peucker keeps at ``tolerance_m`` in the metric plane
    (always the first and the last)."""
    import shapely

    n = lat.size
    if n <= 2:
        return np.arange(n)
    x, y = projector.to_xy(lon, lat)
    kept = shapely.get_coordinates(shapely.simplify(shapely.linestrings(x, y), tolerance_m, preserve_topology=False))
    # kept vertices are original ones, in order: match them by a forward scan
    out, j = [], 0
    for kx, ky in kept:
        while j < n and (abs(x[j] - kx) > 1e-6 or abs(y[j] - ky) > 1e-6):
            j += 1
        if j < n:
            out.append(j)
            j += 1
    return np.asarray(out, dtype=int)


def encode(lat: np.ndarray, lon: np.ndarray) -> list[int]:
    """``[lat0, lon0, dlat1, dlon1, …]`` in units of 1/:data:`COORD_SCALE` degree."""
    q = np.column_stack([np.rint(lat * COORD_SCALE), np.rint(lon * COORD_SCALE)]).astype(np.int64)
    d = np.vstack([q[:1], np.diff(q, axis=0)])
    return [int(v) for v in d.ravel()]


@dataclass
class _Ends:
    """lat/lon of each (track_id, end) for switches and connections."""

    at: dict[tuple[str, str], tuple[float, float]]

    def get(self, track: Any, end: Any) -> tuple[float, float] | None:
        return None if pd.isna(track) or pd.isna(end) else self.at.get((str(track), str(end)))


def _track_layer(net: Network, projector: Projector) -> tuple[list[dict[str, Any]], _Ends, list[Centreline]]:
    tracks, ends, lines = [], _Ends({}), []
    for _, row in all_tracks(net).iterrows():
        cl = centreline(net, row)
        if cl.lat.size < 2:
            continue
        lines.append(cl)
        keep = simplify(cl.lat, cl.lon, projector)
        ends.at[(cl.track_id, "begin")] = (float(cl.lat[0]), float(cl.lon[0]))
        ends.at[(cl.track_id, "end")] = (float(cl.lat[-1]), float(cl.lon[-1]))
        tracks.append(
            {
                "id": cl.track_id,
                "kind": _clean(row["kind"]),
                "line": _clean(row["line_code"]),
                "track": _clean(row["track"]),
                "km0": _clean(row["km_begin_m"]),
                "km1": _clean(row["km_end_m"]),
                "len": round(float(cl.pos_m[-1] - cl.pos_m[0]), 1),
                "implied": bool(row["implied"]),
                "name": _clean(row["name"]),
                "points": int(cl.lat.size),
                "c": encode(cl.lat[keep], cl.lon[keep]),
            }
        )
    return tracks, ends, lines


def _switch_layer(net: Network, ends: _Ends) -> list[dict[str, Any]]:
    out = []
    for r in net.switches.to_dict("records"):
        lat, lon = _clean(r.get("lat")), _clean(r.get("lon"))
        if lat is None or lon is None:
            toe = ends.get(r["a1_track"], r["a1_end"])
            if toe is None:
                continue
            lat, lon = toe
        out.append(
            {
                "id": str(r["switch_id"]),
                "type": _clean(r["type"]),
                "n": _clean(r.get("switch_number")),
                "side": _clean(r.get("diverging_side")),
                "radius": _clean(r.get("diverging_radius_m")),
                "speed": _clean(r.get("diverging_speed_kmh")),
                "ports": {p: _clean(r.get(f"{p}_track")) for p in ("a1", "b1", "b2", "a2")},
                "lat": float(lat),
                "lon": float(lon),
            }
        )
    return out


def _connection_layer(net: Network, ends: _Ends) -> list[dict[str, Any]]:
    places: dict[tuple[int, int], dict[str, Any]] = {}
    for r in net.connections.to_dict("records"):
        at = ends.get(r["track_a"], r["end_a"]) or ends.get(r["track_b"], r["end_b"])
        if at is None:
            continue
        key = (round(at[0] * COORD_SCALE), round(at[1] * COORD_SCALE))
        place = places.setdefault(key, {"lat": at[0], "lon": at[1], "links": []})
        place["links"].append(
            {
                "a": str(r["track_a"]),
                "ea": str(r["end_a"]),
                "b": str(r["track_b"]),
                "eb": str(r["end_b"]),
                "nav": _clean(r["navigability"]),
                "switch": _clean(r["switch_id"]),
            }
        )
    return list(places.values())


def _balise_at(r: dict[str, Any], grid: Any, by_track: dict[str, Centreline]) -> tuple[float, float] | None:
    """lat/lon of a balise: on the line grid by (line, track, km), else on its track by km."""
    p = grid.at(r.get("line_code"), r.get("track"), r.get("km_actual_m"))
    if p is not None:
        return float(p[1]), float(p[0])
    cl = by_track.get(str(r.get("track_id")))
    km = _clean(r.get("km_actual_m"))
    if cl is None or km is None:
        return None
    ok = np.isfinite(cl.km_m)
    if ok.sum() < 2:
        return None
    k, order = cl.km_m[ok], np.argsort(cl.km_m[ok])
    if not k.min() <= km <= k.max():
        return None
    return float(np.interp(km, k[order], cl.lat[ok][order])), float(np.interp(km, k[order], cl.lon[ok][order]))


def _group_layer(net: Network, lines: list[Centreline]) -> list[dict[str, Any]]:
    from dbtools.interchange.geojson import GridLocator

    b = net.balises
    if "nid_c" not in b.columns:
        return []
    g = b[(b["kind"].astype(object) == "G") & b["nid_c"].notna() & b["nid_bg"].notna()]
    if g.empty:
        return []
    grid, by_track = GridLocator(net), {c.track_id: c for c in lines}
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for rec in g.to_dict("records"):
        r = {str(k): v for k, v in rec.items()}
        groups[f"{int(r['nid_c'])}:{int(r['nid_bg'])}"].append(r)
    out = []
    for gid, rows in sorted(groups.items()):
        pts = [p for p in (_balise_at(r, grid, by_track) for r in rows) if p is not None]
        if not pts:
            continue
        rows = sorted(rows, key=lambda r: -1 if pd.isna(r.get("n_pig")) else int(r["n_pig"]))
        out.append(
            {
                "id": gid,
                "lat": float(np.mean([p[0] for p in pts])),
                "lon": float(np.mean([p[1] for p in pts])),
                "balises": [str(r["balise_id"]) for r in rows],
                "n_total": _clean(rows[0].get("n_total")),
                "link": _clean(rows[0].get("link_group")),
                "link_m": _clean(rows[0].get("link_distance_m")),
                "track": _clean(rows[0].get("track_id")),
            }
        )
    return out


def _tick_layer(lines: list[Centreline]) -> list[dict[str, Any]]:
    """Whole multiples of :data:`KM_TICK_M` of km along each track that has km: per track its
    kms and their places, delta-encoded like the tracks (a national DB has tens of thousands)."""
    out = []
    for cl in lines:
        ok = np.isfinite(cl.km_m)
        if ok.sum() < 2:
            continue
        km, lat, lon = cl.km_m[ok], cl.lat[ok], cl.lon[ok]
        order = np.argsort(km)
        km, lat, lon = km[order], lat[order], lon[order]
        ticks = np.arange(np.ceil(km[0] / KM_TICK_M), np.floor(km[-1] / KM_TICK_M) + 1) * KM_TICK_M
        if ticks.size:
            at_lat, at_lon = np.interp(ticks, km, lat), np.interp(ticks, km, lon)
            out.append({"track": cl.track_id, "km": [float(k) for k in ticks], "c": encode(at_lat, at_lon)})
    return out


def network_layers(net: Network, projector: Projector) -> dict[str, Any]:
    """Every layer of the module docstring, JSON-ready, plus the bounds [[S, W], [N, E]]."""
    tracks, ends, lines = _track_layer(net, projector)
    layers: dict[str, Any] = {
        "tracks": tracks,
        "switches": _switch_layer(net, ends),
        "connections": _connection_layer(net, ends),
        "groups": _group_layer(net, lines),
        "ticks": _tick_layer(lines),
        "scale": COORD_SCALE,
    }
    lat = np.concatenate([c.lat for c in lines]) if lines else np.empty(0)
    lon = np.concatenate([c.lon for c in lines]) if lines else np.empty(0)
    layers["bounds"] = (
        [[float(lat.min()), float(lon.min())], [float(lat.max()), float(lon.max())]] if lat.size else None
    )
    return layers
