"""An interactive map that works offline, for self-contained HTML pages (``db review``).

The page carries everything inline: Leaflet 1.9.4 (BSD-2-Clause, vendored from the npm
package under ``vendor/leaflet/`` with its LICENSE), the map script ``review_map.js`` and
the data as JSON (:mod:`dbtools.interchange.netmap` layers plus the changes of
:func:`dbtools.interchange.mapchanges.map_data`). With no tile URL the map draws on a plain
background and loads nothing; ``tiles`` adds an XYZ tile layer (``{z}/{x}/{y}`` template,
e.g. an OpenStreetMap tile server), the only network access the page then makes.
"""

from __future__ import annotations

import json
from importlib import resources
from typing import Any

from dbtools.gis.geometry import Projector
from dbtools.interchange.mapchanges import MapData
from dbtools.interchange.netmap import encode, network_layers, simplify
from dbtools.network import Network

LEAFLET_VERSION = "1.9.4"
#: Attribution shown with a tile layer unless another is given (OpenStreetMap's licence
#: asks for it on every map of its tiles).
OSM_ATTRIBUTION = "© OpenStreetMap contributors"
MAP_HEIGHT_PX = 640

MAP_CSS = """
#review-map{height:%dpx;border:1px solid #ccc;background:#f4f4f2}
.map-legend{background:rgba(255,255,255,.92);padding:6px 10px;font-size:12px;line-height:18px;border-radius:4px}
.map-legend i{display:inline-block;width:18px;height:4px;margin:0 6px 2px 0;vertical-align:middle}
.map-legend i.dot{width:10px;height:10px;border-radius:5px}
.sw-label{font:11px/1.2 system-ui,sans-serif;color:#7a1010;background:rgba(255,255,255,.85);padding:0 3px;
border-radius:3px;white-space:nowrap;pointer-events:none}
"""


def asset(name: str) -> str:
    """Text of a file shipped beside this module (``vendor/leaflet/leaflet.js``, …)."""
    return resources.files("dbtools.interchange").joinpath(name).read_text(encoding="utf-8")


def _script_json(data: Any) -> str:
    """JSON safe inside ``<script>``: no ``<`` (so no ``</script>``) and no U+2028/9."""
    text = json.dumps(data, ensure_ascii=False, separators=(",", ":"), allow_nan=False)
    return text.replace("<", "\\u003c").replace("\u2028", "\\u2028").replace("\u2029", "\\u2029")


def _latlon(p: tuple[float, float] | None) -> list[float] | None:
    return None if p is None else [round(p[1], 7), round(p[0], 7)]


def changes_layer(data: MapData, projector: Projector) -> dict[str, Any]:
    """The changes (lon/lat pairs of :class:`MapData`) as ``changes`` and ``removed_tracks``."""
    import numpy as np

    removed = []
    for label, line in data.removed_lines:
        if len(line) < 2:
            continue
        lon, lat = np.asarray([p[0] for p in line]), np.asarray([p[1] for p in line])
        keep = simplify(lat, lon, projector)
        removed.append({"id": label, "c": encode(lat[keep], lon[keep])})
    changes = [
        {
            "kind": c.kind,
            "what": c.what,
            "label": c.label,
            "old": _latlon(c.old),
            "new": _latlon(c.new),
            "shift": None if c.shift_m is None else float(c.shift_m),
        }
        for c in data.changes
    ]
    return {"changes": changes, "removed_tracks": removed}


def map_payload(
    net: Network,
    projector: Projector,
    data: MapData | None = None,
    *,
    tiles: str | None = None,
    tiles_attribution: str = OSM_ATTRIBUTION,
) -> dict[str, Any]:
    """Everything the map script reads (module doc)."""
    payload = network_layers(net, projector)
    payload.update(changes_layer(data or MapData(), projector))
    payload["tiles"], payload["tiles_attribution"] = tiles, tiles_attribution if tiles else ""
    return payload


def render_map(payload: dict[str, Any], *, height_px: int = MAP_HEIGHT_PX) -> str:
    """The map as one HTML fragment: Leaflet's CSS and script, the data and the map script."""
    return "\n".join(
        [
            f"<style>{asset('vendor/leaflet/leaflet.css')}{MAP_CSS % height_px}</style>",
            "<div id='review-map' role='application' aria-label='interactive network map'></div>",
            f"<script type='application/json' id='review-map-data'>{_script_json(payload)}</script>",
            f"<script>/* Leaflet {LEAFLET_VERSION}, BSD-2-Clause (vendor/leaflet/LICENSE) */\n"
            f"{asset('vendor/leaflet/leaflet.js')}</script>",
            f"<script>{asset('review_map.js')}</script>",
        ]
    )
