"""The two bounds of issue 34 item 2 for ``bench/bench_db.py``, and the whole-process pairs
that measure ``db validate`` and ``db build`` against them (``bench_db.py --processes N``;
each bound runs in a fresh process through ``bench_db.py --child``)."""

from __future__ import annotations

import os
import sqlite3
import sys
from pathlib import Path
from typing import Any

import numpy as np
from _common import verdict


def validate_bound(db: Path) -> None:
    """The bound ``db validate`` is measured against (issue 34): SQLite's integrity and
    foreign-key checks and every table read into pandas (ADBC → Arrow → ``to_pandas``)."""
    import adbc_driver_sqlite.dbapi as adbc

    with sqlite3.connect(f"file:{db}?mode=ro", uri=True) as conn:
        conn.execute("PRAGMA integrity_check").fetchall()
        conn.execute("PRAGMA foreign_key_check").fetchall()
        names = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
    with adbc.connect(str(db)) as ac, ac.cursor() as cur:
        for name in names:
            cur.execute(f"SELECT * FROM [{name}]")
            cur.fetch_arrow_table().to_pandas()


def duckdb_build(src: Path, out: Path) -> None:
    """The bound ``db build`` is measured against (issue 34): DuckDB ``read_csv`` of every
    source file with the declared column types, sorted by the primary key into Arrow, bulk
    inserted by the ADBC driver into the schema ``db build`` creates (same tables, keys,
    indexes after the load, pragmas; foreign-key check); no row checks, no content hash."""
    import duckdb

    from schemas.tables import SOURCE_TABLES

    sql_type = {"str": "VARCHAR", "float": "DOUBLE", "int": "BIGINT", "bool": "BOOLEAN"}
    con = duckdb.connect()
    con.execute("SET enable_progress_bar = false")
    arrow = {}
    for name, table in SOURCE_TABLES.items():
        path = src / f"{name}.csv"
        if not path.exists():
            continue
        header = path.open(encoding="utf-8").readline().strip().split(",")
        known = [c for c in header if c in table.column_names]
        cols = ", ".join(f"'{c}': '{sql_type[table.column(c).dtype]}'" for c in known)
        keys = ", ".join(f'"{k}"' for k in table.primary_key)
        select = ", ".join(f'"{c}"' for c in known)
        arrow[name] = con.sql(
            f"SELECT {select} FROM read_csv('{path}', "
            f"header=true, auto_detect=false, columns={{{cols}}}) ORDER BY {keys}"
        ).to_arrow_table()
    write_keyed(out, arrow)


def write_keyed(out: Path, tables: dict[str, Any], meta: dict[str, str] | None = None) -> None:
    """Arrow tables (sorted by key) into a new SQLite file with the schema ``db build``
    creates (its pragmas, tables and keys; indexes after the load; the foreign-key check),
    through the ADBC bulk insert (the fastest SQLite writer measured); ``meta`` rows too."""
    import adbc_driver_sqlite.dbapi as adbc
    import sqlite_utils

    from dbtools.database import _create_indexes, create_tables
    from schemas.tables import ALL_DB_TABLES, APPLICATION_ID, SCHEMA_VERSION

    out.unlink(missing_ok=True)
    conn = sqlite3.connect(out)
    for pragma in ("journal_mode=OFF", "synchronous=OFF", "cache_size=-262144", f"application_id={APPLICATION_ID}"):
        conn.execute(f"PRAGMA {pragma}")
    conn.execute(f"PRAGMA user_version={SCHEMA_VERSION}")
    db = sqlite_utils.Database(conn)
    create_tables(db, ALL_DB_TABLES, indexes=False)
    conn.commit()
    with adbc.connect(str(out), autocommit=True) as ac, ac.cursor() as cur:
        for pragma in ("journal_mode=OFF", "synchronous=OFF", "cache_size=-262144"):
            cur.execute(f"PRAGMA {pragma}")
        for name, data in tables.items():
            cur.adbc_ingest(name, data, mode="append")
    with conn:
        conn.executemany("INSERT INTO meta (key, value) VALUES (?, ?)", sorted((meta or {}).items()))
    _create_indexes(db, ALL_DB_TABLES)
    if conn.execute("PRAGMA foreign_key_check").fetchone() is not None:
        raise sqlite3.IntegrityError("FOREIGN KEY constraint failed")
    conn.close()


def _child(args: list[str]) -> tuple[float, float]:
    """(CPU s = user + system, peak RSS MB) of one fresh process, as ``/usr/bin/time`` reports
    them: a child forked from this (large) process would start with its resident pages and
    ``ru_maxrss`` would count them. Without ``/usr/bin/time``: the children's CPU, RSS NaN."""
    import resource
    import subprocess
    import tempfile

    root = str(Path(__file__).resolve().parents[1])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([root, *filter(None, [os.environ.get("PYTHONPATH")])])}
    timer = Path("/usr/bin/time")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with tempfile.NamedTemporaryFile("r", suffix=".time") as report:
        wrapped = [str(timer), "-f", "%U %S %M", "-o", report.name, *args] if timer.exists() else args
        proc = subprocess.run(wrapped, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, check=False)
        if proc.returncode != 0:
            raise RuntimeError(f"{' '.join(args)} failed: {proc.stderr.decode()[-400:]}")
        if timer.exists():
            user, system, peak_kb = report.read().split()[-3:]
            return float(user) + float(system), float(peak_kb) / 1024.0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return after.ru_utime + after.ru_stime - before.ru_utime - before.ru_stime, float("nan")


def compare_bounds(src: Path, db: Path, work: Path, rounds: int) -> None:
    """Issue 34 item 2, as interleaved pairs of fresh processes: ``trainpos db validate``
    against :func:`validate_bound` (CPU and peak RSS, targets ≤ 1.5×) and ``trainpos db build``
    (``--no-validate``: the build itself; and as run by default, with the validation rules)
    against :func:`duckdb_build` (CPU, target ≤ 1.3×). Medians of the rounds' ratios."""
    try:
        import duckdb  # noqa: F401
    except ImportError:
        print("bounds: DuckDB not installed (pip install -e '.[bench]'); skipped")
        return
    py, me = sys.executable, str(Path(__file__).resolve().with_name("bench_db.py"))
    cli = [py, "-c", "import sys; sys.argv[0] = 'trainpos'; from cli.main import app; app()"]
    out = work / "bound-build.sqlite"
    runs = {
        "db validate": [*cli, "db", "validate", str(db)],
        "validate bound": [py, me, "--child", "validate-bound", str(db)],
        "db build --no-validate": [*cli, "db", "build", str(src), "-o", str(out), "--force", "--no-validate"],
        "db build": [*cli, "db", "build", str(src), "-o", str(out), "--force"],
        "DuckDB build": [py, me, "--child", "duckdb-build", str(src), str(out)],
    }
    got: dict[str, list[tuple[float, float]]] = {k: [] for k in runs}
    load0 = os.getloadavg()[0]
    for _ in range(rounds):
        for k, args in runs.items():
            got[k].append(_child(args))

    def ratio(a: str, b: str, i: int) -> float:
        return float(np.median([x[i] / y[i] for x, y in zip(got[a], got[b], strict=True)]))

    def med(k: str, i: int) -> float:
        return float(np.median([x[i] for x in got[k]]))

    print(f"fresh processes, {rounds} interleaved rounds, medians  [load {load0:.2f} → {os.getloadavg()[0]:.2f}]")
    for k in runs:
        print(f"  {k:24s} {med(k, 0):6.2f} s CPU  peak RSS {med(k, 1):5.0f} MB")
    for what, i in (("CPU", 0), ("peak RSS", 1)):
        x = ratio("db validate", "validate bound", i)
        print(f"db validate / bound: {what} {x:.2f}× {verdict('≤ 1.5×', x <= 1.5)}")
    x = ratio("db build --no-validate", "DuckDB build", 0)
    print(
        f"db build --no-validate / DuckDB build: CPU {x:.2f}× {verdict('≤ 1.3×', x <= 1.3)}; "
        f"with the validation rules {ratio('db build', 'DuckDB build', 0):.2f}×"
    )
