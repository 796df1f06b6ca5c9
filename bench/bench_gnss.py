"""Bench of the track-constrained GNSS positioning [S002] (SPEC §5.6, issue 17 phase 1).

(a) The paper's experiment on simulated runs (``fieldlogs.experiments.gnss``): GPS only, the
    west half of the sky blocked, the synthetic 3-D track, two receivers; standalone and with
    D-GPS-level corrections; then a faulty satellite (50 m step, 0.2 m/s ramp) from mid-run;
    and a multi-GNSS run through a mixed corridor (buildings, cuttings, overpasses, tunnels);
    and the paper case with broadcast orbit/clock errors in the truth, standalone and with the
    simulated MSAS stream (``fieldlogs.gnss.sbas``: fast, long-term and grid corrections), and
    with two GEOs (PRN 137 silent 200–400 s, PRN 129's MT 0 at 450 s: ``experiment.two_geo_stream``).
    Printed: constrained availability (status ok + antenna-distance check) against the
    unconstrained one (≥ 4 satellites, PDOP ≤ 6), along-track error of the constrained epochs,
    the share of epochs outside the stated uncertainty, and the fault statistics.
(b) Throughput of the constrained solution per receiver-epoch on one core: the batched solver
    against the straightforward per-epoch implementation (``fieldlogs.gnss.reference``) on the
    same prepared rows, with the agreement of the two.

    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_gnss.py --runs 50
    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_gnss.py --runs 50 --only orbit/clock --skip-throughput
    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_gnss.py --solve-only batched --cache /tmp/rows.pkl

``--solve-only`` times one solver alone on rows cached by a previous run (whole-process timing
by an external tool). Figures: bench/NOTES.md (GNSS).
"""

from __future__ import annotations

import argparse
import os
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fieldlogs.experiments.gnss import ANTENNAS, CaseSpec, _simulate, _solve, _track, run_case, summarise
from fieldlogs.gnss.constrained import STATUS_OK, Rows, solve_constrained
from fieldlogs.gnss.position import receiver_rows
from fieldlogs.gnss.reference import solve_epoch

ROWS: tuple[tuple[str, dict[str, object]], ...] = (
    ("paper: GPS, west half blocked, standalone", {}),
    ("paper: GPS, west half blocked, D-GPS", {"dgps": True}),
    ("  + 50 m step on a used satellite", {"fault": "step"}),
    ("  + 0.2 m/s ramp on a used satellite", {"fault": "ramp"}),
    ("paper case with a 5° elevation mask", {"elevation_mask_deg": 5.0}),
    ("paper case without a prior (search whole track)", {"use_prior": False}),
    ("GPS+Galileo+QZSS, west half + mixed corridor", {"systems": ("G", "E", "J"), "corridor": "mixed"}),
    ("paper + orbit/clock errors, standalone", {"sat_errors": True}),
    ("  same runs + MSAS stream (SBAS, orbit/clock)", {"sbas": True}),
    ("  2 GEOs 137/129 switching (orbit/clock)", {"sbas": True, "two_geos": True}),
)


def _fmt(v: float, pct: bool = False, digits: int = 1) -> str:
    if not np.isfinite(v):
        return "   -  "
    return f"{100 * v:6.{digits}f}%" if pct else f"{v:7.2f}"


def accuracy(runs: int, seed0: int, only: str | None = None) -> None:
    print(f"(a) simulated runs: {runs} seeds from {seed0}, 600 s at 1 Hz, 2 receivers (antennas ±8 m, 3.8 m high)")
    cols: tuple[tuple[str, int], ...] = (("epochs", 7), ("constr", 7), ("unconstr", 8), ("med|e|", 7))
    cols += (("p99|e|", 7), ("max|e|", 7), (">U", 7), ("U med", 7))
    print(f"{'case':46s} " + " ".join(f"{c:>{w}s}" for c, w in cols))
    faults = []
    for label, kw in ROWS:
        if only is not None and only not in label:
            continue
        res = [run_case(CaseSpec(seed0 + i, **kw)) for i in range(runs)]  # type: ignore[arg-type]
        s = summarise(res)
        print(
            f"{label:46s} {int(s['epochs']):7d} {_fmt(s['constrained_availability'], True)} "
            f"{_fmt(s['unconstrained_availability'], True):>8s} {_fmt(s['median_abs_err_m'])} "
            f"{_fmt(s['p99_abs_err_m'])} {_fmt(s['max_abs_err_m'])} {_fmt(s['exceed_fraction'], True, 3)} "
            f"{_fmt(s['median_uncertainty_m'])}"
        )
        if "fault_epochs" in s:
            faults.append((label.strip(" +"), s))
    print()
    print(f"{'fault':40s} {'epochs':>7s} {'avail':>7s} {'kept>=2nd':>9s} {'>U':>7s} {'bias@excl':>9s}")
    for label, s in faults:
        print(
            f"{label:40s} {int(s['fault_epochs']):7d} {_fmt(s['fault_availability'], True)} "
            f"{_fmt(s['fault_not_excluded_after_2_epochs'], True, 2):>9s} {_fmt(s['fault_exceed_fraction'], True, 3)} "
            f"{_fmt(s['fault_bias_at_exclusion_m']):>9s}"
        )
    print(
        "epochs: receiver-epochs after onset with the faulty satellite among >= 3 usable. kept>=2nd: share\n"
        "of those, from the 2nd epoch after the fault first became detectable (bias >= the row's minimal\n"
        "detectable bias), where it is still used in an available solution with its bias >= that MDB.\n"
        "bias@excl: median bias at the first exclusion."
    )


def _collect_rows(runs: int, seed0: int) -> list[tuple[Rows, np.ndarray]]:
    """Prepared rows (one receiver, K = 1) and priors of the paper case, run by run."""
    out: list[tuple[Rows, np.ndarray]] = []
    for i in range(runs):
        spec = CaseSpec(seed=seed0 + i)
        sim, _, _, corr, prior = _simulate(spec)
        res = _solve(sim, sim.obs, spec, corr, prior)
        ep = res.observations
        for name in ANTENNAS:
            sel = np.flatnonzero(ep.receiver == name)
            sub = ep.select(sel)
            ps = np.interp(sub.t_run, prior["t"].to_numpy(float), prior["s_m"].to_numpy(float))
            out.append((receiver_rows(sub, np.ones(sel.size)), ps))
    return out


def _batched(batches: list[tuple[Rows, np.ndarray]]) -> tuple[float, list[np.ndarray]]:
    track = _track().grid
    tic = time.perf_counter()
    sols = [
        solve_constrained(track, rows, [ANTENNAS["rx1"]], prior=(ps, np.full(ps.size, 5.0))).s for rows, ps in batches
    ]
    return time.perf_counter() - tic, sols


def _reference(
    batches: list[tuple[Rows, np.ndarray]], limit: int
) -> tuple[float, int, list[tuple[int, int, float, int]]]:
    from fieldlogs.gnss.constrained import ConstrainedConfig

    track = _track().grid
    cfg = ConstrainedConfig()
    done, out = 0, list[tuple[int, int, float, int]]()
    tic = time.perf_counter()
    for b, (rows, ps) in enumerate(batches):
        for i in range(rows.pr_m.shape[0]):
            if done >= limit:
                return time.perf_counter() - tic, done, out
            r = solve_epoch(
                track, rows.sat_pos[i], rows.pr_m[i], rows.sigma_m[i], rows.omega_e[i], list(rows.usable[i]),
                ANTENNAS["rx1"], 1.0, float(ps[i]), (float(ps[i]), 5.0), cfg,
            )  # fmt: skip
            out.append((b, i, r.s, r.status))
            done += 1
    return time.perf_counter() - tic, done, out


def throughput(runs: int, seed0: int, cache: Path | None) -> None:
    batches = _collect_rows(runs, seed0)
    if cache is not None:
        cache.write_bytes(pickle.dumps(batches))
    n = sum(r.pr_m.shape[0] for r, _ in batches)
    _batched(batches[:1])  # warm the χ² table
    t_b, sols = _batched(batches)
    t_r, n_r, ref = _reference(batches, min(n, 3000))
    diff = [abs(sols[b][i] - s) for b, i, s, st in ref if st == STATUS_OK]
    print(f"(b) throughput, constrained solution (one receiver per batch, {len(batches)} batches of ~600 epochs)")
    print(f"  batched:   {n} receiver-epochs in {t_b:.3f} s = {n / t_b:,.0f} epochs/s")
    print(f"  per-epoch: {n_r} receiver-epochs in {t_r:.3f} s = {n_r / t_r:,.0f} epochs/s")
    print(f"  ratio batched/per-epoch: {(n / t_b) / (n_r / t_r):.1f}x")
    print(f"  max |s_batched - s_per_epoch| over the compared epochs: {max(diff, default=0.0):.2e} m")
    print(f"  load: {os.getloadavg()[0]:.2f} (1-min average, 2 cores shared)")


def solve_only(kind: str, cache: Path) -> None:
    batches = pickle.loads(cache.read_bytes())
    if kind == "batched":
        _batched(batches)
    else:
        _reference(batches, sum(r.pr_m.shape[0] for r, _ in batches))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--seed0", type=int, default=1000)
    ap.add_argument("--throughput-runs", type=int, default=5)
    ap.add_argument("--skip-accuracy", action="store_true")
    ap.add_argument("--skip-throughput", action="store_true")
    ap.add_argument("--only", default=None, help="accuracy rows whose label contains this text (e.g. 'orbit/clock')")
    ap.add_argument("--cache", type=Path, default=None, help="write (or, with --solve-only, read) the prepared rows")
    ap.add_argument("--solve-only", choices=("batched", "reference"), default=None)
    args = ap.parse_args()
    if args.solve_only:
        solve_only(args.solve_only, args.cache)
        return
    if not args.skip_accuracy:
        accuracy(args.runs, args.seed0, args.only)
        print()
    if not args.skip_throughput:
        throughput(args.throughput_runs, args.seed0, args.cache)


if __name__ == "__main__":
    main()
