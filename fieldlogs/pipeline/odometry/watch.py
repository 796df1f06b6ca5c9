"""Stage 4: the fail-safe watch (``failsafe_watch_s``).

Not in the papers, which end a correction at the fail-safe. After a fail-safe the wheel may
still be slipping while the distance runs on its pulses. The integration goes on (radar
where it covers the watch) for up to ``failsafe_watch_s`` and its 1 s mean speed is
compared with the 1 s mean pulse speed as in the re-adhesion test; until they have agreed
for ``readhesion_hold_s`` the allowance grows per second by |v − v_pulse| + the speed's own
error bound (Δa·t from the start point, eq. 13's model; radar 1 % of v), and detections
(and residual references) inside the watch belong to the same disturbance (stage 3 ignores
them). Why: a deep slide going on past its fail-safe otherwise leaves an error far beyond
the margin, and a new correction started from the still-sliding pulses doubles it
(bench/NOTES.md, "Odometry").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.integration import Integration
from fieldlogs.pipeline.odometry.signals import IntArray, held, ma, readonly
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.types import FloatArray, SpeedSource

if TYPE_CHECKING:
    from fieldlogs.pipeline.odometry.episodes import Episode

#: Error budget of a radar-measured speed: this share of it [%] (and of a radar-bridged
#: episode's distance, plus RADAR_ERROR_M).
RADAR_ERROR_PCT = 1.0
RADAR_ERROR_M = 0.5


@dataclass(frozen=True, eq=False)
class Watch:
    """The fail-safe watch of one fail-safe episode."""

    end: int
    """Aligned cycle at which the watch ends (re-adhesion, or its time limit)."""
    cycles: IntArray
    """Output cycles after the fail-safe up to the end."""
    grow: FloatArray
    """Cumulative allowance growth on those cycles [m]."""
    readhered: bool
    source: SpeedSource


def readhesion_tolerance(cfg: OdometryConfig) -> float:
    """Constant part of the re-adhesion tolerance [m/s]."""
    return cfg.readhesion_tol_kmh / 3.6


def hold_cycles(cfg: OdometryConfig, cyc: float) -> int:
    """``readhesion_hold_s`` in cycles."""
    return max(round(cfg.readhesion_hold_s / cyc), 1)


def watch_failsafe(
    s: AlignedStreams, cfg: OdometryConfig, ig: Integration, ie: int, radar: FloatArray | None = None
) -> Watch | None:
    """Watch of the correction ``ig`` that failed safe at aligned cycle ``ie``: from ie on,
    compare the 1 s mean inertial speed of its integration (the radar's where it covers the
    watch) with the 1 s mean pulse speed. None when the watch has no room (data end)."""
    t, p, i0 = s.t, s.filters.P, ig.i0
    lead = s.vp[max(i0 - p + 1, 0) : i0]
    v1 = ma(np.concatenate([lead, ig.v_in]), p)[lead.size + ie - i0 :]
    k = np.arange(ie, ie + v1.size)  # aligned cycles; output cycle = k − D
    out = k - s.delay
    if v1.size < 2 or out[0] - p + 1 < 0:
        return None
    tt = t[k] - t[i0]
    cover = slice(out[0] - p + 1, out[-1] + 1)
    use_radar = radar is not None and bool(np.isfinite(radar[cover]).all())
    tol0 = readhesion_tolerance(cfg)
    if use_radar:
        assert radar is not None
        v1 = ma(radar[cover].astype(float), p)[p - 1 :]
        own = RADAR_ERROR_PCT / 100.0 * v1
        tol = tol0 + own
    else:
        own = cfg.delta_a_mps2 * tt
        tol = tol0 + cfg.beta_mps2 * tt
    dv = np.abs(v1 - s.vp1[k])
    ok = held(dv <= tol, hold_cycles(cfg, s.cyc))
    ok[0] = False
    hit = np.flatnonzero(ok)
    j = int(hit[0]) if hit.size else v1.size - 1
    grow = np.cumsum((dv + own)[1 : j + 1] * s.dt[out[1 : j + 1]])
    return Watch(ie + j, readonly(out[1 : j + 1]), readonly(grow), bool(hit.size), "radar" if use_radar else "inertial")


def watch_failsafes(
    s: AlignedStreams, cfg: OdometryConfig, episodes: Sequence[Episode], radar: FloatArray | None
) -> tuple[Watch | None, ...]:
    """Stage 4: the watch of every fail-safe episode (None for the others, and for all
    when ``failsafe_watch_s`` is 0)."""
    on = cfg.failsafe_watch_s > 0
    return tuple(
        watch_failsafe(s, cfg, ep.integration, ep.i_end, radar) if on and ep.failsafe else None for ep in episodes
    )
