"""Every tuning parameter of the positioning pipeline, with SPEC defaults and units.

One dataclass per concern; ``PipelineConfig.from_toml`` reads overrides from a file whose
sections mirror the dataclasses (``[odometry]``, ``[balise]``, ``[feature]``, ``[gps]``,
``[margin]``). Unknown keys are errors, so a misspelt parameter never silently does nothing.
Accelerations are in the papers' km/h/s where the papers state them so.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, TypeVar

from schemas.errors import InputError
from schemas.units import kmh_s_to_mps2

T = TypeVar("T")


@dataclass(frozen=True)
class OdometryConfig:
    """Slip/slide detection and inertial correction [S000 §3.1, SPEC §5.1]."""

    avg_window_s: float = 3.0
    """Moving-average window for A_p and a_x [s]."""
    pulse_delay_cycles: int = 3
    """Delay of the pulse stream to line it up with the IMU [cycles of 100 ms] (SPEC value;
    see ``pulse_delay_search_cycles``)."""
    ta_kmh_s: float = 1.23
    """Detection threshold Ta on |a_x − A_p| [km/h/s] (gravity component of 35 ‰), eq. 1."""
    lookback_s: float = 2.1
    """Look-back from the detection point before searching the start point [s]."""
    jerk_imu_max_kmh_s: float = 0.1
    """|Ji| limit per 0.1 s at the start point [km/h/s] (IMU resolution)."""
    jerk_pulse_max_kmh_s: float = 0.15
    """|Jp| limit per 0.1 s at the start point [km/h/s] (pulse resolution)."""
    jerk_diff_max_kmh_s: float = 0.05
    """|Ji − Jp| limit per 0.1 s at the start point [km/h/s]."""
    hold_cycles: int = 3
    """Consecutive cycles the jerk conditions must hold."""
    beta_kmh_s: float = 0.15
    """Re-adhesion: the 1 s mean inertial and pulse speeds agree within
    ``readhesion_tol_kmh`` + β·t [km/h/s]. The paper uses its full error budget, 1.64 km/h/s,
    on the per-cycle pulse speed; with 1.64 (or the 0.8 used before) a slip of a few tenths
    of a m/s "re-adheres" while still slipping. With the gyro bias removed the inertial
    speed error of an ADIS16480-class IMU stays below 0.3 m/s in 10 s (odometry module
    docstring, "Re-adhesion")."""
    delta_a_kmh_s: float = 1.64
    """Error budget Δa = gyro 0.31 + accel 0.1 + threshold 1.23 [km/h/s], eq. 13."""
    max_correction_s: float = 10.0
    """A correction still running after this is a fail-safe event [s]."""
    failsafe_watch_s: float = 20.0
    """After a fail-safe the inertial (or radar) speed is followed this much longer: until
    it agrees with the pulses again (the re-adhesion test) the slip allowance grows by
    |v_inertial − v_pulse| + Δa·t per second, t from the start point — the pulses may still
    be slipping, and the 5 %/km growth of an uncertain position does not cover a deep slide
    (31 m off with 8 m of margin, once in 300 simulated runs). 0 = no watch [s]."""
    min_speed_kmh: float = 3.0
    """Below this speed no slip/slide is detected (standstill noise) [km/h]."""
    pulse_delay_search_cycles: int = 3
    """The run's own data may move the pulse delay by up to this many cycles from
    ``pulse_delay_cycles`` (regression of the grade-compensated residual on the jerk; the
    SPEC value stays unless the lag is significant); 0 = always the SPEC value. The
    residual criterion needs the true delay [cycles]."""
    bias_window_s: float = 120.0
    """Trailing window over which the gyro pitch-rate bias is estimated (slope of the
    accelerometer pitch minus the gyro pitch on adhering cycles) and removed from eq. 12
    [s]; 0 = no bias estimate."""
    residual_threshold_kmh_s: float = 0.45
    """Second detection criterion, beside Ta: |grade-compensated residual| above this —
    the change of K·(a_x − A_p) over ``residual_horizon_s`` minus the gyro's change of
    G·sinθ (odometry module docstring) [km/h/s]. Adhering it stays within ±0.27 km/h/s;
    catches the shallow slips whose |a_x − A_p| never reaches Ta. 0 = off (SPEC eq. 1 only)."""
    residual_horizon_s: float = 4.0
    """Horizon of the residual: the present K window against the one this long ago [s]."""
    readhesion_tol_kmh: float = 0.36
    """Re-adhesion: constant part of the speed tolerance (1 s mean quantisation and wheel
    wear in v0), added to β·t [km/h]."""
    readhesion_hold_s: float = 1.0
    """Re-adhesion: the speeds must agree this long (a mere crossing does not count) [s]."""
    readhesion_speed_update: bool = True
    """At re-adhesion the wheel measures the ground speed again: the difference of the 1 s
    mean inertial and pulse speeds there is the inertial speed error accumulated since the
    start point (where the speed came from adhering pulses), and it is removed from the
    correction as a ramp growing linearly from 0 at the start point, i.e. the episode
    distance changes by −½·δ·T (δ the difference [m/s], T the correction time [s]; |δ| is
    at most ``readhesion_tol_kmh`` + β·T by the re-adhesion condition). Halves the error of
    the worst low-speed corrections (odometry module docstring, "Re-adhesion speed
    update"). False = the SPEC's open-loop correction [–]."""

    @property
    def ta_mps2(self) -> float:
        return kmh_s_to_mps2(self.ta_kmh_s)

    @property
    def beta_mps2(self) -> float:
        return kmh_s_to_mps2(self.beta_kmh_s)

    @property
    def delta_a_mps2(self) -> float:
        return kmh_s_to_mps2(self.delta_a_kmh_s)


@dataclass(frozen=True)
class BaliseConfig:
    """Initial pairs and correction balises [S003 §4, SPEC §5.2]."""

    pair_max_travel_m: float = 10.0
    """I2 must follow I1 within this travel distance [m]."""
    id_window_m: float = 500.0
    """C-balise identification window around dist_from_initial_m [m]."""
    fix_uncertainty_m: float = 1.0
    """Uncertainty of a balise position fix (antenna/read position) [m]."""


@dataclass(frozen=True)
class FeatureConfig:
    """Curve feature points [S000 §3.2, SPEC §5.3]."""

    tolerance: float = 0.20
    """Upper limit (1/R)(1+tol), lower limit (1/R)(1−tol)."""
    straight_kappa_max: float = 1 / 4000
    """|κ| below this counts as straight [1/m]."""
    length_tolerance: float = 0.20
    """Allowed relative deviation of the measured curve length from the DB [–]."""
    length_tolerance_min_m: float = 10.0
    """… but never tighter than this [m]."""
    min_speed_kmh: float = 10.0
    """No correction below this speed [km/h]."""
    kappa_smoothing_s: float = 1.0
    """Centred moving average (the odd number of cycles nearest this) applied to κ = ωz / v
    before the diagnostics [s]; centred so the crossings are not delayed."""
    fix_uncertainty_m: float = 10.0
    """Least uncertainty of a feature-point correction [m] (paper: within about 10 m); it is
    larger when the κ error could move the exit crossing farther (``crossing_z``)."""
    crossing_z: float = 3.0
    """A correction's uncertainty is at least this many σ of its exit crossing: σ_x =
    σ_ω / (v · s), s = κ_lo / (r5 − r4) the κ slope of the DB exit transition, σ_ω the yaw
    rate's 1σ below [–]. Why: a slow train on a long transition turns a small ωz error into
    metres (0.6 mrad/s at 12 m/s on R 1150 m, 64 m transition: σ_x 4.6 m)."""
    yaw_rate_sigma_rad_s: float = 0.0006
    """1σ of the smoothed ωz once its bias is estimated at a standstill (white noise over the
    smoothing window, vibration, residual bias) [rad/s]."""
    yaw_bias_sigma_rad_s: float = 0.0009
    """1σ of the yaw-gyro bias before any standstill estimate (ADIS16480 class: 0.05 °/s);
    added in quadrature to ``yaw_rate_sigma_rad_s`` then [rad/s]."""
    search_margin_m: float = 100.0
    """Minimum extra distance searched around the predicted feature position [m]; the
    feature is evaluated once the estimate has passed its exit-check end by this much."""
    search_growth_pct: float = 2.0
    """The search margin grows to fix uncertainty + this percent of the travel since the fix
    + slip allowance since the fix, when that is larger [%] (as the safety margin does)."""
    crossing_merge_m: float = 5.0
    """Lower-limit runs of the same sign closer than this are one curve (noise chatter at a
    crossing) [m]."""
    yaw_bias_window_s: float = 60.0
    """ωz is corrected by its mean over the latest this-many seconds of standstill (0 = no
    correction) [s]. Why: a yaw-gyro bias b reads as κ error b/v — 0.05 °/s (1σ of an
    ADIS16480-class gyro) is 8 % of 1/R at 12 m/s on R 1150 m, enough to move a lower-limit
    crossing 25 m along a transition when a train brakes through a curve exit."""
    yaw_bias_settle_s: float = 2.0
    """A standstill counts for the yaw bias only after no pulse for this long (the train has
    stopped rocking and is not creeping between pulses) [s]."""
    yaw_bias_min_s: float = 5.0
    """No yaw bias estimate (0) before this much standstill [s]."""


@dataclass(frozen=True)
class GpsConfig:
    """D-GPS map-matching, trust filter, up/down decision and crossovers [S001 §4.2, SPEC §5.4].

    The statistics are stated in ``fieldlogs.pipeline.gps``. Defaults are calibrated for
    D-GPS whose slow (time-correlated) error is ~0.75 m per axis (2-D RMS ≈ 1.1 m, good
    sky) with a correlation time of one to three minutes and whose fast noise is ≤ 0.3 m
    per axis; change the ``noise_*`` model and the RMS thresholds together when a receiver
    behaves differently.
    """

    # --- usable fixes and map-matching
    min_fix: int = 2
    """Minimum fix quality to use a fix (2 = D-GPS)."""
    max_hdop: float = 3.0
    """Fixes with a larger HDOP are not used (a missing HDOP does not exclude a fix)."""
    max_offset_m: float = 15.0
    """A track farther than this from a fix is not a candidate for it [m]."""
    max_gap_s: float = 1.5
    """A time step longer than this between usable fixes resets the RMS windows [s]."""
    # --- trust filter [S001 §4.2.2]
    windows_s: tuple[int, ...] = (5, 15, 30)
    """RMS windows of the second-to-second position change [s]."""
    rms_threshold_m: tuple[float, ...] = (2.5, 1.8, 1.5)
    """Per window: RMS of the change of the per-second displacement about its window mean
    (the 2-D second difference of positions, constant acceleration removed) above this →
    not trusted [m]. Clean D-GPS gives ~1.0 m (~1.2 m with 0.3 m fast noise); a 5 m jump
    gives ≥ 3.3 / 2.1 / 1.65 m in the 5 / 15 / 30 s windows."""
    max_change_m: float = 3.0
    """The fix's own change of displacement above this → not trusted [m] (catches the
    first fix of a jump, which a causal window sees only once)."""
    jump_hold_s: float = 30.0
    """After a fix whose own change exceeds ``max_change_m``, the fixes of this many seconds are
    not trusted: a multipath burst ramps on and off smoothly after its first jump [s]."""
    min_history_s: float = 5.0
    """Usable fixes needed since the last reset before any fix is trusted [s]."""
    # --- error model of trusted fixes (for the standard error of a mean offset)
    noise_sigma_m: float = 0.75
    """1-σ of the slow lateral D-GPS error (Gauss-Markov) [m]. With 1.5 m per axis, 120 s
    hold about two independent samples of the lateral error: the 3.8 m track spacing then
    cannot be decided within the field target without risking wrong decisions."""
    noise_tau_s: float = 180.0
    """Correlation time of that error [s]: consecutive fixes are not independent. Set it from
    the receiver's measured error (180 s = the suite's simulator model); a value shorter
    than the truth makes decisions overconfident."""
    noise_white_m: float = 0.25
    """1-σ of the independent per-fix noise [m]."""
    # --- up/down decision (sequential likelihood-ratio test on the mean offset)
    decide_window_s: float = 120.0
    """Evidence window: trusted fixes of the last this many seconds [s] (field target < 120 s)."""
    decide_recent_s: float = 30.0
    """The test is also made on the trusted fixes of only the last this many seconds, so that
    older fixes a slow error put between the tracks do not hold back a decision the recent
    ones support (0 = only the full window) [s]."""
    decide_min_fixes: int = 10
    """Trusted fixes needed in the window before deciding."""
    decide_min_duration_s: float = 10.0
    """Time spanned by those fixes [s]."""
    decide_min_share: float = 0.9
    """Share of the window's trusted fixes whose nearest track is the decided one."""
    decide_error: float = 1e-3
    """Accepted probability of deciding the wrong track: the log-likelihood ratio of the
    decided track against every other candidate must reach ln(1/decide_error)."""
    decide_fit_z: float = 3.0
    """|mean offset| from the decided track must be within this many standard errors …"""
    decide_max_mean_m: float = 2.5
    """… and not exceed this [m]: a vehicle between two tracks, or on a track missing from
    the GIS, must not be assigned to its neighbour."""
    redecide_factor: float = 2.0
    """Changing an existing decision without a detected crossover needs this many times the
    log-likelihood ratio (i.e. decide_error ** factor)."""
    km_dir_min_m: float = 10.0
    """|km change| over the evidence window below this → km_dir = 0 (standing) [m]."""
    # --- crossover (渡り線) detection [S001 §7]
    crossover_window_s: float = 5.0
    """Window of the RMS of the offset from the base (decided) track [s]."""
    crossover_ref_s: float = 20.0
    """Reference window for the offset's previous level [s] …"""
    crossover_lag_s: float = 10.0
    """… ending this long before the RMS window starts, so that a slow crossing (up to
    about this long) is compared with the level before it began [s]."""
    crossover_rms_m: float = 2.0
    """RMS of the offset from the base track above this (over the window) [m] …"""
    crossover_min_shift: float = 0.6
    """… and the mean offset moved toward the other track by this share of the track spacing
    (and past the midpoint between the tracks)."""
    crossover_z: float = 3.0
    """… and by at least this many standard deviations of the drift the slow error model
    (``noise_*``) produces between the two windows: with noisy GPS a crossover is only
    reported when it stands out of the noise."""
    # --- use by the solver
    initial_uncertainty_m: float = 10.0
    """Uncertainty of a GPS-derived initial position [m]."""
    allow_initial: bool = True
    """GPS may set the initial position before any balise (flagged GPS-derived)."""


@dataclass(frozen=True)
class MarginConfig:
    """Safety margin: |position error| ≤ margin [S000 §4.3.2]."""

    distance_pct: float = 2.0
    """Percent of the distance travelled since the last absolute correction."""
    slip_allowance_m: float = 2.0
    """Fixed allowance per corrected slip/slide episode, added to ½·Δa·T² (eq. 13) [m]."""
    uncertain_growth_pct: float = 5.0
    """Percent of distance added while the position is uncertain (fail-safe) [%]."""


@dataclass(frozen=True)
class PipelineConfig:
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    balise: BaliseConfig = field(default_factory=BaliseConfig)
    feature: FeatureConfig = field(default_factory=FeatureConfig)
    gps: GpsConfig = field(default_factory=GpsConfig)
    margin: MarginConfig = field(default_factory=MarginConfig)
    cycle_s: float = 0.1

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_toml(cls, path: Path) -> PipelineConfig:
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError as exc:
            raise InputError("no such config file", path=path) from exc
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
            raise InputError(f"not valid TOML: {exc}", path=path) from exc
        return cls.from_dict(data, source=str(path))

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> PipelineConfig:
        cfg = cls()
        sections = {f.name: f for f in fields(cls)}
        for key, value in data.items():
            if key not in sections:
                raise InputError(f"unknown section or key '{key}' (known: {', '.join(sections)})", path=source)
            current = getattr(cfg, key)
            if not isinstance(value, dict):
                cfg = replace(cfg, **{key: _typed(source, key, current, value)})
                continue
            cfg = replace(cfg, **{key: update_section(current, value, key, source)})
        return cfg


def update_section(current: T, values: dict[str, Any], section: str, source: str) -> T:
    """``current`` (a frozen config dataclass) with ``values`` from the TOML section
    ``[section]``: unknown keys and values of the wrong type are errors naming the key."""
    known = {f.name for f in fields(current)}  # type: ignore[arg-type]
    updates = {}
    for k, v in values.items():
        if k not in known:
            raise InputError(f"unknown key '{section}.{k}' (known: {', '.join(known)})", path=source)
        updates[k] = _typed(source, f"{section}.{k}", getattr(current, k), v)
    return replace(current, **updates)  # type: ignore[type-var]


def _typed(source: str, key: str, default: Any, value: Any) -> Any:
    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise InputError(f"'{key}' must be true or false, not {value!r}", path=source)
        return value
    if isinstance(default, tuple):
        if not isinstance(value, list):
            raise InputError(f"'{key}' must be a list, not {value!r}", path=source)
        return tuple(_typed(source, key, default[0] if default else value[0], v) for v in value)
    if isinstance(default, int) and not isinstance(default, bool):
        if not isinstance(value, int) or isinstance(value, bool):
            raise InputError(f"'{key}' must be a whole number, not {value!r}", path=source)
        return value
    if isinstance(default, float):
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
            raise InputError(f"'{key}' must be a number, not {value!r}", path=source)
        return float(value)
    return value
