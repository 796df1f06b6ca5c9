"""GNSS traces as GeoJSON points (RFC 7946; tp-lib's ``gnss.geojson``) → the ``gps`` stream.

A FeatureCollection whose Point features are fixes: ``coordinates`` [lon, lat(, height)] in
WGS 84 — the collection's ``crs`` absent, ``EPSG:4326`` or ``OGC:1.3:CRS84`` (lon/lat order
either way, as RFC 7946 and tp-lib write them); a time stamp in the property ``timestamp``
(or ``time``), ISO 8601, taken in the declared time zone (``logs import --time-zone``) where
it has no offset. Optional properties: ``speed_kmh`` or ``speed_mps``, ``course_deg`` (or
``heading``), ``hdop``, ``nsat``, ``fix``. Without quality properties ``fix`` is 1 (a
position of unknown quality) and ``nsat``/``hdop`` empty, as for a mapped CSV trace
(:mod:`fieldlogs.recorders.tabular`). Features that are not points are skipped and counted.
"""

from __future__ import annotations

import json
from datetime import tzinfo
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fieldlogs.recorders.common import Decoded, read_bytes
from fieldlogs.recorders.timebase import StampError, stamps_to_gps
from schemas.errors import InputError
from schemas.units import KMH

#: CRS names read as WGS 84 longitude/latitude.
WGS84_NAMES = ("EPSG:4326", "urn:ogc:def:crs:EPSG::4326", "urn:ogc:def:crs:OGC:1.3:CRS84", "OGC:CRS84", "CRS84")
TIME_KEYS = ("timestamp", "time")


def _features(path: Path) -> list[Any]:
    try:
        doc = json.loads(read_bytes(path).decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a GeoJSON file: {exc}", path=path) from exc
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection" or not isinstance(doc.get("features"), list):
        raise InputError("not a GeoJSON FeatureCollection", path=path)
    crs = doc.get("crs")
    name = crs.get("properties", {}).get("name") if isinstance(crs, dict) else None
    if name is not None and str(name) not in WGS84_NAMES:
        raise InputError(f"crs '{name}': GNSS points must be WGS 84 longitude/latitude (EPSG:4326)", path=path)
    return list(doc["features"])


def _number(path: Path, props: dict[str, Any], key: str, k: int) -> float:
    v = props.get(key)
    if v is None:
        return np.nan
    try:
        return float(v)
    except (TypeError, ValueError) as exc:
        raise InputError(f"feature {k}: property {key} = {v!r} is not a number", path=path, column=key) from exc


def _point(path: Path, f: Any, k: int) -> tuple[list[float], dict[str, Any]] | None:
    geom = f.get("geometry") if isinstance(f, dict) else None
    if not isinstance(geom, dict) or geom.get("type") != "Point":
        return None
    c = geom.get("coordinates")
    if not isinstance(c, list) or len(c) < 2 or not all(isinstance(v, int | float) for v in c[:3]):
        raise InputError(f"feature {k}: Point coordinates {c!r} are not [lon, lat]", path=path, column="coordinates")
    props = f.get("properties") or {}
    return [float(v) for v in c[:3]], props


def read_geojson(path: Path, zone: tzinfo | None = None) -> Decoded:
    """A GeoJSON point trace → ``gps`` on GPS time (module docstring)."""
    path = Path(path)
    dec = Decoded(str(path), "geojson")
    feats = _features(path)
    dec.records = len(feats)
    rows: list[list[float]] = []
    stamps: list[object] = []
    index: list[int] = []
    for k, f in enumerate(feats):
        got = _point(path, f, k)
        if got is None:
            dec.skipped["feature not a Point"] += 1
            continue
        c, props = got
        stamp = next((props[t] for t in TIME_KEYS if props.get(t) is not None), None)
        if stamp is None:
            raise InputError(f"feature {k}: no time stamp (property timestamp)", path=path, column="timestamp")
        speed = _number(path, props, "speed_mps", k)
        if not np.isfinite(speed):
            speed = _number(path, props, "speed_kmh", k) * KMH
        course = _number(path, props, "course_deg" if "course_deg" in props else "heading", k)
        fix = _number(path, props, "fix", k)
        rows.append([c[1], c[0], c[2] if len(c) > 2 else np.nan, speed, course % 360.0, fix,
                     _number(path, props, "nsat", k), _number(path, props, "hdop", k)])  # fmt: skip
        stamps.append(stamp)
        index.append(k)
    try:
        g = stamps_to_gps(stamps, zone)
    except StampError as exc:
        raise InputError(f"feature {index[exc.row]}: {exc}", path=path, column="timestamp") from exc
    cols = ["lat", "lon", "height_m", "speed_mps", "course_deg", "fix", "nsat", "hdop"]
    frame = pd.DataFrame(np.array(rows, dtype=np.float64).reshape(len(rows), len(cols)), columns=cols)
    pos = np.isfinite(frame["lat"].to_numpy()) & np.isfinite(frame["lon"].to_numpy())
    frame["fix"] = frame["fix"].where(frame["fix"].notna(), pos.astype(np.float64))
    frame.insert(0, "gnss_time_s", g)
    dec.frames["gps"] = frame
    return dec
