"""``db export --format rtm-geojson``: the network as RailTopoModel GeoJSON in the fields
tp-lib's reader takes (``tp-core/src/io/geojson.rs``; the reader of this import,
:mod:`~dbtools.interchange.rtm_read`, takes the same).

* one **netelement** per track of :func:`dbtools.topology.all_tracks` (declared and implied
  line tracks): a ``LineString`` of its centreline (:func:`dbtools.topology.centreline`,
  first vertex at its begin = position 0) with ``id`` (the track id), ``type``
  ``netelement`` and our ``line_code``, ``track``, ``kind``, ``length_m``, ``name`` beside
  (tp-lib ignores properties it does not know). A track without a centreline of two
  points cannot be a LineString and is left out (counted as ``tracks_without_geometry``);
* one **netrelation** per connection: a ``Point`` at track A's connected end with ``type``
  ``netrelation``, ``id`` (``A:end--B:begin``: the DB keeps no relation ids),
  ``netelementA``/``netelementB``, ``positionOnA``/``positionOnB`` (0 at ``begin``, 1 at
  ``end``), ``navigability`` (both/AB/BA/none) and ``switch_id``. Connections whose track
  has no geometry are left out with it;
* a ``crs`` member naming ``EPSG:4326``: lat/lon are written as the DB holds them (in the
  geodetic datum of the network's metric CRS, within a metre or two of WGS 84, as every
  GeoJSON export of the suite: :mod:`~dbtools.interchange.geojson`).
"""

from __future__ import annotations

from typing import Any

import pandas as pd

from dbtools.interchange.geojson import collection, feature, line_string, point
from dbtools.network import Network
from dbtools.topology import Centreline, all_tracks, centreline
from schemas.enums import TrackEnd

CRS_MEMBER = {"type": "name", "properties": {"name": "EPSG:4326"}}


def _opt(v: Any) -> Any:
    return None if v is None or (not isinstance(v, str) and pd.isna(v)) else v


def relation_id(track_a: str, end_a: str, track_b: str, end_b: str) -> str:
    return f"{track_a}:{end_a}--{track_b}:{end_b}"


def centrelines(network: Network) -> dict[str, Centreline]:
    """Every track's centreline with at least two points, by track id."""
    out = {}
    for _, row in all_tracks(network).iterrows():
        cl = centreline(network, row)
        if len(cl.pos_m) >= 2:
            out[cl.track_id] = cl
    return out


def rtm_features(network: Network) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """The features (module doc) and counts: netelements, netrelations, left out."""
    lines = centrelines(network)
    feats: list[dict[str, Any]] = []
    tracks = all_tracks(network)
    for rec in tracks.to_dict("records"):
        cl = lines.get(str(rec["track_id"]))
        if cl is None:
            continue
        props: dict[str, Any] = {"id": cl.track_id, "type": "netelement"}
        props.update({k: _opt(rec[k]) for k in ("line_code", "track", "kind", "length_m", "name")})
        feats.append(feature(line_string(list(zip(cl.lon, cl.lat, strict=True))), props))
    n_rel = 0
    for rec in network.connections.to_dict("records"):
        a, b = str(rec["track_a"]), str(rec["track_b"])
        if a not in lines or b not in lines:
            continue
        at = 0 if rec["end_a"] == TrackEnd.BEGIN.value else -1
        rel = {
            "id": relation_id(a, rec["end_a"], b, rec["end_b"]),
            "type": "netrelation",
            "netelementA": a,
            "netelementB": b,
            "positionOnA": 0 if rec["end_a"] == TrackEnd.BEGIN.value else 1,
            "positionOnB": 0 if rec["end_b"] == TrackEnd.BEGIN.value else 1,
            "navigability": rec["navigability"],
            "switch_id": _opt(rec["switch_id"]),
        }
        feats.append(feature(point(float(lines[a].lon[at]), float(lines[a].lat[at])), rel))
        n_rel += 1
    counts = {
        "netelements": len(lines),
        "netrelations": n_rel,
        "tracks_without_geometry": len(tracks) - len(lines),
        "connections_left_out": len(network.connections) - n_rel,
    }
    return feats, counts


def network_rtm_geojson(network: Network) -> tuple[dict[str, Any], dict[str, int]]:
    """The FeatureCollection (with its ``crs`` member) and the counts of :func:`rtm_features`."""
    feats, counts = rtm_features(network)
    out = collection(feats, name=f"trainpos {network.meta.get('db_version', '')}".strip())
    out["crs"] = CRS_MEMBER
    return out, counts
