"""The foreign keys of the declared tables, checked on the frames an onboard DB is written from.

``write_db`` loads with SQLite's ``foreign_keys`` off (enforcing them row by row costs a third
of the insert) and used to run ``PRAGMA foreign_key_check`` over the written file: a scan of
every child row and a b-tree look-up of its key in the parent's primary-key index — on the
national network 1 M GIS rows against ``lines`` and 0.6 M track references against
``tracks``, 0.13 s line-only and 0.26 s with stations. Here the same relation is tested on
the canonical frames before anything is written, one hash-set membership test per foreign
key column (Arrow's ``is_in``), a few hundredths of a second.

It is the relation SQLite checks: a child row passes when its key column is null
(https://sqlite.org/foreignkeys.html: "if any of the child key columns … are NULL … there
is no requirement for a corresponding row in the parent table") or its value equals a
parent key. Every foreign key of :mod:`schemas.tables` is one text column referencing a
text primary key, both stored with TEXT affinity, so
SQLite's equality under the parent column's BINARY collation is the equality of the UTF-8
bytes, which is what ``is_in`` compares. The frames are the values ``write_db`` binds, so
a failure here is exactly a row ``foreign_key_check`` would have listed.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence

import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from schemas.model import Table


def _text(s: pd.Series) -> pa.Array:
    """The column as one Arrow large_string array (nulls where missing)."""
    arr = pa.array(s.array if isinstance(s.dtype, pd.StringDtype) else s.astype(object), from_pandas=True)
    if isinstance(arr, pa.ChunkedArray):
        arr = arr.combine_chunks()
    return arr.cast(pa.large_string())


def dangling(child: pd.Series, parent: pd.Series) -> int:
    """The position of the first value of ``child`` that is neither missing nor a value of
    ``parent`` (-1 when every value is one or the other)."""
    values = _text(child)
    if values.null_count == len(values):
        return -1
    found = pc.is_in(values, value_set=_text(parent).drop_null())
    missing = pc.and_(pc.invert(found), pc.is_valid(values))
    return int(pc.index(missing, True).as_py())


def check_foreign_keys(frames: Sequence[tuple[Table, pd.DataFrame]]) -> None:
    """Raise ``sqlite3.IntegrityError`` (what a failed ``PRAGMA foreign_key_check`` raised,
    naming the table, column, row and value) when a row of one of the frames references a
    key absent from its parent table's frame. A parent absent from ``frames`` has no rows."""
    by_name = {t.name: f for t, f in frames}
    for table, frame in frames:
        for fk in table.foreign_keys:
            if len(fk.columns) != 1:
                raise NotImplementedError(f"{table.name}: a foreign key of {len(fk.columns)} columns")
            column, parent_column = fk.columns[0], fk.other_columns[0]
            parent = by_name.get(fk.other_table)
            keys = parent[parent_column] if parent is not None else pd.Series([], dtype="string")
            i = dangling(frame[column], keys)
            if i >= 0:
                raise sqlite3.IntegrityError(
                    f"FOREIGN KEY constraint failed: {table.name} row {i + 1}: {column} "
                    f"'{frame[column].iat[i]}' is not a {parent_column} of {fk.other_table}"
                )
