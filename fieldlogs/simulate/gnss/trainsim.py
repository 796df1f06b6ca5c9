"""Raw GNSS observations for the train simulator: the constellation simulator driven by the
simulated run's truth (``trainpos simulate`` with ``[gnss_raw] enabled = true``) [S002].

Per epoch (every ``interval_s`` of the 100 Hz motion) the reference point is on the true track
— the simulator's C2 spline through the DB's GIS grid (lat/lon from the plane coordinates,
height from the grid's height spline, so ellipsoidal like the grid) at the true km — and the
car faces increasing km when its F end does (``Motion.facing``). The heading is the azimuth of
increasing km, from the ENU difference of the track points 0.5 m either side. Antennas are at
x = ``antennas_x_m`` (toward the F end), y = 0, z = ``antenna_z_m`` above the rail, one receiver
each (rx1, rx2, …) with its own clock. :func:`fieldlogs.simulate.gnss.observations.simulate` then gives the
pseudoranges, carrier, Doppler and C/N0 (ionosphere, troposphere, orbit/clock errors, multipath,
noise by C/N0, NLOS beside buildings) and, on a network run with ``network.multipath``, the
reflections off a surface at the neighbouring track (``RawGnssSpec.reflectors``).

Sky: the run's tunnels (``gps.outages_km_m``) block every satellite; ``corridor = "mixed"`` adds
the seeded buildings, cuttings, overpasses and short tunnel of
:func:`fieldlogs.simulate.gnss.scenario.mixed_corridor` along the route. ``noise = false`` switches the
random error components off (the receivers' clocks stay). ``sbas = true`` adds broadcast
orbit/clock errors to the truth and a ``gnss_sbas`` stream (MSAS PRN 137) that corrects them.

Times: ``gnss_time_s`` on the GPS scale from the run's ``start_time`` (the simulator's truth
time is GPS time here), ``t`` the run clock of the epoch. The vehicle block (a 20 m car with its
reference point at the centre, the tacho on axle A1) and the Klobuchar parameters of the
navigation header go to run.json, so the run is positioned like an imported one.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import OBS_COLUMNS, FloatArray
from fieldlogs.gnss.geodesy import enu_basis, geodetic_to_ecef
from fieldlogs.recorders.timebase import gps_to_utc, leap_seconds_utc
from fieldlogs.simulate.gnss.constellation import constellation_nav
from fieldlogs.simulate.gnss.observations import (
    KLOBUCHAR_ALPHA,
    KLOBUCHAR_BETA,
    Corridor,
    ErrorSpec,
    ReceiverSpec,
    Section,
    Trajectory,
    simulate,
    with_sat_errors,
)
from fieldlogs.simulate.gnss.reflection import ReflectorsAt
from fieldlogs.simulate.gnss.scenario import mixed_corridor

#: The simulated car: length, F end and tacho axle (x from the reference point at its centre).
CAR_LENGTH_M = 20.0
CAR_FRONT_X_M = 10.0
TACHO_AXLE_X_M = 8.85
MOTION_DT_S = 0.01


@dataclass(frozen=True)
class RawGnssSpec:
    """What the train simulator passes in (its scenario's ``[gnss_raw]`` and the run's facts)."""

    systems: tuple[str, ...]
    interval_s: float
    antennas_x_m: tuple[float, ...]
    antenna_z_m: float
    corridor: str
    noise: bool
    start_gps_s: float
    tunnels_km_m: tuple[tuple[float, float], ...] = ()
    sbas: bool = False
    """Broadcast orbit/clock errors in the truth and an MSAS ``gnss_sbas`` stream correcting them
    (:mod:`fieldlogs.simulate.gnss.sbas_stream`; it starts with the run, so its first minute is not yet
    corrected)."""
    reflectors: ReflectorsAt | None = None
    """Reflecting surfaces beside the track by km (a network run's ``network.multipath``:
    :meth:`fieldlogs.simulate.netsim.NetworkPlan.reflectors`, :mod:`fieldlogs.simulate.gnss.reflection`)."""


@dataclass
class RawGnss:
    obs: pd.DataFrame
    nav: pd.DataFrame
    gnss_block: dict[str, Any]
    receivers: list[ReceiverSpec]
    sbas: pd.DataFrame | None = None
    reflection: dict[str, Any] | None = None
    """With reflectors: the reflected observations' count and their code errors' RMS and range
    [m] (run.json ``sim_truth.gnss_raw.reflection``)."""


def _headings(geom: Any, km: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """(lat, lon [deg], h [m], azimuth of increasing km [rad]) of track points at ``km``."""

    def geodetic(k: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        x, y = geom.xy(k)
        lon, lat = geom.lonlat(x, y)
        return np.asarray(lat, dtype=float), np.asarray(lon, dtype=float), geom.height(k)

    lat, lon, h = geodetic(km)
    pa = geodetic_to_ecef(*(np.radians(v) if i < 2 else v for i, v in enumerate(geodetic(km - 0.5))))
    pb = geodetic_to_ecef(*(np.radians(v) if i < 2 else v for i, v in enumerate(geodetic(km + 0.5))))
    r = enu_basis(np.radians(lat), np.radians(lon))
    d = np.einsum("eij,ej->ei", r, pb - pa)
    return lat, lon, h, np.arctan2(d[:, 0], d[:, 1])


def _corridor(spec: RawGnssSpec, km_lo: float, km_hi: float, seed: int) -> Corridor:
    sections = [Section(min(a, b), max(a, b), "tunnel") for a, b in spec.tunnels_km_m]
    if spec.corridor == "mixed":
        for sec in mixed_corridor(km_hi - km_lo, seed).sections:
            sections.append(replace(sec, s_from=sec.s_from + km_lo, s_to=sec.s_to + km_lo))
    return Corridor(tuple(sections))


def _errors(noise: bool, sbas: bool = False) -> ErrorSpec:
    if noise:
        return with_sat_errors(ErrorSpec()) if sbas else ErrorSpec()
    return ErrorSpec(
        sis_sigma_m={"G": 0.0, "E": 0.0, "J": 0.0},
        iono_run_sigma=0.0,
        iono_sat_sigma=0.0,
        tropo_run_sigma=0.0,
        mp_zenith_m=0.0,
        mp_low_m=0.0,
        noise_45_m=0.0,
        p_nlos=0.0,
    )


def raw_gnss(motion: Any, geom: Any, spec: RawGnssSpec, rng: np.random.Generator) -> RawGnss:
    """gnss_obs + gnss_nav of a simulated run (module docstring); ``motion``/``geom`` are the
    train simulator's ``Motion`` and ``TrackGeometry``."""
    step = max(round(spec.interval_s / MOTION_DT_S), 1)
    k = np.arange(0, motion.n, step)
    t_run = np.asarray(motion.t[k], dtype=float)
    km = np.asarray(motion.km[k], dtype=float)
    lat, lon, h, az = _headings(geom, km)
    facing = float(motion.facing)
    heading = az + (np.pi if facing < 0 else 0.0)
    t_gps = spec.start_gps_s + t_run
    traj = Trajectory.from_geodetic(t_gps, lat, lon, h, np.degrees(heading), km, facing)
    seeds = rng.integers(0, 2**31 - 1, size=3)
    nav = constellation_nav(float(t_gps[0]), float(t_gps[-1]), seed=int(seeds[0]), systems=spec.systems)
    receivers = [
        ReceiverSpec(
            f"rx{i + 1}",
            forward_m=float(x),
            left_m=0.0,
            up_m=spec.antenna_z_m,
            clock_bias_s=float(rng.uniform(-5e-4, 5e-4)),
            clock_drift_sps=float(rng.normal(0.0, 2e-8)),
        )
        for i, x in enumerate(spec.antennas_x_m)
    ]
    corridor = _corridor(spec, float(np.min(motion.km)), float(np.max(motion.km)), int(seeds[1]))
    errors = _errors(spec.noise, spec.sbas)
    sim = simulate(
        traj, nav, receivers, corridor, seed=int(seeds[2]), errors=errors, systems=spec.systems,
        reflectors=spec.reflectors,
    )  # fmt: skip
    obs = sim.obs.copy()
    obs["t"] = obs["t"].to_numpy(dtype=float) - spec.start_gps_s  # run clock of the epoch
    obs = obs.sort_values(["t", "receiver", "sat", "signal"], kind="stable").reset_index(drop=True)
    leap = int(leap_seconds_utc(gps_to_utc(spec.start_gps_s)))
    block = {"klobuchar_alpha": list(KLOBUCHAR_ALPHA), "klobuchar_beta": list(KLOBUCHAR_BETA), "leap_seconds": leap}
    sbas = None
    if spec.sbas:
        from fieldlogs.simulate.gnss.sbas_stream import sbas_stream

        sbas = sbas_stream(sim, seed=int(seeds[2]), t0_gps=spec.start_gps_s)
    return RawGnss(obs[list(OBS_COLUMNS)], sim.nav, block, receivers, sbas, _reflection(sim.rows, spec))


def _reflection(rows: pd.DataFrame, spec: RawGnssSpec) -> dict[str, Any] | None:
    """The truth of the reflections (``RawGnss.reflection``), None without reflectors."""
    if spec.reflectors is None:
        return None
    e = rows["reflection_m"].to_numpy(dtype=float)
    e = e[e != 0.0]
    return {
        "observations": int(e.size),
        "of": len(rows),
        "code_rms_m": round(float(np.sqrt(np.mean(e * e))), 3) if e.size else 0.0,
        "code_min_m": round(float(e.min()), 3) if e.size else 0.0,
        "code_max_m": round(float(e.max()), 3) if e.size else 0.0,
    }


def vehicle_block(
    vehicle_id: str, vehicle_kind: str, receivers: list[ReceiverSpec], wheel_diameter_m: float, teeth: int
) -> dict[str, Any]:
    """run.json ``vehicle`` of the simulated car (module docstring; ``schemas.vehicle``)."""
    return {
        "vehicle_id": vehicle_id,
        "vehicle_kind": vehicle_kind,
        "length_m": CAR_LENGTH_M,
        "reference": "centre of the simulated car, on the track centreline",
        "front_x_m": CAR_FRONT_X_M,
        "tacho_axle": "A1",
        "antennas": [
            {"id": f"antenna-{r.name}", "receiver": r.name, "x_m": r.forward_m, "y_m": r.left_m, "z_m": r.up_m}
            for r in receivers
        ],
        "axles": [{"id": "A1", "x_m": TACHO_AXLE_X_M, "wheel_diameter_m": wheel_diameter_m, "teeth": teeth}],
    }
