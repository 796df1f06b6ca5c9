"""The source-set tables of an OSM import: tracks, track_points, lines, switches' line and
km, balise groups (SPEC §8.1, §8.2).

**Track kind** from the way's ``service``: ``crossover`` → crossover, ``siding`` and
``spur`` → siding, ``yard`` → yard; without ``service``: *station* when the way carries
``railway:track_ref`` (a numbered track: OSM maps it on station tracks; the station area
itself is not looked at — a guess, reported), else main. Any other ``service`` value →
siding (reported).

**Line** of a track: the ``ref`` of the line relation holding its way (``type=route``,
``route=railway|tracks``; ``route=train`` relations are services, not lines), else the
way's ``ref`` (in Germany the line number, *Streckennummer*), else ``railway:ref``; several
values (``2600;2630``, a shared section) → the first (reported). The line's name: its
relation's ``name``, else the most common ``name`` of its ways. Local track name: ``railway:track_ref``.

**Balise groups** (``railway=balise_group``): a group gives kind ``G`` rows only where the
node's tags give its ETCS identity — ``railway:etcs:nid_bg`` (or ``nid_bg``) 0…16383 and
optionally ``railway:etcs:nid_c`` (``nid_c``) 0…1023 — and its track has a km. It gives
``balise_count`` (1…8, default 1) rows, N_PIG 0…n−1, all at the node's km (OSM maps the
group, not its balises); ids ``<ref or n<node>>_<N_PIG>``. Every other group is reported
with its node id.
"""

from __future__ import annotations

import re
from collections import Counter
from typing import Any

import numpy as np
import pandas as pd

from dbtools.interchange.osm_km import KmModel
from dbtools.interchange.osm_read import OsmData, OsmNode, RailWay
from dbtools.interchange.osm_split import Pieces, at_pos, grid
from schemas.enums import BaliseKind, Severity, TrackKind
from schemas.findings import Finding
from schemas.network import NETWORK_TRACKS, TRACK_POINTS
from schemas.tables import BALISES, LINES

SERVICE_KIND = {
    "crossover": TrackKind.CROSSOVER,
    "siding": TrackKind.SIDING,
    "spur": TrackKind.SIDING,
    "yard": TrackKind.YARD,
}


def _first(value: str | None) -> str | None:
    if value is None or not value.strip():
        return None
    return value.split(";")[0].strip() or None


def line_ref(data: OsmData, way: RailWay) -> tuple[str | None, bool]:
    """The raw line ref of a way (module doc) and whether a line relation gave it."""
    route = data.routes.get(way.way_id)
    if route:
        return route[0], True
    return way.tags.get("ref") or way.tags.get("railway:ref"), False


def _kind(tags: dict[str, str]) -> TrackKind:
    service = tags.get("service")
    if service is None:
        return TrackKind.STATION if tags.get("railway:track_ref") else TrackKind.MAIN
    return SERVICE_KIND.get(service, TrackKind.SIDING)


def way_attributes(data: OsmData, p: Pieces) -> tuple[pd.DataFrame, list[Finding]]:
    """Per piece: line_code, track, kind, name (module doc), and the findings of the guesses."""
    findings: list[Finding] = []
    per_way: list[tuple[str | None, str | None, str, str | None]] = []
    station, odd_service, multi = [], Counter[str](), Counter[str]()
    from_way: list[int] = []
    for way in data.ways:
        t = way.tags
        raw, from_route = line_ref(data, way)
        if raw and not from_route:
            from_way.append(way.way_id)
        if raw and ";" in raw:
            multi[raw] += 1
        kind = _kind(t)
        if kind == TrackKind.STATION:
            station.append(way.way_id)
        elif "service" in t and t["service"] not in SERVICE_KIND:
            odd_service[t["service"]] += 1
        per_way.append((_first(raw), t.get("railway:track_ref"), kind.value, t.get("name")))
    if from_way and data.routes:
        findings.append(
            _note(
                "osm.line_guess", "tracks", f"{len(from_way)} way(s) in no line relation: line from the way's ref", []
            )
        )
    if station:
        findings.append(
            _note(
                "osm.kind_guess",
                "tracks",
                f"{len(station)} way(s) without service but with "
                "railway:track_ref taken as station tracks (station areas not checked)",
                station,
            )
        )
    for service, n in sorted(odd_service.items()):
        findings.append(_note("osm.kind_guess", "tracks", f"service={service} on {n} way(s): taken as siding", []))
    for raw, n in sorted(multi.items()):
        findings.append(
            _note("osm.line_guess", "tracks", f"ref '{raw}' on {n} way(s) names several lines: the first is used", [])
        )
    rows = [per_way[int(w)] for w in p.way_index]
    frame = pd.DataFrame(rows, columns=["line_code", "track", "kind", "name"])
    frame.insert(0, "track_id", p.track_id)
    return frame, findings


def _note(rule: str, table: str, message: str, ids: list[int], kind: str = "way") -> Finding:
    keys = {"element": ",".join(f"{kind}/{i}" for i in ids)} if ids else {}
    return Finding(rule, Severity.WARNING, table, message, keys=keys)


def lines_frame(data: OsmData, attrs: pd.DataFrame) -> pd.DataFrame:
    """One row per line code; name: the line relation's, else the most common way name."""
    names: dict[str, Counter[str]] = {}
    for ref, name, _ in data.routes.values():
        if name:
            names.setdefault(ref, Counter())[name] += 1_000_000  # a relation's name before any way's
    for way in data.ways:
        code = _first(line_ref(data, way)[0])
        if code is not None:
            names.setdefault(code, Counter())
            if way.tags.get("name"):
                names[code][way.tags["name"]] += 1
    codes = sorted(set(attrs["line_code"].dropna()))
    rows = [
        {"line_code": c, "name": names.get(c, Counter()).most_common(1)[0][0] if names.get(c) else None} for c in codes
    ]
    return pd.DataFrame(rows, columns=[c for c in LINES.column_names if c != "attributes_json"])


def tracks_and_points(
    p: Pieces, attrs: pd.DataFrame, km: KmModel, stops: set[tuple[str, str]]
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """``tracks`` and ``track_points`` (20 m grid, km where the track has posts)."""
    piece, pos = grid(p)
    points = pd.DataFrame(
        {
            "track_id": np.asarray(p.track_id, dtype=object)[piece],
            "pos_m": pos,
            "km_m": km.at(piece, pos),
            "lat": at_pos(p, piece, pos, "lat"),
            "lon": at_pos(p, piece, pos, "lon"),
            "height_m": np.nan,
        }
    )
    idx = np.arange(len(p), dtype=np.int64)
    tracks = attrs.copy()
    tracks["km_begin_m"] = km.at(idx, np.zeros(len(p)))
    tracks["km_end_m"] = km.at(idx, p.length)
    tracks["length_m"] = p.length
    for end in ("begin", "end"):
        tracks[f"{end}_buffer_stop"] = [True if (t, end) in stops else None for t in p.track_id]
    return tracks[NETWORK_TRACKS.column_names], points[TRACK_POINTS.column_names]


def _int_tag(tags: dict[str, str], keys: tuple[str, ...], hi: int) -> int | None:
    for k in keys:
        v = tags.get(k, "").strip()
        if re.fullmatch(r"\d+", v) and int(v) <= hi:
            return int(v)
    return None


def balise_groups(data: OsmData, p: Pieces, tracks: pd.DataFrame, km: KmModel) -> tuple[pd.DataFrame, list[Finding]]:
    """Kind G rows of the groups with an identity on a track with a km (module doc)."""
    rows: list[dict[str, Any]] = []
    findings: list[Finding] = []
    groups = [n for n in data.nodes.values() if n.kind == "balise_group"]
    where = _vertex_of(p, [n.node_id for n in groups])
    for node in groups:
        why, placed = _place(node, where, p, km)
        if placed is None:
            findings.append(
                _note("osm.balise_group", "balises", f"balise group not imported: {why}", [node.node_id], "node")
            )
            continue
        k, at_km = placed
        rows += _group_rows(node, p.track_id[k], tracks.iloc[k], at_km)
    return pd.DataFrame(rows, columns=BALISES.column_names), findings


def _vertex_of(p: Pieces, ids: list[int]) -> dict[int, tuple[int, float]]:
    """Node id → (piece, pos) of its first vertex on an imported track."""
    arr = np.asarray(ids, dtype=np.int64)
    on = np.flatnonzero(np.isin(p.node, arr))
    piece = np.searchsorted(p.start, on, side="right") - 1
    out: dict[int, tuple[int, float]] = {}
    for v, k in zip(on.tolist(), piece.tolist(), strict=True):
        out.setdefault(int(p.node[v]), (int(k), float(p.s[v])))
    return out


def _place(
    node: OsmNode, where: dict[int, tuple[int, float]], p: Pieces, km: KmModel
) -> tuple[str, tuple[int, float] | None]:
    nid_bg = _int_tag(node.tags, ("railway:etcs:nid_bg", "nid_bg"), 16383)
    if nid_bg is None:
        tags = ", ".join(f"{k}={v}" for k, v in sorted(node.tags.items()) if k in ("ref", "name", "balise_count"))
        return f"no ETCS identity in its tags (railway:etcs:nid_bg){' — has ' + tags if tags else ''}", None
    if node.node_id not in where:
        return "its node lies on no imported track", None
    k, pos = where[node.node_id]
    at_km = float(km.at(np.array([k]), np.array([pos]))[0])
    if not np.isfinite(at_km):
        return f"its track {p.track_id[k]} has no km (fewer than 2 milestones)", None
    return "", (k, at_km)


def _group_rows(node: OsmNode, track_id: str, track: pd.Series, at_km: float) -> list[dict[str, Any]]:
    t = node.tags
    nid_c = _int_tag(t, ("railway:etcs:nid_c", "nid_c"), 1023)
    nid_bg = _int_tag(t, ("railway:etcs:nid_bg", "nid_bg"), 16383)
    n_total = _int_tag(t, ("balise_count",), 8) or 1
    base = t.get("ref") or f"n{node.node_id}"
    return [
        {
            "balise_id": f"{base}_{pig}",
            "kind": BaliseKind.G.value,
            "line_code": track["line_code"],
            "track": track["track"],
            "km_actual_m": at_km,
            "km_equipment_m": at_km,
            "track_id": track_id,
            "nid_c": nid_c,
            "nid_bg": nid_bg,
            "n_pig": pig,
            "n_total": n_total,
        }
        for pig in range(n_total)
    ]
