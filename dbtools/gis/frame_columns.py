"""The columns of a GIS frame as the grid index (:mod:`dbtools.gis.index`) reads them: numbers
as read-only views of a float column (no copy), text as codes in the sorted order of its
values (Arrow's dictionary encoding, no Python string per row), and the check that rows are
already in (line, track, km) order, a block of rows at a time."""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
#: :func:`text_codes` by runs when a column has at most one run of equal texts per this many rows.
MIN_RUN = 16


def frame_column(frame: pd.DataFrame, name: str, numeric: bool) -> npt.NDArray[Any]:
    if name not in frame.columns:
        return np.full(len(frame), np.nan if numeric else None, dtype=float if numeric else object)
    s = frame[name]
    if numeric:  # a float64 column (a Network's): a read-only view of it, not a copy
        num = s if s.dtype == np.float64 else pd.to_numeric(s, errors="coerce")
        return np.asarray(num.to_numpy(dtype=np.float64, na_value=np.nan))
    return np.asarray(s.astype(object).where(s.notna(), None).to_numpy(dtype=object))


def text_codes(frame: pd.DataFrame, name: str) -> tuple[I64, npt.NDArray[np.object_]]:
    """Codes of a text column in sorted order of its values (−1: missing) and the values:
    factorized in Arrow, no Python string per row."""
    if name not in frame.columns:
        return np.full(len(frame), -1, dtype=np.int64), np.empty(0, dtype=object)
    s = frame[name]
    if not isinstance(s.dtype, pd.StringDtype):
        codes, uniq = pd.factorize(s, sort=True)
        return np.asarray(codes, dtype=np.int64), np.asarray(uniq, dtype=object)
    arr = pa.array(s.array, from_pandas=True)
    runs = _run_codes(arr)
    if runs is not None:
        return runs
    enc = pc.dictionary_encode(arr)  # Arrow's hash: 4× pandas' here
    if isinstance(enc, pa.ChunkedArray):
        enc = enc.combine_chunks()
    order = pc.array_sort_indices(enc.dictionary).to_numpy()  # code point order, as Python sorts str
    rank = np.full(order.size + 1, -1, dtype=np.int64)  # the last entry: missing (index −1)
    rank[order] = np.arange(order.size)
    index = pc.fill_null(enc.indices, -1).to_numpy(zero_copy_only=False)
    return rank[index], np.asarray(enc.dictionary.take(pa.array(order)).to_pylist(), dtype=object)


def _run_codes(arr: Any) -> tuple[I64, npt.NDArray[np.object_]] | None:
    """:func:`text_codes` of a column without missing values whose rows come in runs of one
    value (a GIS frame's line and track): consecutive texts compared once, the few run values
    ranked; None when it has missing values or more than one run per ``MIN_RUN`` rows."""
    n = len(arr)
    if n < 2 or arr.null_count:
        return None
    new = np.ones(n, dtype=bool)
    new[1:] = ~np.asarray(pc.equal(arr[:-1], arr[1:]).to_numpy(zero_copy_only=False), dtype=bool)
    starts = np.flatnonzero(new)
    if starts.size * MIN_RUN > n:
        return None
    values = arr.take(pa.array(starts))
    uniq = pc.unique(values)
    order = pc.array_sort_indices(uniq).to_numpy()  # code point order, as Python sorts str
    sorted_uniq = uniq.take(pa.array(order))
    run_code = pc.index_in(values, value_set=sorted_uniq).to_numpy(zero_copy_only=False).astype(np.int64)
    lengths = np.diff(np.append(starts, n))
    return np.repeat(run_code, lengths), np.asarray(sorted_uniq.to_pylist(), dtype=object)


def lex_sorted(a: I64, b: I64, c: F64, block: int) -> bool:
    """True when the rows are in the order ``np.lexsort((c, b, a))`` gives (a stable sort:
    then it is the identity); ``c`` finite. ``block`` rows at a time: bounded temporaries."""
    for s in range(0, max(a.size - 1, 0), block):
        e = s + block + 1
        da, db, dc = np.diff(a[s:e]), np.diff(b[s:e]), np.diff(c[s:e])
        if not np.all((da > 0) | ((da == 0) & ((db > 0) | ((db == 0) & (dc >= 0))))):
            return False
    return True
