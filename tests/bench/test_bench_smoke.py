"""Every ``bench/*.py`` still runs: each script at a tiny size in its own process, checked to
exit 0 and to print its table (a header or ratio line of it) — benchmarks rot silently when
nothing runs them (issue 34: ``run_breakdown.py`` named a stage that had moved).

Figures are not checked (a tiny run measures nothing); ``bench/run_all.py`` and the scripts'
full sizes do that. A new script needs an entry in :data:`SMOKE` (a test fails without one).
Optional bench-only dependencies (DuckDB, the ``bench`` extra) may be missing: the scripts
then skip that comparison and still print their table.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "bench"
#: The sample run the scripts that take a run folder read (with the ``sample_db`` fixture).
SAMPLE_RUN = ROOT / "fieldlogs" / "sample_logs" / "sim-d-slips"
#: Modules of bench/ that are not scripts.
NOT_SCRIPTS = {"_causes.py", "_common.py", "_db_bounds.py"}
#: Seconds one script may take before it counts as hung (the slowest takes ~10 s on 2 cores).
TIMEOUT_S = 300.0


@dataclass(frozen=True)
class Smoke:
    """How to run a script tiny, and what its output must show.

    ``args``: the arguments, split at spaces, each of which may name ``{tmp}`` (a fresh
    folder), ``{run}`` (the sample run) and ``{db}`` (the sample DB); ``shows``: regular
    expressions each found in stdout + stderr; ``never``: text that must not appear (a stale
    stage, a failed row)."""

    args: str
    shows: tuple[str, ...]
    never: tuple[str, ...] = ()


SMOKE: dict[str, Smoke] = {
    "accuracy.py": Smoke("--runs 1 --workers 1", (r"\|km error\| ≤ margin\s+\d",)),
    "accuracy_network.py": Smoke(
        "--runs 4 --raw-runs 1 --workers 1",
        (
            r"wrong-track claims \(determined cycles\)\s+\d",
            r"selectivity D-GPS\s+[\d.]+ %",
            r"not selected, by cause\s+\S",
            r"unresolved, by reason .*resolved where evidence was possible: \S+( %)? of \d+",
            r"raw GNSS: runs\s+1 ",
            r"median by track_gnss \(raw-GNSS fits\)\s+\S+ m \(n=\d+\)",
        ),
    ),
    "bench_audit.py": Smoke(
        "--runs 2 --workers 1 --no-dask",
        (r"speed-up [\d.]+×", r"1 workers / 1 worker, 2 runs: slowest round [\d.]+× \(target ≥ 1×\): (met|not met)"),
    ),
    "bench_db.py": Smoke(
        "--lines 2 --length-m 2000 --rounds 1 --processes 1",
        (
            r"db build\s+[\d.]+ s wall",
            r"checked fast build: DuckDB not installed|db build vs the fastest path",
            r"bounds: DuckDB not installed|db validate / bound: CPU [\d.]+× \(target ≤ 1\.5×\): (met|not met)",
        ),
    ),
    "bench_engine.py": Smoke(
        "--rounds 1 --runs 1",
        (
            r"line runs on the network DB / on the line-only DB: median [\d.]+× \(target ≤ 1\.3×\): (met|not met)",
            r"sim-net-station\s+[\d.]+ s CPU",
        ),
    ),
    "bench_gis_verify.py": Smoke(
        "--lines 1 --length-km 3 --runs 2 --variants 1 --defects 1 --workers 1 --sizes 2 --seeds 1 "
        "--throughput-fixes 10000",
        (r"recall, all stretches",),
    ),
    "bench_gnss.py": Smoke(
        "--runs 1 --throughput-runs 1 --only elevation", (r"5° elevation mask", r"ratio batched/per-epoch: [\d.]+x")
    ),
    "bench_gnss_fde.py": Smoke("--runs 1", (r"fault\s+epochs\s+detect",)),
    "bench_gnss_pipeline.py": Smoke("--runs 1", (r"GNSS aid on\n",)),
    "bench_impact.py": Smoke("--copies 1 --pairs 1", (r"speed of db impact / speed of two audits",)),
    "bench_import.py": Smoke(
        "--nmea-hours 0.01 --imu-hours 0.01 --rinex-hours 0.01 --georinex-minutes 0.1 --ubx-hours 0.01",
        (r"NMEA .*→ ×[\d.]+", r"RINEX .*→ ×[\d.]+"),
    ),
    "bench_logs.py": Smoke("--hours 0.1 --repeat 1", (r"ours / fastest",)),
    "bench_track_match.py": Smoke(
        "--lines 2 --per-line 50 --repeat 1",
        (r"ratio track match / nearest-track: [\d.]+×", r"fixes/s CPU \(target ≥ 50,000 fixes/s\): (met|not met)"),
    ),
    "bench_matching.py": Smoke(
        "--lines 2 --points 200 --fixes 1000 --loop-fixes 100 --repeat 1",
        (r"ratios: ours / loop = [\d.]+×", r"numpy twin .* fixes/s CPU; frames equal: True"),
    ),
    "bench_odometry.py": Smoke("--hours 0.1 --slips 2 --repeat 1", (r"ratio naive / vectorised \(CPU\): [\d.]+×",)),
    "bench_osm.py": Smoke(
        "--smoke", (r"osmium read", r"× osmium.s read\s+\(target ≤ 10 s\): (met|not met)", r"switches \d+")
    ),
    "bench_outputs.py": Smoke("--hours 0.1", (r"writing [\d.]+ %",)),
    "bench_pipeline.py": Smoke("--hours 0.1", (r"pipeline: .*× real time",)),
    "bench_possession.py": Smoke("--runs 5", (r"kind\s+sky\s+runs",)),
    "bench_radar.py": Smoke("throughput --hours 0.01 --loop-minutes 0.1", (r"vectorised [\d.]+× faster",)),
    "bench_radar_pipeline.py": Smoke("--runs 1 --workers 1 --short-m 300", (r"\|km error\| ≤ margin\s+with radar",)),
    "bench_review_map.py": Smoke("--lines 2 --length-km 5", (r"drawn vertices \d+", r"map fragment [\d.]+ MB")),
    "bench_run.py": Smoke(
        "--hours 0.05 --repeat 1 --breakdown",
        (
            r"trainpos run, .* parquet .*× real time \(target ≥ 2,000×\): (met|not met)",
            r"where one csv run's time goes",
            r"engine \(run_aids\)\s+[\d.]+",
        ),
        ("stages never called",),
    ),
    "bench_scaling.py": Smoke(
        "--hours 0.05 0.1", (r"log-log slope of CPU time on run length: [\d.]+ \(target ≤ 1\.05\): (met|not met)",)
    ),
    "bench_simulate.py": Smoke("--km 3 --slice 100 --repeat 1", (r"naive loop .* → ×\d+",)),
    "bench_topology.py": Smoke(
        "--lines 2 --shared-ids", (r"check_topology\s+wall\s+[\d.]+ s", r"check_balise_network\s+wall")
    ),
    "bench_startup.py": Smoke("--repeat 1 --only run", (r"trainpos --help: [\d.]+ s wall",)),
    "bench_survey.py": Smoke("--lines 1 --length-km 12 --runs 1 --workers 1", (r"metric\s+value\s+target",)),
    "calibration_faults.py": Smoke("clean", (r"clean\s+determined\s+\d+\s+within margin",)),
    "clock_noise.py": Smoke("--runs 1 --workers 1", (r"imu: n 1, error mean",)),
    "run_all.py": Smoke(
        "--only simulate --out {tmp}/RESULTS.md", (r"per simulated hour", r"wrote .*RESULTS\.md"), ("FAILED",)
    ),
    "run_breakdown.py": Smoke(
        "{run} --db {db} --out {tmp}/out",
        (r"phase\s+wall s\s+CPU s", r"engine \(run_aids\)\s+[\d.]+", r"total \(from the script first line\)"),
        ("stages never called",),
    ),
    "slip_margin_scan.py": Smoke(
        "--route-seeds 1 --draw-seeds 31 --runs 1 --workers 1",
        (r"route 0420-U2…D6, IMU-only: runs\s+1", r"wrong-track claims\s+\d+ runs, \d+ cycles"),
    ),
    "slip_study.py": Smoke("--runs 1 --workers 1 --show none", (r"detected \d+/\d+",)),
    "stage_memory.py": Smoke("{run} {db}", (r"correct_odometry\s+RSS",)),
    "wheel_gnss_errors.py": Smoke("{run} --db {db} --workers 1", (r"run\s+z\s+err%",)),
    "units.py": Smoke(
        "--runs 2 --workers 1",
        (r"honest: runs with units_disagree\s+\d+ / 2", r"no correction: runs with units_disagree\s+\d"),
    ),
}

SCRIPTS = sorted(p.name for p in BENCH.glob("*.py") if p.name not in NOT_SCRIPTS)


def test_every_bench_script_has_a_smoke_entry() -> None:
    missing = [s for s in SCRIPTS if s not in SMOKE]
    gone = sorted(set(SMOKE) - set(SCRIPTS))
    assert not missing, f"bench scripts without a SMOKE entry (add their tiny-size arguments): {missing}"
    assert not gone, f"SMOKE entries for scripts that no longer exist: {gone}"


@pytest.mark.parametrize("script", SCRIPTS)
def test_bench_script_runs_at_a_tiny_size(script: str, tmp_path: Path, sample_db: Path) -> None:
    smoke = SMOKE.get(script)
    if smoke is None:
        pytest.fail(f"bench/{script} has no SMOKE entry (its tiny-size arguments)")
    args = [a.format(tmp=tmp_path, run=SAMPLE_RUN, db=sample_db) for a in smoke.args.split()]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONPATH": str(ROOT)}
    cwd = tmp_path / "cwd"  # a script writing where it runs writes here, not into the repository
    cwd.mkdir()
    proc = subprocess.run(
        [sys.executable, str(BENCH / script), *args],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=TIMEOUT_S,
        check=False,
    )
    out = proc.stdout + proc.stderr
    where = f"bench/{script} {' '.join(args)}"
    assert proc.returncode == 0, f"{where} exited {proc.returncode}:\n{out[-3000:]}"
    missing = [p for p in smoke.shows if not re.search(p, out)]
    assert not missing, f"{where} did not print {missing}:\n{out[-3000:]}"
    found = [t for t in smoke.never if t in out]
    assert not found, f"{where} printed {found}:\n{out[-3000:]}"
