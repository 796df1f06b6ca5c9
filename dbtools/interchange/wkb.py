"""Well-known binary (ISO/OGC simple features) of GeoJSON points and line strings, and the
GeoPackage binary header around it (GeoPackage 1.4 §2.1.3).

WKB: byte order 1 (little endian), uint32 type (1 Point, 2 LineString; + 1000 with Z),
IEEE doubles. GeoPackage geometry: ``b"GP"``, version 0, flags (bit 0 little endian, bits
1–3 envelope code 1 = [minx, maxx, miny, maxy], bit 4 empty), int32 srs_id, the envelope,
then the WKB.
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import Any

TYPES = {"Point": 1, "LineString": 2}


def _coords(geometry: dict[str, Any]) -> list[Sequence[float]]:
    c = geometry["coordinates"]
    return [c] if geometry["type"] == "Point" else list(c)


def wkb(geometry: dict[str, Any]) -> bytes:
    """WKB of a GeoJSON Point or LineString (Z when every coordinate has a third value)."""
    pts = _coords(geometry)
    z = all(len(p) > 2 for p in pts)
    dims = 3 if z else 2
    code = TYPES[geometry["type"]] + (1000 if z else 0)
    head = struct.pack("<BI", 1, code)
    body = b"".join(struct.pack(f"<{dims}d", *p[:dims]) for p in pts)
    if geometry["type"] == "LineString":
        head += struct.pack("<I", len(pts))
    return head + body


def envelope(geometry: dict[str, Any]) -> tuple[float, float, float, float]:
    """(min_x, max_x, min_y, max_y)."""
    pts = _coords(geometry)
    xs, ys = [p[0] for p in pts], [p[1] for p in pts]
    return min(xs), max(xs), min(ys), max(ys)


def gpkg_geometry(geometry: dict[str, Any] | None, srs_id: int) -> bytes | None:
    """GeoPackage binary geometry (None for a missing geometry: a NULL column)."""
    if geometry is None:
        return None
    flags = 0b0000_0011  # little endian, xy envelope
    return b"GP" + struct.pack("<BBi", 0, flags, srs_id) + struct.pack("<4d", *envelope(geometry)) + wkb(geometry)
