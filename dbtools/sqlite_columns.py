"""Reading and writing whole SQLite tables as typed columns, at the speed of the file's bytes.

``sqlite3`` hands every value to Python as an object (a tuple per row), which for the
national network's million GIS rows costs more than decoding the file; the ADBC SQLite
driver (``adbc-driver-sqlite``) decodes the same rows straight into Arrow columns in C.
:func:`read_table_columns` reads one declared table that way, in primary-key order, and
returns it in the canonical form of :func:`dbtools.network.canonical` (declared columns,
order and dtypes, sorted by the key): SQLite's BINARY collation orders UTF-8 text by code
point, as pandas orders ``str``, and numbers numerically, so with every key column
non-null the ``ORDER BY`` of the key *is* the canonical order.

A table it leaves out — :func:`dbtools.database.read_network` then reads it through
``sqlite3`` and ``canonical`` as before, with its checks and messages — is one it cannot
vouch for: the driver is not installed or fails (a corrupt file), a column's
values are not of its declared type (ADBC infers a column's type from its values), a
boolean column holds something other than 0/1, or a key column may be null. Files under
``MIN_FILE_BYTES`` are read by ``sqlite3`` alone.
:func:`insert_tables` is the same driver's bulk insert of Arrow batches, for ``write_db``.
Measurements: bench/bench_db.py (read_network and db build against the alternatives).
"""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from dbtools.sqlite_file import ro_uri
from schemas.frames import PANDAS_DTYPE
from schemas.model import Column, Table

_DTYPES = {name: pd.Series([], dtype=dtype).dtype for name, dtype in PANDAS_DTYPE.items()}

_TEXT = (pa.string(), pa.large_string())
#: Files smaller than this are left to ``sqlite3``: loading the driver (≈ 15 ms) costs more
#: than it saves on a regional DB.
MIN_FILE_BYTES = 4 << 20
#: Rows per record batch the driver decodes (its default: 1 024). Large batches are fewer,
#: larger allocations that go back to the system when freed instead of leaving holes in the
#: C heap, and less per-batch work: the national DB reads in 0.53 s instead of 0.57 s with a
#: 17 MB lower peak (bench/bench_db.py; trimming the heap after the read then gains nothing
#: more). The driver infers a column's type from the first batch.
BATCH_ROWS = 1 << 16
BATCH_ROWS_OPTION = "adbc.sqlite.query.batch_rows"


def _column(col: pa.ChunkedArray, c: Column) -> pd.Series | None:
    """The canonical pandas column of one Arrow column, or None if it is not of the
    declared type."""
    t = col.type
    all_null = col.null_count == len(col)
    if c.dtype == "str" and (t in _TEXT or all_null):
        # one chunk, copied out of the driver's batches: they are freed (a view would keep every
        # batch alive, all its columns), and one chunk is what Arrow's kernels read fastest
        return pd.Series(pd.array(col.cast(pa.large_string()).combine_chunks(), dtype=_DTYPES["str"]))
    if c.dtype == "float" and (t == pa.float64() or t == pa.int64() or all_null):
        return pd.Series(col.cast(pa.float64()).to_numpy(zero_copy_only=False), dtype="float64")
    if c.dtype == "int" and (t == pa.int64() or all_null):
        values, missing = _values_and_mask(col)
        return pd.Series(pd.arrays.IntegerArray(values, missing))
    if c.dtype == "bool" and (t == pa.int64() or all_null):
        ints = col.cast(pa.int64())
        valid = ints.drop_null()
        if len(valid) and not pc.all(pc.is_in(valid, pa.array([0, 1]))).as_py():
            return None
        values, missing = _values_and_mask(ints)
        return pd.Series(pd.arrays.BooleanArray(values != 0, missing))
    return None


def _values_and_mask(col: pa.ChunkedArray) -> tuple[np.ndarray, np.ndarray]:
    """An integer column's values (0 where missing) and its missing-value mask, from the
    Arrow buffers: ``pd.array(…, dtype="Int64")`` of the same column gives the same array
    but converts a column with missing values ≈ 30× slower (88,000 balises: 35 ms a column)."""
    ints = col.cast(pa.int64()).combine_chunks()
    missing = np.asarray(ints.is_null().to_numpy(zero_copy_only=False), dtype=bool)
    return np.asarray(ints.fill_null(0).to_numpy(zero_copy_only=False), dtype=np.int64), missing


def _read_one(cur: Any, table: Table) -> pd.DataFrame | None:
    if any(c.nullable for c in table.columns if c.name in table.primary_key):
        return None
    cols = ",".join(f"[{c}]" for c in table.column_names)
    order = f" ORDER BY {','.join(f'[{k}]' for k in table.primary_key)}" if table.primary_key else ""
    try:
        cur.adbc_statement.set_options(**{BATCH_ROWS_OPTION: str(BATCH_ROWS)})
        cur.execute(f"SELECT {cols} FROM [{table.name}]{order}")
        data: Any = cur.fetch_arrow_table()
    except Exception:  # any driver failure: the sqlite3 path reports it
        return None
    if data.num_rows == 0:
        return pd.DataFrame({c.name: pd.Series([], dtype=_DTYPES[c.dtype]) for c in table.columns})
    out: dict[str, pd.Series] = {}
    for c in table.columns:
        s = _column(data.column(c.name), c)
        if s is None:
            return None
        out[c.name] = s
    return pd.DataFrame(out, copy=False)


def read_table_columns(
    path: Path, tables: Sequence[Table], *, min_bytes: int = MIN_FILE_BYTES
) -> dict[str, pd.DataFrame]:
    """The tables of ``tables`` that could be read this way from the SQLite file ``path``
    (opened read-only), in canonical form, by name; the others are left out (module
    docstring). Nothing is read from a file smaller than ``min_bytes``."""
    if Path(path).stat().st_size < min_bytes:
        return {}
    try:
        import adbc_driver_sqlite.dbapi as adbc
    except ImportError:
        return {}
    out: dict[str, pd.DataFrame] = {}
    try:
        with adbc.connect(ro_uri(path)) as conn, conn.cursor() as cur:
            for t in tables:
                frame = _read_one(cur, t)
                if frame is not None:
                    out[t.name] = frame
    except Exception:  # opening or closing failed: the sqlite3 path reports it
        return {}
    return out


def insert_tables(path: Path, frames: Sequence[tuple[Table, pd.DataFrame]]) -> bool:
    """Append each canonical frame to its (existing, empty) table of the SQLite file ``path``
    as Arrow batches through the ADBC driver, one transaction per table; False when the
    driver is not installed (the caller inserts through ``sqlite3``). The values stored
    are those of ``sqlite3``'s ``executemany`` of the same rows: text, integers (booleans
    as 0/1), reals, and NULL for every missing value (NaN included). A failed insert
    (a constraint) raises ``sqlite3.IntegrityError`` as ``executemany`` would."""
    try:
        import adbc_driver_manager
        import adbc_driver_sqlite.dbapi as adbc
    except ImportError:
        return False
    with adbc.connect(str(path), autocommit=True) as conn, conn.cursor() as cur:
        cur.execute("PRAGMA journal_mode=OFF")
        cur.execute("PRAGMA synchronous=OFF")
        cur.execute("PRAGMA cache_size=-262144")  # ≤ 256 MB, as write_db's own connection
        for table, frame in frames:
            if not len(frame):
                continue
            data = pa.Table.from_pandas(frame[table.column_names], preserve_index=False)
            try:
                cur.adbc_ingest(table.name, data, mode="append")
            except adbc_driver_manager.Error as exc:
                raise sqlite3.IntegrityError(f"{table.name}: {exc}") from exc
    return True
