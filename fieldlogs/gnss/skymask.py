"""Sky masks: none, the west or east half of the sky, or an azimuth–elevation table.

A mask is a step function over azimuth bins [a_j, a_{j+1}) (degrees clockwise from north,
covering 0–360): a satellite at azimuth A and elevation E is blocked when E < e_j of its bin.
``west-half`` blocks 180° ≤ A < 360° at every elevation — the paper's experiment with
buildings on the west side (positioning rate 47 % → 93 %) [S002]; ``east-half`` the mirror.

A table file is CSV with columns ``azimuth_deg`` (bin start, increasing, first 0) and
``elevation_deg`` (mask elevation of that bin, 0–90; 90 blocks the bin entirely).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import BoolArray, FloatArray
from schemas.errors import InputError

_FULL = 90.0 + 1e-9


@dataclass(frozen=True)
class SkyMask:
    """Azimuth bin starts and mask elevations [deg] (module docstring)."""

    az_start_deg: FloatArray
    min_el_deg: FloatArray

    def blocked(self, az_rad: FloatArray, el_rad: FloatArray) -> BoolArray:
        az = np.mod(np.degrees(np.asarray(az_rad, dtype=float)), 360.0)
        j = np.clip(np.searchsorted(self.az_start_deg, az, side="right") - 1, 0, self.az_start_deg.size - 1)
        return np.asarray(np.degrees(np.asarray(el_rad, dtype=float)) < self.min_el_deg[j], dtype=bool)


def no_mask() -> SkyMask:
    return SkyMask(np.array([0.0]), np.array([-90.0]))


def west_half() -> SkyMask:
    return SkyMask(np.array([0.0, 180.0]), np.array([-90.0, _FULL]))


def east_half() -> SkyMask:
    return SkyMask(np.array([0.0, 180.0]), np.array([_FULL, -90.0]))


def mask_from_table(table: pd.DataFrame, source: str = "sky mask") -> SkyMask:
    """A mask from a table (module docstring); errors name the source, row and column."""
    for col in ("azimuth_deg", "elevation_deg"):
        if col not in table.columns:
            raise InputError("missing column", path=source, column=col)
    az = pd.to_numeric(table["azimuth_deg"], errors="coerce").to_numpy(float)
    el = pd.to_numeric(table["elevation_deg"], errors="coerce").to_numpy(float)
    for col, vals, lo, hi in (("azimuth_deg", az, 0.0, 360.0), ("elevation_deg", el, 0.0, 90.0)):
        bad = np.flatnonzero(
            ~np.isfinite(vals) | (vals < lo) | (vals > hi)
            if col == "elevation_deg"
            else ~np.isfinite(vals) | (vals < lo) | (vals >= hi)
        )
        if bad.size:
            raise InputError(
                f"value {table[col].iloc[bad[0]]!r} outside [{lo:g}, {hi:g}]",
                path=source,
                row=int(bad[0]) + 2,
                column=col,
            )
    if az.size == 0 or az[0] != 0.0 or np.any(np.diff(az) <= 0):
        raise InputError("azimuths must start at 0 and increase", path=source, column="azimuth_deg")
    return SkyMask(az, np.where(el >= 90.0, _FULL, el))


def load_mask(spec: str | Path) -> SkyMask:
    """'none', 'west-half', 'east-half' or a CSV table path."""
    named = {"none": no_mask, "west-half": west_half, "east-half": east_half}
    if str(spec) in named:
        return named[str(spec)]()
    path = Path(spec)
    try:
        table = pd.read_csv(path)
    except (OSError, ValueError, pd.errors.ParserError) as exc:
        raise InputError(f"cannot read sky mask table ({exc.__class__.__name__})", path=path) from None
    return mask_from_table(table, str(path))
