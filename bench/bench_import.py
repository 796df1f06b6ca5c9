"""Benchmark: ``logs import`` of 10 h of 1 Hz NMEA, 10 h of 100 Hz IMU CSV and 1 h of 1 Hz
multi-GNSS RINEX 3 (target ≤ 5 s each on one core), against the parser library alone;
also 1 h of UBX (NAV-PVT, RAWX, 100 Hz ESF-RAW; no target) against pyubx2.

Run: ``OMP_NUM_THREADS=1 .venv/bin/python bench/bench_import.py``. The files are made first
(not timed) by this project's writers. For each it prints the reader's time, the whole
import (reader + run folder written as Parquet), the throughput, and the ratio against
the library alone reading the same file: pynmea2 (``pynmea2.parse`` per sentence, checksum
on, keeping the GGA fields), pyubx2 (``UBXReader`` over every frame), pyarrow's CSV reader
(what the importer itself uses, so the ratio shows the mapping's cost), georinex
(``georinex.load``; on a slice of ``--georinex-minutes`` of the same file, scaled
linearly, since it takes minutes for the hour). Never fails on timing: it reports.

For whole-process timings from outside (noisy shared machines): ``--make DIR`` writes the
inputs once, ``--one KIND --dir DIR`` runs a single import (nmea, csv, rinex, ubx,
rinex-slice) or a single library read (pynmea2, pyarrow, georinex-slice, pyubx2).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np
import pandas as pd

from fieldlogs.recorders.importer import decode, import_run
from fieldlogs.recorders.nmea import write_nmea
from fieldlogs.recorders.rinex_obs import write_rinex_obs
from fieldlogs.recorders.timebase import iso_to_gps

T0 = iso_to_gps("2026-12-01T00:00:00+00:00")
#: satellites per system and their signals (a multi-GNSS receiver, open sky)
CONSTELLATION = {
    "G": (10, ("C1C", "C2L", "C5Q")),
    "E": (8, ("C1C", "C5Q", "C7Q")),
    "J": (3, ("C1C", "C5Q")),
    "R": (7, ("C1C", "C2C")),
}
VEHICLE = """vehicle_id = "BENCH"
vehicle_kind = "train"
length_m = 20.0
reference = "centre"
front_x_m = 10.0
tacho_axle = "A1"
[[antennas]]
id = "a1"
receiver = "rx"
x_m = 7.0
y_m = 0.0
z_m = 3.8
[[axles]]
id = "A1"
x_m = 8.5
wheel_diameter_m = 0.86
teeth = 90
"""
IMU_MAPPING = """stream = "imu"
[time]
column = "t_ms"
unit = "ms"
base = "relative"
start = "2026-12-01T00:00:00+00:00"
[columns]
ax = "acc_x"
ay = "acc_y"
az = "acc_z"
wx = "gyr_x"
wy = "gyr_y"
wz = "gyr_z"
[units]
ax = "g"
ay = "g"
az = "g"
wx = "deg/s"
wy = "deg/s"
wz = "deg/s"
[axes]
x = "+x"
y = "-y"
z = "-z"
"""


def make_nmea(path: Path, hours: float) -> int:
    n = int(hours * 3600)
    k = np.arange(n, dtype=float)
    gps = pd.DataFrame(
        {
            "gnss_time_s": T0 + k,
            "lat": 35.9 + 1e-5 * np.sin(k / 300.0),
            "lon": 139.4 + 1e-6 * k,
            "fix": 2,
            "nsat": 12,
            "hdop": 0.8,
            "height_m": 40.0,
            "speed_mps": 15.0,
            "course_deg": 90.0,
            "sigma_lat_m": 0.4,
            "sigma_lon_m": 0.3,
            "sigma_height_m": 0.8,
        }
    )
    return write_nmea(gps, path)


def make_imu_csv(path: Path, hours: float) -> int:
    import pyarrow as pa
    import pyarrow.csv as pcsv

    n = int(hours * 3600 * 100)
    rng = np.random.default_rng(3)
    cols = {"t_ms": np.arange(n) * 10.0}
    for c, mean in (("acc_x", 0.01), ("acc_y", 0.0), ("acc_z", -1.0), ("gyr_x", 0.0), ("gyr_y", 0.0), ("gyr_z", 0.0)):
        cols[c] = np.round(mean + 0.01 * rng.standard_normal(n), 5)
    pcsv.write_csv(pa.table(cols), path)
    return n


def _obs(hours: float) -> pd.DataFrame:
    n = int(hours * 3600)
    sats = [(f"{s}{i + 1:02d}", sig) for s, (count, sig) in CONSTELLATION.items() for i in range(count)]
    per = [(sat, sig) for sat, sigs in sats for sig in sigs]
    k = np.repeat(np.arange(n, dtype=float), len(per))
    sat = np.tile([p[0] for p in per], n)
    obs = pd.DataFrame(
        {
            "gnss_time_s": T0 + k,
            "receiver": "rx",
            "sat": sat,
            "signal": np.tile([p[1] for p in per], n),
            "pseudorange_m": 2.2e7 + 700.0 * k + 1000.0 * np.tile(np.arange(len(per)), n),
            "carrier_cycles": 1.15e8 + 3678.25 * k,
            "doppler_hz": -700.125 + 0.01 * k,
            "cn0_dbhz": 44.0,
            "lli": pd.array(np.zeros(len(k), dtype=np.int64), dtype="Int64"),
        }
    )
    return obs


def make_rinex(path: Path, hours: float) -> int:
    obs = _obs(hours)
    write_rinex_obs(obs, path)
    return len(obs)


def timed(fn: Callable[[], Any], repeat: int = 3) -> tuple[float, Any]:
    best, out = float("inf"), None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def pynmea2_alone(path: Path) -> int:
    """pynmea2 per sentence (checksum on), keeping the GGA fields the gps stream needs."""
    import pynmea2

    rows = []
    with path.open(encoding="ascii") as fh:
        for line in fh:
            m = pynmea2.parse(line.strip(), check=True)
            if m.sentence_type == "GGA":
                rows.append((m.timestamp, m.latitude, m.longitude, m.gps_qual, m.num_sats, m.horizontal_dil))
    return len(rows)


def pyubx2_alone(path: Path) -> int:
    from pyubx2 import UBXReader

    n = 0
    with path.open("rb") as fh:
        for _, _msg in UBXReader(fh, protfilter=2):
            n += 1
    return n


def make_ubx(path: Path, hours: float) -> int:
    """1 Hz NAV-PVT/HPPOSLLH/DOP, 1 Hz RXM-RAWX of the multi-GNSS set, 100 Hz ESF-RAW."""
    from fieldlogs.recorders.ubx import write_ubx

    n = int(hours * 3600)
    k = np.arange(n, dtype=float)
    gps = pd.DataFrame(
        {
            "gnss_time_s": T0 + k,
            "lat": 35.9,
            "lon": 139.4 + 1e-6 * k,
            "fix": 2,
            "nsat": 12,
            "hdop": 0.8,
            "height_m": 40.0,
            "speed_mps": 15.0,
            "course_deg": 90.0,
        }
    )
    ti = T0 + np.arange(0.0, n, 0.01)
    imu = pd.DataFrame({"gnss_time_s": ti, "ax": 0.1, "ay": 0.0, "az": 9.8, "wx": 0.0, "wy": 0.0, "wz": 0.01})
    return write_ubx(path, gps=gps, obs=_obs(hours), imu=imu)


def pyarrow_alone(path: Path) -> int:
    import pyarrow.csv as pcsv

    return int(pcsv.read_csv(path, read_options=pcsv.ReadOptions(use_threads=False)).num_rows)


def georinex_alone(path: Path) -> int:
    import georinex

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ds = georinex.load(path, fast=True)
    return int(ds.sizes["time"])


def rinex_slice(src: Path, dst: Path, minutes: float) -> float:
    """The first ``minutes`` of an observation file; returns the fraction of its epochs."""
    lines = src.read_text().splitlines()
    head = next(i for i, ln in enumerate(lines) if "END OF HEADER" in ln) + 1
    epochs = [i for i in range(head, len(lines)) if lines[i].startswith(">")]
    keep = int(minutes * 60)
    end = epochs[keep] if keep < len(epochs) else len(lines)
    dst.write_text("\n".join(lines[:end]) + "\n")
    return min(1.0, keep / len(epochs))


def row(name: str, size_mb: float, records: int, t_read: float, t_import: float, t_lib: float, lib: str) -> None:
    print(
        f"{name:<24} {size_mb:8.1f} MB {records:>10,} rec   read {t_read:6.2f} s ({records / t_read / 1e6:5.2f} M/s, "
        f"{size_mb / t_read:6.1f} MB/s)   import {t_import:6.2f} s {'ok' if t_import <= 5.0 else 'OVER 5 s'}   "
        f"{lib} {t_lib:7.2f} s → ×{t_lib / t_read:.1f}"
    )


ONE = {
    "nmea": lambda d: import_run([d / "rx.nmea"], d / "out", vehicle=d / "vehicle.toml", force=True),
    "csv": lambda d: import_run(
        [d / "imu.csv"], d / "out", mapping=[d / "imu.toml"], vehicle=d / "vehicle.toml", force=True
    ),
    "rinex": lambda d: import_run([d / "rx.obs"], d / "out", vehicle=d / "vehicle.toml", force=True),
    "ubx": lambda d: import_run([d / "rx.ubx"], d / "out", vehicle=d / "vehicle.toml", force=True),
    "pynmea2": lambda d: pynmea2_alone(d / "rx.nmea"),
    "pyarrow": lambda d: pyarrow_alone(d / "imu.csv"),
    "georinex-slice": lambda d: georinex_alone(d / "slice.obs"),
    "rinex-slice": lambda d: import_run([d / "slice.obs"], d / "out", vehicle=d / "vehicle.toml", force=True),
    "pyubx2": lambda d: pyubx2_alone(d / "rx.ubx"),
}


def make_all(d: Path, args: argparse.Namespace) -> None:
    d.mkdir(parents=True, exist_ok=True)
    (d / "vehicle.toml").write_text(VEHICLE)
    (d / "imu.toml").write_text(IMU_MAPPING)
    make_nmea(d / "rx.nmea", args.nmea_hours)
    make_imu_csv(d / "imu.csv", args.imu_hours)
    make_rinex(d / "rx.obs", args.rinex_hours)
    rinex_slice(d / "rx.obs", d / "slice.obs", args.georinex_minutes)
    make_ubx(d / "rx.ubx", args.ubx_hours)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--make", type=Path, help="only write the input files into this folder, then exit")
    ap.add_argument("--one", choices=sorted(ONE), help="one import (or one library read) of the files in --dir")
    ap.add_argument("--dir", type=Path, help="folder written by --make (with --one)")
    ap.add_argument("--nmea-hours", type=float, default=10.0)
    ap.add_argument("--imu-hours", type=float, default=10.0)
    ap.add_argument("--rinex-hours", type=float, default=1.0)
    ap.add_argument("--georinex-minutes", type=float, default=3.0)
    ap.add_argument("--ubx-hours", type=float, default=1.0)
    args = ap.parse_args()
    if args.make:
        make_all(args.make, args)
        return
    if args.one:
        ONE[args.one](args.dir)
        return
    with tempfile.TemporaryDirectory() as tmp_s:
        tmp = Path(tmp_s)
        (tmp / "vehicle.toml").write_text(VEHICLE)
        (tmp / "imu.toml").write_text(IMU_MAPPING)
        nmea, csv, rnx = tmp / "rx.nmea", tmp / "imu.csv", tmp / "rx.obs"
        t = time.perf_counter()
        make_nmea(nmea, args.nmea_hours)
        make_imu_csv(csv, args.imu_hours)
        n_obs = make_rinex(rnx, args.rinex_hours)
        ubx = tmp / "rx.ubx"
        make_ubx(ubx, args.ubx_hours)
        print(f"files made in {time.perf_counter() - t:.1f} s (not timed below); best of 3 runs, one core")

        def imp(src: Path, **kw: Any) -> Callable[[], Any]:
            return lambda: import_run([src], tmp / "out", vehicle=tmp / "vehicle.toml", force=True, **kw)

        t_read, dec = timed(lambda: decode(nmea, "nmea", None))
        t_imp, _ = timed(imp(nmea))
        t_lib, _ = timed(lambda: pynmea2_alone(nmea), repeat=1)
        row(f"NMEA {args.nmea_hours:g} h 1 Hz", nmea.stat().st_size / 1e6, dec.records, t_read, t_imp, t_lib, "pynmea2")

        t_read, dec = timed(lambda: decode(csv, "csv", tmp / "imu.toml"))
        t_imp, _ = timed(imp(csv, mapping=[tmp / "imu.toml"]))
        t_lib, _ = timed(lambda: pyarrow_alone(csv))
        row(
            f"IMU CSV {args.imu_hours:g} h 100 Hz",
            csv.stat().st_size / 1e6,
            dec.records,
            t_read,
            t_imp,
            t_lib,
            "pyarrow.csv",
        )

        t_read, dec = timed(lambda: decode(rnx, "rinex", None))
        t_imp, _ = timed(imp(rnx))
        part = tmp / "slice.obs"
        frac = rinex_slice(rnx, part, args.georinex_minutes)
        t_slice, _ = timed(lambda: georinex_alone(part), repeat=1)
        row(
            f"RINEX 3 {args.rinex_hours:g} h ({n_obs:,} obs)",
            rnx.stat().st_size / 1e6,
            len(dec.frames["gnss_obs"]),
            t_read,
            t_imp,
            t_slice / frac,
            f"georinex (×{1 / frac:.0f} of a {args.georinex_minutes:g} min slice)",
        )

        t_read, dec = timed(lambda: decode(ubx, "ubx", None))
        t_imp, _ = timed(imp(ubx))
        t_lib, _ = timed(lambda: pyubx2_alone(ubx), repeat=1)
        row(
            f"UBX {args.ubx_hours:g} h (PVT, RAWX, ESF)",
            ubx.stat().st_size / 1e6,
            dec.records,
            t_read,
            t_imp,
            t_lib,
            "pyubx2 (no target)",
        )


if __name__ == "__main__":
    main()
