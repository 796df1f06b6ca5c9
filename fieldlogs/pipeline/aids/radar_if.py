"""The radar's raw IF samples (``radar_if`` + the run.json ``radar`` block) as a speed aid [S004].

``fieldlogs.radar.speed.process_if`` turns the samples into one ground speed V_G per T_epi frame,
with its 1σ and a status; this aid puts the frames on the cycle grid:

* a cycle gets the frame covering it — the frame [c_j − T/2, c_j + T/2) (centre c_j, length
  T = N·2·T_pri) that contains the cycle's midpoint t_k − Δt_k/2, the middle of the span
  (t_{k−1}, t_k] its pulse speed is the mean of; a cycle no frame covers (before the first,
  after the last) has none;
* only frames with a speed count: ``ok`` frames give |V_G| ± σ, ``standstill`` frames 0 ± the
  lowest measurable speed; ``aliased``, ``low_quality`` (also the frames a gap in the samples
  leaves incomplete) and ``no_reflections`` frames give none, so no value is carried across
  a gap;
* the sign of V_G (+ toward the F end) is kept (``SpeedOnCycles.signed_mps``) for the
  odometry's direction check, and ``frame_s`` = T tells it that the ≈ 3 cycles of a frame
  share one error.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fieldlogs.pipeline.aid import SpeedOnCycles
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.types import FloatArray
from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.speed import RadarSpeed, process_if
from schemas.radar import RadarParams


def frame_length_s(params: RadarParams) -> float:
    """T = N·2·T_pri: the time one frame's samples span [s] (307 ms for Table 1)."""
    return params.samples_per_frame / params.sample_rate_hz


def frames_on_cycles(
    t_centre: FloatArray, speed: FloatArray, sigma: FloatArray, frame_s: float, t: FloatArray, dt: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Signed speed and σ of the frame covering each cycle's midpoint (NaN where none).

    Frames are consecutive (``fieldlogs.radar.framing``): frame j spans
    [c_j − T/2, c_j + T/2); a midpoint outside every span gets NaN."""
    n = t.size
    out_v, out_s = np.full(n, np.nan), np.full(n, np.nan)
    if t_centre.size == 0 or n == 0:
        return out_v, out_s
    start = t_centre - 0.5 * frame_s
    mid = t - 0.5 * dt
    j = np.searchsorted(start, mid, side="right") - 1
    inside = (j >= 0) & (mid < start[np.clip(j, 0, None)] + frame_s)
    jj = j[inside]
    out_v[inside] = speed[jj]
    out_s[inside] = sigma[jj]
    out_s[~np.isfinite(out_v)] = np.nan
    return out_v, out_s


@dataclass(frozen=True)
class RadarIfSpeedAid:
    """Speed aid from the ``radar_if`` samples of a run and its radar (run.json ``radar``)."""

    stream: pd.DataFrame
    params: RadarParams
    cfg: RadarConfig = field(default_factory=RadarConfig)
    name = "radar_if"

    def frames(self) -> RadarSpeed:
        """The ground speed of every frame (``fieldlogs.radar.speed.process_if``)."""
        f = self.stream
        t = f["t"].to_numpy(dtype=np.float64, na_value=np.nan)
        i1, q1, i2, q2 = (f[c].to_numpy(dtype=np.float32, na_value=np.nan) for c in ("i1", "q1", "i2", "q2"))
        return process_if(t, i1, q1, i2, q2, self.params, self.cfg)

    def on_cycles(self, cycles: Cycles) -> SpeedOnCycles | None:
        """The frames on the cycle grid; None when no frame has a speed."""
        rs = self.frames()
        speed = np.asarray(rs.columns["speed_mps"], dtype=float)
        if not np.isfinite(speed).any():
            return None
        t = np.asarray(cycles.t, dtype=float)
        frame_s = frame_length_s(self.params)
        signed, sigma = frames_on_cycles(
            np.asarray(rs.columns["t"], dtype=float),
            speed,
            np.asarray(rs.columns["sigma_mps"], dtype=float),
            frame_s,
            t,
            np.asarray(cycles.dt, dtype=float),
        )
        return SpeedOnCycles(np.abs(signed), sigma, self.name, signed_mps=signed, frame_s=frame_s)
