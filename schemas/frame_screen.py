"""Vectorised screens of typed frames: key order, and "nothing for pandera to report".

:func:`key_order` tells whether a frame's rows are already in the order a stable sort on its
key gives (so :func:`dbtools.network.canonical` need not sort a frame read back from a DB)
and whether any key repeats. :func:`passes_checks` proves, column by column with Arrow and
numpy kernels, that :func:`schemas.frames.check_frame`'s pandera schema would find no failure
case — so the clean frames of a national DB (a million GIS rows) skip pandera, its import and
its per-check copies; any frame it cannot clear (a single doubtful cell, or a dtype it does
not screen) goes through pandera exactly as before, which then names every problem. The
screen is one-sided by construction: each test below is the negation of a pandera check on
the same values, so ``passes_checks`` is True only when every check would pass.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from schemas.model import Column, Table


def key_order(frame: pd.DataFrame, keys: tuple[str, ...]) -> tuple[bool, bool]:
    """(sorted, unique): the rows are in the order a stable sort on ``keys`` gives (each row's
    key tuple ≤ the next one's), and, if so, no two rows share a key tuple (each < the next).
    (False, False) whenever a key has a missing value (the sort puts those last) or is not
    text or a number: the caller then sorts, or looks for repeats another way."""
    n = len(frame)
    if n < 2:
        return True, True
    undecided = np.ones(n - 1, dtype=bool)  # pairs equal on every key so far
    for k in keys:
        s = frame[k]
        if s.isna().any():
            return False, False
        eq = _pairs_in_order(s, undecided)
        if eq is None:
            return False, False
        undecided &= eq
        if not undecided.any():
            return True, True
    return True, False


def _pairs_in_order(s: pd.Series, undecided: npt.NDArray[np.bool_]) -> npt.NDArray[np.bool_] | None:
    """Whether each value equals the next (length n − 1), or None when an ``undecided`` pair
    of different values is out of order (or ``s`` is neither text nor a number). Text is
    compared once for equality and ordered only where the pairs differ (a few per line or
    track of a GIS frame, not every pair)."""
    if isinstance(s.dtype, pd.StringDtype):
        arr = pa.array(s.array, from_pandas=True)
        eq = np.asarray(pc.equal(arr[:-1], arr[1:]).to_numpy(zero_copy_only=False), dtype=bool)
        change = np.flatnonzero(undecided & ~eq)
        if change.size:
            lt = pc.less(arr.take(pa.array(change)), arr.take(pa.array(change + 1)))
            if not np.all(lt.to_numpy(zero_copy_only=False)):
                return None
        return eq
    if pd.api.types.is_numeric_dtype(s.dtype) and not pd.api.types.is_bool_dtype(s.dtype):
        v = s.to_numpy(dtype=np.float64)
        eq = v[:-1] == v[1:]
        return None if (undecided & ~eq & ~(v[:-1] < v[1:])).any() else eq
    return None


def _column_passes(c: Column, s: pd.Series) -> bool:
    """No failure case for the nullable, enumeration and range checks of ``c`` (pandera
    ignores missing values in the last two)."""
    if not c.nullable and s.isna().any():
        return False
    if c.enum is not None:
        if not isinstance(s.dtype, pd.StringDtype):
            return False
        values = pc.unique(pa.array(s.array, from_pandas=True)).drop_null().to_pylist()
        if not set(values) <= set(c.enum):
            return False
    if c.min is None and c.max is None:
        return True
    if not (s.dtype == np.float64 or isinstance(s.dtype, pd.Int64Dtype)):
        return False
    lo, hi = s.min(skipna=True), s.max(skipna=True)
    if pd.isna(lo):
        return True  # no value to check
    return (c.min is None or bool(lo >= c.min)) and (c.max is None or bool(hi <= c.max))


def passes_checks(table: Table, frame: pd.DataFrame, *, check_keys: bool = True) -> bool:
    """True only when the pandera schema of ``table`` (:func:`schemas.frames.pandera_schema`
    for the frame's columns) finds nothing in ``frame``: every present column non-null where
    declared so, within its enumeration and range; no repeated primary key when
    ``check_keys`` and the key columns are present. False means "not proven": run pandera."""
    present = set(frame.columns)
    if len(frame) == 0:
        return True  # no cell, no failure case
    if len(frame.columns) != len(present):
        return False  # repeated column names: pandera's business
    for c in table.columns:
        if c.name in present and not _column_passes(c, frame[c.name]):
            return False
    keys = table.primary_key
    if not (check_keys and keys and all(k in present for k in keys)) or len(frame) < 2:
        return True
    in_order, unique = key_order(frame, keys)
    if in_order:
        return unique
    return not bool(frame.duplicated(subset=list(keys)).any())
