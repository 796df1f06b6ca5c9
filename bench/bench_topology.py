"""Benchmark: the topology and balise-group rules of ``db validate`` on a national-scale
synthetic network (issue 30: ≥ 50,000 tracks must stay cheap).

Run on demand (prints numbers, never pass/fail)::

    .venv/bin/python bench/bench_topology.py                # 1000 lines → 50,000 tracks
    .venv/bin/python bench/bench_topology.py --lines 100 --shared-ids

The network (built in memory, no files): ``--lines`` double-track lines 5 km long, 1.1 km
apart (lat 60°, lon 24°, a flat-earth layout is exact enough for timing). D is split every
250 m, U 60 m further on; at every odd split a crossover (kind crossover, track_points,
straight at atan(4/60) ≈ 1:15) runs from D up to U through two point switches; at the even
splits the segments are joined without a switch. Per line: 20 D + 20 U tracks + 10
crossovers = 50 tracks, 20 switches, 80 connections; a balise group (2 balises) 100 m into
every D and U segment. ``--shared-ids`` gives every line the same group identities, so every
group is a walker of the route walk (the worst case of ``topology.balise_ambiguous``).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np
import pandas as pd

from dbtools.network import Network, canonical, empty_frame
from dbtools.rules.balise_groups import check_balise_network
from dbtools.rules.common import Locator
from dbtools.rules.config import ValidationConfig
from dbtools.rules.topology import check_topology
from schemas.network import NETWORK_TABLES
from schemas.tables import DB_TABLES

M_LAT = 111_412.0
SW_EXTRA = ("diverging_side", "switch_number")  # metres per degree of latitude at 60°N


def build(lines: int, shared_ids: bool) -> Network:
    gis, tracks, conns, switches, points, balises = [], [], [], [], [], []
    km = np.arange(0.0, 5000.0 + 1e-9, 20.0)
    for li in range(lines):
        code = f"L{li:04d}"
        lat0 = 60.0 + li * 1100.0 / M_LAT
        m_lon = M_LAT * math.cos(math.radians(lat0))
        for tr, y in (("D", -2.0), ("U", 2.0)):
            gis.append(
                pd.DataFrame(
                    {"line_code": code, "track": tr, "km_m": km, "lat": lat0 + y / M_LAT, "lon": 24.0 + km / m_lon}
                )
            )
        d_cuts = [250.0 * j for j in range(1, 20)]
        for tr, cuts in (("D", d_cuts), ("U", [c + 60.0 for c in d_cuts])):
            bounds = [0.0, *cuts, 5000.0]
            for s in range(20):
                tid = f"{code}{tr}{s}"
                tracks.append((tid, code, tr, "main", bounds[s], bounds[s + 1], bounds[s + 1] - bounds[s]))
                for i in range(2):
                    nid = (
                        (0, s * 2 + (tr == "U"))
                        if shared_ids
                        else (li % 1000, (li // 1000) * 100 + s * 2 + (tr == "U"))
                    )
                    balises.append((f"{tid}.{i}", code, tr, bounds[s] + 100.0 + 3 * i, tid, *nid, i, 2))
        for j in range(1, 20):
            a, dl, dr, ul, ur = 250.0 * j, f"{code}D{j - 1}", f"{code}D{j}", f"{code}U{j - 1}", f"{code}U{j}"
            if j % 2 == 0:
                conns += [(dl, "end", dr, "begin", "both", None), (ul, "end", ur, "begin", "both", None)]
                continue
            x = f"{code}X{j}"
            length = math.hypot(60.0, 4.0)
            tracks.append((x, None, None, "crossover", None, None, length))
            for p in (0.0, 20.0, 40.0, length):
                f = p / length
                points.append((x, p, lat0 + (-2.0 + 4.0 * f) / M_LAT, 24.0 + (a + 60.0 * f) / m_lon))
            sw_d, sw_u = f"{code}W{j}D", f"{code}W{j}U"
            switches.append((sw_d, "point", dl, "end", x, "begin", dr, "begin", "left", 15.0))
            switches.append((sw_u, "point", ur, "begin", x, "end", ul, "end", "left", 15.0))
            conns += [(dl, "end", x, "begin", "both", sw_d), (dl, "end", dr, "begin", "both", sw_d)]
            conns += [(x, "begin", dr, "begin", "none", sw_d), (ur, "begin", x, "end", "both", sw_u)]
            conns += [(ur, "begin", ul, "end", "both", sw_u), (x, "end", ul, "end", "none", sw_u)]
    t = {tb.name: empty_frame(tb) for tb in DB_TABLES}
    t["gis"] = canonical(next(x for x in DB_TABLES if x.name == "gis"), pd.concat(gis, ignore_index=True))
    frames = {
        "tracks": pd.DataFrame(
            tracks, columns=["track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m"]
        ),
        "connections": pd.DataFrame(
            conns, columns=["track_a", "end_a", "track_b", "end_b", "navigability", "switch_id"]
        ),
        "switches": pd.DataFrame(
            switches,
            columns=["switch_id", "type", "a1_track", "a1_end", "b1_track", "b1_end", "b2_track", "b2_end", *SW_EXTRA],
        ),
        "track_points": pd.DataFrame(points, columns=["track_id", "pos_m", "lat", "lon"]),
    }
    for tb in NETWORK_TABLES:
        t[tb.name] = canonical(tb, frames[tb.name])
    b = pd.DataFrame(
        balises,
        columns=["balise_id", "line_code", "track", "km_actual_m", "track_id", "nid_c", "nid_bg", "n_pig", "n_total"],
    )
    b["kind"], b["km_equipment_m"] = "G", b["km_actual_m"]
    t["balises"] = canonical(next(x for x in DB_TABLES if x.name == "balises"), b)
    return Network(t, origin="bench")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--lines", type=int, default=1000)
    ap.add_argument("--shared-ids", action="store_true")
    args = ap.parse_args()
    t0 = time.perf_counter()
    net = build(args.lines, args.shared_ids)
    t1 = time.perf_counter()
    cfg = ValidationConfig()
    c1, w1 = time.process_time(), time.perf_counter()
    topo = check_topology(net, cfg, Locator())
    c2, w2 = time.process_time(), time.perf_counter()
    bal = check_balise_network(net, cfg, Locator())
    c3, w3 = time.process_time(), time.perf_counter()
    print(
        f"{len(net.tracks)} tracks, {len(net.connections)} connections, {len(net.switches)} switches, "
        f"{len(net.balises)} balises, {len(net.gis)} GIS points (built in {t1 - t0:.1f} s); "
        f"load {os.getloadavg()[0]:.1f}/{os.cpu_count()} cores"
    )
    print(
        f"check_topology       wall {w2 - w1:6.2f} s, CPU {c2 - c1:6.2f} s: {len(topo)} findings "
        f"{sorted({f.rule for f in topo})}"
    )
    print(
        f"check_balise_network wall {w3 - w2:6.2f} s, CPU {c3 - c2:6.2f} s: {len(bal)} findings "
        f"{sorted({f.rule for f in bal})}"
    )


if __name__ == "__main__":
    main()
