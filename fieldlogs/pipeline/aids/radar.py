"""A ready radar ground-speed stream (``radar``: t, speed_mps) as a speed aid [S004].

The 2-frequency CW radar measures the speed over ground independently of wheel slip and
slide; the odometry detects slips with it, carries their corrections on it and watches
fail-safes with it (``fieldlogs.pipeline.odometry``). Samples are interpolated onto the
cycle grid; a cycle farther than ``max_gap_s`` from a sample has none (NaN). Its 1σ is
RADAR_SIGMA_SHARE of the speed, at least RADAR_SIGMA_MIN_MPS (the stream says nothing of
its own errors, nor of the direction), and RADAR_CUTOFF_SIGMA_MPS next to a sample of 0: a
ready stream reads 0 below its cut-off speed, which is not a standstill the radar saw.
Consecutive cycles share an error over the stream's sample interval (``frame_s``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.pipeline.aid import SpeedOnCycles
from fieldlogs.pipeline.cycles import Cycles

#: 1σ of the ready radar speed, share of the speed [–] (S004: resolution 0.073 km/h).
RADAR_SIGMA_SHARE = 0.01
#: … and at least this [m/s].
RADAR_SIGMA_MIN_MPS = 0.05
#: 1σ next to a sample of 0 (below the stream's cut-off, ≈ 1 km/h) [m/s].
RADAR_CUTOFF_SIGMA_MPS = 0.3


@dataclass(frozen=True)
class RadarSpeedAid:
    """Speed aid from a ready ``radar`` stream."""

    stream: pd.DataFrame
    max_gap_s: float = 1.0
    name = "radar"

    def on_cycles(self, cycles: Cycles) -> SpeedOnCycles | None:
        radar = self.stream
        if radar is None or len(radar) < 2:
            return None
        t = cycles.t
        tr = radar["t"].to_numpy(dtype=float)
        v = radar["speed_mps"].to_numpy(dtype=float, na_value=np.nan)
        out = np.interp(t, tr, v)
        j = np.clip(np.searchsorted(tr, t), 1, len(tr) - 1)
        gap = np.minimum(np.abs(t - tr[j - 1]), np.abs(tr[j] - t))
        speed = np.where(gap <= self.max_gap_s, out, np.nan)
        sigma = np.maximum(RADAR_SIGMA_SHARE * np.abs(speed), RADAR_SIGMA_MIN_MPS)
        zero = np.interp(t, tr, (v == 0.0).astype(float)) > 0.0  # a 0 sample on either side
        sigma = np.where(zero, np.maximum(sigma, RADAR_CUTOFF_SIGMA_MPS), sigma)
        sigma[~np.isfinite(speed)] = np.nan
        return SpeedOnCycles(speed, sigma, self.name, frame_s=float(np.median(np.diff(tr))))
