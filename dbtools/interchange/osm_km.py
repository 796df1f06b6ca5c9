"""Kilometrage of OSM tracks from ``railway=milestone`` nodes (``railway:position``).

**Values** (:func:`parse_position`): ``railway:position:exact`` when present, else
``railway:position``; km with a dot or a comma (``12.3``, ``12,3``), an optional ``km``
(``km 12.3``), or km+metres (``12+345`` = 12.345 km). Anything else (miles ``mi:…``,
several values ``12.3;4.5``) is not used and reported with the node id.

**Which tracks.** A post counts on the track whose way holds its node (its position there
is the node's distance along the track), and on every other track of the *same line*
(``ref``) within :data:`NEAR_M` of it (projected onto that track in the UTM plane, the
distance scaled to the track's geodesic length): OSM puts one post on one of the tracks of
a double-track line, both tracks share its km. A post on no rail way counts on every track
with a line within :data:`NEAR_M`. Only tracks with a line get a km (a km names a line's
kilometrage).

**Chains.** The km runs on where the line runs straight on: the tracks of one line joined
at plain joints and through switches from the toe to the through branch (the one not on the
diverging side) form a *chain* (:func:`km_chains`), and the posts of all its tracks are
fitted along the chain's length — a short track between two switches gets its km from the
posts before and after it.

At a point switch the line runs on to the
through branch, unless only the diverging branch has the toe's line (:func:`switch_links`:
OSM ways often follow the line through the diverging branch).

**Anchors.** Where a chain ends at a track of its own line that it does not run on (the
diverging branch of a switch whose toe and through branch carry the line, a passing loop
rejoining it), the km must not jump at the joint (``topology.km_jump``). Every chain is
first fitted on its own posts; then, the chains with most posts first, each chain is fitted
again with an *anchor* post at each such end: the km of the joined track there. A loop with
no post of its own gets its km from the two switches it leaves and rejoins.

**Interpolation** along a chain with ≥ 2 usable posts, by its own distance: linear between
consecutive posts, beyond the first/last post continued 1 m of km per metre of track in the
posts' direction. **Breaks**: posts are sorted by position; the direction of the km is the
sign of the median step; the longest strictly monotone sequence of posts in that direction
is kept, every other post is reported (``osm.km_break``, node ids) and not used. Between two
kept posts whose km step differs from their distance by more than
:data:`JUMP_M` + :data:`JUMP_SHARE` of it a *km jump* is reported (both node ids); the km
there is still interpolated linearly (OSM does not say where the jump lies). An anchor takes part like
a post (a jump or break against it names only the milestone's node).
"""

from __future__ import annotations

import bisect
import itertools
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from dbtools.interchange.osm_read import OsmNode
from dbtools.interchange.osm_split import Pieces
from schemas.enums import Severity
from schemas.findings import Finding

Link = dict[tuple[int, str], tuple[int, str]]
Joins = dict[tuple[int, str], list[tuple[int, str]]]
End = tuple[str, str]
#: Node id of an anchor among the posts (OSM ids are > 0).
ANCHOR = 0

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]

#: A post counts on tracks of its line within this distance [m] (module doc).
NEAR_M = 15.0
#: A km step differing from the distance by more than JUMP_M + JUMP_SHARE·distance is a jump.
JUMP_M = 50.0
JUMP_SHARE = 0.1

_PLUS = re.compile(r"^(-?\d+)\s*\+\s*(\d+(?:[.,]\d+)?)$")
_KM = re.compile(r"^(-?\d+(?:[.,]\d+)?)$")


def parse_position(text: str | None) -> float | None:
    """A ``railway:position`` value in metres (module doc), None when unreadable."""
    if text is None:
        return None
    t = text.strip().lower()
    t = re.sub(r"^km\s*|\s*km$", "", t).strip()
    m = _PLUS.match(t)
    if m:
        km = int(m.group(1))
        metres = float(m.group(2).replace(",", "."))
        return km * 1000.0 + (metres if km >= 0 else -metres)
    m = _KM.match(t)
    return round(float(m.group(1).replace(",", ".")) * 1000.0, 6) if m else None  # µm: no 0.999… m


@dataclass
class KmModel:
    """Usable posts per track (piece index → positions, km, direction)."""

    posts: dict[int, tuple[F64, F64, float]] = field(default_factory=dict)
    findings: list[Finding] = field(default_factory=list)
    used: set[int] = field(default_factory=set)
    """Node ids of the posts used on some track."""

    def at(self, piece: I64, pos: F64) -> F64:
        """km [m] at (piece, pos) (module doc); NaN on a track without km."""
        out = np.full(len(piece), np.nan)
        for k in np.unique(piece):
            if int(k) not in self.posts:
                continue
            sel = piece == k
            out[sel] = _interp(self.posts[int(k)], pos[sel])
        return out


def _interp(model: tuple[F64, F64, float], pos: F64) -> F64:
    p, km, sign = model
    out = np.interp(pos, p, km)
    lo, hi = pos < p[0], pos > p[-1]
    out[lo] = km[0] + sign * (pos[lo] - p[0])
    out[hi] = km[-1] + sign * (pos[hi] - p[-1])
    return np.asarray(out, dtype=float)


def _monotone(km: list[float], sign: float) -> list[int]:
    """Indices of the longest strictly monotone (sign) subsequence (patience sorting)."""
    vals = [sign * k for k in km]
    tails: list[float] = []
    tail_idx: list[int] = []
    prev = [-1] * len(vals)
    for i, v in enumerate(vals):
        j = bisect.bisect_left(tails, v)
        if j == len(tails):
            tails.append(v)
            tail_idx.append(i)
        else:
            tails[j], tail_idx[j] = v, i
        prev[i] = tail_idx[j - 1] if j else -1
    out, i = [], tail_idx[-1] if tail_idx else -1
    while i >= 0:
        out.append(i)
        i = prev[i]
    return out[::-1]


def _finding(message: str, nodes: list[int], track: str, **extra: Any) -> Finding:
    return Finding(
        "osm.km_break",
        Severity.WARNING,
        "track_points",
        message,
        keys={"element": ",".join(f"node/{n}" for n in nodes), "track_id": track, **extra},
    )


def _dedupe(rows: list[tuple[float, float, int, float]]) -> list[tuple[float, float, int]]:
    """One post per km value: the nearest to the track (a post on the track itself first;
    the same km posted on both tracks of a line is not a break), sorted by position."""
    best: dict[float, tuple[float, float, int, float]] = {}
    for r in rows:
        key = round(r[1], 3)
        if key not in best or r[3] < best[key][3]:
            best[key] = r
    return sorted((r[0], r[1], r[2]) for r in best.values())


def _fit(model: KmModel, piece: int, track: str, found: list[tuple[float, float, int, float]]) -> None:
    rows = _dedupe(found)
    if len(rows) < 2:
        return
    km = [r[1] for r in rows]
    sign = 1.0 if float(np.median(np.diff(km))) >= 0 else -1.0
    keep = _monotone(km, sign)
    dropped = sorted(set(range(len(rows))) - set(keep))
    for i in dropped:
        what = "milestone" if rows[i][2] != ANCHOR else "km of the track joined"
        model.findings.append(
            _finding(
                f"{what} {rows[i][1] / 1000:g} km at {rows[i][0]:.0f} m breaks the km order along {track}: not used",
                [n for n in [rows[i][2]] if n != ANCHOR],
                track,
            )
        )
    kept = [rows[i] for i in keep]
    if len(kept) < 2:
        return
    for a, b in itertools.pairwise(kept):
        dist, step = b[0] - a[0], abs(b[1] - a[1])
        if abs(step - dist) > JUMP_M + JUMP_SHARE * dist:
            model.findings.append(
                _finding(
                    f"km jump on {track}: {a[1] / 1000:g} → {b[1] / 1000:g} km over {dist:.0f} m of track",
                    [n for n in (a[2], b[2]) if n != ANCHOR],
                    track,
                )
            )
    model.posts[piece] = (np.array([r[0] for r in kept]), np.array([r[1] for r in kept]), sign)
    model.used |= {r[2] for r in kept}


def switch_links(points: list[tuple[End, End, End]], lines: dict[str, str | None]) -> list[tuple[End, End]]:
    """Toe ↔ the branch a point switch's line runs on (module doc, *Chains*): the through
    branch, unless only the diverging branch has the toe's line (a line leaving its way's
    straight course, or a through branch that is a siding)."""
    out = []
    for toe, through, diverging in points:
        line = lines.get(toe[0])
        on_diverging = line is not None and lines.get(diverging[0]) == line and lines.get(through[0]) != line
        out.append((toe, diverging if on_diverging else through))
    return out


def km_model(
    p: Pieces,
    lines: list[str | None],
    nodes: dict[int, OsmNode],
    links: Link | None = None,
    joins: Joins | None = None,
) -> KmModel:
    """Usable posts of every track with a line (module doc); ``links``: see :func:`km_chains`;
    ``joins``: every pair of track ends joined ``both`` (both directions), for the anchors."""
    import shapely

    model = KmModel()
    posts: dict[int, float] = {}
    for nid, node in nodes.items():
        if node.kind != "milestone":
            continue
        text = node.tags.get("railway:position:exact") or node.tags.get("railway:position")
        km = parse_position(text)
        if km is None:
            what = f"railway:position '{text}' is not a km (e.g. 12.3, 12,3, 12+345)" if text else "no railway:position"
            model.findings.append(
                Finding(
                    "osm.milestone",
                    Severity.WARNING,
                    "track_points",
                    f"{what}: milestone not used",
                    keys={"element": f"node/{nid}"},
                )
            )
        else:
            posts[nid] = km
    ids = np.fromiter(posts, dtype=np.int64, count=len(posts))
    on = np.flatnonzero(np.isin(p.node, ids))
    piece_of = np.searchsorted(p.start, on, side="right") - 1
    rows: dict[int, list[tuple[float, float, int, float]]] = {}
    line_of_post: dict[int, str | None] = {}
    for v, k in zip(on.tolist(), piece_of.tolist(), strict=True):
        nid = int(p.node[v])
        line_of_post.setdefault(nid, lines[k])
        if lines[k] is not None:
            rows.setdefault(k, []).append((float(p.s[v]), posts[nid], nid, 0.0))
    with_line = [k for k in range(len(p)) if lines[k] is not None]
    if with_line and len(ids):
        geoms = shapely.linestrings(p.x, p.y, indices=np.repeat(np.arange(len(p)), p.stop - p.start))
        tree = shapely.STRtree(geoms[with_line])
        node_xy = {int(p.node[v]): (p.x[v], p.y[v]) for v in on}
        pts_id = [n for n in ids.tolist() if n in node_xy or n in nodes]
        pts = shapely.points([node_xy[n] if n in node_xy else _xy_of(nodes[n], p.epsg) for n in pts_id])
        qi, ti = tree.query(pts, predicate="dwithin", distance=NEAR_M)
        piece = np.asarray(with_line)[ti]
        along = shapely.line_locate_point(geoms[piece], pts[qi])
        off = shapely.distance(geoms[piece], pts[qi])
        scale = p.length[piece] / np.maximum(shapely.length(geoms[piece]), 1e-9)
        for q, k, a, o in zip(qi.tolist(), piece.tolist(), (along * scale).tolist(), off.tolist(), strict=True):
            nid = pts_id[q]
            if nid not in line_of_post or line_of_post[nid] == lines[k]:  # off-rail post, or one of this line
                rows.setdefault(k, []).append((a, posts[nid], nid, o + 1e-3))
    _fit_chains(model, p, km_chains(len(p), lines, links or {}), rows, lines, joins or {})
    return model


def _fit_chains(
    model: KmModel,
    p: Pieces,
    chains: list[list[tuple[int, bool]]],
    rows: dict[int, list[tuple[float, float, int, float]]],
    lines: list[str | None],
    joins: Joins,
) -> None:
    """Fit every chain on its posts, then again — the chains with most posts first — with
    *anchors* at its two ends: the km of a track of its line joined there, as fitted so far
    (module doc, *Anchors*)."""
    per: dict[int, KmModel] = {}
    for c, chain in enumerate(chains):
        per[c] = _fit_chain(model, p, chain, rows, [])
    order = sorted(range(len(chains)), key=lambda c: (-sum(len(rows.get(k, [])) for k, _ in chains[c]), c))
    for c in order:
        anchors = _anchors(model, p, chains[c], lines, joins)
        if anchors:
            per[c] = _fit_chain(model, p, chains[c], rows, anchors)
    for c in range(len(chains)):
        model.findings += per[c].findings
        model.used |= per[c].used


def _anchors(
    model: KmModel, p: Pieces, chain: list[tuple[int, bool]], lines: list[str | None], joins: Joins
) -> list[tuple[bool, float]]:
    """(at the chain's end?, km) of the fitted tracks of the chain's line joined at its ends."""
    members = {k for k, _ in chain}
    line = lines[chain[0][0]]
    out = []
    for at_end, (k, fwd) in ((False, chain[0]), (True, chain[-1])):
        end = ("end" if fwd else "begin") if at_end else ("begin" if fwd else "end")
        ok = [o for o in joins.get((k, end), []) if o[0] not in members and lines[o[0]] == line and o[0] in model.posts]
        if not ok:
            continue
        other = ok[0]
        pos = 0.0 if other[1] == "begin" else float(p.length[other[0]])
        out.append((at_end, float(model.at(np.array([other[0]]), np.array([pos]))[0])))
    return out


def km_chains(n: int, lines: list[str | None], links: Link) -> list[list[tuple[int, bool]]]:
    """Tracks of a line in running order: (piece, forward) lists, each track once; a link
    joins two track ends where the line runs straight on (plain joints, switch toe ↔
    through branch) and both tracks have that line. Tracks without a line are left out."""
    ok = {a: b for a, b in links.items() if lines[a[0]] is not None and lines[a[0]] == lines[b[0]] and a[0] != b[0]}
    visited: set[int] = set()
    out: list[list[tuple[int, bool]]] = []
    for k in range(n):
        if k in visited or lines[k] is None:
            continue
        cur, fwd, seen = k, True, {k}
        while (nxt := ok.get((cur, "begin" if fwd else "end"))) is not None and nxt[0] not in seen:
            cur, fwd = nxt[0], nxt[1] == "end"
            seen.add(cur)
        chain: list[tuple[int, bool]] = []
        while cur not in visited:
            visited.add(cur)
            chain.append((cur, fwd))
            nxt = ok.get((cur, "end" if fwd else "begin"))
            if nxt is None:
                break
            cur, fwd = nxt[0], nxt[1] == "begin"
        out.append(chain)
    return out


def _fit_chain(
    model: KmModel,
    p: Pieces,
    chain: list[tuple[int, bool]],
    rows: dict[int, list[tuple[float, float, int, float]]],
    anchors: list[tuple[bool, float]],
) -> KmModel:
    """Fit the posts (and anchors) of a chain along its length; each track gets them in its
    own pos. Returns the chain's own fit (its findings and used posts)."""
    length = p.length
    offset = np.concatenate(([0.0], np.cumsum([length[k] for k, _ in chain])))
    found = [
        (offset[i] + (q if fwd else length[k] - q), km, nid, d)
        for i, (k, fwd) in enumerate(chain)
        for q, km, nid, d in rows.get(k, [])
    ]
    found += [(float(offset[-1]) if at_end else 0.0, km, ANCHOR, -1.0) for at_end, km in anchors]
    name = p.track_id[chain[0][0]] + (f" (with {len(chain) - 1} track(s) on)" if len(chain) > 1 else "")
    fitted = KmModel()
    _fit(fitted, 0, name, found)
    fitted.used.discard(ANCHOR)
    for k, _ in chain:
        model.posts.pop(k, None)
    if 0 not in fitted.posts:
        return fitted
    at, km, sign = fitted.posts[0]
    for i, (k, fwd) in enumerate(chain):
        if fwd:
            model.posts[k] = (at - offset[i], km, sign)
        else:
            model.posts[k] = ((offset[i] + length[k] - at)[::-1], km[::-1], -sign)
    return fitted


def _xy_of(node: OsmNode, epsg: int) -> tuple[float, float]:
    from pyproj import Transformer

    x, y = Transformer.from_crs(4326, epsg, always_xy=True).transform(node.lon, node.lat)
    return float(x), float(y)
