"""Simulator throughput: seconds per simulated hour, and the speed-up over a naive loop.

Run on demand (never a pass/fail timing test):

    .venv/bin/python bench/bench_simulate.py [--km 110] [--slice 5000]

Builds a synthetic double-track line in memory (stations every 3 km), simulates the whole
down track with every stream on (noise, slips, radar), and compares the vectorised body
kinematics + IMU noise with a per-sample Python loop over a short slice.
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from dbtools.gis.geometry import Projector
from fieldlogs.simulate.kinematics import body_kinematics
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.running import Motion, cant_model, plan_motion
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from fieldlogs.simulate.track import Cant, TrackGeometry
from schemas.units import G


def naive_imu(
    geom: TrackGeometry, cant: Cant, motion: Motion, k0: int, k1: int, rng: np.random.Generator
) -> np.ndarray:
    """The same physics as ``kinematics.body_kinematics`` + white noise, one sample at a time."""
    out = np.empty((k1 - k0, 6))
    f = motion.facing
    for i, k in enumerate(range(k0, k1)):
        st = geom.state(np.array([motion.km[k]]))
        cpsi, spsi = float(st.cos_psi[0]), float(st.sin_psi[0])
        th, j = float(st.theta[0]), float(st.j[0])
        roll_t, droll = (float(x[0]) for x in cant.roll(st.kappa, st.dkappa_dkm))
        u, udot = float(motion.u[k]), float(motion.udot[k])
        kdot = u / j
        theta, roll = f * th, f * roll_t
        hb = float(st.dpsi_dkm[0]) * kdot
        tdot = f * float(st.dtheta_dkm[0]) * kdot
        rdot = f * droll * kdot
        cb, sb, cr, sr = math.cos(theta), math.sin(theta), math.cos(roll), math.sin(roll)
        w = (rdot + hb * sb, -tdot * cr + hb * cb * sr, tdot * sr + hb * cb * cr)
        dth, dps = float(st.dtheta_dkm[0]) / j, float(st.dpsi_dkm[0]) / j
        cth, sth = math.cos(th), math.sin(th)
        fx = udot * cth * cpsi + u * u * (-dth * sth * cpsi - dps * cth * spsi)
        fy = udot * cth * spsi + u * u * (-dth * sth * spsi + dps * cth * cpsi)
        fz = udot * sth + u * u * dth * cth + G
        g1 = f * cpsi * fx + f * spsi * fy
        g2 = -f * spsi * fx + f * cpsi * fy
        h1, h3 = cb * g1 + sb * fz, -sb * g1 + cb * fz
        acc = (h1, cr * g2 + sr * h3, -sr * g2 + cr * h3)
        out[i] = np.array([*acc, *w]) + rng.normal(0.0, 0.08, 6)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--km", type=float, default=110.0, help="line length [km]")
    ap.add_argument("--slice", type=int, default=5000, help="samples for the naive loop")
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()

    t0 = time.perf_counter()
    net = build_network([demo_line("0990", seed=3, length_m=args.km * 1000.0)], Projector(9))
    print(f"network: {args.km:.0f} km double track, built in {time.perf_counter() - t0:.1f} s")
    sc = scenario_from_dict({"route": {"track": "D"}, "sensors": {"radar": True}}, "bench")

    best = math.inf
    streams = {}
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        streams, _ = simulate_run(net, sc, 1)
        best = min(best, time.perf_counter() - t0)
    hours = float(streams["imu"]["t"].iloc[-1]) / 3600.0
    rows = sum(len(f) for f in streams.values())
    print(f"simulated {hours:.2f} h ({rows:,} rows, {len(streams['imu']):,} IMU samples) in {best:.2f} s")
    print(f"  → {best / hours:.2f} s per simulated hour (target ≤ 10 s)")

    geom = TrackGeometry.from_network(net, "0990", "D")
    motion = plan_motion(geom, sc, [])
    cant = cant_model(sc)
    k0 = motion.n // 3
    k1 = k0 + args.slice
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    naive_imu(geom, cant, motion, k0, k1, rng)
    naive = (time.perf_counter() - t0) / args.slice
    t0 = time.perf_counter()
    kin = body_kinematics(geom, cant, motion)
    _ = kin.ax + rng.normal(0.0, 0.08, (6, motion.n))
    vec = (time.perf_counter() - t0) / motion.n
    print(
        f"body kinematics + IMU noise: vectorised {vec * 1e6:.2f} µs/sample, naive loop {naive * 1e6:.0f} µs/sample "
        f"→ ×{naive / vec:.0f} (naive: {naive * 360_000:.0f} s per simulated hour of IMU alone)"
    )


if __name__ == "__main__":
    main()
