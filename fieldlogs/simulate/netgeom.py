"""Geometry of a route over the network: one continuous route coordinate ρ through its tracks.

The route's tracks (:mod:`.netroute`) are laid end to end in travel order: each track's
centreline (:func:`dbtools.topology.centreline`: the ``gis`` grid of a line track, the
``track_points`` of the others) oriented in travel direction, ρ = the route length before the
track + the distance along it from the end it is entered at (the shared point of two tracks
is kept once). :class:`RouteGeometry` is a :class:`~.track.TrackGeometry` whose "km" is ρ, so
the splines, arc length, heading, curvature, pitch and every sensor work on it unchanged.

**Turnouts.** A 20 m grid cannot carry a turnout: the diverging curve of a 1:10 turnout of
R ≈ 200 m is R·α ≈ 20 m long (α = atan(1/n) the frog angle), one grid step. Where the route
passes a point switch between its toe and its diverging branch and the switch gives its
``switch_number`` n and ``diverging_radius_m`` R, the first R·α of the diverging track from
the toe is replaced by the true circular arc, every 1 m: it leaves the toe tangent to the toe
track and turns toward ``diverging_side`` by α, the curve the builders of the networks draw
(the stored points beyond the arc are kept). Then the IMU sees yaw rate v/R on the diverging
curve for R·α/v seconds, a heading change α, and nothing on the through branch.

**Cant and speed.** Turnouts and the tracks that are not ``main`` (crossovers, station and
siding tracks) have no cant: the cant share (:meth:`RouteGeometry.cant_scale`) is 0 there,
ramped linearly over 10 m, so the curve limit on a turnout is v = √(a_ub·R). Over a diverging
curve and a train length behind it the speed is also capped (:meth:`RouteGeometry.speed_cap`)
by the scenario's ``switch_speed_kmh``, else the switch's ``diverging_speed_kmh``.

**Truth.** :meth:`RouteGeometry.locate` maps ρ back to (track_id, pos_m from the track's
begin, line_code, local track, line km where the track has one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.georef import projector_for_points
from dbtools.network import Network
from dbtools.topology import BEGIN, END, all_tracks, centreline
from fieldlogs.simulate.netroute import Leg
from fieldlogs.simulate.track import FloatArray, TrackGeometry
from schemas.enums import Side, SwitchType, TrackKind
from schemas.units import KMH

#: Spacing of the reconstructed turnout arcs [m] and the cant ramp length [m].
ARC_STEP_M = 1.0
CANT_RAMP_M = 10.0
#: Step of the grid on which cant share and speed cap are tabulated [m].
TABLE_STEP_M = 0.5


@dataclass(frozen=True)
class Segment:
    """One leg laid on the route: ρ from ``rho0`` to ``rho0 + length``."""

    track_id: str
    direction: int
    rho0: float
    length: float
    line_code: str | None
    track: str | None
    kind: str
    pos: FloatArray
    """Centreline positions from the track's begin (ascending)."""
    km: FloatArray
    """Line km at those positions (NaN where the track has none)."""

    def rho_of(self, pos: FloatArray | float) -> FloatArray:
        p = np.asarray(pos, dtype=float)
        return np.asarray(self.rho0 + (p if self.direction > 0 else self.length - p), dtype=float)


@dataclass(frozen=True)
class Turnout:
    """A diverging curve on the route: ρ range, radius and the speed cap over it [m/s]."""

    switch_id: str
    rho_lo: float
    rho_hi: float
    radius_m: float
    cap_mps: float
    facing: bool


def _opt(v: Any) -> str | None:
    return None if v is None or pd.isna(v) else str(v)


def _heights(net: Network, row: pd.Series, pos: FloatArray) -> FloatArray:
    """Rail heights at the centreline positions (NaN where the DB has none)."""
    tid = str(row["track_id"])
    tp = net.track_points
    own = tp[tp["track_id"] == tid]
    if len(own):
        own = own.sort_values("pos_m")
        return np.asarray(
            np.interp(pos, own["pos_m"].to_numpy(float), own["height_m"].to_numpy(float, na_value=np.nan))
        )
    g = net.gis
    g = g[(g["line_code"] == row["line_code"]) & (g["track"] == row["track"])].sort_values("km_m")
    if g.empty or "height_m" not in g:
        return np.full(len(pos), np.nan)
    k0, k1 = float(row["km_begin_m"]), float(row["km_end_m"])
    km = k0 + math.copysign(1.0, k1 - k0) * pos
    return np.asarray(np.interp(km, g["km_m"].to_numpy(float), g["height_m"].to_numpy(float, na_value=np.nan)))


def _arc(x0: float, y0: float, heading: float, side: int, radius: float, length: float) -> tuple[FloatArray, ...]:
    """(u, x, y): the circular arc of ``radius`` from (x0, y0) tangent to ``heading``, turning to
    the left for side +1, every ARC_STEP_M up to ``length`` (u = arc length)."""
    n = max(math.ceil(length / ARC_STEP_M), 1)
    u = np.linspace(0.0, length, n + 1)[1:]
    phi = u / radius
    along, across = radius * np.sin(phi), side * radius * (1.0 - np.cos(phi))
    c, s = math.cos(heading), math.sin(heading)
    return u, x0 + along * c - across * s, y0 + along * s + across * c


class RouteGeometry(TrackGeometry):
    """Splines along the route coordinate ρ (module docstring)."""

    def __init__(
        self, net: Network, legs: list[Leg], *, switch_speed_kmh: float, unbalanced_mps2: float, train_length_m: float
    ) -> None:
        tracks = all_tracks(net).drop_duplicates("track_id").set_index("track_id", drop=False)
        self.legs = legs
        self.segments: list[Segment] = []
        rho_l: list[FloatArray] = []
        lat_l: list[FloatArray] = []
        lon_l: list[FloatArray] = []
        h_l: list[FloatArray] = []
        rho0 = 0.0
        for leg in legs:
            row = tracks.loc[[leg.track_id]].iloc[0]
            cl = centreline(net, row)
            if len(cl.pos_m) < 2:
                raise ValueError(f"track {leg.track_id} has no centreline (no gis grid or track_points)")
            length = float(cl.pos_m[-1])
            seg = Segment(
                leg.track_id, leg.direction, rho0, length, _opt(row["line_code"]), _opt(row["track"]),
                str(row["kind"]), cl.pos_m, cl.km_m,
            )  # fmt: skip
            order = slice(None) if leg.direction > 0 else slice(None, None, -1)
            r = seg.rho_of(cl.pos_m)[order]
            lat, lon, h = cl.lat[order], cl.lon[order], _heights(net, row, cl.pos_m)[order]
            if rho_l and r[0] - rho_l[-1][-1] < 0.5:  # the point shared with the previous track
                r, lat, lon, h = r[1:], lat[1:], lon[1:], h[1:]
            rho_l.append(r)
            lat_l.append(lat)
            lon_l.append(lon)
            h_l.append(h)
            self.segments.append(seg)
            rho0 += length
        rho, lat, lon, h = (np.concatenate(a) for a in (rho_l, lat_l, lon_l, h_l))
        proj = projector_for_points(lat, lon)
        x, y = proj.to_xy(lon, lat)
        self.turnouts: list[Turnout] = []
        rho, x, y, h = self._turnouts(net, rho, x, y, h, switch_speed_kmh, unbalanced_mps2)
        lon2, lat2 = proj.to_lonlat(x, y)
        super().__init__("", "", rho, lat2, lon2, h)
        self._tables(train_length_m)

    # -- turnouts ---------------------------------------------------------------------------
    def _turnouts(
        self, net: Network, rho: FloatArray, x: FloatArray, y: FloatArray, h: FloatArray, v_kmh: float, a_ub: float
    ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        sw = net.switches.drop_duplicates("switch_id").set_index("switch_id", drop=False)
        for prev, (i, leg) in zip(self.legs, enumerate(self.legs[1:], start=1), strict=False):
            if leg.switch_in is None or leg.switch_in not in sw.index:
                continue
            s = sw.loc[[leg.switch_in]].iloc[0]
            geom = _diverging(s, prev, leg)
            if geom is None:
                continue
            facing, radius, alpha, side = geom
            joint = self.segments[i].rho0
            j = int(np.argmin(np.abs(rho - joint)))
            # a point of the toe track at least 10 m from the toe gives its direction there
            k = int(np.flatnonzero(rho <= joint - 10.0)[-1]) if facing else int(np.flatnonzero(rho >= joint + 10.0)[0])
            heading = math.atan2(y[j] - y[k], x[j] - x[k])  # from the toe track into the branches
            length = radius * alpha
            u, ax, ay = _arc(float(x[j]), float(y[j]), heading, side, radius, length)
            arc_rho = joint + u if facing else joint - u
            ah = np.interp(arc_rho, rho, h) if np.isfinite(h).any() else np.full(len(u), np.nan)
            lo, hi = (joint, joint + length + 0.5) if facing else (joint - length - 0.5, joint)
            keep = ~((rho > lo) & (rho < hi))
            keep[j] = True
            order = np.argsort(np.concatenate([rho[keep], arc_rho]), kind="stable")
            rho, x, y, h = (np.concatenate([a[keep], b])[order] for a, b in ((rho, arc_rho), (x, ax), (y, ay), (h, ah)))
            v_db = s.get("diverging_speed_kmh")
            v = v_kmh * KMH if v_kmh > 0 else (float(v_db) * KMH if pd.notna(v_db) else math.sqrt(a_ub * radius))
            r_lo, r_hi = (joint, joint + length) if facing else (joint - length, joint)
            self.turnouts.append(Turnout(str(leg.switch_in), r_lo, r_hi, radius, v, facing))
        return rho, x, y, h

    def _tables(self, train_length_m: float) -> None:
        """Cant share and speed cap tabulated along ρ (module docstring)."""
        grid = np.arange(self.km_min, self.km_max + TABLE_STEP_M, TABLE_STEP_M)
        no_cant = np.zeros(len(grid), dtype=bool)
        cap = np.full(len(grid), np.inf)
        for seg in self.segments:
            if seg.kind != TrackKind.MAIN.value:
                no_cant |= (grid >= seg.rho0) & (grid <= seg.rho0 + seg.length)
        for t in self.turnouts:
            no_cant |= (grid >= t.rho_lo) & (grid <= t.rho_hi)
            # the cap from where the head enters the curve until the rear has left it, either way
            inside = (grid >= t.rho_lo - train_length_m) & (grid <= t.rho_hi + train_length_m)
            cap = np.where(inside, np.minimum(cap, t.cap_mps), cap)
        # distance to the nearest cant-free point, ramped over CANT_RAMP_M
        idx = np.flatnonzero(no_cant)
        if idx.size:
            pos = np.searchsorted(idx, np.arange(len(grid)))
            left = np.abs(np.arange(len(grid)) - idx[np.clip(pos - 1, 0, idx.size - 1)])
            right = np.abs(idx[np.clip(pos, 0, idx.size - 1)] - np.arange(len(grid)))
            dist = np.minimum(left, right) * TABLE_STEP_M
            scale = np.clip(dist / CANT_RAMP_M, 0.0, 1.0)
        else:
            scale = np.ones(len(grid))
        self._grid, self._scale, self._dscale, self._cap = grid, scale, np.gradient(scale, grid), cap

    def cant_scale(self, km: npt.ArrayLike) -> tuple[FloatArray, FloatArray]:
        k = np.asarray(km, dtype=float)
        return np.interp(k, self._grid, self._scale), np.interp(k, self._grid, self._dscale)

    def speed_cap(self, km: npt.ArrayLike) -> FloatArray:
        k = np.asarray(km, dtype=float)
        i = np.clip(np.searchsorted(self._grid, k), 0, len(self._grid) - 1)
        return np.asarray(self._cap[i], dtype=float)

    # -- truth ------------------------------------------------------------------------------
    def segment_index(self, rho: npt.ArrayLike) -> npt.NDArray[np.int64]:
        starts = np.array([s.rho0 for s in self.segments])
        r = np.asarray(rho, dtype=float)
        return np.clip(np.searchsorted(starts, r, side="right") - 1, 0, len(starts) - 1).astype(np.int64)

    def locate(self, rho: npt.ArrayLike) -> dict[str, np.ndarray]:
        """track_id, pos_m, line_code, track and km_m at each route coordinate."""
        r = np.asarray(rho, dtype=float)
        idx = self.segment_index(r)
        n = len(r)
        tid = np.empty(n, dtype=object)
        line = np.empty(n, dtype=object)
        track = np.empty(n, dtype=object)
        pos, km = np.full(n, np.nan), np.full(n, np.nan)
        for i, seg in enumerate(self.segments):
            m = idx == i
            if not m.any():
                continue
            along = np.clip(r[m] - seg.rho0, 0.0, seg.length)
            p = along if seg.direction > 0 else seg.length - along
            tid[m], line[m], track[m], pos[m] = seg.track_id, seg.line_code, seg.track, p
            if np.isfinite(seg.km).sum() >= 2:
                ok = np.isfinite(seg.km)
                km[m] = np.interp(p, seg.pos[ok], seg.km[ok])
        return {"track_id": tid, "pos_m": pos, "line_code": line, "track": track, "km_m": km}

    def rho_at(self, track_id: str, pos_m: float, after: float = -np.inf) -> float | None:
        """ρ of a track position: on the first leg of that track ending beyond ``after``."""
        for seg in self.segments:
            if seg.track_id == track_id and seg.rho0 + seg.length > after and -1e-6 <= pos_m <= seg.length + 1e-6:
                return float(seg.rho_of(pos_m))
        return None


def _diverging(s: pd.Series, prev: Leg, leg: Leg) -> tuple[bool, float, float, int] | None:
    """(facing, R, α, side ±1) where the step prev → leg runs between toe and diverging branch of
    a point switch with n and R given; None otherwise."""
    if str(s["type"]) != SwitchType.POINT.value:
        return None
    n, radius, side = s.get("switch_number"), s.get("diverging_radius_m"), s.get("diverging_side")
    if pd.isna(n) or pd.isna(radius) or pd.isna(side):
        return None
    toe = (str(s["a1_track"]), str(s["a1_end"]))
    port = "b1" if side == Side.LEFT.value else "b2"
    div = (_opt(s[f"{port}_track"]), _opt(s[f"{port}_end"]))
    out = (prev.track_id, END if prev.direction > 0 else BEGIN)
    into = (leg.track_id, BEGIN if leg.direction > 0 else END)
    sign = 1 if side == Side.LEFT.value else -1
    alpha = math.atan(1.0 / float(n))
    if out == toe and into == div:
        return True, float(radius), alpha, sign
    if out == div and into == toe:
        return False, float(radius), alpha, sign
    return None
