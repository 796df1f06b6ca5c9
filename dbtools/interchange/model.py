"""The version-independent picture of a railML file, as the readers build it.

Positions along a railML track are ``pos`` [m] from its begin (railML 2.x ``pos``; railML 3
``intrinsicCoord`` × netElement length). Our kilometrage is the railML mileage (2.x
``absPos``, 3.x ``linearCoordinate/@measure``), obtained through :class:`Mileage`: piecewise
linear in ``pos`` through knots, with a jump wherever two knots share a ``pos`` (a mileage
change: the first knot is the incoming km, the second the outgoing one).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Any

from schemas.findings import Finding

Element = Any


@dataclass
class Mileage:
    """``km(pos)`` through ``knots`` [(pos, km)] sorted by pos; equal pos = a jump."""

    knots: list[tuple[float, float]]

    def km(self, pos: float) -> float:
        """km at ``pos``; at a jump the outgoing km; beyond the ends the end slope continues
        (slope ±1 with a single knot, from the knot's direction)."""
        k = self.knots
        if len(k) == 1:
            return k[0][1] + pos - k[0][0]
        ps = [p for p, _ in k]
        i = bisect.bisect_right(ps, pos) - 1
        i = min(max(i, 0), len(k) - 2)
        while i + 1 < len(k) - 1 and k[i + 1][0] <= pos and k[i + 1][0] == k[i + 2][0]:
            i += 1
        (p0, m0), (p1, m1) = k[i], k[i + 1]
        if p1 == p0:  # the last knots are a jump: continue after it with the previous slope
            p0, m0 = p1, m1
            slope = self._slope(i)
        else:
            slope = (m1 - m0) / (p1 - p0)
        return m0 + slope * (pos - p0)

    def jumps(self, pos_a: float, pos_b: float) -> float:
        """Sum of the km jumps (outgoing − incoming) of the mileage changes between two
        positions, signed in the direction from ``pos_a`` to ``pos_b``."""
        lo, hi = sorted((pos_a, pos_b))
        k = self.knots
        total = sum(k[i + 1][1] - k[i][1] for i in range(len(k) - 1) if k[i][0] == k[i + 1][0] and lo < k[i][0] <= hi)
        return total if pos_b >= pos_a else -total

    def _slope(self, i: int) -> float:
        for j in range(i, 0, -1):
            (pa, ma), (pb, mb) = self.knots[j - 1], self.knots[j]
            if pb > pa:
                return (mb - ma) / (pb - pa)
        return 1.0


@dataclass
class GeoPoint:
    """A georeferenced point on a track: pos, km, lon/lat [deg], height [m]."""

    pos: float
    km: float
    lon: float
    lat: float
    height: float | None = None
    vertex_only: bool = False
    """A shape vertex with no stated km (gml LineString): not a kilometre post."""
    km_after: float | None = None
    """At a mileage change: the outgoing km (``km`` is then the incoming one)."""


@dataclass
class RTrack:
    """A railML 2.x track or 3.x netElement."""

    id: str
    el: Element
    name: str | None = None
    length: float | None = None
    mileage: Mileage | None = None
    line_id: str | None = None
    geo: list[GeoPoint] = field(default_factory=list)
    ext: dict[str, str] = field(default_factory=dict)
    kind: str | None = None
    """Our track kind where the file states one (railML 2 ``@type``)."""
    db_id: str | None = None
    """Our track id when it differs from the railML id (railML 3: our export's
    ``tpos:trackId``)."""
    implied: bool = False
    """Not a track row: our export's netElement of a line and track (the gis grid's carrier),
    or a meso/macro netElement (a collection of others)."""


@dataclass
class RLink:
    """A connection between two track ends (railML 2 connection pair, railML 3 netRelation)."""

    track_a: str
    end_a: str
    track_b: str
    end_b: str
    navigability: str = "both"
    switch_id: str | None = None
    el: Element = None


@dataclass(frozen=True)
class Piece:
    """A part of a railML track between its ends and switches inside it: our track ``id``
    covers the railML track's ``pos`` from ``offset`` to ``offset + length``."""

    id: str
    offset: float
    length: float


@dataclass
class RSwitch:
    """A switch or crossing with its ports (``{"a1": (track, end), …}``, our model: point switch
    a1 toe, b1 left, b2 right branch; crossings a1–b1 and a2–b2)."""

    id: str
    el: Element
    type: str
    ports: dict[str, tuple[str, str]]
    diverging_side: str | None = None
    switch_number: float | None = None
    radius: float | None = None
    speed: float | None = None
    km: float | None = None
    name: str | None = None
    track_id: str | None = None
    lat: float | None = None
    lon: float | None = None


@dataclass
class RLine:
    id: str
    el: Element
    code: str | None = None
    name: str | None = None
    track_ids: list[str] = field(default_factory=list)
    ext: dict[str, str] = field(default_factory=dict)


@dataclass
class RBalise:
    id: str
    el: Element
    track_id: str
    pos: float
    km: float
    name: str | None = None
    direction: int = 0
    """+1 read in increasing pos, −1 decreasing, 0 both / unknown."""
    group: str | None = None
    ext: dict[str, str] = field(default_factory=dict)
    nid_c: int | None = None
    """ETCS identity where the file states it (railML 2 ``@countryID``/``@groupID``/``@ndx``)."""
    nid_bg: int | None = None
    n_pig: int | None = None


@dataclass
class RGroup:
    """A railML 3 baliseGroup (railML 2.x: a ``baliseGroup`` element): its balises and the
    signal it belongs to, its ETCS identity and size where stated."""

    id: str
    el: Element
    signal_ref: str | None = None
    function: str | None = None
    nid_c: int | None = None
    nid_bg: int | None = None
    n_total: int | None = None
    direction: int = 0
    """+1 mileageDirection nominal (km rising), −1 reverse, 0 not stated."""
    etcs: bool = False
    """The file says it is a Eurobalise group (railML 3 ``isEurobaliseGroup``)."""


@dataclass
class RSignal:
    id: str
    el: Element
    track_id: str
    km: float
    direction: int = 0
    function: str | None = None


@dataclass
class RCurve:
    """One piece of horizontal alignment on a track, ``km_from`` < ``km_to`` along the track's
    increasing km; ``radius`` signed: negative turning left in increasing km, 0 straight."""

    id: str
    el: Element
    track_id: str
    km_from: float
    km_to: float
    curve_type: str
    radius: float
    ext: dict[str, str] = field(default_factory=dict)
    name: str | None = None


@dataclass
class RailmlDoc:
    """Everything a reader found, plus its findings and the elements it consumed."""

    file: str
    version: str
    lines: dict[str, RLine] = field(default_factory=dict)
    tracks: dict[str, RTrack] = field(default_factory=dict)
    balises: list[RBalise] = field(default_factory=list)
    groups: dict[str, RGroup] = field(default_factory=dict)
    signals: dict[str, RSignal] = field(default_factory=dict)
    curves: list[RCurve] = field(default_factory=list)
    km_breaks: list[dict[str, Any]] = field(default_factory=list)
    links: list[RLink] = field(default_factory=list)
    switches: dict[str, RSwitch] = field(default_factory=dict)
    pieces: dict[str, list[Piece]] = field(default_factory=dict)
    """railML track id → our tracks it is cut into at switches inside it (railML 2: a switch
    not at a track end); a track that is not cut is absent (one piece, itself)."""
    meta: dict[str, str] = field(default_factory=dict)
    """Declarations carried by our own export (metric CRS, area, height datum)."""
    findings: list[Finding] = field(default_factory=list)
    used: set[int] = field(default_factory=set)
    """``id()`` of every element the mapping consumed (the rest is reported); the elements
    are kept in ``_alive`` so that lxml hands out the same proxy object (and id) later."""
    _alive: list[Element] = field(default_factory=list, repr=False)
    quirks: set[int] = field(default_factory=set)
    """``id()`` of elements whose ``@id`` is a reference (2.x trackRef written with @id)."""

    @property
    def root(self) -> Element:
        """The document element (the readers use it first)."""
        return self._alive[0]

    def use(self, *els: Element) -> None:
        for el in els:
            if el is not None:
                self.used.add(id(el))
                self._alive.append(el)

    def is_used(self, el: Element) -> bool:
        return id(el) in self.used

    def track_rows(self) -> list[tuple[RTrack, Piece]]:
        """Every railML track (not our export's line carriers) with each of its pieces."""
        out = []
        for t in self.tracks.values():
            if t.implied:
                continue
            pieces = self.pieces.get(t.id) or [Piece(t.db_id or t.id, 0.0, t.length or 0.0)]
            out += [(t, p) for p in pieces]
        return out

    def piece_at(self, track_id: str, pos: float) -> tuple[str, float]:
        """Our track and the position along it of ``pos`` on a railML track (its pieces)."""
        pieces = self.pieces.get(track_id)
        if not pieces:
            track = self.tracks.get(track_id)
            return (track.db_id or track_id) if track is not None else track_id, pos
        piece = next((p for p in reversed(pieces) if pos >= p.offset), pieces[0])
        return piece.id, pos - piece.offset
