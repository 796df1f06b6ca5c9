"""A track match as GeoJSON (RFC 7946, WGS 84): the path tracks as LineStrings of their
centrelines (layer ``path``, properties the path row) and the fixes as Points at their
measured position (layer ``fix``, properties the fix row), through the suite's one GeoJSON
writer (:mod:`dbtools.interchange.geojson`)."""

from __future__ import annotations

from typing import Any

import pandas as pd

from dbtools.network import Network
from fieldlogs.trackmatch.result import TrackMatch


def match_geojson(net: Network, result: TrackMatch, name: str = "track-match") -> dict[str, Any]:
    """FeatureCollection of the path (centrelines) and the fixes (module docstring)."""
    from dbtools.interchange.geojson import collection, feature, frame_points, line_string
    from dbtools.topology import all_tracks, centreline

    tracks = all_tracks(net)
    row_of = {str(t): i for i, t in enumerate(tracks["track_id"])}
    feats = []
    for rec in result.path.to_dict("records"):
        c = centreline(net, tracks.iloc[row_of[str(rec["track_id"])]])
        geom = line_string(list(zip(c.lon, c.lat, strict=True)))
        props = {"layer": "path", **{str(k): (None if pd.isna(v) else v) for k, v in rec.items()}}
        feats.append(feature(geom, props))
    feats += frame_points(result.fixes, "fix")
    return collection(feats, name)
