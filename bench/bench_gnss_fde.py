"""Fault detection and exclusion of the track-constrained GNSS solution on seeded runs [S002].

The cases of ``bench_gnss.py``'s paper rows (GPS, west half of the sky blocked, standalone,
two receivers; ``fieldlogs.experiments.gnss``): clean, a 50 m step and a 0.2 m/s ramp on the
satellite the clean solution uses most, from mid-run, in every receiver. Printed per case:

* epochs: receiver-epochs after onset with the faulty satellite among ≥ 3 usable;
* detectable: those where its bias has reached the row's minimal detectable bias (or it is excluded);
* latency: epochs from the first detectable epoch to the first exclusion, per receiver
  (median / max; a receiver never excluding it is counted apart);
* kept: from the 2nd detectable epoch on, epochs where it is still used in an available
  solution with its bias ≥ that MDB (the issue's target: 0);
* >U: available fault epochs whose along-track error exceeds the stated uncertainty;
* clean runs: the constrained availability, the receiver-epochs with any satellite excluded
  or flagged by the code-carrier divergence monitor (all false: nothing is faulty there), and
  the distribution of the monitor's statistic.

    OMP_NUM_THREADS=1 nice -n 5 .venv/bin/python bench/bench_gnss_fde.py --runs 50

Figures: bench/NOTES.md (GNSS fault detection).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fieldlogs.experiments.gnss import CaseResult, CaseSpec, _simulate, run_case, summarise
from fieldlogs.gnss.observables import carrier_smoothed


def _divergence(seed: int) -> np.ndarray:
    """|code-carrier divergence| of every row of a clean simulated run (the monitor's input)."""
    sim = _simulate(CaseSpec(seed))[0]
    d = carrier_smoothed(sim.obs)["divergence_mps"].to_numpy(float)
    return np.abs(d[np.isfinite(d)])


def _fault_table(res: list[CaseResult]) -> dict[str, float]:
    tb = pd.concat([r.epochs.assign(run=i) for i, r in enumerate(res)], ignore_index=True)
    f = tb[tb["fault_present"].fillna(False).astype(bool) & tb["fault_usable3"].fillna(False).astype(bool)]
    det = f[f["fault_detectable_epoch"] >= 0]
    late = f[f["fault_detectable_epoch"] >= 1]
    kept = late["ok"] & ~late["fault_excluded"].astype(bool) & (late["fault_bias_m"] >= late["fault_mdb_m"])
    lat = []
    never = 0
    for _, g in det.groupby(["run", "receiver"]):
        ex = g[g["fault_excluded"].astype(bool)]
        if ex.empty:
            never += 1
        else:
            lat.append(float(ex["fault_detectable_epoch"].min()))
    return {
        "epochs": float(len(f)),
        "detectable": float(len(det)),
        "latency_median": float(np.median(lat)) if lat else np.nan,
        "latency_max": float(np.max(lat)) if lat else np.nan,
        "never": float(never),
        "kept": float(kept.sum()),
        "kept_share": float(kept.mean()) if len(late) else np.nan,
        "exceeds": float(f["exceeds"].sum()),
        "available": float(f["ok"].mean()) if len(f) else np.nan,
        "bias_at_exclusion": summarise(res)["fault_bias_at_exclusion_m"],
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=50)
    ap.add_argument("--seed0", type=int, default=1000)
    a = ap.parse_args(argv)
    print(f"{a.runs} seeds from {a.seed0}: GPS, west half blocked, standalone, 600 s at 1 Hz, 2 receivers")
    clean = [run_case(CaseSpec(a.seed0 + i)) for i in range(a.runs)]
    s = summarise(clean)
    tb = pd.concat([r.epochs for r in clean], ignore_index=True)
    excl = tb["n_excluded"] > 0
    div = tb["n_divergence"] > 0 if "n_divergence" in tb.columns else excl & False
    print(
        f"clean: {int(s['epochs'])} receiver-epochs, constrained {100 * s['constrained_availability']:.1f} %, "
        f"unconstrained {100 * s['unconstrained_availability']:.1f} %, receiver-epochs with an exclusion "
        f"{int(excl.sum())} ({int(tb['n_excluded'].sum())} satellite exclusions), "
        f"outside U {int(tb['exceeds'].sum())}; with a code-carrier divergence flag {int(div.sum())} "
        f"({int(tb['n_divergence'].sum()) if 'n_divergence' in tb.columns else 0} rows)"
    )
    div = np.concatenate([_divergence(a.seed0 + i) for i in range(a.runs)])
    print(
        f"clean code-carrier divergence (100 s fit, all rows with a full window): {div.size} rows, "
        f"|d| p50 {np.percentile(div, 50):.4f}, p99.9 {np.percentile(div, 99.9):.4f}, max {div.max():.4f} m/s"
    )
    head = (("epochs", 7), ("detect", 7), ("lat med", 7), ("lat max", 7), ("never", 5), ("kept", 5), ("kept%", 7))
    head += ((">U", 4), ("avail", 7), ("bias@ex", 7))
    print(f"{'fault':6s} " + " ".join(f"{c:>{w}s}" for c, w in head))
    for fault in ("step", "ramp"):
        res = [run_case(CaseSpec(a.seed0 + i, fault=fault)) for i in range(a.runs)]
        f = _fault_table(res)
        print(
            f"{fault:6s} {int(f['epochs']):7d} {int(f['detectable']):7d} {f['latency_median']:7.0f} "
            f"{f['latency_max']:7.0f} {int(f['never']):5d} {int(f['kept']):5d} {100 * f['kept_share']:6.2f}% "
            f"{int(f['exceeds']):4d} {100 * f['available']:6.1f}% {f['bias_at_exclusion']:7.2f}"
        )
    print(
        "latency: epochs from the first detectable one to the first exclusion (per receiver); kept: from the\n"
        "2nd detectable epoch on, used in an available solution with bias >= MDB; bias@ex: median true bias\n"
        "(0.2 m/s x time since onset, or 50 m) at the first exclusion."
    )


if __name__ == "__main__":
    main()
