"""GIS layers of the network (SPEC §8) for QGIS, beside the line-grid layers of
:func:`dbtools.interchange.geojson.network_features`; each feature carries its ``layer``:

* ``tracks``: a LineString per track of :func:`dbtools.topology.all_tracks` (declared and
  implied line tracks) along its centreline (:func:`dbtools.topology.centreline`):
  track_id, line_code, track, kind, km_begin_m, km_end_m, length_m, implied;
* ``switches``: a Point at the toe (the row's lat/lon, else the a1 track's end): switch_id,
  type, switch_number, diverging_side, diverging_radius_m, line_code, km_m, ports, name;
* ``connections``: a Point at the node (track A's connected end): track_a, end_a, track_b,
  end_b, navigability, switch_id;
* ``balise_groups``: a Point per balise of kind G: balise_id, kind, group (NID_C:NID_BG),
  nid_c, nid_bg, n_pig, n_total, link_group, link_distance_m, track_id, line_code, track,
  km_m. Its place: the line grid at its km where it names a line and track; else on its
  ``track_id`` at that km where the track's centreline has km, else at that distance from
  the track's begin;
* ``km_posts``: a Point at every whole kilometre (km_m a multiple of 1000) along each track
  with km: km (the value in km), km_m, track_id, line_code, track; lon/lat interpolated
  linearly in km between the centreline's points (20 m apart).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import pandas as pd

from dbtools.interchange.geojson import Geometry, GridLocator, feature, line_string, point
from dbtools.network import Network
from dbtools.topology import Centreline, all_tracks, centreline
from schemas.enums import BaliseKind, TrackEnd
from schemas.model import Table
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES
from schemas.tables import BALISES

LAYERS = ("tracks", "switches", "connections", "balise_groups", "km_posts")


def _types(*tables: Table, **extra: str) -> dict[str, str]:
    return {**{c.name: c.sql_type for t in tables for c in t.columns}, **extra}


#: SQL type of every attribute of the layers (their schema columns'), for the GeoPackage.
COLUMN_TYPES: dict[str, dict[str, str]] = {
    "tracks": _types(NETWORK_TRACKS, implied="INTEGER"),
    "switches": _types(SWITCHES),
    "connections": _types(CONNECTIONS),
    "balise_groups": _types(BALISES, group="TEXT", km_m="REAL"),
    "km_posts": {"km": "REAL", "km_m": "REAL", "track_id": "TEXT", "line_code": "TEXT", "track": "TEXT"},
    "balises": _types(BALISES),
}


def _v(v: Any) -> Any:
    if v is None or (not isinstance(v, str) and pd.isna(v)):
        return None
    return v.item() if isinstance(v, np.generic) else v


def _end_point(cl: Centreline | None, end: Any) -> Geometry:
    if cl is None or not len(cl.pos_m):
        return None
    i = 0 if end == TrackEnd.BEGIN.value else -1
    return point(float(cl.lon[i]), float(cl.lat[i]))


def _along(cl: Centreline | None, value: float) -> Geometry:
    """The point of the centreline at that km (where it has km) or that distance from its begin."""
    if cl is None or len(cl.pos_m) < 2 or not math.isfinite(value):
        return None
    km = cl.km_m
    by_km = bool(np.isfinite(km).all())
    x = km if by_km else cl.pos_m
    order = np.argsort(x)
    xs = x[order]
    if not xs[0] - 1e-6 <= value <= xs[-1] + 1e-6:
        return None
    return point(float(np.interp(value, xs, cl.lon[order])), float(np.interp(value, xs, cl.lat[order])))


def _tracks(tracks: pd.DataFrame, lines: dict[str, Centreline]) -> list[dict[str, Any]]:
    out = []
    cols = ("track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m", "name", "implied")
    for rec in tracks.to_dict("records"):
        cl = lines.get(str(rec["track_id"]))
        geom = None if cl is None else line_string(list(zip(cl.lon, cl.lat, strict=True)))
        out.append(feature(geom, {"layer": "tracks", **{c: _v(rec.get(c)) for c in cols}}))
    return out


def _switches(network: Network, lines: dict[str, Centreline]) -> list[dict[str, Any]]:
    out = []
    for rec in network.switches.to_dict("records"):
        lat, lon = _v(rec["lat"]), _v(rec["lon"])
        geom = point(lon, lat) if lat is not None and lon is not None else None
        if geom is None:
            geom = _end_point(lines.get(str(rec["a1_track"])), rec["a1_end"])
        props = {"layer": "switches", **{str(k): _v(v) for k, v in rec.items() if k not in ("lat", "lon")}}
        out.append(feature(geom, props, str(rec["switch_id"])))
    return out


def _connections(network: Network, lines: dict[str, Centreline]) -> list[dict[str, Any]]:
    out = []
    for rec in network.connections.to_dict("records"):
        geom = _end_point(lines.get(str(rec["track_a"])), rec["end_a"])
        out.append(feature(geom, {"layer": "connections", **{str(k): _v(v) for k, v in rec.items()}}))
    return out


def _balise_groups(network: Network, lines: dict[str, Centreline]) -> list[dict[str, Any]]:
    b = network.balises
    g = b[b["kind"].astype(object) == BaliseKind.G.value] if "kind" in b else b.iloc[0:0]
    loc = GridLocator(network)
    out = []
    cols = ("balise_id", "kind", "nid_c", "nid_bg", "n_pig", "n_total", "link_group", "link_distance_m")
    for rec in g.to_dict("records"):
        km = _v(rec["km_actual_m"])
        geom = loc.point_at(rec["line_code"], rec["track"], km) if _v(rec["line_code"]) is not None else None
        if geom is None and _v(rec.get("track_id")) is not None and km is not None:
            geom = _along(lines.get(str(rec["track_id"])), float(km))
        nid_c, nid_bg = _v(rec.get("nid_c")), _v(rec.get("nid_bg"))
        props = {c: _v(rec.get(c)) for c in cols}
        props.update(
            group=None if nid_c is None or nid_bg is None else f"{nid_c}:{nid_bg}",
            track_id=_v(rec.get("track_id")),
            line_code=_v(rec["line_code"]),
            track=_v(rec["track"]),
            km_m=km,
        )
        out.append(feature(geom, {"layer": "balise_groups", **props}, str(rec["balise_id"])))
    return out


def _km_posts(tracks: pd.DataFrame, lines: dict[str, Centreline]) -> list[dict[str, Any]]:
    out = []
    for rec in tracks.to_dict("records"):
        cl = lines.get(str(rec["track_id"]))
        if cl is None or len(cl.km_m) < 2 or not np.isfinite(cl.km_m).all():
            continue
        lo, hi = float(np.min(cl.km_m)), float(np.max(cl.km_m))
        for k in range(math.ceil(lo / 1000.0 - 1e-9), math.floor(hi / 1000.0 + 1e-9) + 1):
            props = {
                "layer": "km_posts",
                "km": float(k),
                "km_m": 1000.0 * k,
                "track_id": cl.track_id,
                "line_code": _v(rec["line_code"]),
                "track": _v(rec["track"]),
            }
            out.append(feature(_along(cl, 1000.0 * k), props))
    return out


def _centrelines(network: Network) -> dict[str, Centreline]:
    def build() -> dict[str, Centreline]:
        return {str(row["track_id"]): centreline(network, row) for _, row in all_tracks(network).iterrows()}

    return network.cached(("network_layers", "centrelines"), build)


def on_track(network: Network) -> Callable[[Any, Any], Geometry]:
    """(track_id, km) → the point on that track (as a balise group's: module doc)."""
    lines = _centrelines(network)

    def place(track_id: Any, km: Any) -> Geometry:
        return None if _v(km) is None else _along(lines.get(str(track_id)), float(km))

    return place


def network_layer_features(network: Network) -> list[dict[str, Any]]:
    """The features of every layer of :data:`LAYERS` (module doc)."""
    tracks = all_tracks(network)
    lines = _centrelines(network)
    return (
        _tracks(tracks, lines)
        + _switches(network, lines)
        + _connections(network, lines)
        + _balise_groups(network, lines)
        + _km_posts(tracks, lines)
    )
