"""Wrong-track claims and margin violations around slip/slide corrections on the network sample.

    .venv/bin/python bench/slip_margin_scan.py [--route-seeds 200] [--draw-seeds 31 32 33]
        [--runs 100] [--workers 2]

Two families of seeded runs, each simulated (``simulate_run``) and replayed (``run_pipeline``):

* **route**: the route 0420-U2 → U3 → U4 → X2 → D5 → D6 at 60 km/h, IMU-only (no GPS), the
  scenario seeds 0 … ``--route-seeds`` − 1 — seed 2 is the case of bench/NOTES.md,
  "Slip margin": a slide whose correction started on sliding pulses (θ̄ clipped, no start
  point found) claimed the wrong track for 29 cycles;
* **draws**: ``--runs`` routes of ``bench/accuracy_network.py`` (its four GNSS conditions) for
  each draw seed of ``--draw-seeds``.

Printed per family: runs, runs with a wrong-track claim and the claimed cycles on the wrong
track (:func:`~fieldlogs.pipeline.track_truth.compare_tracks`), runs with determined cycles whose
|km error| exceeds the margin and those cycles
(:func:`~fieldlogs.pipeline.truth.compare_with_truth`), the slip/slide episodes and those
whose start point was not adhering (``SlipEpisode.start_trusted`` false: |θ̄| beyond
arcsin(Ta/G), or none found and the look-back point itself flagged), their kinds (slip, slide)
and those labelled opposite to the simulated episodes they overlap (``t_start`` ≤ t1 + 3 s,
``t_end`` ≥ t0 − 1 s, as ``bench/accuracy.py`` matches them; an episode overlapping injected
ones of both kinds is not counted), the determined cycles, the allowance the fail-safe watches
added (``FailsafeWatch.allowance_m``), and the runs with a finding.
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench._common import over_network_runs, print_rows
from bench.accuracy_network import CONDITIONS, with_condition
from dbtools.database import read_network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.track_truth import compare_tracks
from fieldlogs.pipeline.truth import compare_with_truth
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.enums import PositionState

#: The route of the case (module docstring).
ROUTE = ("0420-U2", "0420-U3", "0420-U4", "0420-X2", "0420-D5", "0420-D6")


def route_scenario(seed: int) -> dict[str, Any]:
    """The route family's scenario of ``seed`` (module docstring)."""
    return {
        "name": f"slip-margin-{seed}",
        "seed": seed,
        "run": {"run_id": f"SM{seed:04d}"},
        "running": {"line_speed_kmh": 60.0},
        "network": {"tracks": list(ROUTE), "points": [[ROUTE[0], 300.0], [ROUTE[-1], 600.0]]},
        "sensors": {"gps": False},
    }


def judge(i: int, db: str, tmp: str, sc: dict[str, Any], cfg: dict[str, Any]) -> dict[str, Any]:
    """Simulate, replay and count the findings of scenario ``sc`` (run ``i``)."""
    net = read_network(Path(db))
    streams, meta = simulate_run(net, scenario_from_dict(sc, source=sc["name"]))
    folder = Path(tmp) / f"scan{i:05d}"
    write_run(folder, meta, streams, force=True)
    res = run_pipeline(read_run(folder), net, PipelineConfig.from_dict(cfg))
    truth = streams["truth"]
    tc = compare_tracks(res.positions, truth, net)
    cmp = compare_with_truth(res.positions, truth)
    det = res.positions["state"].to_numpy(dtype=object) == PositionState.DETERMINED.value
    outside = ~cmp["within_margin"].to_numpy(dtype=bool)
    eps = res.odometry.episodes
    injected = meta.extra["sim_truth"]["slip_episodes"]
    return {
        "name": sc["name"],
        "wrong": int(tc["wrong"].sum()),
        "over": int((det & outside).sum()),
        "over_claimed": int(outside.sum()),
        "episodes": len(eps),
        "untrusted": sum(1 for e in eps if not e.start_trusted),
        "slides": sum(1 for e in eps if e.kind == "slide"),
        "determined": int(det.sum()),
        "watch_m": sum(e.watch.allowance_m for e in eps if e.watch is not None),
        "mislabelled": sum(1 for e in eps if _mislabelled(e, injected)),
    }


def _mislabelled(ep: Any, injected: list[dict[str, Any]]) -> bool:
    """``ep`` overlaps simulated episodes (module docstring), all of the other kind."""
    kinds = {e["kind"] for e in injected if ep.t_end >= e["t0"] - 1.0 and ep.t_start <= e["t1"] + 3.0}
    return len(kinds) == 1 and ep.kind not in kinds


def route_job(args: tuple[Any, ...]) -> dict[str, Any]:
    """``judge`` of job ``(i, db, tmp, seed)`` of the route family."""
    i, db, tmp, seed = args
    return judge(i, db, tmp, route_scenario(seed), {})


def draw_job(args: tuple[Any, ...]) -> dict[str, Any]:
    """``judge`` of job ``(i, db, tmp, run)`` of a draw: ``bench/accuracy_network.py``'s conditions."""
    i, db, tmp, run = args
    condition = CONDITIONS[i % len(CONDITIONS)]
    no_imu = {"imu_max_margin_m": 1e-9, "feature_headings": False}
    out = judge(
        i, db, tmp, with_condition(run, condition, i), {"track_select": no_imu} if condition == "balise-only" else {}
    )
    return {**out, "name": f"{run['name']} ({condition})"}


def route_family(seeds: int, workers: int) -> list[dict[str, Any]]:
    """The route family over scenario seeds 0 … ``seeds`` − 1."""
    import tempfile

    from dbtools.build import build_db
    from dbtools.sample_network import sample_network_source_dir

    with tempfile.TemporaryDirectory() as tmpd:
        db = Path(tmpd) / "net.sqlite"
        build_db(sample_network_source_dir(), db)
        with ProcessPoolExecutor(workers) as pool:
            return list(pool.map(route_job, [(s, str(db), tmpd, s) for s in range(seeds)]))


def rows(label: str, results: list[dict[str, Any]]) -> list[tuple[str, str]]:
    """The printed figures of one family."""
    wrong = [r for r in results if r["wrong"]]
    over = [r for r in results if r["over"]]
    found = sorted({r["name"] for r in wrong + over + [r for r in results if r["over_claimed"]]})
    eps = sum(r["episodes"] for r in results)
    slides = sum(r["slides"] for r in results)
    return [
        (f"{label}: runs", str(len(results))),
        ("  wrong-track claims", f"{len(wrong)} runs, {sum(r['wrong'] for r in results)} cycles"),
        ("  determined |km error| > margin", f"{len(over)} runs, {sum(r['over'] for r in results)} cycles"),
        (
            "  claimed |km error| > margin",
            f"{sum(r['over_claimed'] > 0 for r in results)} runs, "
            f"{sum(r['over_claimed'] for r in results)} cycles (uncertain included; ambiguous by its km)",
        ),
        ("  slip/slide episodes", f"{eps}, {sum(r['untrusted'] for r in results)} from a start that was not adhering"),
        (
            "  kinds",
            f"{eps - slides} slip, {slides} slide; {sum(r['mislabelled'] for r in results)} labelled opposite to "
            "the simulated episode",
        ),
        (
            "  determined cycles; fail-safe watches' allowance",
            f"{sum(r['determined'] for r in results)}; {sum(r['watch_m'] for r in results):.0f} m",
        ),
        ("  runs with a finding", ", ".join(found[:12]) + (" …" if len(found) > 12 else "") if found else "none"),
    ]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--route-seeds", type=int, default=200)
    ap.add_argument("--draw-seeds", type=int, nargs="*", default=[31, 32, 33])
    ap.add_argument("--runs", type=int, default=100)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    t0 = time.perf_counter()
    out = rows("route 0420-U2…D6, IMU-only", route_family(args.route_seeds, args.workers))
    for seed in args.draw_seeds:
        results, _ = over_network_runs(draw_job, args.runs, seed, args.workers)
        out += rows(f"accuracy_network draw, seed {seed}", results)
    print(f"slip margin scan on the network sample ({time.perf_counter() - t0:.1f} s wall)")
    print_rows(out)


if __name__ == "__main__":
    main()
