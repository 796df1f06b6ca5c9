"""Benchmark of the 2-frequency CW radar speed meter [S004] (issue 18).

    .venv/bin/python bench/bench_radar.py accuracy [--runs 30] [--workers 1]
    .venv/bin/python bench/bench_radar.py throughput [--hours 1] [--loop-minutes 5]
    .venv/bin/python bench/bench_radar.py process --data FILE.npz --impl vectorised|per-frame|loop

``accuracy`` simulates seeded runs (``tests/fieldlogs/radar/runs.py``: from standstill to
30–100 km/h and back, ballast and slab, under an overpass, cab R, radar looking back,
vibration) on the bundled sample network and compares every frame with the simulator's
truth: |V_G − truth| above 5 km/h (median, p95; targets 0.1 and 0.5 km/h) for the speed
meter, the paper's eq. 2 as published and the naive strongest-line speed; how often the
error is inside 2σ; the delay from motion onset (true speed > 0.5 km/h) to the first
``ok`` frame (target ≤ 1 frame); false speeds at rest; a run at 150 km/h (aliasing: no
``ok`` frame may be wrong by more than 1 km/h).

``throughput`` builds one hour of IF samples (the ~10 s cruise of a simulated run at
60 km/h, repeated in whole frames),
times ``process_if`` on it (target ≤ 36 s: 100× real time), the same processing one frame
per Python iteration, and a minimal per-frame loop with numpy FFTs (peaks and the plain
eq. 2 only), both on ``--loop-minutes`` (scaled). ``process`` runs one implementation on
saved samples (``throughput --save FILE.npz``), for timing whole processes from outside.
Never fails on timing: it reports.
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from dbtools.build import build_db
from dbtools.database import read_network
from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.framing import frame_samples
from fieldlogs.radar.speed import process_frames, process_if
from schemas.enums import RadarStatus
from schemas.radar import RadarParams
from tests.fieldlogs.radar.runs import onset_time, radar_of, simulate_radar_run, truth_at

KMH = 3.6
SAMPLE_SOURCES = Path(__file__).resolve().parents[1] / "dbtools" / "sample_network" / "sources"


def sample_db(tmp: Path) -> Path:
    db = tmp / "net.sqlite"
    build_db(SAMPLE_SOURCES, db, db_version="bench")
    return db


def evaluate(streams: dict[str, Any], params: RadarParams) -> dict[str, Any]:
    """Per-frame comparison of one run with its truth."""
    d = streams["radar_if"]
    res = process_if(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], params)
    c = res.columns
    truth = streams["truth"]
    vt = truth_at(truth, c["t"])
    status = c["status"]
    ok = status == RadarStatus.OK.value
    moving = np.abs(vt) > 5.0 / KMH
    sel = ok & moving
    onset = onset_time(truth)
    frame_of_onset = int(np.searchsorted(c["t"] - params.t_epi_s / 2, onset, side="right") - 1)
    first_ok = int(np.argmax(ok)) if ok.any() else len(ok)
    edges = np.stack([truth_at(truth, c["t"] + dt) for dt in np.linspace(-params.t_epi_s / 2, params.t_epi_s / 2, 7)])
    rest = np.abs(edges).max(axis=0) < 1e-3  # at rest during the whole frame
    return {
        "err": (c["speed_mps"][sel] - vt[sel]) * KMH,
        "eq2": (c["v_eq2_mps"][sel] - vt[sel]) * KMH,
        "naive": (c["v_naive_mps"][sel] - vt[sel]) * KMH,
        "z": (c["speed_mps"][sel] - vt[sel]) / c["sigma_mps"][sel],
        "availability": (int(sel.sum()), int(moving.sum())),
        "delay_frames": first_ok - frame_of_onset,
        "false_at_rest": int((rest & ok & (np.abs(c["speed_mps"]) > 0.3 / KMH)).sum()),
        "standstill_at_rest": (int((rest & (status == RadarStatus.STANDSTILL.value)).sum()), int(rest.sum())),
        "sign_ok": bool(np.all(np.sign(c["speed_mps"][sel]) == np.sign(vt[sel]))),
        "status": {s.value: int((status == s.value).sum()) for s in RadarStatus},
    }


def one(args: tuple[int, str, float | None]) -> dict[str, Any]:
    i, db, top = args
    net = read_network(Path(db))
    streams, meta = simulate_radar_run(i, net, top_kmh=top)
    out = evaluate(streams, radar_of(meta))
    out["i"], out["top_kmh"] = i, float(streams["truth"]["speed_mps"].abs().max() * KMH)
    return out


def _row(name: str, e: np.ndarray) -> str:
    a = np.abs(e)
    return f"  {name:<28} {np.median(a):7.3f} {np.quantile(a, 0.95):7.3f} {np.mean(e):+8.3f} {len(e):7d}"


def accuracy(args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        db = str(sample_db(Path(tmp)))
        jobs = [(i, db, None) for i in range(args.runs)]
        t0 = time.perf_counter()
        if args.workers > 1:
            with ProcessPoolExecutor(args.workers) as ex:
                runs = list(ex.map(one, jobs))
        else:
            runs = [one(j) for j in jobs]
        alias = one((10_000, db, 150.0))
        wall = time.perf_counter() - t0
    cat = {k: np.concatenate([r[k] for r in runs]) for k in ("err", "eq2", "naive", "z")}
    print(f"{args.runs} simulated runs (sample network, seeds 7000+i), frames above 5 km/h with status ok")
    print(f"  {'|V − truth| [km/h]':<28} {'median':>7} {'p95':>7} {'mean':>8} {'frames':>7}")
    print(_row("V_G (eq. 2, refined)", cat["err"]) + "   targets: median ≤ 0.1, p95 ≤ 0.5")
    print(_row("eq. 2 as published", cat["eq2"]))
    print(_row("naive single peak", cat["naive"]))
    got, want = (sum(r["availability"][k] for r in runs) for k in (0, 1))
    print(f"  frames above 5 km/h with a speed: {got}/{want} ({got / max(want, 1):.1%})")
    print(f"  |error| ≤ 2σ: {np.mean(np.abs(cat['z']) <= 2):.1%}, median |z| {np.median(np.abs(cat['z'])):.2f}")
    delays = np.array([r["delay_frames"] for r in runs])
    print(
        f"  first ok frame − frame of motion onset (v > 0.5 km/h): max {delays.max()}, median "
        f"{np.median(delays):.0f} (target ≤ 1); runs over 1 frame: {int((delays > 1).sum())}"
    )
    still = [sum(r["standstill_at_rest"][k] for r in runs) for k in (0, 1)]
    print(
        f"  at rest: standstill {still[0]}/{still[1]} frames, false speeds > 0.3 km/h: "
        f"{sum(r['false_at_rest'] for r in runs)}"
    )
    print(f"  direction sign right in every ok moving frame: {all(r['sign_ok'] for r in runs)}")
    big = np.abs(alias["err"]) > 1.0
    print(f"  150 km/h run: status {alias['status']}; ok frames wrong by > 1 km/h: {int(big.sum())}")
    print(f"  wall time {wall:.0f} s")


# --- throughput -------------------------------------------------------------------------


def hour_of_samples(hours: float) -> tuple[dict[str, np.ndarray], RadarParams]:
    """The cruise (> 55 km/h) of run 0 at 60 km/h, cut to whole frames, repeated to ``hours``."""
    with tempfile.TemporaryDirectory() as tmp:
        net = read_network(sample_db(Path(tmp)))
        streams, meta = simulate_radar_run(0, net, top_kmh=60.0)
    params = radar_of(meta)
    d = streams["radar_if"]
    v = truth_at(streams["truth"], d["t"].to_numpy())
    cruise = np.flatnonzero(np.abs(v) > 55.0 / KMH)
    n = len(cruise) // params.samples_per_frame * params.samples_per_frame
    seg = {c: d[c].to_numpy()[cruise[0] : cruise[0] + n] for c in ("i1", "q1", "i2", "q2")}
    total = int(hours * 3600 * params.sample_rate_hz)
    reps = math.ceil(total / n)
    out = {c: np.tile(x, reps)[:total] for c, x in seg.items()}
    out["t"] = np.arange(total, dtype=np.float64) / params.sample_rate_hz
    return out, params


def loop_process(d: dict[str, np.ndarray], params: RadarParams, cfg: RadarConfig) -> list[float]:
    """The per-frame way: one Python iteration per frame, numpy FFTs, the same steps."""
    n = params.samples_per_frame
    n_fft = 1 << (n - 1).bit_length()
    w = 0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n) / n)
    h, lam = params.height_m, params.wavelength_m
    lo, hi = (math.radians(params.depression_deg + s * 2 * params.beam_elev_deg) for s in (1, -1))
    out = []
    for k in range(len(d["t"]) // n):
        sl = slice(k * n, (k + 1) * n)
        specs, pows, floors = [], [], []
        for a, b in (("i1", "q1"), ("i2", "q2")):
            z = d[a][sl] + 1j * d[b][sl]
            s = np.fft.fft((z - z.mean()) * w, n_fft)
            p = np.abs(s) ** 2
            specs.append(s)
            pows.append(p)
            floors.append(np.median(p) / math.log(2))
        pk = [
            (p > np.roll(p, 1)) & (p >= np.roll(p, -1)) & (p > -math.log(cfg.pfa) * f)
            for p, f in zip(pows, floors, strict=True)
        ]
        pair = pk[0] & (pk[1] | np.roll(pk[1], 1) | np.roll(pk[1], -1))
        pair[: cfg.dc_guard_bins + 1] = False
        pair[-cfg.dc_guard_bins :] = False
        ks = np.flatnonzero(pair)
        amp = np.sqrt(pows[0] + pows[1])
        delta = 2 * (amp[(ks + 1) % n_fft] - amp[ks - 1]) / (amp[ks - 1] + 2 * amp[ks] + amp[(ks + 1) % n_fft])
        fd = (np.where(ks >= n_fft // 2, ks - n_fft, ks) + delta) * params.sample_rate_hz / n_fft
        cross = sum(specs[0][(ks + j) % n_fft] * np.conj(specs[1][(ks + j) % n_fft]) for j in (-1, 0, 1))
        r = params.r_max_m * np.mod(np.angle(cross * np.exp(2j * np.pi * fd * params.t_pri_s)), 2 * np.pi) / (2 * np.pi)
        g = (r >= h / math.sin(lo)) & (r <= h / math.sin(hi))
        u, s2 = (fd[g] * lam / 2) ** 2, (h / r[g]) ** 2
        out.append(float(1 / math.sqrt(np.sum(u * (1 - s2)) / np.sum(u * u))) if g.any() else math.nan)
    return out


def same_per_frame(d: dict[str, np.ndarray], params: RadarParams, cfg: RadarConfig) -> int:
    """The library's own steps, one frame per Python iteration (what vectorising over frames saves)."""
    frames = frame_samples(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], params)
    return sum(len(process_frames(frames.block(k, k + 1), params, cfg)) for k in range(frames.n_frames))


def throughput(args: argparse.Namespace) -> None:
    t0 = time.perf_counter()
    d, params = hour_of_samples(args.hours)
    print(f"IF samples: {args.hours:g} h, {len(d['t']):,} pairs ({time.perf_counter() - t0:.0f} s to build)")
    if args.save:
        np.savez(args.save, params=np.array([params.to_json()], dtype=object), **d)  # type: ignore[arg-type]
        print(f"saved to {args.save}")
    cfg = RadarConfig()
    t0 = time.perf_counter()
    res = process_if(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], params, cfg)
    vec = time.perf_counter() - t0
    real = args.hours * 3600
    print(f"vectorised process_if: {vec:6.2f} s for {len(res)} frames, {real / vec:6.0f}× real time (target ≥ 100×)")
    m = int(args.loop_minutes * 60 * params.sample_rate_hz)
    part = {k: v[:m] for k, v in d.items()}
    scale = real / (args.loop_minutes * 60)
    t0 = time.perf_counter()
    same_per_frame(part, params, cfg)
    same = (time.perf_counter() - t0) * scale
    t0 = time.perf_counter()
    loop_process(part, params, cfg)
    loop = (time.perf_counter() - t0) * scale
    mins = f"{args.loop_minutes:g} min scaled"
    print(f"same processing, one frame per iteration ({mins}): {same:6.2f} s; vectorised {same / vec:.1f}× faster")
    print(
        f"minimal per-frame loop (numpy FFTs, peaks, plain eq. 2 only; {mins}): {loop:6.2f} s; ratio {loop / vec:.1f}×"
    )


def process(args: argparse.Namespace) -> None:
    data = np.load(args.data, allow_pickle=True)
    params = RadarParams(**data["params"][0])
    d = {k: data[k] for k in ("t", "i1", "q1", "i2", "q2")}
    if args.impl == "vectorised":
        print(len(process_if(d["t"], d["i1"], d["q1"], d["i2"], d["q2"], params)))
    elif args.impl == "per-frame":
        print(same_per_frame(d, params, RadarConfig()))
    else:
        print(len(loop_process(d, params, RadarConfig())))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    a = sub.add_parser("accuracy")
    a.add_argument("--runs", type=int, default=30)
    a.add_argument("--workers", type=int, default=1)
    t = sub.add_parser("throughput")
    t.add_argument("--hours", type=float, default=1.0)
    t.add_argument("--loop-minutes", type=float, default=5.0)
    t.add_argument("--save", type=Path, default=None)
    p = sub.add_parser("process")
    p.add_argument("--data", type=Path, required=True)
    p.add_argument("--impl", choices=("vectorised", "per-frame", "loop"), default="vectorised")
    args = ap.parse_args()
    {"accuracy": accuracy, "throughput": throughput, "process": process}[args.cmd](args)


if __name__ == "__main__":
    main()
