"""Every tuning parameter of the positioning pipeline, with SPEC defaults, units and ranges.

One frozen section per concern — ``[odometry]``, ``[balise]``, ``[feature]``, ``[gps]``,
``[margin]``, ``[clock]``, ``[window]``, ``[track_select]`` of a ``--config`` TOML file, plus ``cycle_s``,
and ``[gnss]`` (declared in
:mod:`fieldlogs.gnss.config`) — each field declared with
:func:`schemas.settings.setting` (default, one-line meaning, unit, allowed range), so that
``trainpos config show`` prints them all and a value out of range is refused wherever it
comes from. Accelerations are in the papers' km/h/s where the papers state them so. The
maths behind each parameter is in the module that uses it; measurements behind the
non-SPEC defaults are in ``bench/NOTES.md``.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

from dbtools.inputs import not_special
from fieldlogs.gnss.config import GnssConfig
from schemas.errors import InputError
from schemas.settings import SettingError, check_ranges, section_from_dict, setting, typed
from schemas.units import kmh_s_to_mps2


@dataclass(frozen=True)
class OdometryConfig:
    """Slip/slide detection and inertial correction [S000 §3.1, SPEC §5.1]."""

    avg_window_s: float = setting(3.0, "moving-average window of A_p and a_x", "s", gt=0)
    pulse_delay_cycles: int = setting(3, "delay of the pulse stream to line it up with the IMU (SPEC)", "cycles", ge=0)
    ta_kmh_s: float = setting(1.23, "detection threshold Ta on |a_x − A_p|, eq. 1 (gravity of 35 ‰)", "km/h/s", gt=0)
    lookback_s: float = setting(2.1, "look-back from the detection point before the start-point search", "s", ge=0)
    jerk_imu_max_kmh_s: float = setting(0.1, "|Ji| limit per 0.1 s at the start point", "km/h/s", gt=0)
    jerk_pulse_max_kmh_s: float = setting(0.15, "|Jp| limit per 0.1 s at the start point", "km/h/s", gt=0)
    jerk_diff_max_kmh_s: float = setting(0.05, "|Ji − Jp| limit per 0.1 s at the start point", "km/h/s", gt=0)
    hold_cycles: int = setting(3, "consecutive cycles the jerk conditions must hold", "cycles", ge=1)
    beta_kmh_s: float = setting(
        0.15, "re-adhesion: the 1 s mean speeds agree within readhesion_tol_kmh + β·t", "km/h/s", ge=0
    )
    delta_a_kmh_s: float = setting(1.64, "error budget Δa = gyro 0.31 + accel 0.1 + Ta 1.23, eq. 13", "km/h/s", gt=0)
    max_correction_s: float = setting(10.0, "a correction still running after this is a fail-safe event", "s", gt=0)
    failsafe_watch_s: float = setting(
        20.0, "after a fail-safe, follow the inertial (or radar) speed this long; 0 = no watch", "s", ge=0
    )
    min_speed_kmh: float = setting(3.0, "no slip/slide is detected below this speed", "km/h", ge=0)
    pulse_delay_search_cycles: int = setting(
        3, "the run's own data may move the pulse delay by up to this; 0 = the SPEC value", "cycles", ge=0
    )
    bias_window_s: float = setting(
        120.0, "window of the gyro pitch-rate bias estimate; 0 = no bias estimate", "s", ge=0
    )
    residual_threshold_kmh_s: float = setting(
        0.45, "second criterion: |grade-compensated residual| above this; 0 = off (eq. 1 only)", "km/h/s", ge=0
    )
    residual_horizon_s: float = setting(4.0, "horizon of the residual (present K window vs this long ago)", "s", gt=0)
    readhesion_tol_kmh: float = setting(
        0.36, "re-adhesion: constant part of the speed tolerance (quantisation, wheel wear)", "km/h", ge=0
    )
    readhesion_hold_s: float = setting(1.0, "re-adhesion: the speeds must agree this long", "s", gt=0)
    readhesion_speed_update: bool = setting(
        True, "close a re-adhered correction on the measured speed difference (false: the SPEC's open loop)"
    )
    ground_detect_z: float = setting(
        4.0,
        "ground-speed criterion (radar): |1 s pulse − ground speed| beyond this many σ + tolerances; 0 = off",
        ge=0,
    )
    ground_max_correction_s: float = setting(
        60.0, "with a ground speed carrying it, a correction may run this long before a fail-safe", "s", gt=0
    )
    ground_low_speed_kmh: float = setting(
        20.0, "below this the speed is the ground speed's, not the coarse pulses'; 0 = never", "km/h", ge=0
    )
    wheel_calibration: bool = setting(
        False, "scale the pulses by the radar's wheel calibration once it is known (summary: wheel_calibration)"
    )

    def __post_init__(self) -> None:
        check_ranges(self, "odometry")

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

    pair_max_travel_m: float = setting(10.0, "I2 must follow I1 within this travel", "m", gt=0)
    id_window_m: float = setting(500.0, "C-balise identification window around dist_from_initial_m", "m", gt=0)
    fix_uncertainty_m: float = setting(1.0, "uncertainty of a balise position fix (antenna, read position)", "m", gt=0)
    latency_budget_s: float = setting(
        0.1, "undetected telegram time-stamp error held by each fix: its uncertainty grows by this × speed", "s", ge=0
    )

    def __post_init__(self) -> None:
        check_ranges(self, "balise")


@dataclass(frozen=True)
class FeatureConfig:
    """Curve feature points [S000 §3.2, SPEC §5.3].

    A correction's uncertainty is max(``fix_uncertainty_m``, ``crossing_z``·σ_x) with σ_x =
    σ_ω / (v·s), s = κ_lo / (r5 − r4) the κ slope of the DB exit transition: a slow train on
    a long transition turns a small ωz error into metres (0.6 mrad/s at 12 m/s on R 1150 m,
    64 m transition: σ_x 4.6 m). ωz is corrected by its mean over standstills: a yaw-gyro
    bias b reads as a κ error b/v.
    """

    tolerance: float = setting(0.20, "upper limit (1/R)(1 + tol), lower limit (1/R)(1 − tol)", gt=0, lt=1)
    straight_kappa_max: float = setting(1 / 4000, "|κ| below this counts as straight", "1/m", gt=0)
    length_tolerance: float = setting(0.20, "allowed relative deviation of the measured curve length", ge=0)
    length_tolerance_min_m: float = setting(10.0, "… but never tighter than this", "m", ge=0)
    min_speed_kmh: float = setting(10.0, "no correction below this speed", "km/h", ge=0)
    kappa_smoothing_s: float = setting(1.0, "centred moving average of κ = ωz / v before the diagnostics", "s", ge=0)
    fix_uncertainty_m: float = setting(
        10.0, "least uncertainty of a feature-point correction (paper: ~10 m)", "m", gt=0
    )
    crossing_z: float = setting(3.0, "the uncertainty is at least this many σ of the exit crossing", ge=0)
    clock_budget_s: float = setting(
        0.5,
        "undetected IMU clock offset held by each correction: its uncertainty grows by this × speed"
        " (keep ≥ clock.tolerance_s)",
        "s",
        ge=0,
    )
    yaw_rate_sigma_rad_s: float = setting(0.0006, "1σ of the smoothed ωz once its bias is estimated", "rad/s", ge=0)
    yaw_bias_sigma_rad_s: float = setting(0.0009, "1σ of the yaw-gyro bias before any standstill", "rad/s", ge=0)
    search_margin_m: float = setting(100.0, "least extra distance searched around the predicted feature", "m", gt=0)
    search_growth_pct: float = setting(
        2.0, "the search margin grows by this share of the travel since the fix (+ slip allowance)", "%", ge=0
    )
    crossing_merge_m: float = setting(5.0, "same-sign lower-limit runs closer than this are one curve", "m", ge=0)
    yaw_bias_window_s: float = setting(60.0, "ωz corrected by its mean over the latest standstills; 0 = off", "s", ge=0)
    yaw_bias_settle_s: float = setting(
        2.0, "a standstill counts for the yaw bias after no pulse for this long", "s", ge=0
    )
    yaw_bias_min_s: float = setting(5.0, "no yaw bias estimate before this much standstill", "s", ge=0)

    def __post_init__(self) -> None:
        check_ranges(self, "feature")


@dataclass(frozen=True)
class GpsConfig:
    """D-GPS map-matching, trust filter, up/down decision and crossovers [S001 §4.2, SPEC §5.4].

    The statistics are stated in :mod:`fieldlogs.pipeline.gps`. Defaults are for D-GPS whose
    slow (time-correlated) error is ~0.75 m per axis with a correlation time of one to three
    minutes and whose fast noise is ≤ 0.3 m per axis; change the ``noise_*`` model and the
    RMS thresholds together for another receiver (a ``noise_tau_s`` shorter than the truth
    makes decisions overconfident).
    """

    min_fix: int = setting(2, "least fix quality used (2 = D-GPS)", ge=0)
    max_hdop: float = setting(3.0, "fixes with a larger HDOP are not used (a missing HDOP does not exclude)", gt=0)
    max_offset_m: float = setting(15.0, "a track farther than this from a fix is not a candidate", "m", gt=0)
    max_gap_s: float = setting(1.5, "a longer step between usable fixes resets the RMS windows", "s", gt=0)
    windows_s: tuple[int, ...] = setting((5, 15, 30), "RMS windows of the second-to-second position change", "s", gt=0)
    rms_threshold_m: tuple[float, ...] = setting(
        (2.5, 1.8, 1.5), "per window: RMS of the change of displacement above this → not trusted", "m", gt=0
    )
    max_change_m: float = setting(3.0, "a fix's own change of displacement above this → not trusted", "m", gt=0)
    jump_hold_s: float = setting(30.0, "after such a jump the fixes of this long are not trusted", "s", ge=0)
    min_history_s: float = setting(5.0, "usable fixes needed since the last reset before any is trusted", "s", ge=0)
    noise_sigma_m: float = setting(0.75, "1σ of the slow lateral D-GPS error (Gauss-Markov)", "m", gt=0)
    noise_tau_s: float = setting(180.0, "correlation time of that error", "s", ge=0)
    noise_white_m: float = setting(0.25, "1σ of the independent per-fix noise", "m", ge=0)
    decide_window_s: float = setting(120.0, "evidence window of the up/down test (field target < 120 s)", "s", gt=0)
    decide_recent_s: float = setting(
        30.0, "the test is also made on the last this-many seconds alone; 0 = full window only", "s", ge=0
    )
    decide_min_fixes: int = setting(10, "trusted fixes needed in the window before deciding", ge=1)
    decide_min_duration_s: float = setting(10.0, "time spanned by those fixes", "s", ge=0)
    decide_min_share: float = setting(0.9, "share of the fixes whose nearest track is the decided one", ge=0, le=1)
    decide_error: float = setting(1e-3, "accepted probability of deciding the wrong track", gt=0, lt=1)
    decide_fit_z: float = setting(3.0, "|mean offset| from the decided track within this many SE …", gt=0)
    decide_max_mean_m: float = setting(2.5, "… and at most this (not between two tracks, not beside one)", "m", gt=0)
    redecide_factor: float = setting(
        2.0, "changing a decision without a crossover needs this many times the LLR threshold", ge=1
    )
    km_dir_min_m: float = setting(10.0, "|km change| over the evidence window below this → standing", "m", ge=0)
    crossover_window_s: float = setting(5.0, "window of the RMS of the offset from the decided track", "s", gt=0)
    crossover_ref_s: float = setting(20.0, "reference window of the offset's previous level …", "s", gt=0)
    crossover_lag_s: float = setting(10.0, "… ending this long before the RMS window starts", "s", ge=0)
    crossover_rms_m: float = setting(2.0, "RMS of the offset above this …", "m", gt=0)
    crossover_min_shift: float = setting(0.6, "… and the mean moved by this share of the track spacing …", ge=0)
    crossover_z: float = setting(3.0, "… and by this many σ of the slow error's drift", ge=0)
    initial_uncertainty_m: float = setting(10.0, "uncertainty of a GPS-derived initial position", "m", gt=0)
    allow_initial: bool = setting(True, "GPS may set the initial position before any balise (flagged)")

    def __post_init__(self) -> None:
        check_ranges(self, "gps")
        if len(self.windows_s) != len(self.rms_threshold_m) or not self.windows_s:
            raise SettingError(
                f"'gps.windows_s' and 'gps.rms_threshold_m' need one threshold per window "
                f"({len(self.windows_s)} windows, {len(self.rms_threshold_m)} thresholds)"
            )


@dataclass(frozen=True)
class MarginConfig:
    """Safety margin: |position error| ≤ margin [S000 §4.3.2] (:mod:`fieldlogs.pipeline.positions`)."""

    distance_pct: float = setting(2.0, "share of the travel since the last absolute fix", "%", ge=0)
    uncertain_growth_pct: float = setting(5.0, "share of the travel added while the position is uncertain", "%", ge=0)
    imu_gap_s: float = setting(3.0, "an IMU silent this long while moving makes the position uncertain", "s", gt=0)
    imu_gap_share: float = setting(
        0.5, "share of the travel added to the margin while the IMU is silent (undetectable slip)", ge=0, le=1
    )
    scale_check_pct: float = setting(
        1.0, "a balise interval showing a wheel scale error above this widens distance_pct by that error", "%", gt=0
    )
    wheel_rescale: bool = setting(
        True, "a fitted wheel scale error above scale_check_pct divides the pulse distance by 1 + it (replayed)"
    )

    def __post_init__(self) -> None:
        check_ranges(self, "margin")


@dataclass(frozen=True)
class ClockConfig:
    """Clock offsets of the IMU and GPS against the tacho, and of the balises against the DB
    (:mod:`fieldlogs.quality.clocks`, :mod:`fieldlogs.pipeline.consistency`)."""

    max_lag_s: float = setting(10.0, "offsets searched up to this either way; 0 = no clock check", "s", ge=0)
    tolerance_s: float = setting(
        0.5, "a determined offset beyond this is reported and the stream's t moved back", "s", gt=0
    )
    min_corr: float = setting(
        0.6, "an offset is determined when the correlation at its peak is at least this", gt=0, le=1
    )
    min_span_s: float = setting(60.0, "… and at least this much motion went into it", "s", ge=0)
    highpass_s: float = setting(30.0, "both signals minus their centred mean over this before correlating", "s", gt=0)
    balise_tolerance_s: float = setting(
        0.1,
        "a determined balise clock offset beyond this moves the telegrams' t back (keep ≤ balise.latency_budget_s)",
        "s",
        gt=0,
    )

    def __post_init__(self) -> None:
        check_ranges(self, "clock")


@dataclass(frozen=True)
class WindowConfig:
    """Replay of a long run in time windows, memory bounded by the window
    (:mod:`fieldlogs.pipeline.windows`; ``trainpos run`` and ``trainpos audit``)."""

    length_h: float = setting(
        2.0, "a Parquet run longer than 1.5 × this is replayed in windows of this length; 0 = always whole", "h", ge=0
    )
    overlap_min: float = setting(
        30.0, "each window is replayed from this long before its part (the position settles)", "min", ge=0
    )
    lookahead_min: float = setting(
        5.0, "… and to this long after it (what is decided after the fact: curve exits, the smoother)", "min", ge=0
    )

    def __post_init__(self) -> None:
        check_ranges(self, "window")


#: Default target of the position-correction % [S003 §5.2] (:mod:`fieldlogs.pipeline.corrections`;
#: declared here, with the settings, so that ``trainpos report --help`` needs no numpy).
TARGET_PCT = 0.5

#: The one plain setting of the pipeline (declared once, also used by the suite's tree).
CYCLE_S: dict[str, Any] = {
    "default": 0.1,
    "meaning": "processing cycle of the onboard unit (the tacho's rate)",
    "unit": "s",
    "gt": 0,
}


@dataclass(frozen=True)
class TrackSelectConfig:
    """Which track after a facing switch: the evidence tests of the network aids
    (:mod:`fieldlogs.pipeline.aids.track_gps`, :mod:`fieldlogs.pipeline.aids.track_imu`,
    :mod:`fieldlogs.pipeline.aids.track_crossover`, :mod:`fieldlogs.pipeline.aids.track_features`), and the
    D-GPS corrections along a determined track (:mod:`fieldlogs.pipeline.aids.track_gps_along`).

    A candidate is dropped when another one's log-likelihood ratio against it reaches
    A = ln((1 − β)/α) (Wald's upper threshold): α the accepted probability of dropping the true
    track, β that of not deciding on evidence that should decide.
    """

    alpha: float = setting(1e-4, "accepted probability that evidence drops the true track", gt=0, lt=0.5)
    beta: float = setting(0.01, "accepted probability of not deciding when the evidence should", gt=0, lt=0.5)
    gyro_bias_dps: float = setting(0.05, "1σ of the yaw-rate bias over a turnout", "deg/s", ge=0)
    gyro_noise_dps_rthz: float = setting(0.02, "yaw-rate white noise density", "deg/s/√Hz", ge=0)
    heading_geometry_deg: float = setting(
        0.5, "1σ of a turnout's heading change from laying tolerances and car-body motion", "deg", gt=0
    )
    crossover_geometry_m: float = setting(
        0.3,
        "1σ of a crossover's lateral displacement from the tracks' spacing, car-body motion and the odometry's scale",
        "m",
        gt=0,
    )
    imu_max_margin_m: float = setting(
        30.0, "no IMU test when the margin at the switch exceeds this (the window would hold other curves)", "m", gt=0
    )
    feature_headings: bool = setting(
        True, "curve feature points of the tracks are evidence while the track is ambiguous (the IMU heading test)"
    )
    gps_along_k: float = setting(
        4.0, "a D-GPS fix's along-track margin in σ of its error (noise_sigma_m, noise_white_m)", gt=0
    )
    gps_along_map_m: float = setting(0.5, "the centreline's own along-track error, added to that margin", "m", ge=0)
    gps_along_ratio: float = setting(
        1.5, "a D-GPS fix corrects the distance along the track only when the margin exceeds this × its own", gt=1
    )
    gps_along_confirm: int = setting(
        5, "D-GPS fixes in a row, each step agreeing with the odometry, before one corrects the position", ge=2
    )
    gps_min_fixes: int = setting(
        5, "GPS fixes at which two candidates' offsets differ before those offsets may decide between them", ge=1
    )
    gps_jump_sigma: float = setting(
        3.5, "a fix-to-fix change of every candidate's GPS offset beyond this many σ (white, √2) is a jump", gt=0
    )
    gps_along_step_m: float = setting(
        1.5, "a fix-to-fix step of a D-GPS fix along the track beyond this from the odometry's is a jump", "m", gt=0
    )

    def __post_init__(self) -> None:
        check_ranges(self, "track_select")

    @property
    def threshold(self) -> float:
        """Wald's A = ln((1 − β)/α)."""
        return math.log((1.0 - self.beta) / self.alpha)


@dataclass(frozen=True)
class PipelineConfig:
    """The pipeline's sections of the configuration tree."""

    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    balise: BaliseConfig = field(default_factory=BaliseConfig)
    feature: FeatureConfig = field(default_factory=FeatureConfig)
    gps: GpsConfig = field(default_factory=GpsConfig)
    margin: MarginConfig = field(default_factory=MarginConfig)
    cycle_s: float = setting(**CYCLE_S)
    gnss: GnssConfig = field(default_factory=GnssConfig)
    clock: ClockConfig = field(default_factory=ClockConfig)
    window: WindowConfig = field(default_factory=WindowConfig)
    track_select: TrackSelectConfig = field(default_factory=TrackSelectConfig)

    def __post_init__(self) -> None:
        check_ranges(self)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_toml(cls, path: Path) -> PipelineConfig:
        return cls.from_dict(read_toml(path), source=str(path))

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> PipelineConfig:
        """Overrides from ``data`` (TOML tables per section); sections that are not the
        pipeline's (``[possession]``, ``[gis_verify]``) are left to their applications."""
        cfg = cls()
        sections = {f.name for f in fields(cls)}
        for key, value in data.items():
            if key in FOREIGN_SECTIONS:
                continue
            if key not in sections:
                known = ", ".join(sorted(sections | FOREIGN_SECTIONS))
                raise InputError(f"unknown section or key '{key}' (known: {known})", path=source)
            current = getattr(cfg, key)
            try:
                if isinstance(value, dict):
                    cfg = replace(cfg, **{key: section_from_dict(current, value, key, source)})
                else:
                    cfg = replace(cfg, **{key: typed(source, key, current, value)})
            except SettingError as exc:
                raise SettingError(exc.message, path=source) from None
        check_budgets(cfg.balise, cfg.feature, cfg.clock, source)
        return cfg


def check_budgets(balise: BaliseConfig, feature: FeatureConfig, clock: ClockConfig, source: str) -> None:
    """The fail-safe pairs of keys: an offset a check leaves uncorrected (at most its
    tolerance) must be held by the budget the fixes carry for it, or a position could be
    claimed outside its margin. Checked once the whole file is read (either key may be set
    first); :class:`SettingError` names both keys."""
    pairs = (
        ("clock.balise_tolerance_s", clock.balise_tolerance_s, "balise.latency_budget_s", balise.latency_budget_s),
        ("clock.tolerance_s", clock.tolerance_s, "feature.clock_budget_s", feature.clock_budget_s),
    )
    for tol_key, tol, budget_key, budget in pairs:
        if tol > budget:
            raise SettingError(
                f"'{tol_key}' = {tol:g} s is above '{budget_key}' = {budget:g} s: an offset the check leaves "
                f"uncorrected would not be held by the margin (raise '{budget_key}' to at least {tol:g} s)",
                path=source,
            )


#: Sections of the configuration tree that belong to other applications.
FOREIGN_SECTIONS = frozenset({"possession", "gis_verify", "survey", "input"})


def read_toml(path: Path) -> dict[str, Any]:
    """A TOML file as a dict (missing file or bad TOML: InputError naming the file)."""
    path = Path(path)
    not_special(path, "config file (TOML)")
    try:
        return tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InputError("no such config file", path=path) from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from exc


def update_section(current: Any, values: dict[str, Any], section: str, source: str) -> Any:
    """Kept for the possession and GIS-verify sections until they move into the tree."""
    return section_from_dict(current, values, section, source)
