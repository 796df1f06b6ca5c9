"""bench/bench_osm.py runs (``--smoke``: the VDE 8.2 file, one run) and prints its figures."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def test_bench_osm_smoke() -> None:
    res = subprocess.run(
        [sys.executable, str(ROOT / "bench" / "bench_osm.py"), "--smoke"],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert res.returncode == 0, res.stderr
    assert "osmium read" in res.stdout and "× osmium's read" in res.stdout
    assert "switches 799" in res.stdout
