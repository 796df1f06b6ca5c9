"""The one JSON sanitiser: any value the suite emits → plain JSON data.

Every JSON the suite writes (events ``detail``, ``summary.json``, findings, possession and
GIS-verification results, audit records) goes through :func:`jsonable`, so the policy is
the same everywhere:

* numpy scalars and arrays → Python numbers, bools and lists; ``pd.NA``/``NaT`` → null;
* a NaN → null (a missing number); ±∞ → the strings ``"inf"``/``"-inf"`` (JSON has no
  infinity, and a silent null would hide an impossible value such as a wheel diameter of
  1e308 × 10);
* floats rounded to ``digits`` decimals when given (outputs people read), else kept;
* dict keys → strings; tuples and sets → lists (sets sorted); dates and times → ISO 8601;
  paths and anything else → ``str``.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Mapping
from datetime import date, datetime, time, timedelta
from enum import Enum
from pathlib import PurePath
from typing import Any


def jsonable(value: Any, digits: int | None = None) -> Any:
    """``value`` as JSON-ready data (see the module docstring for the policy)."""
    if value is None or isinstance(value, bool | str):
        return value
    if isinstance(value, Enum):
        return jsonable(value.value, digits)
    if isinstance(value, int):
        return int(value)
    if isinstance(value, float):
        return _float(value, digits)
    # numpy is never imported here (schemas stays light): a value can only be a numpy one
    # when numpy was imported by whoever made it
    np = sys.modules.get("numpy")
    if np is not None and isinstance(value, np.generic):
        return jsonable(value.item(), digits)
    if isinstance(value, Mapping):
        return {str(k): jsonable(v, digits) for k, v in value.items()}
    if isinstance(value, list | tuple) or (np is not None and isinstance(value, np.ndarray)):
        return [jsonable(v, digits) for v in value]
    if isinstance(value, set | frozenset):
        return [jsonable(v, digits) for v in sorted(value, key=str)]
    return _other(value, digits)


def _float(v: float, digits: int | None) -> float | str | None:
    if math.isnan(v):
        return None
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    return round(float(v), digits) if digits is not None else float(v)


def _other(value: Any, digits: int | None = None) -> Any:
    if _missing(value):
        return None
    if hasattr(value, "tolist"):  # pandas Series/Index and array-likes
        return jsonable(value.tolist(), digits)
    if isinstance(value, datetime | date | time) or hasattr(value, "isoformat"):  # also pd.Timestamp
        return value.isoformat()
    if isinstance(value, timedelta):
        return value.total_seconds()
    if isinstance(value, PurePath):
        return str(value)
    return str(value)


def _missing(value: Any) -> bool:
    """pd.NA and pd.NaT (pandas is not imported here: schemas stays light)."""
    return type(value).__name__ in ("NAType", "NaTType")
