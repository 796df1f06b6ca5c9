"""Rolling back without a two-phase tachometer: the IMU tells the sense [S003 §2, §5.3(2)].

An older tachometer counts pulses whatever the sense of rotation (the tacho has no
``direction`` column), so a train rolling back r metres on a gradient before it moves off
has its travel counted forward: the position runs 2·r ahead of the truth, and a GPS initial
position taken while it rolls back gets the km direction the wrong way round. The driving cab
(our ``cab`` stream, S003 §4.1(5)) says where the train is *meant* to go, not where it goes.

The IMU's longitudinal acceleration does know. At every **start from rest** (a standstill of
at least :data:`STANDSTILL_S` without a pulse, followed by pulses):

* the acceleration at rest a₀ (mean ``ax`` over the last :data:`REST_S` of the standstill) is
  gravity's component along the body on the gradient plus the sensor's bias; over the few
  metres of a start both stay the same, so a_x − a₀ is the body's acceleration toward its F end;
* its integral from just before the first pulse, v_I(k) = Σ_{j=k₀}^{k} (a_x,j − a₀)·Δt_j, is the
  body's velocity toward F (+) or R (−);
* the start's low-speed part: pulse speed ≤ :data:`LOW_SPEED_MPS` and travel ≤ :data:`JUDGE_M`.
  When the whole movement is that slow and ends at rest again (a roll back, then the brakes),
  the velocity is 0 at both ends: the drift of v_I (a₀'s error, the gradient's change) is
  removed as a ramp v_I(k) − v_I(end)·(k − k₀ + 1)/(end − k₀) (a zero-velocity update), and
  the whole movement is judged; otherwise its first :data:`JUDGE_S` seconds are;
* the least-squares ratio ρ = Σ v_I·v_p / Σ v_p² against the unsigned pulse speed v_p is ≈ +c
  when the train moves as its cab c (±1) says and ≈ −c when it rolls back;
* ρ·c ≤ −:data:`AGAINST_RATIO` with at least :data:`MIN_DISTANCE_M` of pulses in the low-speed
  part: a **rollback** — the whole movement when it ended at rest, else from the first pulse
  until v_I changes sign (the train stops rolling back and moves off) or the low-speed part ends.

:func:`inferred_rotation` turns the rollbacks into the sense of motion a two-phase tachometer
would have given (−c over the rollback, c on the other cycles that moved, 0 at rest), so the
odometry and the hypotheses subtract the roll back (:attr:`Cycles.motion`); and since the
sense now rests on an inference, the ``rollback`` aid (:mod:`fieldlogs.pipeline.aids.rollback`)
makes the position *uncertain* (fail-safe) from the rollback's end until the next absolute fix,
with the ``rollback_suspected`` event. A run whose tacho has the ``direction`` column, or
without IMU, is not examined.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from fieldlogs.pipeline.cycles import Cycles

STANDSTILL_S = 1.0
"""A start from rest follows at least this long without a pulse [s]."""
REST_S = 2.0
"""The acceleration at rest a₀ is the mean over at most this much of the standstill [s]."""
LOW_SPEED_MPS = 2.0
"""The start is judged while the pulse speed stays at or below this [m/s]."""
JUDGE_M = 20.0
"""... and over at most this much pulse travel [m]."""
JUDGE_S = 8.0
"""... and, unless the start ends at rest again within it, over its first this many seconds [s]."""
MIN_DISTANCE_M = 0.5
"""Less pulse travel than this in the judged part: no judgement [m]."""
AGAINST_RATIO = 0.5
"""ρ·c at or below −this: the IMU says the train moves against its cab."""
LEAD_CYCLES = 3
"""The integration starts this many cycles before the first pulse (motion precedes it)."""


@dataclass(frozen=True)
class Rollback:
    """One start that rolled back against the cab (cycle indices into the run's cycles)."""

    first: int
    """First cycle of the rollback (its first pulse)."""
    last: int
    """Last cycle of the rollback."""
    t_start: float
    t_end: float
    distance_m: float
    """Pulse travel over the rollback [m]."""
    ratio: float
    """ρ·c of the start (≈ −1)."""


@dataclass(frozen=True)
class _Trace:
    """The per-cycle arrays every start is judged on, computed once per run: judging a start
    reads only a few seconds around it, so the detection costs O(cycles + starts) and not
    O(cycles · starts) (a 24 h run has thousands of starts)."""

    v: npt.NDArray[np.float64]
    """Pulse speed, NaN as 0 [m/s]."""
    d: npt.NDArray[np.float64]
    """Pulse distance [m]."""
    dt: npt.NDArray[np.float64]
    """Cycle length [s]."""
    ax: npt.NDArray[np.float64]
    cab: npt.NDArray[np.int8]
    t: npt.NDArray[np.float64]
    step: float
    """The run's median cycle length [s] (not below 1 ms)."""
    last_moving: npt.NDArray[np.int64]
    """Index of the last cycle with v > 0 at or before each cycle, −1 before the first."""

    @classmethod
    def of(cls, cycles: Cycles) -> _Trace:
        v = np.nan_to_num(cycles.v_pulse, nan=0.0)
        dt = cycles.dt
        idx = np.where(v > 0, np.arange(v.size), -1)
        last = np.maximum.accumulate(idx) if idx.size else idx
        step = max(float(np.median(dt)), 1e-3)
        return cls(v, cycles.d_pulse, dt, cycles.imu["ax"], cycles.cab, cycles.t, step, last)

    def cycles_of(self, seconds: float) -> int:
        """``seconds`` in whole cycles of the median length."""
        return round(seconds / self.step)


def _starts(v: npt.NDArray[np.float64], rest: int) -> list[tuple[int, int]]:
    """(first moving cycle, end of its stretch) of every start after ≥ ``rest`` cycles at rest;
    the stretch ends at the next standstill of ≥ ``rest`` cycles (or the run's end).

    With s(j) true where cycles j … j + rest − 1 are all at rest (a prefix sum of the cycles at
    rest), a start is a first moving cycle i₀ ≥ rest with s(i₀ − rest), and its end the first j
    ≥ i₀ with s(j), found by a binary search in the sorted j with s(j)."""
    moving = v > 0
    n = v.size
    if n <= rest:
        return []
    at_rest = np.concatenate(([0], np.cumsum(~moving)))
    still = at_rest[rest:] - at_rest[: n - rest + 1] == rest  # s(j), j = 0 … n − rest
    edges = np.flatnonzero(np.diff(moving.astype(np.int8)) == 1) + 1
    edges = edges[edges >= rest]
    starts = edges[still[edges - rest]]
    still_at = np.flatnonzero(still)
    nxt = np.searchsorted(still_at, starts)
    ends = np.where(nxt < still_at.size, still_at[np.minimum(nxt, still_at.size - 1)], n)
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _judge(tr: _Trace, i0: int, end: int) -> Rollback | None:
    """The start at cycle ``i0`` (stretch up to ``end``): a rollback or None."""
    ax, v, d, dt = tr.ax, tr.v, tr.d, tr.dt
    k0 = max(i0 - LEAD_CYCLES, 0)
    r0 = max(k0 - tr.cycles_of(REST_S), int(tr.last_moving[i0 - 1]) + 1)
    a0 = ax[r0:k0]
    if a0.size == 0 or not np.isfinite(a0).all():
        return None
    base = d[i0 - 1]
    low = (v[i0:end] <= LOW_SPEED_MPS) & (d[i0:end] - base <= JUDGE_M)
    stop = i0 + (int(np.argmin(low)) if not low.all() else end - i0)  # first cycle past the low part
    seg = ax[k0:stop]
    if stop <= i0 or not np.isfinite(seg).all() or d[stop - 1] - base < MIN_DISTANCE_M:
        return None
    v_i = np.cumsum((seg - float(a0.mean())) * dt[k0:stop])
    at_rest_after = stop == end < tr.t.size  # the whole stretch is slow and ends at rest: v = 0 there
    if at_rest_after:  # zero-velocity update: the integral's drift is a ramp ending at v_i(end)
        v_i = v_i - v_i[-1] * np.arange(1, v_i.size + 1) / v_i.size
    v_i = v_i[i0 - k0 :]
    vp = v[i0:stop]
    judged = slice(None) if at_rest_after else slice(0, max(tr.cycles_of(JUDGE_S), 1))
    c = float(tr.cab[i0])
    ratio = float(np.sum(v_i[judged] * vp[judged]) / max(float(np.sum(vp[judged] ** 2)), 1e-12)) * c
    if ratio > -AGAINST_RATIO:
        return None
    turned = np.flatnonzero(v_i * c >= 0)
    last = stop - 1 if at_rest_after or not turned.size else max(i0 + int(turned[0]) - 1, i0)
    return Rollback(i0, last, float(tr.t[i0]), float(tr.t[last]), float(d[last] - base), ratio)


def detect_rollbacks(cycles: Cycles) -> list[Rollback]:
    """The starts that rolled back against the cab (see the module docstring); none where the
    tacho gives the sense itself, or without tacho or IMU."""
    if cycles.rotation is not None or not (cycles.has_tacho and cycles.has_imu) or cycles.n < 2:
        return []
    tr = _Trace.of(cycles)
    found = (_judge(tr, i0, end) for i0, end in _starts(tr.v, max(tr.cycles_of(STANDSTILL_S), 1)))
    return [r for r in found if r is not None]


def inferred_rotation(cycles: Cycles, rollbacks: list[Rollback]) -> npt.NDArray[np.int8]:
    """The sense a two-phase tachometer would have given: −cab over the rollbacks, the cab's
    on the other cycles with pulses, 0 at rest (:func:`~fieldlogs.pipeline.cycles.tacho_motion`
    keeps the last sense there)."""
    moved = np.nan_to_num(cycles.v_pulse, nan=0.0) > 0
    rot = np.where(moved, cycles.cab, 0).astype(np.int8)
    for r in rollbacks:
        rot[r.first : r.last + 1] = -cycles.cab[r.first : r.last + 1]
    return rot
