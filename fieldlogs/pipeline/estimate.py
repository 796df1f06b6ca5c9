"""Dead reckoning between absolute fixes, and the travel it runs on.

With the corrected unsigned travel d (odometry, never decreasing) and the sense of motion m
(+1 toward the vehicle's F end, −1 toward its R end: the driving cab's direction, or a
two-phase tachometer's sense where the run has one — :attr:`fieldlogs.pipeline.cycles.Cycles.motion`),
the signed body-forward travel is

    S(t) = Σ m·Δd,

and from a fix (km_m, k, s_ref) the position is

    km(t) = km_of_c( c_of_km(km_m) + k·(S(t) − s_ref) ),

where c is the cumulative length of the fix's track on the GIS grid
(:mod:`fieldlogs.pipeline.metric`): the wheels roll the track's own length, which in a
curve differs from the km difference of a double-track line's shared kilometrage. k = ±1
is the sign of km per metre of forward travel set by the aid that made the fix, so a cab
reversal after the fix is followed without a new fix [S003 §5.3].
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from dbtools.network import Network
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.metric import IDENTITY, TrackMetric, track_metric
from fieldlogs.pipeline.types import Fix, FloatArray, Odometry

Metric = Callable[[Fix], TrackMetric]


def signed_travel(cycles: Cycles, odo: Odometry) -> FloatArray:
    """S = Σ m·Δd: travel toward the vehicle's F end (+) or R end (−), m the sense of motion."""
    dd = np.diff(odo.d, prepend=odo.d[0] if odo.d.size else 0.0)
    return np.cumsum(cycles.motion.astype(float) * dd)


def km_along(fix: Fix, s: FloatArray | float, m: TrackMetric, c_ref: FloatArray | None = None) -> FloatArray:
    """Dead reckoning from ``fix``: travel S − S_ref along the track's own length, as km
    (``c_ref``: ``m.c_of_km(fix.km_m)`` when known)."""
    c0 = m.c_of_km(fix.km_m) if c_ref is None else c_ref
    return m.km_of_c(c0 + fix.k * (np.asarray(s, dtype=float) - fix.s_ref))


@dataclass(frozen=True)
class Travel:
    """The run's travel on the cycle grid: what the engine dead-reckons on."""

    t: FloatArray
    d: FloatArray
    """Corrected unsigned travel [m]."""
    s: FloatArray
    """Signed body-forward travel S [m]."""
    v: FloatArray
    """Corrected speed [m/s]."""
    cab: np.ndarray
    """The driving cab: +1 toward the F end, −1 reversed."""
    on_track: np.ndarray
    """True where the vehicle is on the track (PTO on for road-rail vehicles; trains always)."""
    allowance: FloatArray
    """Cumulative slip-correction error budget (eq. 13) [m]."""
    network: Network | None = None
    """With a network, dead reckoning runs along each track's own length."""
    rotation_motion: np.ndarray | None = None
    """The sense of motion where a two-phase tachometer gives it (None: the cab's)."""
    _at: dict[float, tuple[int, float, float]] = field(default_factory=dict, init=False, repr=False, compare=False)
    """:meth:`at` of the times already asked (the aids of one fix time share it)."""
    _allow: dict[float, float] = field(default_factory=dict, init=False, repr=False, compare=False)
    _refs: dict[int, tuple[Fix, TrackMetric, FloatArray]] = field(
        default_factory=dict, init=False, repr=False, compare=False
    )
    """Per fix (by id, the fix kept): its metric and ``c_of_km(km_m)`` (:meth:`km`)."""

    @classmethod
    def of(cls, cycles: Cycles, odo: Odometry, network: Network | None = None) -> Travel:
        on_track = np.asarray(cycles.pto) != 0
        s = signed_travel(cycles, odo)
        motion = None if cycles.rotation is None else cycles.motion
        return cls(cycles.t, odo.d, s, odo.v, cycles.cab, on_track, odo.allowance, network, motion)

    @property
    def motion(self) -> np.ndarray:
        """Sense of motion per cycle (+1 toward the F end): :attr:`Cycles.motion`."""
        return self.cab if self.rotation_motion is None else self.rotation_motion

    @property
    def n(self) -> int:
        return int(self.t.size)

    def metric(self, fix: Fix) -> TrackMetric:
        if self.network is None or not fix.line_code:
            return IDENTITY
        return track_metric(self.network, fix.line_code, fix.track)

    def km(self, fix: Fix, s: FloatArray | float) -> FloatArray:
        """km of ``fix`` dead-reckoned to signed travel ``s`` (its metric and rolled length at
        the fix made once per fix: the engine's aids read the estimate many times)."""
        ref = self._refs.get(id(fix))
        if ref is None or ref[0] is not fix:
            m = self.metric(fix)
            ref = self._refs[id(fix)] = (fix, m, m.c_of_km(fix.km_m))
        return km_along(fix, s, ref[1], ref[2])

    def at(self, t: float) -> tuple[int, float, float]:
        """Cycle index at or after ``t`` and the travel d, S interpolated at ``t`` (remembered:
        several aids are heard at one time)."""
        hit = self._at.get(t)
        if hit is None:
            i = min(int(np.searchsorted(self.t, t, side="left")), self.t.size - 1)
            hit = self._at[t] = (i, interp_at(t, self.t, self.d), interp_at(t, self.t, self.s))
        return hit

    def prime(self, ts: FloatArray) -> None:
        """Remember :meth:`at` and :meth:`allowance_at` of many times at once (the aids' known moments): vectorised, the
        same numbers (``searchsorted`` and ``np.interp`` are elementwise; :func:`interp_at` is
        ``np.interp`` of one time)."""
        ts = np.unique(np.asarray(ts, dtype=float))
        ts = ts[np.isfinite(ts)]
        if self.t.size < 2 or ts.size == 0:
            return
        i = np.minimum(np.searchsorted(self.t, ts, side="left"), self.t.size - 1)
        d, s = np.interp(ts, self.t, self.d), np.interp(ts, self.t, self.s)
        keys = ts.tolist()
        self._at.update(zip(keys, zip(i.tolist(), d.tolist(), s.tolist(), strict=True), strict=True))
        self._allow.update(zip(keys, np.interp(ts, self.t, self.allowance).tolist(), strict=True))

    def allowance_at(self, t: float) -> float:
        hit = self._allow.get(t)
        if hit is None:
            hit = self._allow[t] = interp_at(t, self.t, self.allowance)
        return hit


def interp_at(x: float, xp: FloatArray, fp: FloatArray) -> float:
    """``np.interp(x, xp, fp)`` for one ``x``, from the two samples around it only: the same
    number (np.interp also interpolates between the last ``xp ≤ x`` and the next one), in
    O(log n) instead of O(n) per call."""
    n = xp.size
    j = int(np.searchsorted(xp, x, side="right")) - 1
    if not np.isfinite(x) or n < 2:
        return float(np.interp(x, xp, fp))
    if j < 0:
        return float(fp[0])
    if j >= n - 1:
        return float(fp[-1])
    return float(np.interp(x, xp[j : j + 2], fp[j : j + 2]))
