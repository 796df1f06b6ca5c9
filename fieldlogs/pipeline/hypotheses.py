"""Track-selective positioning: candidate tracks carried along the topology [SPEC §8.3].

On a network the position is one or more :class:`~fieldlogs.pipeline.types.Hypothesis`
(track, distance ``pos`` along it from its begin, its sign per metre of body-forward travel,
an extra margin). Dead reckoning moves every candidate by the same signed travel S:
pos(S) = pos_ref + kp·(S − s_ref). With the fix's margin m (:func:`fieldlogs.pipeline.
positions.margin_m`, plus the candidate's ``extra_m``) and the track's own length L, at each
end of its track (out = pos − L beyond the end, −pos beyond the begin):

* **one navigable exit** (plain joint, trailing switch): when the dead-reckoned point passes
  the end (out > 0) the candidate moves onto the next track at pos = entry + out, travelling
  away from the entry end (:class:`dbtools.topology.Exit`);
* **two or more exits** (a facing switch): when the dead-reckoned point passes the toe, one
  candidate per branch (*split*), each ``out`` beyond its entry;
* **no navigable exit** (buffer stop, ``none``): the candidate is dropped when its whole
  interval lies beyond the end — the odometry says the train cannot be there.

Candidates on the same track running the same way are merged into one whose interval covers
both (a trailing merge after two branches rejoin). Aids (balise groups, GNSS, IMU) drop
the candidates their evidence contradicts. What a cycle claims — one track only when every
candidate's interval lies on it, joints within the margin included — is
:mod:`fieldlogs.pipeline.claims`'.

:class:`TrackLine` maps pos ↔ km per track: along a line through the line grid's own
length (:mod:`fieldlogs.pipeline.metric`), so pos is the distance the wheels roll; for a
track with ``track_points`` by their ``pos_m``/``km_m``; km is NaN off a line.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from dbtools.topology import BEGIN, END, Exit, Topology, all_tracks, centreline, topology
from fieldlogs.pipeline.metric import IDENTITY, TrackMetric, track_metric
from fieldlogs.pipeline.types import Fix, FloatArray, Hypothesis

#: Earth radius of the local plane of a track's centreline (equirectangular) [m].
_R_EARTH = 6_371_000.0


@dataclass(frozen=True)
class TrackLine:
    """One track's length, its pos ↔ km map and its centreline in a local metric plane."""

    track_id: str
    line_code: str
    """Empty off a line."""
    track: str
    length_m: float
    metric: TrackMetric | None
    """Line tracks: the line grid's metric (km ↔ rolled length c); None: by ``pos``/``km``."""
    c_begin: float
    dirn: int
    """+1 when km grows from the begin to the end, −1 otherwise."""
    pos: FloatArray
    km: FloatArray
    xy: FloatArray
    """(n, 2) centreline east/north [m] in the plane centred at ``origin`` (lat, lon)."""
    cpos: FloatArray
    """pos of each centreline point (as a candidate's: rail length from the begin, not km)."""
    origin: tuple[float, float]

    def km_of_pos(self, pos: FloatArray | float) -> FloatArray:
        p = np.asarray(pos, dtype=float)
        if self.metric is not None:
            return np.asarray(self.metric.km_of_c(self.c_begin + self.dirn * p), dtype=float)
        if not self.line_code or self.pos.size < 2:
            return np.full(p.shape, np.nan)
        return _extrap(p, self.pos, self.km)

    def pos_of_km(self, km: float) -> float:
        return float(self.pos_of_kms(np.asarray(km, dtype=float)))

    def pos_of_kms(self, km: FloatArray) -> FloatArray:
        """:meth:`pos_of_km` of an array of km (NaN off a line)."""
        k = np.asarray(km, dtype=float)
        if self.metric is not None:
            return np.asarray(self.dirn * (np.asarray(self.metric.c_of_km(k), dtype=float) - self.c_begin), dtype=float)
        if not self.line_code or self.pos.size < 2:
            return np.full(k.shape, np.nan)
        km, pos = self.by_km
        return _extrap(k, km, pos)

    @cached_property
    def by_km(self) -> tuple[FloatArray, FloatArray]:
        """``km`` and ``pos`` of the track points in the order of ascending km (``np.argsort``)."""
        order = np.argsort(self.km)
        return self.km[order], self.pos[order]

    @property
    def km_sign(self) -> int:
        """Sign of dkm/dpos (+1 when unknown)."""
        if self.metric is not None:
            return self.dirn
        if self.km.size >= 2 and np.isfinite(self.km[[0, -1]]).all() and self.km[-1] < self.km[0]:
            return -1
        return 1

    def point(self, pos: float) -> tuple[float, float, float, float]:
        """East, north of the centreline at ``pos`` and its unit tangent (toward the end).
        Scalar arithmetic on the points as Python floats (the same IEEE operations as on
        NumPy scalars: it is called once per candidate per GPS fix)."""
        cp, xy = self._points
        p = min(max(pos, cp[0]), cp[-1])
        j = min(max(bisect.bisect_right(cp, p) - 1, 0), len(cp) - 2)
        (x0, y0), (x1, y1) = xy[j], xy[j + 1]
        seg = max(cp[j + 1] - cp[j], 1e-9)
        u = (p - cp[j]) / seg
        dx, dy = x1 - x0, y1 - y0
        norm = max(math.hypot(dx, dy), 1e-9)
        return x0 + u * dx, y0 + u * dy, dx / norm, dy / norm

    def points(self, pos: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """:meth:`point` at each of the ``pos`` at once: the same IEEE operations elementwise
        (``max``/``min`` as ``where`` of the same comparisons, ``bisect_right`` as
        ``searchsorted(side="right")``, the segment's length by ``math.hypot``), so the same
        numbers as one at a time."""
        cp, xy = np.asarray(self.cpos, dtype=float), np.asarray(self.xy, dtype=float)
        p = np.where(cp[0] > pos, cp[0], pos)
        p = np.where(cp[-1] < p, cp[-1], p)
        j = np.clip(np.searchsorted(cp, p, side="right") - 1, 0, cp.size - 2)
        diff = cp[j + 1] - cp[j]
        u = (p - cp[j]) / np.where(1e-9 > diff, 1e-9, diff)
        x0, y0, dx, dy = xy[j, 0], xy[j, 1], xy[j + 1, 0] - xy[j, 0], xy[j + 1, 1] - xy[j, 1]
        norm = np.asarray([max(math.hypot(a, b), 1e-9) for a, b in zip(dx.tolist(), dy.tolist(), strict=True)])
        return x0 + u * dx, y0 + u * dy, dx / norm, dy / norm

    @cached_property
    def _points(self) -> tuple[list[float], list[list[float]]]:
        """``cpos`` and ``xy`` as Python lists (:meth:`point`)."""
        return [float(c) for c in self.cpos], self.xy.tolist()

    @cached_property
    def _segments(self) -> tuple[list[list[float]], list[float]]:
        """Each centreline segment's b − a and max(|b − a|², 1e-18) (:meth:`project`)."""
        ab = self.xy[1:] - self.xy[:-1]
        return ab.tolist(), np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18).tolist()

    def project(self, x: float, y: float, near: float, window_m: float) -> tuple[float, float]:
        """(pos, offset) of the plane point (x, y) on the centreline: the nearest point of the
        segments whose ``cpos`` lies within ``near`` ± ``window_m`` (pos along the track,
        offset + left of the begin→end direction); (NaN, NaN) when no segment lies there.
        The point's foot on segment j is u = clip(((p − a_j)·(b_j − a_j)) / |b_j − a_j|², 0, 1);
        the nearest foot the first of least squared distance (a NaN one first, as ``np.argmin``).
        A handful of segments per call: Python floats, the same IEEE operations as NumPy's."""
        cp, xy = self._points
        n = len(cp)
        if n < 2:
            return math.nan, math.nan
        lo = max(bisect.bisect_right(cp, near - window_m) - 1, 0)
        hi = min(bisect.bisect_left(cp, near + window_m) + 1, n)
        if hi - lo < 2:
            return math.nan, math.nan
        abs_, l2s = self._segments
        best_d2, j, u = math.inf, -1, 0.0
        for k in range(lo, hi - 1):
            (ax, ay), (dx, dy) = xy[k], abs_[k]
            v = ((x - ax) * dx + (y - ay) * dy) / l2s[k]
            v = v if v != v else (1.0 if v > 1.0 else (v if v > 0.0 else 0.0))  # np.clip(v, 0, 1), NaN kept
            ex, ey = x - (ax + v * dx), y - (ay + v * dy)
            d2 = ex * ex + ey * ey
            if d2 != d2:  # NaN
                j, u = k, v
                break
            if d2 < best_d2 or j < 0:
                best_d2, j, u = d2, k, v
        (ax, ay), (dx, dy) = xy[j], abs_[j]
        fx, fy = ax + u * dx, ay + u * dy  # the nearest foot again: the same operations
        pos = cp[j] + u * (cp[j + 1] - cp[j])
        norm = max(math.sqrt(l2s[j]), 1e-9)
        off = (-(x - fx) * abs_[j][1] + (y - fy) * abs_[j][0]) / norm
        return pos, off

    def plane(self, lat: FloatArray, lon: FloatArray) -> tuple[FloatArray, FloatArray]:
        """lat/lon [deg] in this track's local plane [m]."""
        return equirect(self.origin, lat, lon)


def equirect(origin: tuple[float, float], lat: FloatArray, lon: FloatArray) -> tuple[FloatArray, FloatArray]:
    """lat/lon [deg] in the equirectangular plane centred at ``origin`` (lat, lon) [m]: east
    (lon − lon0)·k·cos(lat0), north (lat − lat0)·k, k = π/180·R."""
    lat0, lon0 = origin
    k = math.pi / 180.0 * _R_EARTH
    return (np.asarray(lon) - lon0) * k * math.cos(math.radians(lat0)), (np.asarray(lat) - lat0) * k


def to_plane(origin: tuple[float, float], tl: TrackLine, xy: FloatArray) -> FloatArray:
    """(n, 2) points of ``tl``'s own plane in the equirectangular plane centred at ``origin``."""
    k = math.pi / 180.0 * _R_EARTH
    lat0, lon0 = tl.origin
    lat = xy[:, 1] / k + lat0
    lon = xy[:, 0] / (k * math.cos(math.radians(lat0))) + lon0
    return np.column_stack(equirect(origin, lat, lon))


def _extrap(x: FloatArray, xp: FloatArray, fp: FloatArray) -> FloatArray:
    """Linear interpolation, extended beyond both ends with the end segments' slopes."""
    out = np.interp(x, xp, fp)
    lo = fp[0] + (x - xp[0]) * (fp[1] - fp[0]) / max(xp[1] - xp[0], 1e-9)
    hi = fp[-1] + (x - xp[-1]) * (fp[-1] - fp[-2]) / max(xp[-1] - xp[-2], 1e-9)
    return np.asarray(np.where(x < xp[0], lo, np.where(x > xp[-1], hi, out)), dtype=float)


def _text(v: object) -> str:
    return "" if v is None or (isinstance(v, float) and math.isnan(v)) or v is pd.NA else str(v)


def _track_line(net: Network, row: pd.Series) -> TrackLine:
    tid, line, track = str(row["track_id"]), _text(row["line_code"]), _text(row["track"])
    cl = centreline(net, row)
    has_points = bool((net.track_points["track_id"] == tid).any())
    k0, k1 = row["km_begin_m"], row["km_end_m"]
    lat0, lon0 = (float(cl.lat[0]), float(cl.lon[0])) if cl.lat.size else (0.0, 0.0)
    metric: TrackMetric | None = None
    c_begin, dirn, length = 0.0, 1, float(row["length_m"])
    if line and not has_points and pd.notna(k0) and pd.notna(k1):
        m = track_metric(net, line, track)
        dirn = 1 if float(k1) >= float(k0) else -1
        metric = m
        c_begin = float(m.c_of_km(float(k0)))
        length = abs(float(m.c_of_km(float(k1))) - c_begin) if m is not IDENTITY else abs(float(k1) - float(k0))
    pos = cl.pos_m.astype(float) if has_points else np.empty(0)
    km = cl.km_m.astype(float) if has_points else np.empty(0)
    cpos = cl.pos_m.astype(float)
    if metric is not None and cl.km_m.size:
        # the grid's pos is |km − km at begin|; a candidate's pos is rail length (the metric's c)
        cpos = dirn * (np.asarray(metric.c_of_km(cl.km_m.astype(float)), dtype=float) - c_begin)
    tl = TrackLine(tid, line, track, length, metric, c_begin, dirn, pos, km, np.zeros((0, 2)), cpos, (lat0, lon0))
    x, y = tl.plane(cl.lat, cl.lon)
    return replace(tl, xy=np.column_stack([x, y]) if cl.lat.size >= 2 else np.zeros((0, 2)))


@dataclass(frozen=True)
class TrackLines:
    """Every track's :class:`TrackLine` and the topology, built once per loaded network."""

    lines: dict[str, TrackLine]
    by_line: dict[tuple[str, str], list[TrackLine]]
    topo: Topology
    headings: dict[str, FloatArray] = field(default_factory=dict, repr=False, compare=False)
    """Chord headings per track, made on first use (:mod:`fieldlogs.pipeline.track_heading`)."""

    def __getitem__(self, track_id: str) -> TrackLine:
        return self.lines[track_id]

    def locate(self, line_code: str, track: str, km: float, tol_m: float = 0.5) -> tuple[TrackLine, float] | None:
        """The track of ``line_code``/``track`` holding ``km`` and the pos there (the one with
        km farthest inside when it lies on a joint); None when no track holds it."""
        best: tuple[float, TrackLine, float] | None = None
        for tl in self.by_line.get((line_code, track), []):
            p = tl.pos_of_km(km)
            inside = min(p, tl.length_m - p)
            if math.isfinite(p) and inside >= -tol_m and (best is None or inside > best[0]):
                best = (inside, tl, p)
        return None if best is None else (best[1], best[2])


def track_lines(net: Network) -> TrackLines:
    def build() -> TrackLines:
        lines: dict[str, TrackLine] = {}
        by_line: dict[tuple[str, str], list[TrackLine]] = {}
        for _, row in all_tracks(net).iterrows():
            tl = _track_line(net, row)
            lines[tl.track_id] = tl
            if tl.line_code:
                by_line.setdefault((tl.line_code, tl.track), []).append(tl)
        return TrackLines(lines, by_line, topology(net))

    return net.cached(("hypotheses", "track_lines"), build)


@dataclass
class Changes:
    """What :func:`advance` did: splits (switch, from track, to tracks) and drops (track, reason)."""

    splits: list[tuple[str | None, str, list[str]]]
    drops: list[tuple[str, str]]


def outward(h: Hypothesis, length: float, end: str) -> float:
    """How far the candidate's point lies beyond ``end`` of its track (negative: inside)."""
    return h.pos_m - length if end == END else -h.pos_m


def _moved(h: Hypothesis, ex: Exit, out: float, lines: TrackLines, end: str) -> Hypothesis:
    """``h`` carried ``out`` beyond ``end`` onto ``ex``: entry at ``ex.end``, away from it."""
    entry = 0.0 if ex.end == BEGIN else lines[ex.track_id].length_m
    motion = h.kp if end == END else -h.kp  # sign of dS that moves h outward at this end
    return replace(
        h,
        track_id=ex.track_id,
        pos_m=entry + ex.direction * out,
        kp=ex.direction * motion,
        came_from=(h.track_id, end),
    )


def _at_end(
    h: Hypothesis, end: str, m: float, d: float, lines: TrackLines, ids: list[int], ch: Changes
) -> list[Hypothesis]:
    """The candidates ``h`` becomes at ``end`` of its track (itself when nothing happens)."""
    tl = lines[h.track_id]
    out = outward(h, tl.length_m, end)
    exits = lines.topo.exits.get((h.track_id, end), [])
    if not exits:
        if out - (m + h.extra_m) > 0:
            ch.drops.append((h.track_id, f"beyond its {end}: no navigable exit (buffer stop or none)"))
            return []
        return [h]
    if out <= 0:
        return [h]
    if len(exits) == 1:
        return [_moved(h, exits[0], out, lines, end)]
    res: list[Hypothesis] = []
    for ex in exits:
        ids[0] += 1
        res.append(replace(_moved(h, ex, out, lines, end), hid=ids[0], switch_id=ex.switch_id, split_d=d))
    ch.splits.append((exits[0].switch_id, h.track_id, [e.track_id for e in exits]))
    return res


def merge(hyps: list[Hypothesis]) -> list[Hypothesis]:
    """One candidate per (track, kp): the interval covering all of them (first one's lineage)."""
    groups: dict[tuple[str, int], list[Hypothesis]] = {}
    for h in hyps:
        groups.setdefault((h.track_id, h.kp), []).append(h)
    out: list[Hypothesis] = []
    for g in groups.values():
        if len(g) == 1:
            out.append(g[0])
            continue
        lo = min(h.pos_m - h.extra_m for h in g)
        hi = max(h.pos_m + h.extra_m for h in g)
        out.append(replace(g[0], pos_m=(lo + hi) / 2, extra_m=(hi - lo) / 2))
    return out


def advance(
    hyps: list[Hypothesis], m: float, d: float, lines: TrackLines, next_id: int
) -> tuple[list[Hypothesis], Changes, int]:
    """Apply the rules of the module docstring to candidates placed at the present travel
    (margin ``m`` without their extra, unsigned travel ``d``) until none applies; returns them,
    what happened, and the last lineage id used."""
    ch = Changes([], [])
    ids = [next_id]
    for _ in range(16):  # a short track may be crossed within one step: repeat
        new: list[Hypothesis] = []
        for h in hyps:
            for_end = _at_end(h, END, m, d, lines, ids, ch)
            new.extend(x for g in for_end for x in _at_end(g, BEGIN, m, d, lines, ids, ch))
        new = merge(new)
        if new == hyps:
            break
        hyps = new
    return hyps, ch, ids[0]


def triggers(h: Hypothesis, pos: FloatArray, m: FloatArray, lines: TrackLines) -> FloatArray:
    """Where (over arrays of the candidate's pos and margin) one of the rules applies."""
    tl = lines[h.track_id]
    hit = np.zeros(pos.shape, dtype=bool)
    for end in (END, BEGIN):
        out = pos - tl.length_m if end == END else -pos
        hit |= out > (0.0 if lines.topo.exits.get((h.track_id, end)) else m + h.extra_m)
    return hit


def one_split(fix: Fix | None) -> tuple[str, float] | None:
    """(``switch_id``, ``split_d``) of the one split all of ``fix``'s candidates (two or more)
    came out of; None when there are fewer candidates, or they came out of several splits or
    of none."""
    if fix is None or len(fix.hyps) < 2:
        return None
    keys = {(h.switch_id, h.split_d) for h in fix.hyps}
    if len(keys) != 1:
        return None
    sid, split_d = next(iter(keys))
    return None if sid is None or split_d is None else (sid, split_d)


def after_switch_m(hyps: Iterable[Hypothesis], d: float) -> float | None:
    """Travel [m] from the latest split among ``hyps`` (their ``split_d``) to travel ``d``,
    to the cm; None when none of them came out of a split: the ``after_switch_m`` of the
    evidence events."""
    split = [h.split_d for h in hyps if h.split_d is not None]
    return round(d - max(split), 2) if split else None


def rebased(hyps: tuple[Hypothesis, ...], s_ref: float, s: float) -> list[Hypothesis]:
    """The candidates with their pos at signed travel ``s`` instead of ``s_ref``."""
    return [replace(h, pos_m=h.pos_m + h.kp * (s - s_ref)) for h in hyps]


def reachable(hyps: list[Hypothesis], reach_m: float, lines: TrackLines) -> set[str]:
    """Tracks a train may be on after at most ``reach_m`` metres of travel (either way) from
    any of the candidates (each widened by its ``extra_m``): a breadth-first walk over the
    navigable exits, each track entered with the reach left at its entry, so a track counts
    only where a navigable path of length ≤ ``reach_m`` leads to it. The gate of
    :mod:`fieldlogs.pipeline.aids.topology`: a line-based aid may move the position only onto
    one of these tracks."""
    out: set[str] = set()
    todo: list[tuple[str, str, float]] = []  # (track, end to leave by, reach left at the candidate)
    for h in hyps:
        out.add(h.track_id)
        r = reach_m + h.extra_m
        length = lines[h.track_id].length_m
        todo.append((h.track_id, END, r - max(length - h.pos_m, 0.0)))
        todo.append((h.track_id, BEGIN, r - max(h.pos_m, 0.0)))
    best: dict[tuple[str, str], float] = {}
    while todo:
        tid, end, left = todo.pop()
        if left < 0.0 or best.get((tid, end), -1.0) >= left:
            continue
        best[(tid, end)] = left
        for ex in lines.topo.exits.get((tid, end), []):
            out.add(ex.track_id)
            far = END if ex.end == BEGIN else BEGIN
            todo.append((ex.track_id, far, left - lines[ex.track_id].length_m))
    return out


@dataclass(frozen=True)
class Segments:
    """Every track's centreline segments in one local plane (equirectangular at ``origin``):
    ends (x0, y0)–(x1, y1) [m], the pos at each end and the index of the track in ``ids``."""

    ids: list[str]
    track: npt.NDArray[np.int64]
    x0: FloatArray
    y0: FloatArray
    x1: FloatArray
    y1: FloatArray
    p0: FloatArray
    p1: FloatArray
    origin: tuple[float, float]

    def to_plane(self, tl: TrackLine, xy: FloatArray) -> FloatArray:
        """(n, 2) points of ``tl``'s own plane in this one."""
        return to_plane(self.origin, tl, xy)

    def nearest(self, x: float, y: float, radius_m: float) -> list[tuple[int, float, float, float, float]]:
        """Per track whose centreline passes within ``radius_m`` of (x, y) in this plane:
        (track index in ``ids``, pos of its nearest point, that point's distance, unit tangent
        x, y toward increasing pos) — the nearest segment's foot u = clip(((p − a)·(b − a))/|b − a|², 0, 1)."""
        dx, dy = self.x1 - self.x0, self.y1 - self.y0
        u = np.clip(((x - self.x0) * dx + (y - self.y0) * dy) / np.maximum(dx * dx + dy * dy, 1e-12), 0.0, 1.0)
        dist = np.hypot(self.x0 + u * dx - x, self.y0 + u * dy - y)
        out = []
        for j in np.unique(self.track[dist <= radius_m]):
            mine = np.flatnonzero(self.track == j)
            k = int(mine[np.argmin(dist[mine])])
            norm = max(math.hypot(float(dx[k]), float(dy[k])), 1e-9)
            pos = float(self.p0[k] + u[k] * (self.p1[k] - self.p0[k]))
            out.append((int(j), pos, float(dist[k]), float(dx[k]) / norm, float(dy[k]) / norm))
        return out


def segments(lines: TrackLines) -> Segments:
    """:class:`Segments` of ``lines`` (tracks without a centreline have none)."""
    ids = list(lines.lines)
    origin = next((tl.origin for tl in lines.lines.values() if tl.xy.shape[0] >= 2), (0.0, 0.0))
    empty = np.empty(0)
    seg = Segments(ids, np.empty(0, np.int64), empty, empty, empty, empty, empty, empty, origin)
    parts: list[list[FloatArray]] = [[] for _ in range(7)]
    for j, tid in enumerate(ids):
        tl = lines[tid]
        if tl.xy.shape[0] < 2:
            continue
        xy = seg.to_plane(tl, tl.xy)
        cols = (np.full(len(xy) - 1, j), xy[:-1, 0], xy[:-1, 1], xy[1:, 0], xy[1:, 1], tl.cpos[:-1], tl.cpos[1:])
        for store, col in zip(parts, cols, strict=True):
            store.append(np.asarray(col, dtype=float))
    if not parts[0]:
        return seg
    c = [np.concatenate(p) for p in parts]
    return Segments(ids, c[0].astype(np.int64), c[1], c[2], c[3], c[4], c[5], c[6], origin)


def parallel_candidates(h: Hypothesis, radius_m: float, lines: TrackLines, seg: Segments) -> list[Hypothesis]:
    """Candidates on the other tracks whose centreline passes within ``radius_m`` of ``h``'s
    point (nearest point inside the track, not at one of its ends: a continuation beyond a
    joint is no parallel track), each at the pos of that nearest point and running the way
    ``h`` runs (kp = h.kp · sign(t_h · t_other), t the unit tangents toward increasing pos).
    The line's other track is kept as well: the line-based decision that placed ``h`` tested
    only the line's two tracks, with the line geometry, not the network's."""
    tl = lines[h.track_id]
    if tl.xy.shape[0] < 2 or not seg.ids:
        return []
    x, y, tx, ty = tl.point(h.pos_m)
    (px, py), (qx, qy) = seg.to_plane(tl, np.array([[x, y], [x + tx, y + ty]]))
    tx, ty = qx - px, qy - py
    out: list[Hypothesis] = []
    for j, pos, _dist, ox, oy in seg.nearest(float(px), float(py), radius_m):
        other = lines[seg.ids[j]]
        if other.track_id == tl.track_id or not 0.5 < pos < other.length_m - 0.5:
            continue
        sign = 1 if tx * ox + ty * oy >= 0.0 else -1
        out.append(Hypothesis(other.track_id, pos, h.kp * sign, extra_m=h.extra_m))
    return out
