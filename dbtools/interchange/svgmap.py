"""An offline map of a DB change as inline SVG: no tiles, no script, no external resource.

Points are projected into the network's metric CRS (:func:`dbtools.gis.index.network_georef`)
and fitted into the drawing (north up, one scale for x and y). Drawn: the GIS lines of the
new network (grey; removed track lines dashed), then the changes — added (green) and
removed (red) balises, feature points and GIS points as markers, and moves (orange) as
arrows from the old to the new position. A move of metres is invisible at the scale of a
line, so arrows are drawn exaggerated by one factor for the whole map (the largest move
becomes :data:`MAX_ARROW_PX`; the factor is printed in the legend, and the true shift in
metres is in each element's tooltip).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from dbtools.gis.geometry import Projector
from dbtools.interchange.geojson import GridLocator
from dbtools.network import Network
from dbtools.pagekit import escape

WIDTH, HEIGHT, PAD = 1000, 620, 40
MAX_ARROW_PX = 40.0
COLOURS = {"added": "#1a7f37", "removed": "#c0392b", "moved": "#d4760a", "line": "#9aa0a6"}


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
    lines: list[list[tuple[float, float]]] = field(default_factory=list)
    removed_lines: list[list[tuple[float, float]]] = field(default_factory=list)
    changes: list[Change] = field(default_factory=list)


class _Frame:
    """lon/lat → SVG pixels through the metric CRS."""

    def __init__(self, projector: Projector, pts: Sequence[tuple[float, float]]) -> None:
        self.p = projector
        x, y = self.xy(pts)
        self.x0, self.y1 = float(np.min(x)), float(np.max(y))
        span = max(float(np.ptp(x)), float(np.ptp(y)) * (WIDTH - 2 * PAD) / (HEIGHT - 2 * PAD), 1.0)
        self.scale = (WIDTH - 2 * PAD) / span
        self.cx = (WIDTH - 2 * PAD - float(np.ptp(x)) * self.scale) / 2
        self.cy = (HEIGHT - 2 * PAD - float(np.ptp(y)) * self.scale) / 2

    def xy(self, pts: Sequence[tuple[float, float]]) -> tuple[np.ndarray, np.ndarray]:
        a = np.asarray(pts, dtype=float).reshape(-1, 2)
        return self.p.to_xy(a[:, 0], a[:, 1])

    def px(self, pts: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
        x, y = self.xy(pts)
        return [
            (PAD + self.cx + (xi - self.x0) * self.scale, PAD + self.cy + (self.y1 - yi) * self.scale)
            for xi, yi in zip(x.tolist(), y.tolist(), strict=True)
        ]


def _poly(pts: list[tuple[float, float]], style: str) -> str:
    d = " ".join(f"{x:.1f},{y:.1f}" for x, y in pts)
    return f"<polyline points='{d}' fill='none' {style}/>"


def _marker(c: Change, fr: _Frame) -> str:
    where = c.new or c.old
    assert where is not None
    (x, y), colour = fr.px([where])[0], COLOURS[c.kind]
    title = f"<title>{escape(c.what)} {escape(c.label)} {escape(c.kind)}</title>"
    if c.what == "GIS point":
        return (
            f"<rect class='chg {c.kind}' x='{x - 3:.1f}' y='{y - 3:.1f}' width='6' height='6' "
            f"fill='{colour}'>{title}</rect>"
        )
    shape = "circle" if c.what == "balise" else "rect"
    if shape == "circle":
        return (
            f"<circle class='chg {c.kind}' cx='{x:.1f}' cy='{y:.1f}' r='5' fill='{colour}' "
            f"stroke='#fff'>{title}</circle>"
        )
    return (
        f"<polygon class='chg {c.kind}' points='{x:.1f},{y - 6:.1f} {x + 6:.1f},{y + 5:.1f} "
        f"{x - 6:.1f},{y + 5:.1f}' fill='{colour}'>{title}</polygon>"
    )


def _arrow(c: Change, fr: _Frame, factor: float) -> str:
    assert c.old is not None and c.new is not None
    (x0, y0), (x1, y1) = fr.px([c.old, c.new])
    dx, dy = (x1 - x0) * factor, (y1 - y0) * factor
    title = f"<title>{escape(c.what)} {escape(c.label)} moved {c.shift_m or 0:.2f} m</title>"
    return (
        f"<line class='chg moved' x1='{x0:.1f}' y1='{y0:.1f}' x2='{x0 + dx:.1f}' y2='{y0 + dy:.1f}' "
        f"stroke='{COLOURS['moved']}' stroke-width='2' marker-end='url(#arrow)'>{title}</line>"
        f"<circle cx='{x0:.1f}' cy='{y0:.1f}' r='2.5' fill='{COLOURS['moved']}'/>"
    )


def _factor(moves: list[Change], fr: _Frame) -> float:
    lengths = []
    for c in moves:
        (x0, y0), (x1, y1) = fr.px([c.old, c.new])  # type: ignore[list-item]
        lengths.append(float(np.hypot(x1 - x0, y1 - y0)))
    top = max(lengths, default=0.0)
    return 1.0 if top <= 0 else max(1.0, MAX_ARROW_PX / top)


def _legend(factor: float, counts: dict[str, int], metres_per_px: float) -> str:
    items = [
        ("added", "circle", f"added ({counts['added']})"),
        ("removed", "circle", f"removed ({counts['removed']})"),
        ("moved", "line", f"moved ({counts['moved']}), arrows ×{factor:,.0f}"),
    ]
    out = [
        "<g class='legend' font-size='12' font-family='sans-serif'>",
        f"<rect x='10' y='10' width='300' height='{28 + 18 * (len(items) + 2)}' fill='#fff' "
        "fill-opacity='0.9' stroke='#ccc'/>",
        "<text x='20' y='28' font-weight='bold'>Legend</text>",
    ]
    y = 46
    for kind, shape, text in items:
        if shape == "line":
            out.append(
                f"<line x1='20' y1='{y - 4}' x2='40' y2='{y - 4}' stroke='{COLOURS[kind]}' "
                "stroke-width='2' marker-end='url(#arrow)'/>"
            )
        else:
            out.append(f"<circle cx='30' cy='{y - 4}' r='5' fill='{COLOURS[kind]}'/>")
        out.append(f"<text x='50' y='{y}'>{escape(text)}</text>")
        y += 18
    out.append(f"<text x='20' y='{y}'>● balise ▲ feature point ■ GIS point; grey: track</text>")
    out.append(f"<text x='20' y='{y + 18}'>scale: 100 px = {metres_per_px * 100:,.0f} m; north up</text>")
    out.append("</g>")
    return "".join(out)


def render_svg(data: MapData, projector: Projector) -> str:
    """The map as one ``<svg>`` element (module doc)."""
    pts = [p for ln in data.lines + data.removed_lines for p in ln]
    pts += [p for c in data.changes for p in (c.old, c.new) if p is not None]
    if not pts:
        return "<p class='note'>Nothing to draw: neither network has GIS points.</p>"
    fr = _Frame(projector, pts)
    moves = [c for c in data.changes if c.kind == "moved" and c.old and c.new]
    factor = _factor(moves, fr)
    counts = {k: sum(c.kind == k for c in data.changes) for k in ("added", "removed", "moved")}
    parts = [
        f"<svg xmlns='http://www.w3.org/2000/svg' id='review-map' role='img' aria-label='map of the changes' "
        f"viewBox='0 0 {WIDTH} {HEIGHT}' width='{WIDTH}' height='{HEIGHT}' "
        "style='background:#fafafa;border:1px solid #ddd'>",
        "<defs><marker id='arrow' viewBox='0 0 10 10' refX='9' refY='5' markerWidth='6' markerHeight='6' orient='auto'>"
        f"<path d='M0,0 L10,5 L0,10 z' fill='{COLOURS['moved']}'/></marker></defs>",
    ]
    parts += [_poly(fr.px(ln), f"stroke='{COLOURS['line']}' stroke-width='2'") for ln in data.lines if len(ln) > 1]
    parts += [
        _poly(fr.px(ln), f"stroke='{COLOURS['removed']}' stroke-width='1.5' stroke-dasharray='6,4'")
        for ln in data.removed_lines
        if len(ln) > 1
    ]
    parts += [_marker(c, fr) for c in data.changes if c.kind != "moved" and (c.new or c.old)]
    parts += [_arrow(c, fr, factor) for c in moves]
    parts.append(_legend(factor, counts, 1.0 / fr.scale))
    parts.append("</svg>")
    return "".join(parts)


def _grid_lines(net: Network) -> dict[tuple[str, str], list[tuple[float, float]]]:
    loc = GridLocator(net)
    return {k: list(zip(v[1].tolist(), v[2].tolist(), strict=True)) for k, v in loc.tracks.items()}


def map_data(old: Network, new: Network, diff: Any) -> MapData:
    """What changed, placed on the grids (balises and feature points by their km)."""
    lo, ln = GridLocator(old), GridLocator(new)
    new_lines, old_lines = _grid_lines(new), _grid_lines(old)
    data = MapData(list(new_lines.values()), [v for k, v in old_lines.items() if k not in new_lines])
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
