"""Benchmark: ``db build`` and ``db validate`` on a national-scale synthetic network.

Run on demand (never part of the test suite; prints numbers, never pass/fail)::

    .venv/bin/python bench/bench_db.py                 # 1000 lines × 10 km double track
    .venv/bin/python bench/bench_db.py --lines 100     # a quick smaller run
    .venv/bin/python bench/bench_db.py --workdir /tmp/tp-bench --keep
    .venv/bin/python bench/bench_db.py --workdir /tmp/tp-bench --keep --naive-fraction 0 --rounds 5
    .venv/bin/python bench/bench_db.py --workdir /tmp/tp-bench --keep --naive-fraction 0 --processes 3

Targets (SPEC / brief): 1,000,000 GIS points, ~50,000 balises, ~10,000 features;
``db build`` ≤ 10 s and ``db validate`` ≤ 15 s on one core, peak memory ≤ 4 GB. Also
``db info`` (with and without the content check) and ``db show gis --limit 10`` (issue 33:
``COUNT(*)`` and ``LIMIT``ed reads only, fast whatever the size).

The network: ``--lines`` lines on a square grid of 15 km cells around the origin of
JGD2011 zone 9 (each line is a :func:`~fieldlogs.simulate.networks.synthetic.random_alignment` starting near its
cell centre, so lines do not overlap), double track, a station every 1.1 km (initial pair,
home-signal C balise per station and track), one feature per curve and track.

Beside ``db build`` (issue 21, "within 1.3× of the fastest path you can measure with the
same checks"): the floor (Arrow CSV read + ADBC insert, no checks) and
:func:`checked_fast_build`, the same DB (schema, content hash) from the same files with the
same row checks, read by Arrow or by DuckDB, checked in DuckDB SQL, written by the ADBC
bulk insert (the fastest SQLite writer measured; ``executemany`` of the same rows took
twice its time). ``--rounds`` interleaves ``db build`` and those paths in one process
(needs ``pip install -e '.[bench]'`` for DuckDB; skipped without it).

Issue 34 (``--processes N``, interleaved rounds of fresh processes, :mod:`_db_bounds`): ``db
validate`` against SQLite's integrity and foreign-key checks plus every table read into pandas
(CPU and peak RSS, target ≤ 1.5× each), ``db build`` against DuckDB ``read_csv`` → Arrow →
the same SQLite schema and indexes (CPU, target ≤ 1.3×); prints both ratios.

The naive baseline is what a straightforward script would do: ``csv.DictReader``, per-row
type and range checks in Python, one ``INSERT`` per row in autocommit mode. It runs on a
1 % slice of every source file and is scaled ×100 to estimate the full run.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import re
import resource
import shutil
import sqlite3
import sys
import tempfile
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any, TypeVar

os.environ.setdefault("OMP_NUM_THREADS", "1")  # one core, as the targets are stated

import numpy as np
import pandas as pd
import pyarrow as pa

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _common import verdict
from _db_bounds import compare_bounds, duckdb_build, validate_bound, write_keyed

from dbtools.browse import select_rows
from dbtools.build import build_db
from dbtools.db_info import db_info
from dbtools.gis.geometry import Projector
from dbtools.network import Network, canonical, content_hash, empty_frame
from dbtools.sources import write_source_set
from dbtools.validate import validate_path
from fieldlogs.simulate.networks.synthetic import LineSpec, Station, balises, feature_points, gis_grid, random_alignment
from fieldlogs.simulate.networks.topology import station_network
from schemas.enums import Severity
from schemas.network import NETWORK_TABLES
from schemas.tables import BALISES, DB_TABLES, FEATURE_POINTS, GIS, KM_BREAKS, LAT_RANGE, LINES, LON_RANGE

T = TypeVar("T")
#: Side of the square cell each line is drawn in [m].
CELL_M = 15_000.0
#: Station spacing [m]: ~25 balises per track on a 10 km line.
STATION_SPACING_M = 1_100.0
#: Grid points per switch of the German network (DB Netz: about 61,000 km of track, i.e.
#: 3.05 M points of the 20 m grid, and about 66,000 switches and crossings): a real national
#: network's density of topology, against which the synthetic one's is printed.
GERMAN_POINTS_PER_SWITCH = 61_000_000.0 / 20.0 / 66_000.0
#: The station spacing that gives the synthetic lines about that density (measured: 1,100 m
#: gives 23 points per switch, twice as dense).
GERMAN_SPACING_M = 2_400.0


def national_network(
    n_lines: int,
    length_m: float,
    seed: int = 2026,
    *,
    topology: bool = False,
    station_spacing_m: float = STATION_SPACING_M,
) -> Network:
    """``n_lines`` double-track lines of ``length_m`` each, one per grid cell (zone 9), a station
    every ``station_spacing_m``; ``topology``: with a loop pair and a crossover at every station,
    the main tracks split at their switches (:mod:`fieldlogs.simulate.networks.topology`: ≈ 9
    tracks and 6 switches a station)."""
    rng = np.random.default_rng(seed)
    side = math.ceil(math.sqrt(n_lines))
    projector = Projector(9)
    gis, bal, fp, lines = [], [], [], []
    net_parts: dict[str, list[pd.DataFrame]] = {t.name: [] for t in NETWORK_TABLES}
    for i in range(n_lines):
        row, col = divmod(i, side)
        x0 = (col - side / 2 + 0.5) * CELL_M
        y0 = (row - side / 2 + 0.5) * CELL_M
        heading = float(rng.uniform(-np.pi, np.pi))
        # start half a line length behind the cell centre so the line stays in its cell
        x0 -= 0.5 * length_m * math.cos(heading) * 0.8
        y0 -= 0.5 * length_m * math.sin(heading) * 0.8
        a = random_alignment(rng, length_m, km0=float(rng.integers(0, 50)) * 1000.0, x0=x0, y0=y0, heading0=heading)
        n_st = int((length_m - 600.0) // station_spacing_m) + 1
        stations = [Station(f"{j + 1:02d}", f"S{j + 1}", a.km0 + 300.0 + j * station_spacing_m) for j in range(n_st)]
        spec = LineSpec(f"{i + 1:04d}", f"Line {i + 1}", a, stations)
        gis.append(gis_grid(spec, projector))
        bal.append(balises(spec))
        fp.append(feature_points(spec))
        lines.append((spec.line_code, spec.name))
        if topology:
            parts = station_network(spec, projector)
            bal.append(parts.pop("balises"))
            for name, frame in parts.items():
                net_parts[name].append(frame)
    tables = {
        LINES.name: pd.DataFrame({"line_code": [c for c, _ in lines], "name": [n for _, n in lines]}),
        GIS.name: pd.concat(gis, ignore_index=True),
        BALISES.name: pd.concat(bal, ignore_index=True),
        FEATURE_POINTS.name: pd.concat(fp, ignore_index=True),
        KM_BREAKS.name: empty_frame(KM_BREAKS),
        **{name: pd.concat(frames, ignore_index=True) for name, frames in net_parts.items() if frames},
    }
    return Network({t.name: canonical(t, tables[t.name]) for t in DB_TABLES if t.name in tables})


# ----------------------------------------------------------------------------- naive baseline

_NAIVE_DDL = {
    "gis": "CREATE TABLE gis (line_code TEXT, track TEXT, km_m REAL, lat REAL, lon REAL, height_m REAL, "
    "PRIMARY KEY (line_code, track, km_m))",
    "balises": "CREATE TABLE balises (balise_id TEXT PRIMARY KEY, kind TEXT, line_code TEXT, station_code TEXT, "
    "track TEXT, signal_type TEXT, km_actual_m REAL, km_equipment_m REAL, dist_from_initial_m REAL)",
    "feature_points": "CREATE TABLE feature_points (line_code TEXT, track TEXT, feature_id TEXT, seq INTEGER, "
    "km_m REAL, radius_m REAL, attribute TEXT, role TEXT)",
}


def naive_build(src: Path, out: Path, fraction: float) -> tuple[float, int]:
    """Row-by-row build of the first ``fraction`` of every file; returns (seconds, rows)."""
    t0 = time.perf_counter()
    conn = sqlite3.connect(out, isolation_level=None)  # autocommit: one transaction per INSERT
    n_rows = 0
    for name, ddl in _NAIVE_DDL.items():
        conn.execute(ddl)
        with open(src / f"{name}.csv", newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
        cols = re.findall(r"(\w+) (?:TEXT|REAL|INTEGER)", ddl)  # the line-only columns (not the v2 ones)
        keep = [{k: r[k] for k in cols} for r in rows[: max(1, int(len(rows) * fraction))]]
        for row in keep:
            values = []
            for key, cell in row.items():
                if key in ("km_m", "lat", "lon", "height_m", "km_actual_m", "km_equipment_m", "radius_m") or (
                    key == "dist_from_initial_m" and cell
                ):
                    v = float(cell)
                    if not math.isfinite(v):
                        raise ValueError(key)
                    if key == "lat" and not LAT_RANGE[0] <= v <= LAT_RANGE[1]:
                        raise ValueError(key)
                    if key == "lon" and not LON_RANGE[0] <= v <= LON_RANGE[1]:
                        raise ValueError(key)
                    values.append(v)
                else:
                    values.append(cell or None)
            marks = ",".join("?" * len(values))
            conn.execute(f"INSERT INTO {name} ({','.join(row)}) VALUES ({marks})", values)
            n_rows += 1
    conn.close()
    return time.perf_counter() - t0, n_rows


def read_alternatives(db: Path) -> dict[str, Callable[[], object]]:
    """Readers of every content table of ``db``: the ones read_network was chosen from."""

    def query(t: object) -> str:
        return f"SELECT {','.join(t.column_names)} FROM [{t.name}]"  # type: ignore[attr-defined]

    def pandas_sql() -> object:
        with sqlite3.connect(db) as conn:
            return [pd.read_sql_query(query(t), conn) for t in DB_TABLES]

    def sqlite3_numpy() -> object:
        with sqlite3.connect(db) as conn:
            return [[np.asarray(c) for c in zip(*conn.execute(query(t)).fetchall(), strict=True)] for t in DB_TABLES]

    out: dict[str, Callable[[], object]] = {"pd.read_sql_query": pandas_sql, "sqlite3 fetchall + numpy": sqlite3_numpy}
    try:
        import adbc_driver_sqlite.dbapi as adbc

        def adbc_arrow() -> object:
            with adbc.connect(str(db)) as conn, conn.cursor() as cur:
                tables = []
                for t in DB_TABLES:
                    cur.execute(query(t))
                    tables.append(cur.fetch_arrow_table())
                return tables

        out["ADBC → Arrow (no types checked)"] = adbc_arrow
    except ImportError:
        pass
    return out


def build_floor(src: Path, out: Path) -> None:
    """A lower bound for db build: Arrow's CSV reader and the ADBC bulk insert of the three
    big tables, no checks, no canonical order, no content hash."""
    import adbc_driver_sqlite.dbapi as adbc
    import pyarrow.csv as pcsv

    out.unlink(missing_ok=True)
    with adbc.connect(str(out), autocommit=True) as conn, conn.cursor() as cur:
        cur.execute("PRAGMA journal_mode=OFF")
        cur.execute("PRAGMA synchronous=OFF")
        for name, ddl in _NAIVE_DDL.items():
            cur.execute(ddl)
            cols = re.findall(r"(\w+) (?:TEXT|REAL|INTEGER)", ddl)  # the line-only columns (not the v2 ones)
            cur.adbc_ingest(name, pcsv.read_csv(src / f"{name}.csv").select(cols), mode="append")


class _Stages:
    """CPU seconds per named stage (laps of ``time.process_time``)."""

    def __init__(self) -> None:
        self.cpu: dict[str, float] = {}
        self.t = time.process_time()

    def lap(self, name: str) -> None:
        now = time.process_time()
        self.cpu[name] = self.cpu.get(name, 0.0) + now - self.t
        self.t = now


def _sql_text(name: str) -> str:
    """A text cell as coerce_frame types it: stripped, NULL where blank (empty or
    nan/na/null in any letter case)."""
    return f"CASE WHEN lower(trim({name})) IN ('', 'nan', 'na', 'null') THEN NULL ELSE trim({name}) END AS {name}"


def _sql_problems(table: Any, view: str) -> str:
    """One query counting every row-level problem our checks look for in ``view``: a null
    in a non-nullable column, a value outside its enumeration or range, an infinite
    number, a fractional whole number, a repeated primary key."""
    terms = []
    for c in table.columns:
        q = f'"{c.name}"'
        if not c.nullable:
            terms.append(f"count(*) FILTER (WHERE {q} IS NULL)")
        if c.enum is not None:
            values = ", ".join(f"'{v}'" for v in c.enum)
            terms.append(f"count(*) FILTER (WHERE {q} NOT IN ({values}))")
        if c.dtype in ("float", "int"):
            terms.append(f"count(*) FILTER (WHERE isinf({q}))")
        if c.dtype == "int":
            terms.append(f"count(*) FILTER (WHERE {q} <> floor({q}))")
        if c.min is not None:
            terms.append(f"count(*) FILTER (WHERE {q} < {c.min})")
        if c.max is not None:
            terms.append(f"count(*) FILTER (WHERE {q} > {c.max})")
    keys = ", ".join(f'"{k}"' for k in table.primary_key)
    dup = f"(SELECT count(*) FROM (SELECT {keys} FROM {view} GROUP BY {keys} HAVING count(*) > 1))"
    return f"SELECT {' + '.join(terms) or '0'} + {dup} FROM {view}"


def checked_fast_build(src: Path, out: Path, reader: str = "arrow") -> str:
    """The fastest path measured to the same DB with the same checks (issue 21): DuckDB
    reads every source CSV with the declared types (blank cells and nan/na/null as NULL,
    text stripped, as ``coerce_frame``), counts every row-level problem our checks look
    for in SQL (:func:`_sql_problems`) and the line codes missing from ``lines``, and hands
    each table sorted by its primary key to Arrow; the ADBC driver bulk-inserts them into
    the schema ``db build`` creates (same tables, keys, indexes, pragmas, foreign-key check
    after the load). Our own functions give what has no faster equivalent measured: the
    content hash (its bytes are defined on the canonical frames), the area and georeference
    checks, the source-file hashes. Returns the content hash. Holds for source sets in
    plain numbers (a km in 12k345.6 notation, an .xlsx file or a ``seq`` left blank need
    our text path) and stops at the first problem instead of naming each."""
    import duckdb
    import pyarrow.csv as pcsv

    from dbtools.gis.index import network_georef
    from dbtools.rules.area import check_area
    from dbtools.rules.common import Locator
    from dbtools.tabular import sha256_file
    from dbtools.typed_csv import BLANK_CELLS
    from schemas.tables import DB_TABLES, SOURCE_TABLES
    from schemas.text_cells import stripped_text

    stages = _Stages()
    sql_type = {"str": "VARCHAR", "float": "DOUBLE", "int": "DOUBLE", "bool": "VARCHAR"}
    nulls = "['', 'nan', 'NaN', 'NAN', 'na', 'NA', 'null', 'NULL']"
    con = duckdb.connect()
    arrow: dict[str, object] = {}
    for name, table in SOURCE_TABLES.items():
        path = src / f"{name}.csv"
        if not path.exists():
            continue
        header = path.open(encoding="utf-8").readline().strip().split(",")
        if reader == "duckdb":
            cols = ", ".join(
                f"'{c}': '{sql_type[table.column(c).dtype] if c in table.column_names else 'VARCHAR'}'" for c in header
            )
            select = ", ".join(
                _sql_text(f'"{c.name}"')
                if c.dtype == "str" and c.name in header
                else (f'"{c.name}"' if c.name in header else f'NULL AS "{c.name}"')
                for c in table.columns
            )
            con.execute(
                f"CREATE TEMP TABLE t_{name} AS SELECT {select} FROM read_csv('{path}', header=true, "
                f"auto_detect=false, columns={{{cols}}}, nullstr={nulls}, quote='\"', delim=',')"
            )
        else:  # Arrow's CSV reader, text stripped and blanked by the kernels coerce_frame's use
            numeric = {c.name for c in table.columns if c.dtype in ("float", "int")}
            types = {c: (pa.float64() if c in numeric else pa.string()) for c in header}
            t = pcsv.read_csv(
                path,
                convert_options=pcsv.ConvertOptions(
                    column_types=types, null_values=BLANK_CELLS, strings_can_be_null=False
                ),
            )
            n = t.num_rows
            columns = {
                c.name: (stripped_text(t.column(c.name)) if c.dtype == "str" else t.column(c.name))
                if c.name in header
                else pa.nulls(n, pa.string() if c.dtype == "str" else pa.float64())
                for c in table.columns
            }
            con.register(f"t_{name}", pa.table(columns))
        stages.lap(f"read ({reader})")
        bad = con.execute(_sql_problems(table, f"t_{name}")).fetchall()[0]
        if bad is None or bad[0]:
            raise ValueError(f"{name}: {bad} problems")
        stages.lap("DuckDB checks")
        keys = ", ".join(f'"{k}"' for k in table.primary_key)
        arrow[name] = con.sql(f"SELECT * FROM t_{name} ORDER BY {keys}").to_arrow_table()
        stages.lap("DuckDB sort → Arrow")
    missing = con.execute(
        " UNION ".join(f"SELECT line_code FROM t_{n}" for n in ("gis", "balises", "feature_points") if n in arrow)
        + " EXCEPT SELECT line_code FROM t_lines"
    ).fetchall()
    if missing:
        raise ValueError(f"line codes not in lines: {missing[:5]}")
    stages.lap("DuckDB checks")
    frames = {t.name: canonical(t, arrow[t.name].to_pandas()) if t.name in arrow else empty_frame(t) for t in DB_TABLES}
    stages.lap("Arrow → canonical frames")
    net = Network(frames, origin=str(src), files={n: str(src / f"{n}.csv") for n in arrow})
    net.meta = {f"source_sha256:{n}.csv": sha256_file(src / f"{n}.csv") for n in sorted(arrow)}
    if check_area(net, Locator(net.files, {})):
        raise ValueError("area")
    georef = network_georef(net)
    stages.lap("area, georef, file hashes")
    digest = content_hash(net.tables)
    stages.lap("content hash")
    meta = {"content_hash": digest, **net.meta, **(georef.to_meta() if georef is not None else {})}
    data = {t.name: pa.Table.from_pandas(frames[t.name][t.column_names], preserve_index=False) for t in DB_TABLES}
    write_keyed(out, {k: v for k, v in data.items() if v.num_rows}, meta)
    stages.lap("SQLite write (schema, ADBC insert, indexes, FK check)")
    if os.environ.get("BENCH_STAGES"):
        print("  stages (CPU s): " + ", ".join(f"{k} {v:.2f}" for k, v in stages.cpu.items()))
    return digest


def compare_read_build(src: Path, db: Path, work: Path, t_build: float, rounds: int = 3) -> None:
    """read_network and db build against the alternatives, side by side (CPU s, best of 3)."""
    from dbtools.database import read_network

    def cpu(fn: Callable[[], object]) -> float:
        return min(timed(fn)[0][1] for _ in range(3))

    ours = cpu(lambda: read_network(db, verify=False))
    net = read_network(db, verify=False)
    hashed = cpu(lambda: content_hash(net.tables))
    print(
        f"content hash        {hashed:7.2f} s CPU: the check of every load (read_network verify=True) adds "
        f"{hashed / ours:.0%} to read_network's {ours:.2f} s  [load {os.getloadavg()[0]:.2f}]"
    )
    alts = {name: cpu(fn) for name, fn in read_alternatives(db).items()}
    best = min(alts, key=lambda k: alts[k])
    print(
        f"read_network        {ours:7.2f} s CPU; "
        + "; ".join(f"{k} {v:.2f} s" for k, v in alts.items())
        + f"; ours / fastest ({best}) = {ours / alts[best]:.2f}×  [load {os.getloadavg()[0]:.2f}]"
    )
    try:
        floor = cpu(lambda: build_floor(src, work / "floor.sqlite"))
    except ImportError:
        return
    print(
        f"db build floor      {floor:7.2f} s CPU (Arrow CSV read + ADBC insert, no checks); db build / floor = "
        f"{t_build / floor:.2f}×  [load {os.getloadavg()[0]:.2f}]"
    )
    compare_checked_builds(src, work, rounds)


def compare_checked_builds(src: Path, work: Path, rounds: int) -> None:
    """``db build`` against :func:`checked_fast_build` (Arrow or DuckDB reading), interleaved
    in one process (round by round: ours, then each alternative; CPU of all threads), warm
    (the lazy imports done by a first build of each). Prints the best CPU of each, the
    median of the rounds' ratios ours / fastest alternative, and whether the content
    hashes agree."""
    try:
        import duckdb  # noqa: F401
    except ImportError:
        print("checked fast build: DuckDB not installed (pip install -e '.[bench]'); skipped")
        return
    ours_db = work / "ours-checked.sqlite"

    def ours() -> str:
        return build_db(src, ours_db, db_version="bench", force=True).content_hash

    runs: dict[str, Callable[[], str]] = {
        "db build": ours,
        "Arrow read + DuckDB checks + ADBC": lambda: checked_fast_build(src, work / "fast-arrow.sqlite", "arrow"),
        "DuckDB read + checks + ADBC": lambda: checked_fast_build(src, work / "fast-duckdb.sqlite", "duckdb"),
    }
    hashes = {k: fn() for k, fn in runs.items()}  # warm-up
    cpu: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(rounds):
        for k, fn in runs.items():
            cpu[k].append(timed(fn)[0][1])
    alts = [k for k in runs if k != "db build"]
    best = {k: min(v) for k, v in cpu.items()}
    fastest = min(alts, key=lambda k: best[k])
    ratio = float(np.median([cpu["db build"][i] / min(cpu[k][i] for k in alts) for i in range(rounds)]))
    same = "same content hash" if len(set(hashes.values())) == 1 else f"HASHES DIFFER {hashes}"
    print(
        f"db build vs the fastest path with the same checks: db build {best['db build']:.2f} s CPU; "
        + "; ".join(f"{k} {best[k]:.2f} s" for k in alts)
        + f"; ours / fastest ({fastest}) = {best['db build'] / best[fastest]:.2f}× best of {rounds}, "
        f"median of the rounds' ratios {ratio:.2f}× {verdict('≤ 1.3×', ratio <= 1.3)}; {same}  "
        f"[load {os.getloadavg()[0]:.2f}]"
    )


def timed(fn: Callable[[], T]) -> tuple[tuple[float, float], T]:
    """((wall s, CPU s of this process), result)."""
    w, c = time.perf_counter(), time.process_time()
    result = fn()
    return (time.perf_counter() - w, time.process_time() - c), result


def peak_rss_mb() -> float:
    """Peak resident set size of this process [MB] (ru_maxrss is KiB on Linux)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--lines", type=int, default=1000, help="number of lines (default 1000)")
    p.add_argument("--length-m", type=float, default=10_000.0, help="length of each line [m] (default 10000)")
    p.add_argument("--workdir", type=Path, default=None, help="where to write sources and DBs (default: temp)")
    p.add_argument("--keep", action="store_true", help="keep the workdir (reuses an existing source set)")
    p.add_argument(
        "--naive-fraction", type=float, default=0.01, help="slice for the naive baseline (default 1 %%; 0 skips it)"
    )
    p.add_argument("--rounds", type=int, default=3, help="interleaved rounds of the checked-build comparison")
    p.add_argument("--cores", type=int, default=1, help="pin the process to this many cores (default 1)")
    p.add_argument(
        "--processes",
        type=int,
        default=3,
        help="interleaved rounds of fresh processes against the issue-34 bounds (0 skips them)",
    )
    p.add_argument("--child", nargs="+", help=argparse.SUPPRESS)  # one bound, in a fresh process
    p.add_argument(
        "--topology",
        action="store_true",
        help="compare build and validate per grid point: the lines with station layouts (tracks, switches, "
        "connections, balise groups) against the same lines alone",
    )
    p.add_argument(
        "--station-spacing-m",
        type=float,
        default=STATION_SPACING_M,
        help=f"with --topology: a station (6 switches) every this many metres along each line (default "
        f"{STATION_SPACING_M:.0f}; {GERMAN_SPACING_M:.0f} gives the German network's grid points per switch)",
    )
    args = p.parse_args(argv)
    if args.child:
        what, *paths = args.child
        if what == "validate-bound":
            validate_bound(Path(paths[0]))
        else:
            duckdb_build(Path(paths[0]), Path(paths[1]))
        return 0
    os.sched_setaffinity(0, sorted(os.sched_getaffinity(0))[: args.cores])
    if args.topology:
        return compare_topology(args.lines, args.length_m, args.rounds, args.station_spacing_m)

    work = args.workdir or Path(tempfile.mkdtemp(prefix="trainpos-bench-"))
    work.mkdir(parents=True, exist_ok=True)
    src, db = work / f"src-{args.lines}x{int(args.length_m)}", work / "bench.sqlite"
    try:
        if not (src / "gis.csv").exists():
            t0 = time.perf_counter()
            net = national_network(args.lines, args.length_m)
            write_source_set(net, src, force=True)
            print(f"generated in {time.perf_counter() - t0:.1f} s → {src}")
        sizes = {n: sum(1 for _ in open(src / f"{n}.csv", encoding="utf-8")) - 1 for n in _NAIVE_DDL}
        print("rows: " + ", ".join(f"{k} {v:,}" for k, v in sizes.items()))

        db.unlink(missing_ok=True)
        (t_build, c_build), _ = timed(lambda: build_db(src, db, db_version="bench"))
        rss_build = peak_rss_mb()
        (t_validate, c_validate), findings = timed(lambda: validate_path(db))
        (t_validate_src, c_validate_src), src_findings = timed(lambda: validate_path(src))
        n_err = sum(f.severity == Severity.ERROR for f in findings)

        print(f"cores: {sorted(os.sched_getaffinity(0))}; wall and CPU time (CPU = wall on an idle core)")
        print(f"db build            {t_build:7.2f} s wall {c_build:7.2f} s CPU  (target ≤ 10 s)")
        print(
            f"db validate (DB)    {t_validate:7.2f} s wall {c_validate:7.2f} s CPU  (target ≤ 15 s)"
            f"  {len(findings)} findings, {n_err} errors"
        )
        print(
            f"db validate (src)   {t_validate_src:7.2f} s wall {c_validate_src:7.2f} s CPU"
            f"  {len(src_findings)} findings"
        )
        (t_info, c_info), _ = timed(lambda: db_info(db))
        (_, c_quick), _ = timed(lambda: db_info(db, verify=False))
        (_, c_show), _ = timed(lambda: select_rows(db, "gis", None, 10))
        print(
            f"db info             {t_info:7.2f} s wall {c_info:7.2f} s CPU  (--quick {c_quick:.3f} s CPU;"
            f" db show gis --limit 10 {c_show:.3f} s CPU; in process, no start-up)"
        )
        print(f"peak RSS            {peak_rss_mb():7.0f} MB (after build {rss_build:.0f} MB; target ≤ 4096 MB)")
        compare_read_build(src, db, work, c_build, args.rounds)
        if args.processes > 0:
            compare_bounds(src, db, work, args.processes)
        if args.naive_fraction > 0:
            naive_db = work / "naive.sqlite"
            naive_db.unlink(missing_ok=True)
            t_naive_slice, n_naive = naive_build(src, naive_db, args.naive_fraction)
            t_naive = t_naive_slice / args.naive_fraction
            print(
                f"naive build         {t_naive:7.1f} s   (estimated: {t_naive_slice:.2f} s for {n_naive:,} rows ×"
                f" {1 / args.naive_fraction:g}); ratio naive / build = {t_naive / t_build:.0f}× (wall)"
            )
        for f in findings[:10]:
            print("  ", f)
    finally:
        if not args.keep and args.workdir is None:
            shutil.rmtree(work, ignore_errors=True)
    return 0


def _grid_points(src: Path) -> int:
    return sum(
        sum(1 for _ in open(src / f"{n}.csv", encoding="utf-8")) - 1
        for n in ("gis", "track_points")
        if (src / f"{n}.csv").exists()
    )


def compare_topology(n_lines: int, length_m: float, rounds: int, station_spacing_m: float = STATION_SPACING_M) -> int:
    """``db build`` and ``db validate`` CPU per grid point (gis + track_points rows) of the
    network with station layouts against the same lines without them (issue 30: target
    ≤ 1.3×); rounds interleaved (line-only, then with stations), the median and the best
    of the rounds printed with their ratios.

    The network's density is printed as grid points per switch beside a real one's
    (:data:`GERMAN_POINTS_PER_SWITCH`): the ratio grows with the share of topology per grid
    point, so a figure is only meaningful with the density it was measured at."""
    work = Path(tempfile.mkdtemp(prefix="trainpos-bench-topo-"))
    try:
        srcs = {}
        for topo in (False, True):
            net = national_network(n_lines, length_m, topology=topo, station_spacing_m=station_spacing_m)
            srcs[topo] = write_source_set(net, work / f"src-{int(topo)}", force=True)
        counts = {k: (_grid_points(v), len(pd.read_csv(v / "tracks.csv")) if k else 0) for k, v in srcs.items()}
        n_sw = len(pd.read_csv(srcs[True] / "switches.csv", usecols=[0]))
        print(
            f"line-only: {counts[False][0]:,} grid points; with stations: {counts[True][0]:,} grid points, "
            f"{counts[True][1]:,} tracks, {n_sw:,} switches (a station every {station_spacing_m:.0f} m: "
            f"{counts[True][0] / max(n_sw, 1):.0f} grid points per switch; the German network "
            f"≈ {GERMAN_POINTS_PER_SWITCH:.0f})"
        )
        per: dict[tuple[bool, str], list[float]] = {}
        for r in range(rounds + 1):  # round 0 warms the imports and caches up, not counted
            for topo, src in srcs.items():
                db = work / f"db-{int(topo)}.sqlite"
                db.unlink(missing_ok=True)
                (_, c_build), _ = timed(partial(build_db, src, db, db_version="bench"))
                (_, c_val), findings = timed(partial(validate_path, db))
                n = counts[topo][0]
                if r == 0:
                    continue
                per.setdefault((topo, "build"), []).append(c_build / n * 1e6)
                per.setdefault((topo, "validate"), []).append(c_val / n * 1e6)
                errors = [f for f in findings if f.severity == Severity.ERROR]
                if errors:
                    print(f"  {len(errors)} validation errors, first: {errors[0]}")
        print(
            f"{'':12}{'line-only':>14}{'with stations':>16}{'ratio':>8}   (CPU µs per grid point, median of "
            f"{rounds} interleaved rounds; best of each in brackets)"
        )
        for step in ("build", "validate"):
            a, b = (float(np.median(per[(t, step)])) for t in (False, True))
            a_min, b_min = (min(per[(t, step)]) for t in (False, True))
            print(
                f"db {step:9}{a:14.2f}{b:16.2f}{b / a:8.2f}×  {verdict('≤ 1.3×', b / a <= 1.3)}; best "
                f"{a_min:.2f} / {b_min:.2f} = {b_min / a_min:.2f}×  [load {os.getloadavg()[0]:.2f}]"
            )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
