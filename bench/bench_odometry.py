"""Benchmark: ``correct_odometry`` on a 1-hour run (36 000 cycles) with 20 slips/slides.

Run: ``.venv/bin/python bench/bench_odometry.py [--hours 1] [--slips 20]``. The cycle arrays
are synthesised directly (speed profile, gradient, quantised pulses, IMU cycle means with
0.1 km/h/s noise). Prints cycles/s of the vectorised function (full correction) and of a
straightforward per-cycle Python implementation of only the detection front end (pulse
delay, 1 s + 3 s trailing moving averages, differentiation, eq. 1 mask) and their ratio; it
also checks that both front ends flag the same cycles. Never fails on timing: it reports.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.pipeline.odometry.detection import detect
from fieldlogs.pipeline.odometry.streams import SPEED_AVG_S, align_streams
from schemas.units import G

Q = np.pi * 0.86 / 90


def synthetic_cycles(hours: float, slips: int, seed: int = 0) -> tuple[Cycles, np.ndarray]:
    """A run of station-to-station legs (accelerate, cruise, brake, dwell) with slips."""
    rng = np.random.default_rng(seed)
    dt = 0.1
    n = round(hours * 3600 / dt)
    t = np.arange(n) * dt
    acc = np.zeros(n)
    k = 0
    while k < n:  # one leg: 0.6 m/s² to 20–30 m/s, cruise, −0.7 m/s², 30 s dwell
        vmax = rng.uniform(20, 30)
        n_acc, n_cru, n_brk = round(vmax / 0.6 / dt), round(rng.uniform(60, 240) / dt), round(vmax / 0.7 / dt)
        acc[k : k + n_acc] = 0.6
        acc[k + n_acc + n_cru : k + n_acc + n_cru + n_brk] = -0.7
        k += n_acc + n_cru + n_brk + 300
    v = np.maximum(np.cumsum(acc * dt), 0.0)
    grade = np.arctan(np.clip(np.cumsum(rng.normal(0, 0.0003, n)), -0.02, 0.02))
    moving = np.flatnonzero(v > 12.0)
    onsets = np.sort(rng.choice(moving[moving < n - 400], slips, replace=False))
    factor = np.zeros(n)
    for i in onsets:
        sign = 1.0 if acc[i] >= 0 else -1.0
        factor[i : i + 30] = sign * 0.3  # 3 s at ±30 % wheel speed
    s_wheel = np.cumsum(v * (1 + factor) * dt)
    pulses = np.floor(s_wheel / Q)
    d_pulse = (pulses - pulses[0]) * Q
    v_pulse = np.diff(d_pulse, prepend=d_pulse[0]) / dt
    lag = 3
    ax_true = np.concatenate([np.zeros(lag), (acc + G * np.sin(grade))[:-lag]])
    imu = {
        "ax": ax_true + rng.normal(0, 0.1 / 3.6, n),
        "ay": rng.normal(0, 0.02, n),
        "az": np.full(n, G),
        "wx": rng.normal(0, 1e-3, n),
        "wy": rng.normal(0, 1e-3, n),
        "wz": rng.normal(0, 1e-3, n),
    }
    ones = np.ones(n, dtype=np.int8)
    return Cycles(t, pulses, d_pulse, v_pulse, imu, ones, ones, True, True), t[onsets]


def naive_detection(c: Cycles, cfg: OdometryConfig) -> list[bool]:
    """Per-cycle Python: delay line, running-sum moving averages, eq. 1 — what a C-style
    onboard loop would do, written in plain Python."""
    n, dly = c.n, cfg.pulse_delay_cycles
    p, w = round(SPEED_AVG_S / 0.1), round(cfg.avg_window_s / 0.1)
    ta, vmin, warm = cfg.ta_mps2, cfg.min_speed_kmh / 3.6, dly + p + p + w - 1
    vp_hist: list[float] = []
    v1_hist: list[float] = []
    ap_hist: list[float] = []
    ax_hist: list[float] = []
    ax1_hist: list[float] = []
    mask = []
    vpulse, axs = c.v_pulse.tolist(), c.imu["ax"].tolist()
    for k in range(n):
        vp = vpulse[k - dly] if k >= dly else vpulse[0]
        vp_hist.append(vp if k > dly else float("nan"))
        win = [x for x in vp_hist[-p:] if x == x]
        v1 = sum(win) / len(win) if win else float("nan")
        ap = (v1 - v1_hist[-1]) / 0.1 if v1_hist and k > dly + p else float("nan")
        v1_hist.append(v1)
        ap_hist.append(ap)
        win = [x for x in ap_hist[-w:] if x == x]
        aps = sum(win) / len(win) if win else float("nan")
        ax_hist.append(axs[k])
        win = [x for x in ax_hist[-p:] if x == x]
        ax1_hist.append(sum(win) / len(win) if win else float("nan"))
        win = [x for x in ax1_hist[-w:] if x == x]
        axm = sum(win) / len(win) if win else float("nan")
        mask.append(k >= warm and abs(axm - aps) > ta and v1 >= vmin)
    return mask


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--slips", type=int, default=20)
    ap.add_argument("--repeat", type=int, default=20)
    args = ap.parse_args()
    cfg = OdometryConfig()
    cyc, onsets = synthetic_cycles(args.hours, args.slips)
    correct_odometry(cyc, cfg)  # warm-up
    times, cpu = [], []
    for _ in range(args.repeat):
        t0, c0 = time.perf_counter(), time.thread_time()
        odo = correct_odometry(cyc, cfg)
        times.append(time.perf_counter() - t0)
        cpu.append(time.thread_time() - c0)
    fast, fast_cpu = statistics.median(times), min(cpu)
    t0, c0 = time.perf_counter(), time.thread_time()
    mask = naive_detection(cyc, cfg)
    slow, slow_cpu = time.perf_counter() - t0, time.thread_time() - c0
    ref = np.zeros(cyc.n)
    t0 = time.thread_time()
    for _ in range(100):
        np.cumsum(cyc.t, out=ref)
    pass_ms = (time.thread_time() - t0) * 10
    same = np.array_equal(np.array(mask), detect(align_streams(cyc, cfg), cfg).ta_mask)
    hit = sum(any(e.t_start <= to <= e.t_end for e in odo.episodes) for to in onsets)
    print(
        f"cycles: {cyc.n} ({args.hours:g} h), injected slips: {len(onsets)}, inside a correction: {hit}, "
        f"episodes: {len(odo.episodes)}"
    )
    print(
        f"correct_odometry (vectorised, full):  {fast * 1e3:8.2f} ms wall (median), {fast_cpu * 1e3:6.2f} ms CPU (min)"
        f"  {cyc.n / fast_cpu:12,.0f} cycles/s"
    )
    print(
        f"naive per-cycle detection front end:  {slow * 1e3:8.2f} ms wall, {slow_cpu * 1e3:8.2f} ms CPU"
        f"  {cyc.n / slow_cpu:12,.0f} cycles/s"
    )
    print(f"ratio naive / vectorised (CPU): {slow_cpu / fast_cpu:,.0f}×   masks identical: {same}")
    print(
        f"machine scale: one np.cumsum over {cyc.n} cycles = {pass_ms:.3f} ms → correct_odometry ≈ "
        f"{fast_cpu * 1e3 / pass_ms:.0f} such passes"
    )
    errs = [(e.d_corrected_m, e.d_pulse_m) for e in odo.episodes]
    print(
        f"fail-safe episodes: {sum(e.failsafe for e in odo.episodes)}; |pulse − corrected| summed over "
        f"{len(errs)} episodes: {sum(abs(p - c) for c, p in errs):.1f} m"
    )


if __name__ == "__main__":
    main()
