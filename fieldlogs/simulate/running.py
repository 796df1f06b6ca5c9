"""Running-time calculation: where the vehicle is at every 10 ms.

1. **Moves.** The scenario's path ``[km0, km1, …]`` becomes moves along the track's arc
   length σ, each toward increasing or decreasing km; stations strictly inside a move
   split it into segments that start and end at rest.
2. **Speed limit** per metre of a segment: the line speed and the curve limit
   v = √((a_ub + G·cant/gauge)·R) with the cant of :class:`~.track.Cant` (ramped along the
   transitions with the curvature).
3. **Forward/backward passes** on the distance grid: v² ≤ v_lim(s_j)² + 2·a·(s − s_j) for
   every j behind (acceleration a) and v² ≤ v_lim(s_j)² + 2·b·(s_j − s) for every j ahead
   (braking b) — exactly ``minimum.accumulate`` of a shifted array, no loop.
4. **Time**: t(s) = ∫ ds / v, resampled at 100 Hz, each segment scaled (by ~1e-4) so that its
   trapezoid integral is its length exactly; dwells and standstills are zeros.
5. **Jerk limit**: the 100 Hz speed is smoothed by a centred moving average of
   T = (a + b)/j_max seconds. Every jump of the raw acceleration is at most a + b, so the
   smoothed acceleration changes by at most j_max per second. Position is the trapezoid
   integral of the smoothed speed and acceleration its central difference, so s, v and a
   are mutually consistent; since averaging commutes with integration, the vehicle still
   stops exactly at every stop (dwells are longer than T).
6. **Rolling back** (``running.rollback_m`` = r > 0): at a start from rest whose gradient in the
   direction of the move is uphill by at least ``rollback_min_gradient_permille``, the train first
   rolls back r metres (a rest-to-rest profile at ≤ ``rollback_speed_mps``, accelerating and braking
   at :data:`ROLLBACK_ACCEL`, with the speed *negative* along the move), stands for the smoothing window
   + 1 s, and then drives r + the segment's length: it still ends exactly at the planned stop. The cab
   does not change (a train rolling back on a gradient, S003 §2 / §5.3(2)). Each 100 Hz step belongs to
   the move whose timeline it lies in (the boundary in the middle of the dwell before the move), the
   signed speed is integrated into the position along the move and its magnitude into the travelled
   distance. Without any rollback the computation is the one above, step for step.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from fieldlogs.simulate.scenario import Scenario, ScenarioError
from fieldlogs.simulate.track import Cant, TrackGeometry
from schemas.enums import CabDirection
from schemas.units import KMH, KMH_PER_S, G

FloatArray = npt.NDArray[np.float64]
SpeedLimit = Callable[[FloatArray], FloatArray]
"""Speed limit [m/s] as a function of the distance travelled in a segment [m]."""
DT = 0.01
"""Simulation step [s] (the IMU rate)."""
DS_M = 1.0
"""Distance grid of the speed profile [m]."""
STOP_MARGIN_M = 50.0
"""A station closer than this to a move's ends is not a separate stop [m]."""
ROLLBACK_ACCEL = 0.1
"""Acceleration and braking of a rollback [m/s²] (≈ a 10 ‰ gradient less the train's resistance)."""


@dataclass(frozen=True)
class Move:
    sigma0: float
    sigma1: float
    direction: int
    """+1 toward increasing km, −1 toward decreasing km."""
    cab: str
    """F: moving toward the vehicle's F end; R: toward its R end."""

    @property
    def length(self) -> float:
        return abs(self.sigma1 - self.sigma0)


@dataclass
class Motion:
    """The true motion at 100 Hz (index k ↔ t = k/100 s)."""

    t: FloatArray
    v: FloatArray
    """Speed over ground ≥ 0 [m/s]."""
    a: FloatArray
    """dv/dt [m/s²] of the speed along the move (signed: negative while rolling back)."""
    p: FloatArray
    """Travelled distance [m] (never decreasing, rollbacks included)."""
    sigma: FloatArray
    """Arc length along the track [m] (increasing with km)."""
    km: FloatArray
    u: FloatArray
    """dσ/dt, signed (+ toward increasing km) [m/s]."""
    udot: FloatArray
    move: npt.NDArray[np.int64]
    on_rail: npt.NDArray[np.bool_]
    facing: int
    """+1 when the body x axis (F end) points toward increasing km."""
    moves: list[Move]
    cab_events: list[tuple[float, str, int | None]]
    window_s: float
    stops_km: list[float] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def duration_s(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    @property
    def speed_toward_f(self) -> FloatArray:
        """Signed speed along body x (+ toward the F end)."""
        return self.facing * self.u


def cant_model(scenario: Scenario) -> Cant:
    r = scenario.running
    v_design = r.design_speed_kmh or r.line_speed_kmh
    return Cant(coef_m2=r.cant_coefficient * v_design**2 / 1000.0, max_m=r.cant_max_mm / 1000.0, gauge_m=r.gauge_m)


def curve_limit(kappa: FloatArray, cant: Cant, unbalanced_mps2: float, scale: FloatArray | None = None) -> FloatArray:
    """v_max = √((a_ub + G·cant/gauge)·R) [m/s]; +inf on straights; ``scale``: the share of the
    cant laid (none on a turnout: v_max = √(a_ub·R))."""
    laid = cant.cant_m(kappa) if scale is None else cant.cant_m(kappa) * scale
    with np.errstate(divide="ignore"):
        return np.sqrt((unbalanced_mps2 + G * laid / cant.gauge_m) / np.abs(kappa))


def speed_profile(vlim: FloatArray, ds: float, accel: float, brake: float) -> FloatArray:
    """Fastest speeds on a uniform distance grid under the limit, from and to rest."""
    q = np.arange(len(vlim)) * ds
    vl2 = np.square(vlim)
    vl2[0] = vl2[-1] = 0.0
    fwd = 2 * accel * q + np.minimum.accumulate(vl2 - 2 * accel * q)
    bwd = -2 * brake * q + np.minimum.accumulate((vl2 + 2 * brake * q)[::-1])[::-1]
    return np.asarray(np.sqrt(np.clip(np.minimum(np.minimum(fwd, bwd), vl2), 0.0, None)), dtype=float)


def segment_samples(length: float, vlim_at: SpeedLimit, accel: float, brake: float) -> FloatArray:
    """100 Hz speeds of one rest-to-rest segment (first and last sample 0), ∫ = length."""
    n = max(int(np.ceil(length / DS_M)), 2)
    ds = length / n
    q = np.arange(n + 1, dtype=np.float64) * ds
    v = speed_profile(vlim_at(q), ds, accel, brake)
    t_nodes = np.concatenate([[0.0], np.cumsum(ds / (0.5 * (v[1:] + v[:-1])))])
    m = int(np.ceil(t_nodes[-1] / DT)) + 1
    vs = np.interp(np.arange(m + 1) * DT, t_nodes, v, right=0.0)
    vs[0] = vs[-1] = 0.0
    trap = DT * (vs.sum() - 0.5 * (vs[0] + vs[-1]))
    return np.asarray(vs * (length / trap), dtype=float)


def moving_average(x: FloatArray, w: int) -> FloatArray:
    """Centred moving average over ``w`` (odd) samples, zero outside."""
    h = w // 2
    c = np.concatenate([[0.0], np.cumsum(np.concatenate([np.zeros(h), x, np.zeros(h)]))])
    return np.asarray((c[w:] - c[:-w]) / w, dtype=float)


def plan_moves(geom: TrackGeometry, scenario: Scenario) -> tuple[list[Move], int]:
    """Moves along the validated path and the body facing (+1: F end toward increasing km)."""
    route = scenario.route
    path = list(route.path_km_m)
    lo, hi = geom.km_min, geom.km_max
    if not path:
        m = min(route.margin_m, 0.25 * (hi - lo))
        path = [lo + m, hi - m] if geom.normal_sign > 0 else [hi - m, lo + m]
    if len(path) < 2:
        raise ScenarioError("needs at least a start and an end km", path=scenario.source, key="route.path_km_m")
    for km in path:
        if not lo <= km <= hi:
            raise ScenarioError(
                f"km {km:.1f} is outside the GIS range {lo:.0f}–{hi:.0f} of {geom.line_code}/{geom.track}",
                path=scenario.source,
                key="route.path_km_m",
            )
    sig = geom.sigma(np.asarray(path))
    moves: list[Move] = []
    facing = 0
    for s0, s1 in itertools.pairwise(sig):
        if abs(s1 - s0) < 1.0:
            continue
        d = 1 if s1 > s0 else -1
        if facing == 0:
            facing = d if route.start_cab == CabDirection.FORWARD else -d
        moves.append(Move(float(s0), float(s1), d, "F" if d == facing else "R"))
    if not moves:
        raise ScenarioError(
            "the path does not move (all points within 1 m)", path=scenario.source, key="route.path_km_m"
        )
    return moves, facing


@dataclass
class _Timeline:
    """100 Hz speed blocks of the run in the making, with its cab/PTO events and stops."""

    blocks: list[FloatArray] = field(default_factory=list)
    cab_events: list[tuple[float, str, int | None]] = field(default_factory=list)
    stops_km: list[float] = field(default_factory=list)
    n: int = 0
    marks: list[tuple[int, int]] = field(default_factory=list)
    """(first step, move index) of each move's stretch of the timeline."""
    rolled: bool = False
    """Whether a rollback (negative speed block) was added."""

    def add(self, arr: FloatArray) -> None:
        self.blocks.append(arr)
        self.n += len(arr)

    def still(self, seconds: float) -> int:
        k = round(seconds / DT)
        self.add(np.zeros(k))
        return k

    @property
    def t(self) -> float:
        return self.n * DT


@dataclass(frozen=True)
class _Driving:
    geom: TrackGeometry
    accel: float
    brake: float
    v_line: float
    cant: Cant
    unbalanced_mps2: float
    rollback_m: float = 0.0
    rollback_min_grade: float = 0.0
    """Minimum uphill gradient of a start that rolls back [m/m]."""
    rollback_speed: float = 0.5
    min_still_s: float = 0.0

    def rollback_limit(self, q: FloatArray) -> FloatArray:
        """Speed limit of a rollback [m/s]."""
        return np.full(q.shape, self.rollback_speed)

    def rollback_at(self, move: Move, sigma: float) -> float:
        """Distance rolled back before starting ``move`` from rest at ``sigma`` (0: none)."""
        if self.rollback_m <= 0:
            return 0.0
        theta = float(self.geom.state(np.asarray([self.geom.km_at(sigma)])).theta[0])
        return self.rollback_m if move.direction * np.tan(theta) >= self.rollback_min_grade else 0.0

    def vlim_for(self, move: Move, sigma_start: float) -> SpeedLimit:
        def f(q: FloatArray) -> FloatArray:
            km = self.geom.km_at(sigma_start + move.direction * q)
            scale = self.geom.cant_scale(km)
            lim = curve_limit(
                self.geom.curvature(km), self.cant, self.unbalanced_mps2, None if scale is None else scale[0]
            )
            cap = self.geom.speed_cap(km)
            if cap is not None:
                lim = np.minimum(lim, cap)
            return np.asarray(np.minimum(self.v_line, lim), dtype=float)

        return f


def _drive(tl: _Timeline, drv: _Driving, mv: Move, stations_sigma: FloatArray, dwell_s: float, stop: bool) -> None:
    """One move: segments between the station stops inside it (if ``stop``)."""
    lo_s, hi_s = sorted((mv.sigma0, mv.sigma1))
    inner = stations_sigma[(stations_sigma > lo_s + STOP_MARGIN_M) & (stations_sigma < hi_s - STOP_MARGIN_M)]
    if not stop:
        inner = np.empty(0)
    inner = np.sort(inner) if mv.direction > 0 else np.sort(inner)[::-1]
    points = [mv.sigma0, *inner.tolist(), mv.sigma1]
    for j, (a0, a1) in enumerate(itertools.pairwise(points)):
        if j > 0:
            tl.still(dwell_s)
            tl.stops_km.append(float(drv.geom.km_at(a0)))
        rb = drv.rollback_at(mv, a0)
        if rb > 0:
            tl.add(-segment_samples(rb, drv.rollback_limit, ROLLBACK_ACCEL, ROLLBACK_ACCEL))
            tl.still(drv.min_still_s)
            tl.rolled = True
        a0 -= mv.direction * rb
        tl.add(segment_samples(abs(a1 - a0), drv.vlim_for(mv, a0), drv.accel, drv.brake))


def plan_motion(geom: TrackGeometry, scenario: Scenario, stations_km: list[float]) -> Motion:
    """The true motion of the whole run (see module docstring)."""
    r = scenario.running
    road_rail = scenario.is_road_rail
    accel, brake = r.accel_kmh_s * KMH_PER_S, r.brake_kmh_s * KMH_PER_S
    w = round((accel + brake) / r.jerk_mps3 / DT) | 1  # odd window
    window_s = w * DT
    min_still = window_s + 1.0
    moves, facing = plan_moves(geom, scenario)
    drv = _Driving(
        geom, accel, brake, r.line_speed_kmh * KMH, cant_model(scenario), r.unbalanced_lateral_mps2,
        r.rollback_m, r.rollback_min_gradient_permille / 1000.0, r.rollback_speed_mps, min_still,
    )  # fmt: skip
    stations_sigma = np.sort(geom.sigma(np.asarray(stations_km, dtype=float))) if stations_km else np.empty(0)
    tl = _Timeline()
    tl.cab_events.append((0.0, moves[0].cab, 0 if road_rail else None))
    t_on = 0.0
    if road_rail:
        tl.still(scenario.road_rail.off_rail_before_s)
        t_on = tl.t
        tl.cab_events.append((round(t_on, 2), moves[0].cab, 1))
    tl.still(max(r.standstill_start_s, min_still))
    tl.marks.append((0, 0))
    for i, mv in enumerate(moves):
        _drive(tl, drv, mv, stations_sigma, max(r.dwell_s, min_still), r.stop_at_stations and not road_rail)
        if i + 1 < len(moves):
            reverse = moves[i + 1].direction != mv.direction
            k0 = tl.n
            k = tl.still(max(r.reversal_dwell_s if reverse else r.dwell_s, min_still))
            tl.stops_km.append(float(geom.km_at(mv.sigma1)))
            tl.marks.append((k0 + k // 2, i + 1))
            if moves[i + 1].cab != mv.cab:
                tl.cab_events.append((round((k0 + k // 2) * DT, 2), moves[i + 1].cab, 1 if road_rail else None))
    tl.still(max(r.standstill_end_s, min_still))
    t_off = tl.t
    if road_rail:
        tl.cab_events.append((round(t_off, 2), moves[-1].cab, 0))
        tl.still(scenario.road_rail.off_rail_after_s)
    return _motion(geom, tl, moves, facing, w, (t_on, t_off) if road_rail else None)


def _motion(
    geom: TrackGeometry, tl: _Timeline, moves: list[Move], facing: int, w: int, on_rail: tuple[float, float] | None
) -> Motion:
    """Smoothed speeds → distance, along-track position, km, signed speed per 100 Hz step."""
    v_raw = np.concatenate(tl.blocks)
    vs = moving_average(v_raw, w)  # speed along the move (negative: rolling back)
    if not tl.rolled:
        vs = np.clip(vs, 0.0, None)
    v = np.abs(vs) if tl.rolled else vs
    n = len(v)
    t = np.arange(n) / 100.0
    q = _integral(vs)  # position along the moves
    p = _integral(v) if tl.rolled else q
    a = np.gradient(vs, DT) if n > 1 else np.zeros(n)
    starts = np.concatenate([[0.0], np.cumsum([mv.length for mv in moves])])
    if tl.rolled:
        first = np.array([k for k, _ in tl.marks])
        idx = np.asarray([i for _, i in tl.marks], dtype=np.int64)[np.searchsorted(first, np.arange(n), "right") - 1]
    else:
        idx = np.clip(np.searchsorted(starts[1:-1], q, side="right"), 0, len(moves) - 1).astype(np.int64)
    s0 = np.array([mv.sigma0 for mv in moves])
    d = np.array([mv.direction for mv in moves], dtype=float)
    sigma = s0[idx] + d[idx] * (q - starts[idx])
    # end of the run: never beyond the last path point (float drift of ~1e-9 m)
    sigma = np.clip(sigma, geom.sigma(geom.km_min), geom.sigma(geom.km_max))
    if on_rail is not None:
        on = (t >= on_rail[0] - 1e-9) & (t < on_rail[1] - 1e-9)
    else:
        on = np.ones(n, dtype=bool)
    return Motion(
        t=t,
        v=v,
        a=a,
        p=p,
        sigma=sigma,
        km=geom.km_at(sigma),
        u=d[idx] * vs,
        udot=d[idx] * a,
        move=idx,
        on_rail=on,
        facing=facing,
        moves=moves,
        cab_events=tl.cab_events,
        window_s=w * DT,
        stops_km=tl.stops_km,
    )


def _integral(x: FloatArray) -> FloatArray:
    """Trapezoid integral of a 100 Hz series from its first step."""
    c = np.cumsum(x)
    return np.asarray(DT * (c - 0.5 * (x[0] + x)), dtype=float)
