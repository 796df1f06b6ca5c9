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
  ``network.gnss_outages`` as tunnels; ``network.multipath`` moves the GPS fixes only.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from dbtools.rules.balise_groups import locate as locate_balises
from dbtools.topology import all_tracks, centreline
from fieldlogs.runs.meta import RunMeta
from fieldlogs.simulate.netgeom import RouteGeometry
from fieldlogs.simulate.netroute import resolve_route
from fieldlogs.simulate.running import Motion
from fieldlogs.simulate.scenario import Scenario, ScenarioError
from fieldlogs.simulate.sensors import TACHO_STEP
from schemas.enums import Track

TRACK_NAMES = frozenset(t.value for t in Track)


@dataclass
class NetworkPlan:
    geom: RouteGeometry
    scenario: Scenario
    """The scenario in route coordinates (module docstring)."""
    balises: pd.DataFrame
    network: Network
    points_rho: list[float]

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
        at = self.geom.locate(rho)
        bias = np.zeros(len(t))
        for tid, a, b, m in cfg.multipath:
            bias += np.where((at["track_id"] == tid) & (at["pos_m"] >= a) & (at["pos_m"] <= b), m, 0.0)
        hit = np.flatnonzero((bias != 0) & gps["lat"].notna().to_numpy())
        if hit.size == 0:
            return gps
        x, y = self.geom.xy(rho[hit])
        nx, ny = self.geom.xy(rho[hit], 1.0)
        nx, ny = nx - x, ny - y  # unit normal, left of the route
        side = self._neighbour_side(x, y, nx, ny, at["track_id"][hit], cfg.multipath_search_m)
        gx, gy = self.geom.projector.to_xy(gps["lon"].to_numpy(float)[hit], gps["lat"].to_numpy(float)[hit])
        shift = bias[hit] * side
        lon, lat = self.geom.lonlat(gx + shift * nx, gy + shift * ny)
        out = gps.copy()
        out.loc[out.index[hit], "lat"] = np.round(lat, 9)
        out.loc[out.index[hit], "lon"] = np.round(lon, 9)
        return out

    def _neighbour_side(
        self, x: np.ndarray, y: np.ndarray, nx: np.ndarray, ny: np.ndarray, own: np.ndarray, search_m: float
    ) -> np.ndarray:
        """+1 / −1: the nearest other track lies left / right of the route; 0: none within reach."""
        from scipy.spatial import cKDTree

        px, py, pid = self._other_points()
        side = np.zeros(len(x))
        if len(px) == 0:
            return side
        tree = cKDTree(np.column_stack([px, py]))
        for i in range(len(x)):
            near = tree.query_ball_point((x[i], y[i]), search_m)
            near = [j for j in near if pid[j] != own[i]]
            if near:
                j = min(near, key=lambda q: (px[q] - x[i]) ** 2 + (py[q] - y[i]) ** 2)
                side[i] = np.sign((px[j] - x[i]) * nx[i] + (py[j] - y[i]) * ny[i])
        return side

    def _other_points(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centreline points of every track, resampled every 2 m, in the route's plane."""
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
            return np.empty(0), np.empty(0), np.empty(0, dtype=object)
        return np.concatenate(xs), np.concatenate(ys), np.concatenate(ids)

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
