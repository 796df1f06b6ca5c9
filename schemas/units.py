"""Units and kilometrage notation.

Internally everything is SI (m, s, m/s, m/s², rad/s). The papers and railway staff use
km/h/s for acceleration and ``12k345.6`` for kilometrage; conversions live here only.
"""

from __future__ import annotations

import math
import re
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np
    import numpy.typing as npt

#: Standard gravity [m/s²].
G = 9.80665
#: 1 km/h/s in m/s².
KMH_PER_S = 1000.0 / 3600.0
#: 1 km/h in m/s.
KMH = 1000.0 / 3600.0
#: Speed of light in vacuum [m/s] (radar wavelength λ = c/f0 and range c·Δφ/(4π·Δf)).
SPEED_OF_LIGHT_MPS = 299_792_458.0

_KM_RE = re.compile(r"^\s*(-?)(\d+)[kK](\d{1,3}(?:\.\d*)?)\s*$")


def kmh_s_to_mps2(value: float) -> float:
    """km/h/s → m/s²."""
    return value * KMH_PER_S


def mps2_to_kmh_s(value: float) -> float:
    """m/s² → km/h/s."""
    return value / KMH_PER_S


def wheel_circumference_m(wheel_diameter_m: float) -> float:
    """Distance one wheel revolution rolls: π·D [m] (the nominal diameter of run.json)."""
    return math.pi * wheel_diameter_m


def metres_per_pulse(wheel_diameter_m: float, teeth: int) -> float:
    """Distance per tachometer pulse: k = π·D / teeth [m] (``teeth`` pulses per revolution).

    The one place the tacho's scale is defined: the pipeline's cycles, ``logs check`` and
    ``logs info``, the possession tacho and the simulator's pulse counter all use it.
    """
    return wheel_circumference_m(wheel_diameter_m) / teeth


def parse_km(text: str) -> float:
    """Parse kilometrage in metres: ``"12345.6"`` or railway notation ``"12k345.6"``.

    Raises ``ValueError`` when the text is neither.
    """
    m = _KM_RE.match(text)
    if m:
        sign, km, rest = m.groups()
        metres_str = rest.split(".")[0]
        if len(metres_str) != 3:
            raise ValueError(f"kilometrage {text!r}: expected three metre digits after 'k'")
        value = int(km) * 1000.0 + float(rest)
        return -value if sign else value
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"kilometrage {text!r} is not finite")
    return value


def parse_km_array(values: npt.ArrayLike) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_]]:
    """Vectorised :func:`parse_km` over strings; returns (metres, ok). Empty → NaN, ok."""
    import numpy as np  # local: units stays importable without numpy and pandas (CLI start-up)
    import pandas as pd

    arr = np.asarray(values, dtype=object)
    out = np.full(arr.shape, np.nan)
    ok = np.ones(arr.shape, dtype=bool)

    s = pd.Series(arr, dtype="object").astype("string").str.strip()
    num = pd.to_numeric(s, errors="coerce")
    out[:] = num.to_numpy(dtype=float, na_value=np.nan)
    empty = s.isna() | (s == "")
    todo = np.flatnonzero(np.isnan(out) & ~empty.to_numpy())
    for i in todo:  # only the (rare) rows in 12k345.6 notation or bad text
        try:
            out[i] = parse_km(str(arr[i]))
        except ValueError:
            ok[i] = False
    ok &= ~(np.isinf(out))
    return out, ok


def format_km(metres: float, decimals: int = 1) -> str:
    """Format metres in railway notation: 12345.6 → ``12k345.6``."""
    if metres is None or not math.isfinite(metres):
        return "—"
    sign = "-" if metres < 0 else ""
    m = round(abs(metres), decimals)
    km = int(m // 1000)
    rest = m - km * 1000
    width = 3 if decimals == 0 else 4 + decimals
    return f"{sign}{km}k{rest:0{width}.{decimals}f}"
