"""A columnar CSV writer: the bytes of ``frame.to_csv(path, index=False, lineterminator="\\n")``.

pandas writes CSV row by row through the ``csv`` module; here every column is turned into
its cells at once (Arrow string arrays) and Arrow's CSV writer joins them, which is
several times faster for the long, narrow frames of the pipeline (positions: one row per
100 ms cycle). The cells are the ones pandas writes:

* float64: the shortest round-trip repr of each value (Python's ``repr(float)``, which is
  what NumPy's ``astype(str)`` — pandas' own formatter for floats without
  ``float_format`` — returns), NaN as the empty cell. Arrow's cast to string gives the
  same shortest digits; it writes an integral value without ``.0`` (added here) and uses
  other exponent forms outside 1e-4 ≤ |x| < 1e10, where ``repr`` itself is used;
* integers: their decimal digits; booleans: ``True``/``False``;
* strings (object, ``str`` or ``string`` dtype): as they are, missing values (None, NaN,
  ``pd.NA``) as the empty cell.

A frame with a cell the ``csv`` module would quote (a comma, a double quote, CR or LF in a
string or a column name), another column type (datetimes, categoricals, nullable
integers, mixed objects) or a single column (where ``csv`` writes an empty cell as ``""``)
goes through :meth:`pandas.DataFrame.to_csv` itself, so the output is always pandas' own.
Measurements: bench/bench_outputs.py, bench/NOTES.md (Performance).
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

_STRUCTURAL = r'[,"\r\n]'
#: |x| range where Arrow's float → string cast is Python's repr once ``.0`` is added to
#: integral values (exponent forms differ outside it).
_ARROW_FLOAT_RANGE = (1e-4, 1e10)


def _float_cells(values: np.ndarray) -> pa.Array:
    mag = np.abs(values)
    lo, hi = _ARROW_FLOAT_RANGE
    by_arrow = ((mag >= lo) & (mag < hi)) | (values == 0.0)
    text = pc.cast(pa.array(values, mask=~by_arrow), pa.string())
    text = pc.if_else(pc.match_substring(text, "."), text, pc.binary_join_element_wise(text, ".0", ""))
    other = ~by_arrow & ~np.isnan(values)
    if other.any():
        text = pc.replace_with_mask(
            text, pa.array(other), pa.array([repr(v) for v in values[other].tolist()], type=pa.string())
        )
    return text


def _objects(col: pd.Series) -> np.ndarray:
    """The column's values as Python objects, every missing value as None."""
    values = np.array(col.to_numpy(dtype=object), dtype=object)  # a copy: writable
    values[pd.isna(values)] = None
    return values


def _string_cells(col: pd.Series) -> pa.Array | None:
    if isinstance(col.dtype, pd.StringDtype):  # Arrow- or object-backed: Arrow takes it whole
        arr = pa.array(col.array, from_pandas=True)
    else:
        arr = pa.array(_objects(col), type=pa.string(), from_pandas=True)
    if pc.any(pc.match_substring_regex(arr, _STRUCTURAL)).as_py():
        return None  # a cell csv would quote: pandas writes the frame
    return arr


def _object_cells(col: pd.Series) -> pa.Array | None:
    if not all(v is None or isinstance(v, str) for v in _objects(col).tolist()):
        return None  # a non-string object: pandas decides how it is written
    return _string_cells(col)


def column_cells(col: pd.Series) -> pa.Array | None:
    """The CSV cells of one column as pandas writes them (an Arrow string array, null for
    the empty cell), or None for a column this writer does not format (module docstring)."""
    dtype: Any = col.dtype
    if isinstance(dtype, np.dtype):
        if dtype == np.float64:
            return _float_cells(col.to_numpy())
        if dtype.kind in "iu":
            return pa.array(col.to_numpy()).cast(pa.string())
        if dtype.kind == "b":
            return pa.array(np.where(col.to_numpy(), "True", "False"), type=pa.string())
        if dtype.kind == "O":
            return _object_cells(col)
        return None
    if isinstance(dtype, pd.StringDtype):
        return _string_cells(col)
    return None


def _header(frame: pd.DataFrame) -> str | None:
    names = list(frame.columns)
    if not all(isinstance(c, str) for c in names) or any(ch in c for c in names for ch in ',"\r\n'):
        return None
    return ",".join(names) + "\n"


def csv_bytes(frame: pd.DataFrame) -> bytes:
    """The UTF-8 bytes ``frame.to_csv(index=False, lineterminator="\\n")`` returns as text
    (module docstring)."""
    import pyarrow.csv as pcsv

    header = _header(frame) if frame.shape[1] > 1 else None
    cols = [column_cells(frame.iloc[:, j]) for j in range(frame.shape[1])] if header is not None else [None]
    if header is None or any(c is None for c in cols):
        return str(frame.to_csv(index=False, lineterminator="\n")).encode("utf-8")
    buf = io.BytesIO()
    buf.write(header.encode("utf-8"))
    if len(frame):
        table = pa.Table.from_arrays(cols, names=[f"c{j}" for j in range(len(cols))])
        pcsv.write_csv(table, buf, pcsv.WriteOptions(include_header=False, quoting_style="none"))
    return buf.getvalue()


def write_csv(frame: pd.DataFrame, path: Path) -> None:
    """Write ``frame`` as CSV to ``path``: the bytes of ``frame.to_csv(path, index=False,
    lineterminator="\\n")`` (UTF-8)."""
    Path(path).write_bytes(csv_bytes(frame))
