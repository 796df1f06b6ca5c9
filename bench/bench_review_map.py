"""Benchmark: size and build time of ``db review``'s interactive network map for a national DB.

Run: ``.venv/bin/python bench/bench_review_map.py [--lines 50] [--length-km 200]``. The
network is :func:`bench.bench_db.national_network` (double-track random alignments, 20 m
grid: lines × 2 × length / 20 m GIS points, 1 M by default). Printed: GIS points, drawn
vertices after the 0.5 m Douglas–Peucker simplification, JSON and HTML sizes, and the time
to build the layers. The naive baseline is every grid point as ``[lat, lon]`` decimals in
the JSON (what an unsimplified GeoJSON-like payload costs). Target (issue 30): the page
stays at a few MB for 1 M points.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lines", type=int, default=50)
    ap.add_argument("--length-km", type=float, default=200.0)
    args = ap.parse_args()
    from bench.bench_db import national_network
    from dbtools.interchange.leaflet_map import map_payload, render_map
    from dbtools.interchange.netmap import COORD_SCALE, map_projector

    t0 = time.perf_counter()
    net = national_network(args.lines, args.length_km * 1000.0)
    t1 = time.perf_counter()
    proj = map_projector(net)
    assert proj is not None
    payload = map_payload(net, proj)
    t2 = time.perf_counter()
    html = render_map(payload)
    t3 = time.perf_counter()
    n_gis = len(net.gis)
    n_drawn = sum(len(t["c"]) // 2 for t in payload["tracks"])
    naive = len(json.dumps([[round(a, 7), round(b, 7)] for a, b in zip(net.gis["lat"], net.gis["lon"], strict=True)]))
    print(f"network: {args.lines} lines x 2 tracks x {args.length_km:g} km, {n_gis:,} GIS points ({t1 - t0:.1f} s)")
    print(f"tracks {len(payload['tracks'])}, km ticks {sum(len(t['km']) for t in payload['ticks'])}")
    print(f"drawn vertices {n_drawn:,} ({n_drawn / n_gis:.1%} of the grid), unit {1 / COORD_SCALE:g} deg")
    print(f"layers built in {t2 - t1:.1f} s, page fragment in {t3 - t2:.2f} s")
    print(f"map fragment {len(html.encode()) / 1e6:.2f} MB (Leaflet itself 0.16 MB)")
    print(f"naive baseline (every point as decimals): {naive / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
