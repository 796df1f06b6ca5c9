"""Helpers shared by the rule modules: locating rows in source files, capped finding lists,
Python scalars for finding keys, angle and kilometrage formatting."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from schemas.enums import Severity
from schemas.findings import Finding
from schemas.units import format_km


@dataclass(frozen=True)
class Locator:
    """Where a row of a table came from: file and 1-based line (source sets only)."""

    files: Mapping[str, str] = field(default_factory=dict)
    rows: Mapping[str, npt.NDArray[np.int64]] = field(default_factory=dict)

    def file(self, table: str) -> str | None:
        return self.files.get(table)

    def at(self, table: str, pos: int | None) -> dict[str, Any]:
        """``{"file": …, "row": …}`` for Finding(**…); empty for a DB."""
        file = self.files.get(table)
        if file is None:
            return {}
        lines = self.rows.get(table)
        row = int(lines[pos]) if pos is not None and lines is not None and 0 <= pos < len(lines) else None
        return {"file": file, "row": row}


def py(v: Any) -> Any:
    """A plain Python scalar (None for missing) for finding keys and values."""
    if v is None or v is pd.NA:
        return None
    if isinstance(v, float | np.floating):
        return None if np.isnan(v) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def column(frame: pd.DataFrame, name: str) -> npt.NDArray[Any]:
    """A column as a NumPy array: float64 (NaN for missing) or object (None for missing)."""
    s = frame[name]
    if pd.api.types.is_float_dtype(s.dtype):
        return s.to_numpy(dtype=np.float64, na_value=np.nan)
    if pd.api.types.is_integer_dtype(s.dtype):
        return s.to_numpy(dtype=np.float64, na_value=np.nan)
    if isinstance(s.dtype, pd.StringDtype):  # the same values in one pass
        return np.asarray(s.array.to_numpy(dtype=object, na_value=None), dtype=object)
    return s.astype(object).where(s.notna(), None).to_numpy(dtype=object)


def group_ids(frame: pd.DataFrame, names: Sequence[str]) -> npt.NDArray[np.int64]:
    """The group of each row by its values of the columns ``names``, numbered in the order the
    groups first appear (``groupby(…, sort=False).ngroup()``); −1 where any of them is missing.
    Grouped on the frame's own typed columns: on their object copies (:func:`column`) pandas
    would first convert every text back to an Arrow string (4× the time: 52,000 balises 42 ms)."""
    out = np.full(len(frame), -1, dtype=np.int64)
    names = list(names)
    keyed = np.asarray(frame[names].notna().all(axis=1).to_numpy(), dtype=bool)
    if keyed.any():
        ids = frame.loc[keyed, names].groupby(names, sort=False, dropna=False).ngroup()
        out[keyed] = ids.to_numpy(dtype=np.int64)
    return out


def capped(
    rule: str,
    severity: Severity,
    table: str,
    items: Sequence[int] | npt.NDArray[np.int64],
    build: Callable[[int], Finding],
    cap: int,
    file: str | None = None,
) -> list[Finding]:
    """``build(i)`` for the first ``cap`` items, then one finding counting the rest."""
    out = [build(int(i)) for i in items[:cap]]
    if len(items) > cap:
        out.append(
            Finding(
                rule,
                severity,
                table,
                f"{len(items) - cap} more of the same (only the first {cap} are listed)",
                value=len(items),
                limit=cap,
                file=file,
            )
        )
    return out


def fmt_km(km: float) -> str:
    """Kilometrage for messages: ``12k345.6``."""
    return format_km(float(km))


def isin(values: npt.ArrayLike, known: npt.ArrayLike | set[Any]) -> npt.NDArray[np.bool_]:
    """``values[i] in known`` for text ids, by a hash look-up (``np.isin`` on object arrays
    sorts and compares Python objects: seconds for 10⁵ ids)."""
    index = pd.Index(pd.unique(np.asarray(list(known) if isinstance(known, set) else known, dtype=object)))
    return np.asarray(index.get_indexer(np.asarray(values, dtype=object)) >= 0, dtype=bool)


def texts(s: pd.Series) -> npt.NDArray[np.object_]:
    """A text column as an object array with None (never pd.NA) for missing values."""
    return np.asarray(s.astype(object).where(s.notna(), None).to_numpy(dtype=object), dtype=object)
