"""Stage 4: the fail-safe watch (``failsafe_watch_s``).

Not in the papers, which end a correction at the fail-safe. After a fail-safe the wheel may
still be slipping while the distance runs on its pulses. The integration goes on for up to
``failsafe_watch_s`` and its 1 s mean speed is compared with the 1 s mean pulse speed as in
the re-adhesion test; until they have agreed for ``readhesion_hold_s`` the allowance grows
per second by |v − v_pulse| + the speed's own error bound (Δa·t from the start point,
eq. 13's model), and detections (and residual references) inside the watch belong to the
same disturbance (stage 3 ignores them). Why: a deep slide going on past its fail-safe
otherwise leaves an error far beyond the margin, and a new correction started from the
still-sliding pulses doubles it (bench/NOTES.md, "Odometry").

With a ground speed (the radar [S004]) the watch compares with the radar's 1 s mean
instead (:func:`.fusion.agreement`: its gaps bridged by the filtered speed), within its
tolerance and with its own error bound AGREE_Z·σ: the radar does not drift, so the
allowance grows by the pulses' loss, not by Δa·t (which comes back only over the radar's
gaps).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.fusion import Fusion, agreement
from fieldlogs.pipeline.odometry.integration import Integration
from fieldlogs.pipeline.odometry.signals import IntArray, held, ma, readonly
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.types import FloatArray, SpeedSource


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
    s: AlignedStreams, cfg: OdometryConfig, ig: Integration, ie: int, after: int | None = None
) -> Watch | None:
    """Watch of the correction ``ig`` that failed safe at aligned cycle ``ie``: from ie on,
    compare the 1 s mean inertial speed of its integration with the 1 s mean pulse speed
    (agreement counted only after aligned cycle ``after``, when given: a detection's).
    None when the watch has no room (data end)."""
    t, p, i0 = s.t, s.filters.P, ig.i0
    lead = s.vp[max(i0 - p + 1, 0) : i0]
    v1 = ma(np.concatenate([lead, ig.v_in]), p)[lead.size + ie - i0 :]
    k = np.arange(ie, ie + v1.size)  # aligned cycles; output cycle = k − D
    out = k - s.delay
    if v1.size < 2 or out[0] - p + 1 < 0:
        return None
    tt = t[k] - t[i0]
    own = cfg.delta_a_mps2 * tt
    tol = readhesion_tolerance(cfg) + cfg.beta_mps2 * tt
    return _watch(s, cfg, ie, out, np.abs(v1 - s.vp1[k]), tol, own, "inertial", 0 if after is None else after - ie)


def watch_fused(s: AlignedStreams, cfg: OdometryConfig, f: Fusion, ie: int) -> Watch | None:
    """Watch of a correction fused with a ground speed that failed safe at aligned cycle
    ``ie``: its filtered speed (1 s means) against the pulses for ``failsafe_watch_s``."""
    p, i0 = s.filters.P, f.i0
    a = agreement(s, cfg, f, s.vp[max(i0 - p + 1, 0) : i0])
    m0 = ie - i0
    m1 = min(f.size, m0 + round(cfg.failsafe_watch_s / s.cyc) + 1)
    k = np.arange(ie, i0 + m1)
    out = k - s.delay
    if k.size < 2 or out[0] - p + 1 < 0:
        return None
    dv = np.abs(a.v1[m0:m1] - s.vp1[k])
    w = _watch(s, cfg, ie, out, dv, a.tol[m0:m1], a.own[m0:m1], "inertial")
    if f.used[m0 : m0 + w.cycles.size + 1].any():
        return Watch(w.end, w.cycles, w.grow, w.readhered, "radar")
    return w


def _watch(
    s: AlignedStreams,
    cfg: OdometryConfig,
    ie: int,
    out: IntArray,
    dv: FloatArray,
    tol: FloatArray,
    own: FloatArray,
    source: SpeedSource,
    quiet: int = 0,
) -> Watch:
    """The watch from aligned cycle ``ie`` (output cycles ``out``): it ends where |Δv| ≤ tol
    held ``readhesion_hold_s`` (not on its first ``quiet`` + 1 cycles); the allowance grows by
    (|Δv| + own)·dt until then."""
    with np.errstate(invalid="ignore"):
        ok = held(dv <= tol, hold_cycles(cfg, s.cyc))
    ok[: max(quiet, 0) + 1] = False
    hit = np.flatnonzero(ok)
    j = int(hit[0]) if hit.size else dv.size - 1
    grow = np.cumsum((dv + own)[1 : j + 1] * s.dt[out[1 : j + 1]])
    return Watch(ie + j, readonly(out[1 : j + 1]), readonly(grow), bool(hit.size), source)
