"""Benchmark: ``db import --format osm`` of the Cologne railway extract (3,657 switches,
© OpenStreetMap contributors, ODbL 1.0; target ≤ 10 s on one core), printed beside
osmium's own read of the same file — a plain pass with the node location index that counts
the ways and the nodes with a location — as a ratio (what the mapping costs on top of
reading). ``--smoke``: the small VDE 8.2 file, one run (the smoke test runs it).

Run: ``OMP_NUM_THREADS=1 .venv/bin/python bench/bench_osm.py [--smoke] [--file F.osm.pbf]``.
Never fails on timing: it reports.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench._common import best_of, load, verdict
from dbtools.interchange.osm_import import import_osm

DATA = Path(__file__).resolve().parents[1] / "tests" / "data" / "osm"
COLOGNE = DATA / "cologne-railway.osm.pbf"
VDE = DATA / "vde8.2-rail.osm.pbf"
TARGET_S = 10.0


def osmium_read(path: Path) -> tuple[int, int]:
    """osmium alone: (ways, nodes with a location) of one pass with locations."""
    import osmium

    ways = nodes = 0
    for obj in osmium.FileProcessor(str(path)).with_locations():
        if isinstance(obj, osmium.osm.Way):
            ways += 1
        elif isinstance(obj, osmium.osm.Node) and obj.location.valid():
            nodes += 1
    return ways, nodes


def run(path: Path, repeat: int) -> dict[str, float]:
    """Time the import (into a fresh folder each time) and osmium's read; print them."""
    counter = iter(range(1_000_000))
    with tempfile.TemporaryDirectory() as tmp:
        wall, cpu, res = best_of(lambda: import_osm(path, Path(tmp) / f"o{next(counter)}"), repeat)
    rwall, rcpu, (ways, nodes) = best_of(lambda: osmium_read(path), repeat)
    print(f"{path.name}: {ways} ways, {nodes} nodes; {load()}")
    print(f"  osmium read      {rwall:6.2f} s wall {rcpu:6.2f} s CPU")
    print(
        f"  db import (osm)  {wall:6.2f} s wall {cpu:6.2f} s CPU  = {wall / rwall:.1f}× osmium's read"
        f"  {verdict(f'≤ {TARGET_S:g} s', wall <= TARGET_S)}"
    )
    print("  rows: " + ", ".join(f"{k} {v}" for k, v in res.rows.items()))
    return {"import_s": wall, "osmium_s": rwall, "ratio": wall / rwall}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--smoke", action="store_true", help="the small VDE 8.2 file, one run")
    ap.add_argument("--file", type=Path, default=None, help="another .osm.pbf file")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args(argv)
    t0 = time.perf_counter()
    run(a.file or (VDE if a.smoke else COLOGNE), 1 if a.smoke else a.repeat)
    print(f"total {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
