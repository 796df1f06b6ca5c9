"""The heading of the track a candidate runs on, from the network's centrelines [SPEC §8.3].

A track's centreline (``gis`` grid of its line, or its ``track_points``) is a polyline of
chords; chord j from point j to j + 1 has the heading ψ_j = atan2(Δnorth, Δeast) (radians,
anticlockwise from east, so a left turn increases ψ as a positive yaw rate ωz does). Where
the track is straight every chord has the same heading; inside a curve the true tangent at a
point of chord j lies between ψ_{j−1} and ψ_{j+1} (the chords of a circle turn by their
length / R each, and the tangent turns continuously between them), so the headings the
track can have at pos ∈ [p_lo, p_hi] are bounded by the chords overlapping that interval and
one more on each side.

The *travel heading* of a candidate (track, kp) is ψ where kp = +1 (running begin → end) and
ψ + π where kp = −1. An interval that reaches beyond an end of the track continues on the
track beyond it when that end has exactly one navigable exit (a plain joint, the toe side of
a trailing switch — :class:`dbtools.topology.Exit`): leaving by the end, the begin → end
orientation continues on the next track in the exit's direction, leaving by the begin in the
opposite one. Beyond a facing switch (two exits) or a buffer stop (none) the heading is
unknown (None): no one can say which way the train came or went.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from dbtools.gis.geometry import wrap_angle
from dbtools.topology import BEGIN, END
from fieldlogs.pipeline.hypotheses import TrackLines
from fieldlogs.pipeline.types import FloatArray

#: How many joints an interval may cross to the next track (a heading window spans metres to
#: tens of metres; short crossover tracks may lie between).
MAX_JOINTS = 3


def chord_headings(lines: TrackLines, track_id: str) -> FloatArray:
    """ψ_j of the track's chords in its begin → end orientation, unwrapped along the track
    (cached per network)."""

    def build() -> FloatArray:
        xy = lines[track_id].xy
        if xy.shape[0] < 2:
            return np.empty(0)
        d = np.diff(xy, axis=0)
        return np.asarray(np.unwrap(np.arctan2(d[:, 1], d[:, 0])), dtype=float)

    cache = lines.headings
    if track_id not in cache:
        cache[track_id] = build()
    return cache[track_id]


def headings(lines: TrackLines, track_id: str, kp: int, p_lo: float, p_hi: float, depth: int = 0) -> FloatArray | None:
    """Every travel heading the track of candidate (``track_id``, ``kp``) can have at pos in
    [``p_lo``, ``p_hi``] (module docstring), or None when part of the interval lies where the
    track is not known (no centreline, beyond a facing switch or a buffer stop)."""
    tl = lines[track_id]
    psi = chord_headings(lines, track_id)
    if psi.size == 0 or p_hi < p_lo:
        return None
    out: list[FloatArray] = []
    a, b = max(p_lo, 0.0), min(p_hi, tl.length_m)
    if b >= a:
        cpos = tl.cpos
        j0 = max(int(np.searchsorted(cpos, a, side="right")) - 2, 0)
        j1 = min(int(np.searchsorted(cpos, b, side="left")) + 1, psi.size)
        out.append(psi[j0 : max(j1, j0 + 1)] + (math.pi if kp < 0 else 0.0))
    for end, beyond in ((END, (p_lo - tl.length_m, p_hi - tl.length_m)), (BEGIN, (-p_hi, -p_lo))):
        if beyond[1] <= 0.0:
            continue
        more = _beyond(lines, track_id, kp, end, max(beyond[0], 0.0), beyond[1], depth)
        if more is None:
            return None
        out.append(more)
    return np.concatenate(out) if out else None


def _beyond(
    lines: TrackLines, track_id: str, kp: int, end: str, d_lo: float, d_hi: float, depth: int
) -> FloatArray | None:
    """Headings ``d_lo``…``d_hi`` metres beyond ``end`` of the track, on the one track there."""
    exits = lines.topo.exits.get((track_id, end), [])
    if len(exits) != 1 or depth >= MAX_JOINTS:
        return None
    ex = exits[0]
    nxt = lines[ex.track_id]
    entry = 0.0 if ex.end == BEGIN else nxt.length_m
    # the begin → end orientation of this track continues on the next one as ``along``
    along = ex.direction if end == END else -ex.direction
    lo, hi = sorted((entry + ex.direction * d_lo, entry + ex.direction * d_hi))
    return headings(lines, ex.track_id, kp * along, lo, hi, depth + 1)


def sure_turns(lines: TrackLines, track_id: str, kd: int, p_lo: float, p_hi: float) -> tuple[float, float]:
    """(left, right): the turns a train running ``kd`` along the track surely made while
    passing every chord lying wholly within pos [``p_lo``, ``p_hi``] of its own track — the
    greatest rise and fall (:func:`rises`) of those chords' headings in travel order. The track
    is smooth and passes through the centreline's points, so somewhere on each chord it heads
    as the chord does (the mean value theorem): a train that ran over chords j and then k
    turned by ψ_k − ψ_j on the way. (0, 0) with fewer than two such chords."""
    psi = chord_headings(lines, track_id)
    cpos = lines[track_id].cpos
    if psi.size < 2:
        return 0.0, 0.0
    inside = np.flatnonzero((cpos[:-1] >= p_lo) & (cpos[1:] <= p_hi))
    if inside.size < 2:
        return 0.0, 0.0
    seq = psi[inside] if kd > 0 else psi[inside][::-1]
    return rises(seq)


def turn_range(start: FloatArray, end: FloatArray) -> tuple[float, float]:
    """(least, greatest) heading change from a heading in ``start`` to one in ``end``, each
    wrapped to within π of the first start heading (turns over a window are far below π)."""
    ref = float(start[0])
    s = ref + wrap_angle(start - ref)
    e = ref + wrap_angle(end - ref)
    return float(e.min() - s.max()), float(e.max() - s.min())


def span(values: FloatArray) -> float:
    """max − min of headings wrapped to within π of the first."""
    w = float(values[0]) + wrap_angle(values - float(values[0]))
    return float(w.max() - w.min())


def rises(h: FloatArray) -> tuple[float, float]:
    """(greatest rise, greatest fall) of the heading profile ``h`` in time order:
    max over j ≤ k of h_k − h_j, and of h_j − h_k (a left and a right turn somewhere in it)."""
    return float(np.max(h - np.minimum.accumulate(h))), float(np.max(np.maximum.accumulate(h) - h))


def violation_llr(violation: Sequence[float | None], sigma: float) -> FloatArray:
    """LLR[a, b] of candidate a against b from each one's violation δ_c ≥ 0 [rad] (how far the
    measurement lies outside what its track allows): LLR_ab = (δ_b² − δ_a²) / (2σ²), the
    Gaussian LLR of the best-fitting geometry of each (so no candidate is judged by a geometry
    it need not have). A candidate whose geometry is unknown (None) neither beats nor is
    beaten (0)."""
    known = np.array([v is not None for v in violation])
    d = np.array([0.0 if v is None else v for v in violation])
    d2 = d * d
    llr = (d2[None, :] - d2[:, None]) / (2.0 * sigma * sigma)
    llr[~known, :] = 0.0
    llr[:, ~known] = 0.0
    return np.asarray(llr, dtype=float)
