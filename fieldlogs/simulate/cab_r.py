"""The R cab's own sensors (scenario ``[cab_r] sensors = true``): a vehicle with a positioning
unit in each cab, each working independently ([the position-detection field test §2]:
車載装置は各運転台に設置し，独立して動作する), has in each cab its own IMU, tachometer (on its own
axle) and GPS antenna. The streams ``imu_r``, ``tacho_r``, ``gps_r`` (``schemas.logs.CAB_R_STREAMS``)
are what the R cab's sensors record, in the **R cab's frame**: the vehicle's frame turned half
round about z, x_R = −x, y_R = −y, z_R = z (x toward the vehicle's R end, the R cab's forward).

* **IMU** at x_i (``imu_x_m``, vehicle frame) on the rigid car body: the body rates ω are the
  same everywhere on it; the specific force at the point r = (x_i, 0, 0) is that at the
  reference point plus the lever-arm terms, f_P = f_O + ω̇ × r + ω × (ω × r), i.e.
  f_x += −(ω_y² + ω_z²)·x_i, f_y += (ω̇_z + ω_x·ω_y)·x_i, f_z += (ω_x·ω_z − ω̇_y)·x_i
  (ω̇ by a central difference over ``OMEGA_DOT_SPAN_S`` = 1 s: a car body's yaw follows the
  curvature through its bogies, spread over their spacing, while the simulated geometry has
  curvature steps at turnouts whose 100 Hz difference would be an impulse no body shows). Turned into the R cab's frame:
  (ax, ay, az, wx, wy, wz)_R = (−f_x, −f_y, f_z, −ω_x, −ω_y, ω_z) — a left turn is ω_z > 0 for
  both cabs, and its centripetal force points to +y of the cab that leads and −y of the other.
  Then the noise model of :func:`~fieldlogs.simulate.sensors.imu_stream` with its own draws.
* **Tacho** on the R cab's own axle: its own diameter (nominal × (1 − wear draw) × (1 +
  ``wheel_error_pct``/100)), its own slip/slide episodes (the ``[slip]`` knobs drawn again), its
  ``direction`` +1 toward the vehicle's R end (:func:`~fieldlogs.simulate.sensors.tacho_stream`,
  ``sense`` = −1).
* **GPS** antenna at x_g (``gps_x_m``): it reads the track at arc length σ + facing·x_g
  (as a balise reader per cab does, :func:`~fieldlogs.simulate.events.reader_events`), with its
  own error draws (and a network run's multipath at its own place).

The truth stays the reference point's; it gains ``slipping_r`` (the R axle's episodes), and
run.json's ``sim_truth.cab_r`` gives the R axle's true diameter, wear, rolled distance and
episodes and the sensors' places; the vehicle block gets ``gps_antenna`` and ``imu`` (the F
cab's: at the reference point, where the simulator's F sensors are) and ``gps_antenna_r``,
``imu_r``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from fieldlogs.runs.meta import RunMeta
from fieldlogs.simulate.kinematics import BodyKinematics
from fieldlogs.simulate.netsim import NetworkPlan
from fieldlogs.simulate.running import DT, Motion
from fieldlogs.simulate.scenario import Scenario
from fieldlogs.simulate.sensors import gps_stream, imu_stream, tacho_stream, wheel_distance, wheel_draw
from fieldlogs.simulate.slip import place_episodes, wheel_factor
from fieldlogs.simulate.track import TrackGeometry
from schemas.logs import CAB_R_STREAMS

FloatArray = np.ndarray
#: The span ω̇ is taken over [s] (module docstring).
OMEGA_DOT_SPAN_S = 1.0


@dataclass(frozen=True)
class CabR:
    """What the R cab's sensors are simulated from."""

    scenario: Scenario
    motion: Motion
    geom: TrackGeometry
    plan: NetworkPlan | None
    kin: BodyKinematics | None
    """The reference point's true kinematics (None: the run has no IMU)."""


def rate_of_change(t: FloatArray, w: FloatArray, span_s: float = OMEGA_DOT_SPAN_S) -> FloatArray:
    """ω̇ as the central difference over ``span_s``: (ω(t + span/2) − ω(t − span/2)) / span, the
    ends held (module docstring)."""
    if len(t) < 2:
        return np.zeros_like(w)
    half = span_s / 2.0
    lo, hi = np.clip(t - half, t[0], t[-1]), np.clip(t + half, t[0], t[-1])
    return np.asarray((np.interp(hi, t, w) - np.interp(lo, t, w)) / np.maximum(hi - lo, 1e-9), dtype=float)


def lever_arm(kin: BodyKinematics, t: FloatArray, x_m: float) -> dict[str, FloatArray]:
    """True IMU values at x_m forward of the reference point, in the vehicle's frame (module
    docstring: f_P = f_O + ω̇ × r + ω × (ω × r), r = (x_m, 0, 0))."""
    wx, wy, wz = kin.wx, kin.wy, kin.wz
    dwy, dwz = rate_of_change(t, wy), rate_of_change(t, wz)
    return {
        "ax": kin.ax - (wy * wy + wz * wz) * x_m,
        "ay": kin.ay + (dwz + wx * wy) * x_m,
        "az": kin.az + (wx * wz - dwy) * x_m,
        "wx": wx,
        "wy": wy,
        "wz": wz,
    }


def turned(values: dict[str, FloatArray]) -> dict[str, FloatArray]:
    """IMU values in the R cab's frame: x and y change sign, z does not (a half turn about z)."""
    return {k: (-v + 0.0 if k[1] in "xy" else v) for k, v in values.items()}


def add_cab_r(streams: dict[str, pd.DataFrame], meta: RunMeta, src: CabR, rng: np.random.Generator) -> None:
    """The R cab's streams for the F streams the run has, the truth's ``slipping_r``, run.json's
    vehicle sections and ``sim_truth.cab_r`` (module docstring)."""
    cfg, sc, motion = src.scenario.cab_r, src.scenario, src.motion
    r_wheel, r_slip, r_imu, r_gps = rng.spawn(4)
    d_true, wear = wheel_draw(sc, r_wheel)
    d_true *= 1.0 + cfg.wheel_error_pct / 100.0
    episodes = place_episodes(sc, motion, src.geom, r_slip)
    factor, slipping = wheel_factor(episodes, motion.t)
    rolled = wheel_distance(motion, factor)
    if "tacho" in streams:
        streams[CAB_R_STREAMS["tacho"]] = tacho_stream(rolled, motion, d_true, sc.tacho.teeth, sc.tacho.two_phase, -1)
    if "imu" in streams and src.kin is not None:
        true = turned(lever_arm(src.kin, motion.t, cfg.imu_x_m))
        streams[CAB_R_STREAMS["imu"]] = imu_stream(true, motion, sc, r_imu)
    if "gps" in streams:
        lo, hi = src.geom.sigma(src.geom.km_min), src.geom.sigma(src.geom.km_max)
        at = replace(motion, km=src.geom.km_at(np.clip(motion.sigma + motion.facing * cfg.gps_x_m, lo, hi)))
        gps, _ = gps_stream(at, src.geom, sc, r_gps)
        streams[CAB_R_STREAMS["gps"]] = gps if src.plan is None else src.plan.multipath(gps, at)
    if "truth" in streams:
        truth = streams["truth"].copy()
        k = np.clip(np.round(truth["t"].to_numpy(dtype=float) / DT).astype(np.int64), 0, motion.n - 1)
        truth["slipping_r"] = slipping[k].astype(np.int64)
        streams["truth"] = truth
    _vehicle(meta, src)
    meta.extra["sim_truth"]["cab_r"] = {
        "imu_x_m": cfg.imu_x_m,
        "gps_x_m": cfg.gps_x_m,
        "wheel_diameter_true_m": round(d_true, 6),
        "wheel_wear_pct": round(wear, 4),
        "wheel_error_pct": cfg.wheel_error_pct,
        "wheel_rolled_m": round(float(rolled[-1]), 3),
        "slip_episodes": [e.to_json() for e in episodes],
    }


def _vehicle(meta: RunMeta, src: CabR) -> None:
    """run.json's vehicle block with the F cab's sensors at the reference point and the R cab's."""
    from fieldlogs.simulate.gnss.trainsim import vehicle_block

    sc, cfg = src.scenario, src.scenario.cab_r
    block: dict[str, Any] = meta.vehicle or vehicle_block(
        meta.vehicle_id, meta.vehicle_kind, [], sc.tacho.wheel_diameter_m, sc.tacho.teeth
    )
    meta.vehicle = {
        **block,
        "gps_antenna": {"x_m": 0.0, "y_m": 0.0},
        "gps_antenna_r": {"x_m": cfg.gps_x_m, "y_m": 0.0},
        "imu": {"x_m": 0.0, "y_m": 0.0, "z_m": 0.0},
        "imu_r": {"x_m": cfg.imu_x_m, "y_m": 0.0, "z_m": 0.0},
    }
