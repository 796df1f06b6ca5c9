"""Data passed between the pipeline's units: odometry, fixes (anchors), events."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal, TypeVar

import numpy as np
import numpy.typing as npt

from schemas.enums import EventType, FixSource, PositionState

if TYPE_CHECKING:
    from fieldlogs.pipeline.odometry.diagnostics import OdometryDiagnostics

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]
BoolArray = npt.NDArray[np.bool_]


SlipKind = Literal["slip", "slide"]
"""'slip': wheel faster than the train (traction); 'slide': slower (braking)."""
DetectionCriterion = Literal["ta", "residual", "residual-end", "radar"]
"""What detected an episode: eq. 1 (|a_x − A_p| > Ta), the grade-compensated residual at
the slip's onset, the residual at its end (a short shallow slip), or the pulses leaving the
radar's ground speed."""
SpeedSource = Literal["inertial", "radar"]
"""Where a correction's speed came from ("radar": the radar's ground speed, fused with the
inertial one by their variances and bridging the radar's gaps)."""


@dataclass(frozen=True)
class WheelCalibration:
    """The wheel diameter from the ground speed: true / nominal, with its 95 % interval."""

    ratio: float
    """r = ground distance / pulse distance over the adhering stretches [–]."""
    half_width: float
    """95 % half-width of r [–]."""
    distance_m: float
    """Pulse distance in the estimate [m]."""
    stretches: int
    applied: bool
    """The odometry's scale uses it (setting ``wheel_calibration``)."""
    applied_from_t: float | None
    """First cycle the running estimate scaled (None: never) [s]."""

    def to_json(self, nominal_diameter_m: float) -> dict[str, Any]:
        lo, hi = self.ratio - self.half_width, self.ratio + self.half_width
        return {
            "ratio": self.ratio,
            "ratio_ci95": [lo, hi],
            "diameter_m": self.ratio * nominal_diameter_m,
            "diameter_ci95_m": [lo * nominal_diameter_m, hi * nominal_diameter_m],
            "wear_pct": 100.0 * (1.0 - self.ratio),
            "distance_m": self.distance_m,
            "stretches": self.stretches,
            "applied": self.applied,
            "applied_from_t": self.applied_from_t,
        }


@dataclass(frozen=True)
class GroundReport:
    """What the ground-speed sensor gave the odometry of one run."""

    source: str
    covered_share: float
    """Share of the moving cycles (1 s mean pulse speed ≥ CAL_MIN_SPEED_MPS) with a ground speed."""
    against_cab_s: float
    """Time the direction check found the vehicle moving against the cab [s]."""
    low_speed_share: float
    """Share of the cycles whose speed is the ground speed's (low speed, standstill)."""
    calibration: WheelCalibration | None

    def to_json(self, nominal_diameter_m: float) -> dict[str, Any]:
        return {
            "source": self.source,
            "covered_share": self.covered_share,
            "against_cab_s": self.against_cab_s,
            "low_speed_share": self.low_speed_share,
            "wheel_calibration": None if self.calibration is None else self.calibration.to_json(nominal_diameter_m),
        }


@dataclass(frozen=True)
class FailsafeWatch:
    """After a fail-safe: the inertial (or radar) speed followed until the pulses agree
    again; the allowance grew meanwhile (``OdometryConfig.failsafe_watch_s``)."""

    end_t: float
    """When the watch ended (re-adhesion, or its time limit) [s]."""
    allowance_m: float
    """Allowance it added [m]."""
    readhered: bool
    """The pulses agreed again within the watch."""
    speed_source: SpeedSource


@dataclass(frozen=True)
class SlipEpisode:
    """One slip (wheel faster, traction) or slide (wheel slower, braking) episode and its
    correction, as the events report it (``event_detail``). Algorithm internals are in
    ``Odometry.diagnostics``."""

    kind: SlipKind
    t_detect: float
    """Detection (clock time of the detection cycle) [s]."""
    t_start: float
    """Correction start point (found by the look-back search) [s]."""
    t_end: float
    """Re-adhesion, or the fail-safe time [s]."""
    i_start: int
    """Cycle of ``t_start`` (index into the run's cycle arrays)."""
    i_end: int
    """Cycle of ``t_end``."""
    d_pulse_m: float
    """Distance by pulses over [t_start, t_end] [m]."""
    d_corrected_m: float
    """Corrected distance over the same interval [m]."""
    max_error_m: float
    """Error budget: ½·Δa·T² for the correction duration T (eq. 13); with a radar the
    fused correction's, from the radar's σ (``odometry.fusion``) [m]."""
    readhered: bool
    failsafe: bool
    """Still correcting after ``max_correction_s``: the position becomes uncertain."""
    criterion: DetectionCriterion = field(kw_only=True)
    start_found: bool = field(kw_only=True)
    """A jerk-quiet start point was found (else the look-back point is used)."""
    theta0_rad: float = field(kw_only=True)
    """Pitch at the start point: the gradient climbed in the travel direction [rad]."""
    v0_mps: float = field(kw_only=True)
    """Speed at the start point [m/s]."""
    truncated: bool = field(default=False, kw_only=True)
    """The data ended before re-adhesion or fail-safe (the speed is held to the end)."""
    speed_source: SpeedSource = field(default="inertial", kw_only=True)
    speed_update_m: float = field(default=0.0, kw_only=True)
    """Distance the re-adhesion speed update moved the correction (0 when not applied:
    switched off, no re-adhesion, or the radar's speed used) [m]."""
    watch: FailsafeWatch | None = field(default=None, kw_only=True)
    """The fail-safe watch (fail-safe episodes, when enabled)."""
    start_trusted: bool = field(default=True, kw_only=True)
    """The start point adhered (found, and |θ̄| within arcsin(Ta/G)); when not, v0 and θ0 come
    from slipping pulses, beyond eq. 13's budget: the episode fails safe at its start."""
    after_failsafe_t: tuple[float, ...] = field(default=(), kw_only=True)
    """A fail-safe episode's detections after its fail-safe that no correction could follow
    (inside its watch, or before a new start point had room) [s]: each makes the position
    uncertain again (``FailsafeAid``)."""

    @property
    def duration_s(self) -> float:
        """Correction duration T [s]."""
        return self.t_end - self.t_start

    def event_detail(self) -> dict[str, Any]:
        """The ``detail`` of the episode's slip/slide event (public fields only)."""
        out: dict[str, Any] = {
            "t_detect": self.t_detect,
            "t_end": self.t_end,
            "duration_s": self.duration_s,
            "d_pulse_m": self.d_pulse_m,
            "d_corrected_m": self.d_corrected_m,
            "max_error_m": self.max_error_m,
            "readhered": self.readhered,
            "failsafe": self.failsafe,
            "truncated": self.truncated,
            "criterion": self.criterion,
            "start_found": self.start_found,
            "theta0_rad": self.theta0_rad,
            "v0_mps": self.v0_mps,
            "speed_source": self.speed_source,
            "speed_update_m": self.speed_update_m,
            "start_trusted": self.start_trusted,
            "after_failsafe_t": list(self.after_failsafe_t),
        }
        if self.watch is not None:
            out.update(
                watch_end_t=self.watch.end_t,
                watch_allowance_m=self.watch.allowance_m,
                watch_readhered=self.watch.readhered,
                watch_speed_source=self.watch.speed_source,
            )
        return out


@dataclass
class Odometry:
    """Corrected travel distance per cycle (what dead reckoning runs on)."""

    d: FloatArray
    """Corrected cumulative travel distance [m] (unsigned, never decreasing)."""
    v: FloatArray
    """Corrected speed [m/s] (unsigned)."""
    slipping: npt.NDArray[np.bool_]
    """True while a slip/slide correction is running."""
    allowance: FloatArray
    """Cumulative error allowance of all corrections so far [m] (for the margin)."""
    episodes: list[SlipEpisode] = field(default_factory=list)
    diagnostics: OdometryDiagnostics | None = field(default=None, repr=False)
    """Algorithm internals for tests and bench scripts (None without inertial correction);
    never part of the pipeline's outputs."""
    ground: GroundReport | None = None
    """What a ground-speed sensor (the radar) gave the odometry, with the wheel calibration
    (None without one)."""


@dataclass
class Event:
    """One row of the ``events`` output."""

    t: float
    type: EventType
    km_m: float | None = None
    correction_m: float | None = None
    correction_pct: float | None = None
    detail: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Hypothesis:
    """One candidate of a position on a network [SPEC §8.3]: a track, the distance along it
    from its begin at the fix's reference travel ``s_ref`` and the sign of that distance per
    metre of body-forward travel, so that pos(S) = ``pos_m`` + ``kp``·(S − s_ref)
    (:mod:`fieldlogs.pipeline.hypotheses`)."""

    track_id: str
    pos_m: float
    kp: int
    """+1: pos grows with body-forward travel S, −1 it shrinks."""
    extra_m: float = 0.0
    """Added to the fix's margin (the spread of hypotheses merged into this one) [m]."""
    hid: int = 0
    """Lineage: kept when dead reckoning carries the candidate onto the next track, new at a split."""
    switch_id: str | None = None
    """The facing switch whose split made this candidate (None: none since the last determination)."""
    split_d: float | None = None
    """Unsigned travel d at that split [m]."""
    came_from: tuple[str, str] | None = None
    """The track and end dead reckoning carried it from onto this track (None: placed here)."""


@dataclass(frozen=True)
class Fix:
    """An estimate anchor: from ``t_effective`` on, km follows from ``km_m`` after a travel
    k·(S − s_ref) along the track's own length (:func:`fieldlogs.pipeline.estimate.km_along`),
    where S = Σ cab·Δd is the signed body-forward travel.

    ``k`` is the sign of km per metre of body-forward travel (±1), so cab reversals after the
    fix are followed automatically. The reference point (``t_ref``, ``s_ref``, ``d_ref``)
    may precede ``t_effective``: a feature point is recognised some metres after its exit
    crossing.
    """

    t_effective: float
    s_ref: float
    """Signed travel S at the reference point [m]."""
    d_ref: float
    """Unsigned travel d at the reference point [m] (for the margin and correction %)."""
    km_m: float
    km_equipment_m: float
    line_code: str
    track: str
    k: int
    source: FixSource
    uncertainty_m: float
    state: PositionState = PositionState.DETERMINED
    t_ref: float | None = None
    """Time of the reference point (None: ``t_effective``)."""
    allowance_ref_m: float = 0.0
    """Odometry slip allowance already accumulated at the reference point [m] (set by the
    engine when the fix takes effect)."""
    uncertain_since_d: float | None = None
    """Travel d at which the position became uncertain (fail-safe), if it is."""
    hyps: tuple[Hypothesis, ...] = ()
    """On a network: every candidate (one: determined on its track; several: ambiguous, and
    ``line_code``/``track`` empty so that no line-based aid acts on one of them). Empty: the
    fix was set by a line-based aid and is not yet placed on a network track."""
    carried: bool = False
    """Dead reckoning carried this estimate onto another track or changed its candidates: no
    new measurement (the balise-interval checks skip it)."""

    @property
    def reference_t(self) -> float:
        return self.t_effective if self.t_ref is None else self.t_ref

    @classmethod
    def undetermined(cls, t: float, s: float, d: float) -> Fix:
        """No position from ``t`` on (off rail)."""
        nan = float("nan")
        return cls(t, s, d, nan, nan, "", "", 1, FixSource.NONE, nan, state=PositionState.UNDETERMINED)


_Frozen = TypeVar("_Frozen", Fix, Hypothesis)


def evolved(obj: _Frozen, **changes: Any) -> _Frozen:
    """``dataclasses.replace(obj, **changes)`` of a :class:`Fix` or :class:`Hypothesis` — plain
    frozen dataclasses (every field an ``__init__`` argument, no ``__post_init__``), so the copy
    of their fields with ``changes`` is the same object ``replace`` makes, without its per-field
    work (the engine makes several per D-GPS correction, one every few seconds)."""
    cls = type(obj)
    unknown = changes.keys() - cls.__dataclass_fields__.keys()
    if unknown:
        raise TypeError(f"{cls.__name__} has no field {', '.join(sorted(unknown))}")
    new = object.__new__(cls)
    new.__dict__.update(obj.__dict__)
    new.__dict__.update(changes)
    return new


def slip_budget_m(duration_s: float, delta_a_mps2: float) -> float:
    """Eq. 13: Δd = ½·Δa·t² (±22.8 m at t = 10 s with Δa = 1.64 km/h/s)."""
    return 0.5 * delta_a_mps2 * duration_s * duration_s


def pulse_only_odometry(d_pulse: FloatArray, v_pulse: FloatArray) -> Odometry:
    """Odometry without inertial correction (no IMU in the run)."""
    return Odometry(d_pulse.copy(), v_pulse.copy(), np.zeros(d_pulse.size, dtype=bool), np.zeros(d_pulse.size))


@dataclass
class FeatureOutcome:
    """Result of evaluating one feature point (curve) against the κ trace [S000 §3.2]."""

    accepted: bool
    feature_id: str
    line_code: str
    track: str
    i_ref: int | None
    """Cycle of the exit lower-limit crossing (the correction point), if found."""
    km_db: float | None
    """DB km of the curve-exit row (seq 4)."""
    failed: list[str] = field(default_factory=list)
    """Names of the failed diagnostics (empty when accepted)."""
    detail: dict[str, Any] = field(default_factory=dict)
    uncertainty_m: float | None = None
    """Uncertainty of the correction it gives [m] (None: the config's least value)."""


@dataclass
class TrackDecision:
    """A GPS decision on line and track (up/down) from trusted fixes [S001 §4.2]."""

    t: float
    line_code: str
    track: str
    km_m: float
    """Map-matched km of the last fix used."""
    km_dir: int
    """+1 km increasing with time, −1 decreasing, 0 unknown (standing)."""
    evidence: dict[str, Any] = field(default_factory=dict)


@dataclass
class GpsAnalysis:
    """Vectorised GPS results over a whole run (see ``fieldlogs.pipeline.gps``)."""

    fixes: Any
    """DataFrame, one row per GPS fix: t, trusted, line_code, track, km_m, offset_m, …"""
    decisions: list[TrackDecision] = field(default_factory=list)
    crossovers: list[Event] = field(default_factory=list)
