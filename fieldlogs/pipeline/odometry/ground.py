"""Stage 1b: an independent ground speed (the radar [S004]) on the aligned cycles.

Not in S000, whose odometry has pulses and an IMU only. A speed aid
(:class:`~fieldlogs.pipeline.aid.SpeedOnCycles`) gives |V_G| ± σ on the output grid. Like the
pulses (both measure the present, the IMU lags), it is delayed D cycles onto the IMU, so
aligned index k holds pulses, ground speed and IMU of one instant.

Direction check
    With a signed speed (+ toward the F end), the travel-frame speed is V_G·cab. Where it is
    below −AGAINST_Z·σ the vehicle moves against the cab's direction by the radar — rolling
    back, or a radar whose ``looks_toward`` is wrong: those cycles are not used
    (``against``), since the pulses (unsigned) and the cab then disagree with it.

1 s means
    ``v1`` is the trailing 1 s mean (the window of ``vp1``), only where the whole window has
    values; its 1σ is σ̄/√(P/n_c) with σ̄² the window mean of σ² and n_c = max(frame/Δt, 1)
    the cycles that share one frame's error, so a 1 s mean holds P/n_c independent frames.

Tolerance between pulses and ground speed
    ``tolerance(g, cfg, v, sd)`` = ``readhesion_tol_kmh`` (pulse quantisation of a 1 s mean)
    + WEAR_SHARE·v (the pulses' scale: the wheel's wear within its limit) + the ground
    speed's own ``sd``: slip detection, re-adhesion and the fail-safe watch compare the 1 s
    mean pulse speed with it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.pipeline.aid import SpeedOnCycles
from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.cycles import delay, trailing_sum
from fieldlogs.pipeline.odometry.signals import BoolArray, ma, readonly
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.types import FloatArray

#: Share of the speed by which the pulses' scale may be off (wheel wear within its limit) [–].
WEAR_SHARE = 0.005
#: Travel-frame speed below −AGAINST_Z·σ: moving against the cab's direction [–].
AGAINST_Z = 3.0
#: 1σ of the ground speed's systematic error, which its per-frame σ does not contain (the
#: radar's mean error is +0.002 … +0.007 m/s at every speed: bench/NOTES.md) [m/s].
GROUND_BIAS_MPS = 0.005


@dataclass(frozen=True, eq=False)
class GroundSpeed:
    """The ground speed of one run; aligned arrays (k ↔ output cycle k − delay) and the
    output-grid ones; read-only."""

    source: str
    v: FloatArray
    """|V_G| on the aligned cycles, NaN where none or against the cab [m/s]."""
    sigma: FloatArray
    """Its 1σ [m/s]."""
    n_corr: float
    """Cycles sharing one measurement error (≥ 1)."""
    v1: FloatArray
    """Trailing 1 s mean where the whole window has values (NaN elsewhere) [m/s]."""
    sigma1: FloatArray
    """Its 1σ [m/s]."""
    out_v: FloatArray
    """|V_G| on the output grid (NaN where none or against the cab) [m/s]."""
    out_sigma: FloatArray
    against: BoolArray
    """Output cycles at which the signed speed says the vehicle moves against the cab."""
    pulse_m: float
    """One pulse [m] (0 without motion)."""

    @property
    def covered(self) -> BoolArray:
        """Aligned cycles with a ground speed."""
        out: BoolArray = np.isfinite(self.v)
        return out


def tolerance(cfg: OdometryConfig, v: FloatArray, sd: FloatArray, z: float) -> FloatArray:
    """Allowed |1 s pulse − ground speed| while adhering: quantisation + wear + z·sd [m/s]."""
    out: FloatArray = cfg.readhesion_tol_kmh / 3.6 + WEAR_SHARE * np.abs(v) + z * sd
    return out


def align_ground(s: AlignedStreams, speed: SpeedOnCycles, pulse_m: float = 0.0) -> GroundSpeed:
    """Stage 1b: the speed aid's values checked for direction, delayed onto the IMU, and
    their 1 s means; ``pulse_m``: one pulse [m] (0: unknown, then the smallest step of the
    pulse distance stands in for it)."""
    n = s.n
    v = np.abs(np.asarray(speed.v_mps, dtype=float))[:n]
    sd = np.asarray(speed.sigma_mps, dtype=float)[:n]
    ok = np.isfinite(v) & np.isfinite(sd)
    against = np.zeros(n, dtype=bool)
    if speed.signed_mps is not None:
        with np.errstate(invalid="ignore"):
            travel = np.asarray(speed.signed_mps, dtype=float)[:n] * s.sgn
            against = ok & (travel < -AGAINST_Z * sd)
    ok &= ~against
    v, sd = np.where(ok, v, np.nan), np.where(ok, sd, np.nan)
    n_corr = max(speed.frame_s / s.cyc, 1.0)
    va, sa = delay(v, s.delay), delay(sd, s.delay)
    p = s.filters.P
    full = trailing_sum(np.isfinite(va), p) == p
    v1 = np.where(full, ma(np.nan_to_num(va), p), np.nan)
    s1 = np.where(full, np.sqrt(ma(np.nan_to_num(sa) ** 2, p) / max(p / n_corr, 1.0)), np.nan)
    return GroundSpeed(
        source=speed.source,
        v=readonly(va),
        sigma=readonly(sa),
        n_corr=n_corr,
        v1=readonly(v1),
        sigma1=readonly(s1),
        out_v=readonly(v),
        out_sigma=readonly(sd),
        against=readonly(against),
        pulse_m=pulse_m if pulse_m > 0 else _pulse_step(s.d_pulse),
    )


def metres_per_pulse(pulses: FloatArray, d_pulse: FloatArray) -> float:
    """One pulse [m] from the run's counts and distances (0 without any pulse)."""
    ok = np.isfinite(pulses)
    if ok.sum() < 2:
        return 0.0
    p, d = pulses[ok], d_pulse[ok]
    count = float(p[-1] - p[0])
    return float(d[-1] - d[0]) / count if count > 0 else 0.0


def _pulse_step(d_pulse: FloatArray) -> float:
    """The smallest positive step of the pulse distance (one pulse when the run has a
    slow cycle, else an upper bound of it)."""
    step = np.diff(d_pulse)
    step = step[step > 1e-9]
    return float(step.min()) if step.size else 0.0
