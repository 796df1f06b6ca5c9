"""Synthetic 3-D test track, vehicle runs on it and the corridor around it (bench and tests).

The track is built from elements (length, curvature 1/R, gradient) in the local east/north/up
plane at a base point near Tokyo (35.68° N, 139.77° E, 40 m ellipsoidal): heading
ψ(ℓ) = ψ0 + ∫κ dℓ with clothoid transitions (κ ramps over 60 m), up(ℓ) = ∫grade dℓ, sampled
every metre (the truth) and every 20 m with 2 cm survey noise (the GIS grid the solver gets,
as the onboard DB's 20 m grid). ECEF = base + R_ENUᵀ·enu (a 15 km track departs from the
ellipsoid's curvature by < 20 m in height, irrelevant to a synthetic truth).

A run: the reference point moves with v(t) accelerating at 0.6 m/s² to a cruise speed,
braking at 0.7 m/s² to stop at stations every ``station_spacing_m`` with 30 s dwell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.gnss.constants import FloatArray
from fieldlogs.gnss.geodesy import enu_basis, geodetic_to_ecef
from fieldlogs.gnss.track import TrackLine
from fieldlogs.simulate.gnss.observations import Corridor, Section, Trajectory

BASE_LAT_DEG = 35.68
BASE_LON_DEG = 139.77
BASE_H_M = 40.0


@dataclass(frozen=True)
class SyntheticTrack:
    """Truth polyline (1 m), the solver's 20 m grid and the ENU heading of the truth."""

    truth: TrackLine
    grid: TrackLine
    heading_rad: FloatArray
    """Azimuth (clockwise from north) of increasing s at each truth vertex."""


ELEMENTS: tuple[tuple[float, float, float], ...] = (
    (1500.0, 0.0, 0.0),
    (900.0, 1 / 600.0, 0.010),
    (2000.0, 0.0, 0.010),
    (700.0, -1 / 800.0, -0.005),
    (2500.0, 0.0, -0.015),
    (1200.0, 1 / 1000.0, 0.0),
    (3000.0, 0.0, 0.005),
    (800.0, -1 / 500.0, 0.0),
    (2400.0, 0.0, -0.008),
)


def synthetic_track(seed: int = 0, heading0_deg: float = 10.0) -> SyntheticTrack:
    """The module docstring's track (the survey noise of the grid is seeded)."""
    step = 1.0
    kappa, grade = [], []
    prev_k = 0.0
    for length, k, g in ELEMENTS:
        n = int(length / step)
        ramp = np.clip(np.arange(n) * step / 60.0, 0.0, 1.0)
        kappa.append(prev_k + (k - prev_k) * ramp)
        grade.append(np.full(n, g))
        prev_k = k
    kap = np.concatenate(kappa)
    gr = np.concatenate(grade)
    psi = np.radians(heading0_deg) + np.concatenate([[0.0], np.cumsum(kap * step)])
    hz = np.cos(np.arctan(np.concatenate([[0.0], gr])))
    east = np.concatenate([[0.0], np.cumsum(np.sin(psi[:-1]) * hz[1:] * step)])
    north = np.concatenate([[0.0], np.cumsum(np.cos(psi[:-1]) * hz[1:] * step)])
    up = np.concatenate([[0.0], np.cumsum(gr * step)])
    lat, lon = np.radians(BASE_LAT_DEG), np.radians(BASE_LON_DEG)
    base = geodetic_to_ecef(lat, lon, BASE_H_M)
    r = enu_basis(lat, lon)
    enu = np.stack([east, north, up], axis=-1)
    xyz = base + enu @ r
    truth = TrackLine.from_ecef(xyz)
    rng = np.random.default_rng(seed)
    grid_pts = xyz[::20] + rng.normal(0.0, 0.02, xyz[::20].shape)
    if (xyz.shape[0] - 1) % 20:
        grid_pts = np.vstack([grid_pts, xyz[-1]])
    return SyntheticTrack(truth, TrackLine.from_ecef(grid_pts), psi)


def run_profile(
    length_m: float, duration_s: float, dt: float, v_cruise: float, s0: float, station_spacing_m: float
) -> FloatArray:
    """s(t) of a run with stops (module docstring), clipped to the track."""
    n = int(duration_s / dt) + 1
    s = np.empty(n)
    v = 0.0
    pos = s0
    next_stop = (np.floor(s0 / station_spacing_m) + 1) * station_spacing_m
    dwell = 0.0
    for i in range(n):  # a speed profile is a recursion in time (n ≤ a few thousand)
        s[i] = pos
        if dwell > 0:
            dwell -= dt
            continue
        brake = v * v / (2 * 0.7)
        if pos + brake >= next_stop - 1.0:
            v = max(v - 0.7 * dt, 0.0)
            if v == 0.0:
                dwell, next_stop = 30.0, next_stop + station_spacing_m
        else:
            v = min(v + 0.6 * dt, v_cruise)
        pos = min(pos + v * dt, length_m - 1.0)
    return s


def trajectory(track: SyntheticTrack, s: FloatArray, t0: float, dt: float, direction: float = 1.0) -> Trajectory:
    """Reference-point truth along ``track.truth`` at s (facing increasing s if direction > 0)."""
    t = np.asarray(t0 + dt * np.arange(s.size), dtype=float)
    ref = track.truth.point(s)
    j = track.truth.segment(s)
    heading = track.heading_rad[j] + (np.pi if direction < 0 else 0.0)
    return Trajectory(t, ref, heading, s, np.full(s.size, float(direction)))


def mixed_corridor(length_m: float, seed: int) -> Corridor:
    """Buildings on either side, cuttings, overpasses and one short tunnel at seeded places."""
    rng = np.random.default_rng(seed)
    sections = []
    pos = 0.0
    while pos < length_m:
        kind = rng.choice(
            ["open", "left", "right", "cutting", "overpass", "tunnel"], p=[0.45, 0.15, 0.15, 0.15, 0.08, 0.02]
        )
        if kind == "overpass":
            ln = rng.uniform(10.0, 30.0)
        elif kind == "tunnel":
            ln = rng.uniform(100.0, 300.0)
        else:
            ln = rng.uniform(200.0, 1200.0)
        if kind != "open":
            elev = {
                "left": rng.uniform(30.0, 70.0),
                "right": rng.uniform(30.0, 70.0),
                "cutting": rng.uniform(15.0, 35.0),
            }
            sections.append(Section(pos, pos + ln, str(kind), float(elev.get(str(kind), 90.0))))
        pos += ln
    return Corridor(tuple(sections))
