"""What a network route changes in a simulated run (:func:`network_plan`), used by
:func:`fieldlogs.simulate.simulator.simulate_run` when the scenario's ``[network]`` is set.

* the geometry is the route's (:class:`~.netgeom.RouteGeometry`, "km" = route coordinate ρ), and
  the scenario handed to the motion and sensor models is rewritten in ρ: ``route.path_km_m``
  from ``network.points`` and ``gps.outages_km_m`` from ``network.gnss_outages`` (a track
  range may lie on the route more than once: every pass counts);
* balises: every balise placed on a route track (:func:`dbtools.rules.balise_groups.locate`:
  its ``track_id``, else its line, track and km), at its ρ, S003 kinds and ETCS group
  balises (kind G, their NID_C/NID_BG/N_PIG/N_TOTAL telegram): a group is read in N_PIG
  order when travelling toward increasing position in the group, reversed the other way;
* GPS multipath near a parallel track (``network.multipath``): over each range the fix is
  moved by bias_m along the route's normal toward (bias > 0) the nearest point of another
  track's centreline within ``multipath_search_m`` (none there: no bias);
* truth: ``track_id`` and ``pos_m`` besides line, track (U/D/S only) and km (:meth:`.locate`);
* raw GNSS (``[gnss_raw] enabled = true``): :func:`fieldlogs.simulate.gnss.trainsim.raw_gnss` on
  the route geometry — antennas above the true route (turnout arcs included), the
  ``network.gnss_outages`` as tunnels; ``network.multipath`` puts a reflecting surface at the
  neighbouring track's centreline (:meth:`NetworkPlan.reflectors`): the pseudoranges gain the
  reflection's code, carrier and C/N0 errors of :mod:`fieldlogs.simulate.gnss.reflection`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from dbtools.rules.balise_groups import locate as locate_balises
from dbtools.topology import all_tracks, centreline
from fieldlogs.runs.meta import RunMeta
from fieldlogs.simulate.gnss.reflection import Reflectors, ReflectorsAt, amplitude
from fieldlogs.simulate.netgeom import RouteGeometry
from fieldlogs.simulate.netroute import resolve_route
from fieldlogs.simulate.running import Motion
from fieldlogs.simulate.scenario import Scenario, ScenarioError
from fieldlogs.simulate.sensors import TACHO_STEP
from schemas.enums import Track

TRACK_NAMES = frozenset(t.value for t in Track)
#: Nearest centreline points searched for another track's, beyond the own track's 2 m points
#: within the reach r (at most r + 1 of them).
NEIGHBOUR_K = 64


@dataclass
class NetworkPlan:
    geom: RouteGeometry
    scenario: Scenario
    """The scenario in route coordinates (module docstring)."""
    balises: pd.DataFrame
    network: Network
    points_rho: list[float]
    _points: tuple[np.ndarray, np.ndarray, np.ndarray] | None = field(default=None, repr=False)
    _tree: Any = field(default=None, repr=False)

    def truth(self, motion: Motion, slipping: npt.NDArray[np.bool_]) -> pd.DataFrame:
        """The truth stream at 10 Hz with ``track_id`` and ``pos_m``."""
        k = np.arange(0, motion.n, TACHO_STEP)
        at = self.geom.locate(motion.km[k])
        track = pd.Series(at["track"], dtype="string")
        return pd.DataFrame(
            {
                "t": motion.t[k],
                "line_code": pd.Series(at["line_code"], dtype="string"),
                "track": track.where(track.isin(TRACK_NAMES)),
                "km_m": np.round(at["km_m"], 4),
                "speed_mps": np.round(motion.speed_toward_f[k], 5) + 0.0,
                "slipping": slipping[k].astype(np.int64),
                "track_id": pd.Series(at["track_id"], dtype="string"),
                "pos_m": np.round(at["pos_m"], 4),
            }
        )

    def multipath(self, gps: pd.DataFrame, motion: Motion) -> pd.DataFrame:
        """The GPS frame with the ``network.multipath`` biases applied."""
        cfg = self.scenario.network
        if not cfg.multipath or gps.empty:
            return gps
        t = gps["t"].to_numpy(float)
        rho = np.interp(t, motion.t, motion.km)
        bias, own = self._bias(rho)
        hit = np.flatnonzero((bias != 0) & gps["lat"].notna().to_numpy())
        if hit.size == 0:
            return gps
        x, y, nx, ny = self._frame(rho[hit])
        side, _ = self._neighbour(x, y, nx, ny, own[hit])
        gx, gy = self.geom.projector.to_xy(gps["lon"].to_numpy(float)[hit], gps["lat"].to_numpy(float)[hit])
        shift = bias[hit] * side
        lon, lat = self.geom.lonlat(gx + shift * nx, gy + shift * ny)
        out = gps.copy()
        out.loc[out.index[hit], "lat"] = np.round(lat, 9)
        out.loc[out.index[hit], "lon"] = np.round(lon, 9)
        return out

    def reflectors(self) -> ReflectorsAt | None:
        """The reflecting surfaces of ``network.multipath`` for raw GNSS, by route coordinate ρ:
        over each range a surface at the nearest other track's centreline within
        ``multipath_search_m`` (side and perpendicular distance from the route's centreline; none
        there: no surface), amplitude :func:`~fieldlogs.simulate.gnss.reflection.amplitude` of the
        range's bias_m; None without multipath (module docstring)."""
        if not self.scenario.network.multipath:
            return None
        lo, hi = self.geom.segments[0].rho0, self.geom.segments[-1].rho0 + self.geom.segments[-1].length

        def at(rho: np.ndarray) -> Reflectors:
            r = np.clip(np.asarray(rho, dtype=float), lo, hi)
            bias, own = self._bias(r)
            side, dist = np.zeros(r.size), np.zeros(r.size)
            hit = np.flatnonzero(bias != 0)
            if hit.size:
                side[hit], dist[hit] = self._neighbour(*self._frame(r[hit]), own[hit])
            return Reflectors(side, dist, amplitude(bias, dist) * (side != 0))

        return at

    def _bias(self, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The summed ``network.multipath`` bias_m at route coordinates ρ and the track there."""
        at = self.geom.locate(rho)
        bias = np.zeros(len(rho))
        for tid, a, b, m in self.scenario.network.multipath:
            bias += np.where((at["track_id"] == tid) & (at["pos_m"] >= a) & (at["pos_m"] <= b), m, 0.0)
        return bias, at["track_id"]

    def _frame(self, rho: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Centreline point (x, y) at ρ and the unit normal (nx, ny) left of the route."""
        x, y = self.geom.xy(rho)
        nx, ny = self.geom.xy(rho, 1.0)
        return x, y, nx - x, ny - y

    def _neighbour(
        self, x: np.ndarray, y: np.ndarray, nx: np.ndarray, ny: np.ndarray, own: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """(side, d): +1 / −1 where the nearest point of another track within
        ``multipath_search_m`` lies left / right of the route (0: none within reach), and its
        distance along the normal [m]."""
        px, py, pid = self._other_points()
        side, dist = np.zeros(len(x)), np.zeros(len(x))
        if len(px) == 0 or len(x) == 0:
            return side, dist
        if self._tree is None:
            from scipy.spatial import cKDTree

            self._tree = cKDTree(np.column_stack([px, py]))
        reach = self.scenario.network.multipath_search_m
        k = min(int(reach) + 1 + NEIGHBOUR_K, len(px))
        dd, jj = self._tree.query(np.column_stack([x, y]), k=k, distance_upper_bound=reach)
        dd, jj = dd.reshape(len(x), k), jj.reshape(len(x), k)
        ok = np.isfinite(dd)
        ok[ok] = pid[jj[ok]] != np.repeat(own, k).reshape(len(x), k)[ok]
        found = ok.any(axis=1)
        j = jj[np.arange(len(x)), np.argmax(ok, axis=1)][found]
        along = (px[j] - x[found]) * nx[found] + (py[j] - y[found]) * ny[found]
        side[found], dist[found] = np.sign(along), np.abs(along)
        return side, dist

    def _other_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centreline points of every track, resampled every 2 m, in the route's plane (once)."""
        if self._points is not None:
            return self._points
        xs, ys, ids = [], [], []
        for _, row in all_tracks(self.network).iterrows():
            cl = centreline(self.network, row)
            if len(cl.pos_m) < 2:
                continue
            p = np.arange(0.0, cl.pos_m[-1], 2.0)
            x, y = self.geom.projector.to_xy(cl.lon, cl.lat)
            xs.append(np.interp(p, cl.pos_m, x))
            ys.append(np.interp(p, cl.pos_m, y))
            ids.append(np.full(len(p), str(row["track_id"]), dtype=object))
        if not xs:
            self._points = np.empty(0), np.empty(0), np.empty(0, dtype=object)
        else:
            self._points = np.concatenate(xs), np.concatenate(ys), np.concatenate(ids)
        return self._points

    def finish(
        self,
        streams: dict[str, pd.DataFrame],
        motion: Motion,
        slipping: npt.NDArray[np.bool_],
        meta: RunMeta,
        seed: int,
    ) -> None:
        """The network's truth, GPS multipath and run.json route in place of one line's."""
        if "truth" in streams:
            streams["truth"] = self.truth(motion, slipping)
        if "gps" in streams:
            streams["gps"] = self.multipath(streams["gps"], motion)
        self.patch_meta(meta, seed)

    def patch_meta(self, meta: RunMeta, seed: int) -> None:
        """run.json: the route's tracks and points instead of one line/track's km path."""
        st: dict[str, Any] = meta.extra["sim_truth"]
        st["line_code"] = self.geom.segments[0].line_code or ""
        st["track"] = self.geom.segments[0].track or ""
        st.pop("path_km_m", None)
        st.pop("stops_km_m", None)
        st["f_end_toward"] = "route_forward" if st.pop("f_end_toward") == "increasing_km" else "route_backward"
        st["route"] = [
            {"track_id": s.track_id, "direction": s.direction, "route_from_m": round(s.rho0, 3)}
            for s in self.geom.segments
        ]
        at = self.geom.locate(np.asarray(self.points_rho))
        st["points"] = [[str(t), round(float(p), 3)] for t, p in zip(at["track_id"], at["pos_m"], strict=True)]
        st["turnouts"] = [
            {"switch_id": t.switch_id, "facing": t.facing, "radius_m": t.radius_m, "speed_cap_mps": round(t.cap_mps, 3)}
            for t in self.geom.turnouts
        ]
        if not self.scenario.run.run_id:
            meta.run_id = f"SIM-NET-{seed}"


def _points(geom: RouteGeometry, scenario: Scenario) -> list[float]:
    cfg = scenario.network
    if not cfg.points:
        first, last = geom.segments[0], geom.segments[-1]
        m0 = min(scenario.route.margin_m, 0.25 * first.length)
        m1 = min(scenario.route.margin_m, 0.25 * last.length)
        return [first.rho0 + m0, last.rho0 + last.length - m1]
    out: list[float] = []
    for i, (tid, pos) in enumerate(cfg.points):
        r = geom.rho_at(tid, pos)
        if r is None:
            on = ", ".join(f"{s.track_id} (0–{s.length:.0f} m)" for s in geom.segments)
            raise ScenarioError(
                f"[{tid}, {pos}] is not on the route (its tracks: {on})",
                path=scenario.source,
                key=f"network.points[{i}]",
            )
        out.append(r)
    return out


def _spans(geom: RouteGeometry, scenario: Scenario) -> tuple[tuple[float, float], ...]:
    spans: list[tuple[float, float]] = []
    for tid, a, b in scenario.network.gnss_outages:
        for seg in geom.segments:
            if seg.track_id == tid:
                lo, hi = sorted((float(seg.rho_of(min(a, seg.length))), float(seg.rho_of(min(b, seg.length)))))
                if hi > lo:
                    spans.append((lo, hi))
    return tuple(spans)


def route_balises(network: Network, geom: RouteGeometry) -> pd.DataFrame:
    """The balises on the route's tracks, ``km_actual_m`` = their ρ (every pass of a track)."""
    b = network.balises
    tid, pos = locate_balises(network)
    rows, rho = [], []
    for seg in geom.segments:
        hit = np.flatnonzero((tid == seg.track_id) & np.isfinite(pos))
        rows.append(hit)
        rho.append(seg.rho_of(pos[hit]))
    idx = np.concatenate(rows) if rows else np.empty(0, dtype=np.int64)
    out = b.iloc[idx].reset_index(drop=True).copy()
    out["km_actual_m"] = np.concatenate(rho) if rho else np.empty(0)
    return out


def network_plan(network: Network, scenario: Scenario) -> NetworkPlan:
    """The route, its geometry and the scenario rewritten in route coordinates."""
    cfg = scenario.network
    legs = resolve_route(network, cfg, scenario.source)
    try:
        geom = RouteGeometry(
            network,
            legs,
            switch_speed_kmh=cfg.switch_speed_kmh,
            unbalanced_mps2=scenario.running.unbalanced_lateral_mps2,
            train_length_m=cfg.train_length_m,
        )
    except ValueError as exc:
        raise ScenarioError(str(exc), path=scenario.source, key="network") from None
    pts = _points(geom, scenario)
    inner = replace(
        scenario,
        route=replace(scenario.route, path_km_m=tuple(pts), line_code="", track=""),
        gps=replace(scenario.gps, outages_km_m=_spans(geom, scenario)),
        running=replace(scenario.running, stop_at_stations=False),
    )
    return NetworkPlan(geom, inner, route_balises(network, geom), network, pts)
