"""Horizontal curves ↔ feature points [S000 Table 1, §3.2].

A feature point is one curve as six rows: entry straight check start and end, curve entry,
curve exit, exit straight check start and end. With the curvature κ linear along a
clothoid of length L (0 at the straight, 1/R at the arc), the lower limit (1/R)(1 − 20 %)
(SPEC §5.3) is crossed 0.8·L into the entry transition and 0.2·L into the exit one. So, in
increasing km, with TS the start of the entry transition (length L1) and ST the end of the
exit transition (L2)::

    rows (D, S) = [TS − 20, TS, TS + 0.8·L1, ST − 0.8·L2, ST, ST + 20]

and on U (running km-decreasing) the same points in reverse order, left and right swapped
— exactly as :func:`fieldlogs.simulate.networks.synthetic.feature_rows` lays them out. A curve is a
feature only where the geometry allows: an arc with a radius, each side either a clothoid
or nothing (the curvature then jumps at the arc end), and a straight of at least 20 m
beyond; everything else (compound curves, reverse curves without a straight between them,
unknown curve types, a curve at a track end) is reported, not guessed.

The export writes the inverse: per feature a straight, clothoid, arc, clothoid, straight
sequence from the six rows, and the rows themselves as ``tpos:featureRows`` on the arc so
that a round trip is exact.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from typing import Any

from dbtools.interchange import xmltree as xt
from dbtools.interchange.mapping import Target
from dbtools.interchange.model import RailmlDoc, RCurve
from schemas.enums import Attribute, Severity, Track
from schemas.findings import Finding
from schemas.tables import FEATURE_TOLERANCE

STRAIGHT_M = 20.0
#: Curve pieces closer than this are contiguous [m].
GAP_M = 0.5
LOWER = 1.0 - FEATURE_TOLERANCE
ROLES = (
    "entry straight check starts",
    "entry straight check ends",
    "curvature exceeds the lower limit (curve entry)",
    "curvature falls below the lower limit (curve exit)",
    "exit straight check starts",
    "exit straight check ends",
)
TRANSITIONS = ("clothoide", "clothoid", "transition")


def rows_for(
    ts: float, l1: float, st: float, l2: float, radius: float, target: Target, fid: str
) -> list[dict[str, Any]]:
    """The six rows of one curve (module doc); ``radius`` signed, negative left in increasing km."""
    left = radius < 0
    if target.track == Track.UP.value:
        kms = [st + STRAIGHT_M, st, st - LOWER * l2, ts + LOWER * l1, ts, ts - STRAIGHT_M]
        left = not left
    else:
        kms = [ts - STRAIGHT_M, ts, ts + LOWER * l1, st - LOWER * l2, st, st + STRAIGHT_M]
    attrs = [Attribute.STRAIGHT, Attribute.TRANSITION, Attribute.LEFT if left else Attribute.RIGHT]
    attrs += [Attribute.TRANSITION, Attribute.STRAIGHT, Attribute.NONE]
    return [
        {
            "line_code": target.line_code,
            "track": target.track,
            "feature_id": fid,
            "seq": i + 1,
            "km_m": round(km, 6),
            "radius_m": round(abs(radius), 1) if i == 2 else 0.0,
            "attribute": str(a),
            "role": ROLES[i],
        }
        for i, (km, a) in enumerate(zip(kms, attrs, strict=True))
    ]


def _is(c: RCurve | None, kinds: Sequence[str]) -> bool:
    return c is not None and c.curve_type.lower() in kinds


def _side(pieces: list[RCurve], i: int, step: int) -> tuple[RCurve | None, RCurve | None, str | None]:
    """(transition or None, straight, problem) on one side of the arc ``pieces[i]``."""
    j = i + step
    trans = pieces[j] if 0 <= j < len(pieces) and _is(pieces[j], TRANSITIONS) else None
    if trans is not None:
        j += step
    straight = pieces[j] if 0 <= j < len(pieces) else None
    edge = (trans or pieces[i]).km_from if step < 0 else (trans or pieces[i]).km_to
    if straight is None:
        return trans, None, "no straight beyond it (track end)"
    if not _is(straight, ("straight",)) and straight.radius != 0:
        return trans, None, f"next to a {straight.curve_type} ({straight.id or 'no id'}), not a straight"
    far = straight.km_to if step < 0 else straight.km_from
    if abs(far - edge) > GAP_M:
        return trans, None, "a gap between the curve and its straight"
    if straight.km_to - straight.km_from < STRAIGHT_M:
        return trans, None, f"the straight is {straight.km_to - straight.km_from:.1f} m, shorter than {STRAIGHT_M:g} m"
    return trans, straight, None


def _own_rows(doc: RailmlDoc, c: RCurve, target: Target) -> list[dict[str, Any]]:
    rows = json.loads(c.ext["featureRows"])
    return [
        {
            "line_code": target.line_code,
            "track": target.track,
            "feature_id": c.ext.get("featureId") or c.name or c.id,
            "seq": int(r[0]),
            "km_m": float(r[1]),
            "radius_m": float(r[2]),
            "attribute": str(r[3]),
            "role": r[4],
        }
        for r in rows
    ]


def map_curves(doc: RailmlDoc, targets: dict[str, Target]) -> tuple[list[dict[str, Any]], list[Finding]]:
    """Feature-point rows from every arc that can be one; findings for the others."""
    rows: list[dict[str, Any]] = []
    findings: list[Finding] = []
    by_track: dict[str, list[RCurve]] = {}
    for c in doc.curves:
        by_track.setdefault(c.track_id, []).append(c)
    for track_id, pieces in by_track.items():
        pieces.sort(key=lambda c: c.km_from)
        target = targets.get(track_id)
        for i, c in enumerate(pieces):
            if target is None:
                findings.append(_warn(doc, c, f"curve {c.id}: its track {track_id} has no line code"))
            elif "featureRows" in c.ext:
                rows += _own_rows(doc, c, target)
                doc.use(c.el)
            elif "featureId" in c.ext:  # a straight or transition piece of one of our features
                doc.use(c.el)
            elif _is(c, ("arc",)):
                rows += _arc(doc, pieces, i, target, findings)
    for c in doc.curves:  # straights map to nothing; the rest was used or is reported here
        if not doc.is_used(c.el) and not _is(c, ("straight", "arc")):
            findings.append(_warn(doc, c, f"{c.curve_type} {c.id} is not part of a curve that can be a feature point"))
        doc.use(c.el)
    return rows, findings


def _warn(doc: RailmlDoc, c: RCurve, message: str) -> Finding:
    return xt.finding(c.el, "railml.curve", message, file=doc.file, table="feature_points", severity=Severity.WARNING)


def _arc(doc: RailmlDoc, pieces: list[RCurve], i: int, target: Target, findings: list[Finding]) -> list[dict[str, Any]]:
    arc = pieces[i]
    if arc.radius == 0:
        findings.append(_warn(doc, arc, f"arc {arc.id} has no radius: it cannot be a feature point"))
        return []
    t1, s1, why1 = _side(pieces, i, -1)
    t2, s2, why2 = _side(pieces, i, +1)
    if why1 or why2:
        findings.append(
            _warn(doc, arc, f"arc {arc.id} (R {abs(arc.radius):g} m) cannot be a feature point: {why1 or why2}")
        )
        return []
    ts = (t1 or arc).km_from
    st = (t2 or arc).km_to
    l1 = (t1.km_to - t1.km_from) if t1 else 0.0
    l2 = (t2.km_to - t2.km_from) if t2 else 0.0
    doc.use(arc.el, *(p.el for p in (t1, t2, s1, s2) if p is not None))
    return rows_for(ts, l1, st, l2, arc.radius, target, arc.name or arc.id or f"arc@{arc.km_from:.0f}")


def curves_of_feature(rows: Sequence[dict[str, Any]], track: str) -> list[tuple[str, float, float, float]] | None:
    """(curveType, km_from, km_to, signed radius) pieces in increasing km from a feature's
    six rows (seq order), or None when the rows are not a straight-clothoid-arc-clothoid-straight shape."""
    if len(rows) != 6:
        return None
    k = [float(r["km_m"]) for r in rows]
    left = rows[2]["attribute"] == Attribute.LEFT.value
    radius = float(rows[2]["radius_m"])
    if track == Track.UP.value:
        k = k[::-1]
        left = not left
    s0, ts, entry, exit_, st, s1 = k
    l1, l2 = (entry - ts) / LOWER, (st - exit_) / LOWER
    sc, cs = ts + l1, st - l2
    if not (s0 < ts <= sc < cs <= st < s1) or radius <= 0:
        return None
    r = -radius if left else radius
    out = [("straight", s0, ts, 0.0)]
    if l1 > 0:
        out.append(("clothoide", ts, sc, r))
    out.append(("arc", sc, cs, r))
    if l2 > 0:
        out.append(("clothoide", cs, st, r))
    out.append(("straight", st, s1, 0.0))
    return out
