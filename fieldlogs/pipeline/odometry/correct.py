""":func:`correct_odometry`: the stages of :mod:`fieldlogs.pipeline.odometry` (described there) in order."""

from __future__ import annotations

import numpy as np

from fieldlogs.pipeline.aid import SpeedOnCycles
from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.odometry.assembly import assemble
from fieldlogs.pipeline.odometry.detection import detect
from fieldlogs.pipeline.odometry.episodes import find_episodes
from fieldlogs.pipeline.odometry.ground import align_ground, metres_per_pulse
from fieldlogs.pipeline.odometry.ground_products import ground_products
from fieldlogs.pipeline.odometry.streams import align_streams
from fieldlogs.pipeline.types import Odometry, pulse_only_odometry


def correct_odometry(cycles: Cycles, cfg: OdometryConfig, ground: SpeedOnCycles | None = None) -> Odometry:
    """Pulse odometry with slip/slide episodes replaced by the inertial solution (SPEC §5.1).

    ``ground``: an independent ground speed on the cycle grid (the 2-frequency CW radar
    [S004]; NaN where there is none): stage 1b aligns it, stage 2 detects with it, stage 3
    fuses it with the inertial solution and tests re-adhesion on it, stage 4 watches on it
    and stage 6 adds the low-speed speed and the wheel calibration. Without IMU or tacho
    (or with fewer than 3 cycles): the pulse odometry.
    """
    if not cycles.has_imu or not cycles.has_tacho or cycles.n < 3:
        d_pulse = np.nan_to_num(np.asarray(cycles.d_pulse, dtype=float), nan=0.0)
        v_pulse = np.nan_to_num(np.asarray(cycles.v_pulse, dtype=float), nan=0.0)
        return pulse_only_odometry(d_pulse, v_pulse)
    streams = align_streams(cycles, cfg)
    g = None
    if ground is not None:
        pulses = np.asarray(cycles.pulses, dtype=float)
        g = align_ground(streams, ground, metres_per_pulse(pulses, np.asarray(cycles.d_pulse, dtype=float)))
    detections = detect(streams, cfg, g)
    episodes = find_episodes(streams, detections, cfg, g)
    odo = assemble(streams, detections, cfg, episodes)
    if g is None:
        return odo
    return ground_products(streams, g, cfg, odo, [ep.i_settled - streams.delay for ep in episodes])
