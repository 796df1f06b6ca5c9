"""Settings of ``trainpos survey`` (``[survey]`` of a ``--config`` TOML file).

The survey also reads the pipeline's ``[feature]`` section for the curve rule it shares
with the onboard unit (the 20 % tolerance of the lower and upper limits, the straight
threshold, the merge distance of noise chatter), so a curve is located exactly as the
pipeline would see it. How the defaults were chosen is in ``bench/NOTES.md`` ("Survey").
"""

from __future__ import annotations

from dataclasses import dataclass

from schemas.settings import check_ranges, setting

#: Confidence of every interval the survey reports.
CONFIDENCE = 0.95


@dataclass(frozen=True)
class SurveyConfig:
    """Balises, feature points and wheels surveyed from many runs (issue 19; [S003 §5.5, §6], [S000 §4.3.2])."""

    # -- telegrams and passes --------------------------------------------------------------------
    match_window_m: float = setting(
        50.0, "a telegram is the DB balise of its kind and codes nearest its dead-reckoned km within this", "m", gt=0
    )
    pass_margin_m: float = setting(
        20.0, "a pass needs the position to cover the balise km by this plus the position's margin", "m", ge=0
    )
    extrapolate_m: float = setting(
        3000.0, "dead reckoning back before the first fix and beyond the last read at most this far", "m", ge=0
    )
    # -- balise residuals ------------------------------------------------------------------------
    cluster_m: float = setting(
        30.0, "balises closer than this (an initial pair) are never each other's anchors", "m", ge=0
    )
    max_slip_allowance_m: float = setting(
        1.0, "a balise interval whose slip-correction budget grew more is not used", "m", ge=0
    )
    interval_sigma_m: float = setting(
        0.15, "1σ of a balise-to-balise travel: constant part (read position, pulse quantisation)", "m", gt=0
    )
    interval_sigma_pct: float = setting(
        0.01, "… plus this share of the interval's length (balise residuals; not the wheel scale)", "%", ge=0
    )
    min_passes: int = setting(3, "fewer usable passes (runs for curves and wheels) → unverified", ge=2)
    moved_min_m: float = setting(1.0, "smallest balise residual reported as moved (and proposed)", "m", gt=0)
    ok_tolerance_m: float = setting(1.0, "a balise is ok only if its 95 % interval lies within ± this", "m", gt=0)
    max_iterations: int = setting(20, "rounds of the balise adjustment (flag, correct, re-estimate)", ge=1)
    # -- missed and unknown balises --------------------------------------------------------------
    min_missed_passes: int = setting(2, "a balise never read on at least this many passes is missed", ge=1)
    candidate_runs: int = setting(
        3, "unknown telegrams from at least this many runs at one place → a candidate (proposed)", ge=1
    )
    candidate_radius_m: float = setting(
        20.0, "unknown telegrams of the same content within this are one candidate", "m", gt=0
    )
    # -- feature points --------------------------------------------------------------------------
    feature_km_tolerance_m: float = setting(
        10.0, "a DB feature is ok when both lower-limit crossings agree within this", "m", gt=0
    )
    feature_radius_tolerance: float = setting(0.20, "… and its radius within this share", gt=0, lt=1)
    max_radius_m: float = setting(3000.0, "curves of a larger radius are not surveyed as feature points", "m", gt=0)
    min_curve_m: float = setting(
        20.0, "curve bodies (between the lower-limit crossings) shorter than this are ignored", "m", gt=0
    )
    min_speed_kmh: float = setting(
        30.0, "curvature samples slower than this are not used (κ = ωz/v amplifies the gyro's noise)", "km/h", ge=0
    )
    max_gap_m: float = setting(
        10.0, "a lower-limit crossing needs curvature samples this close on both sides", "m", gt=0
    )
    profile_bin_m: float = setting(2.0, "bin of the mean curvature profile along a track", "m", gt=0)
    curve_pad_m: float = setting(
        150.0, "curvature kept around every curve and DB feature (enough for its transitions)", "m", gt=0
    )
    # -- wheels ----------------------------------------------------------------------------------
    wheel_min_distance_m: float = setting(
        2000.0, "a run's wheel diameter needs this much clean balise-to-balise travel", "m", gt=0
    )
    gnss_error_tau_s: float = setting(
        180.0, "correlation time of the GNSS along-track error (Gauss–Markov) in the GNSS wheel scale", "s", gt=0
    )
    gnss_outlier_z: float = setting(
        5.0, "GNSS points whose whitened residual is beyond this many robust σ are dropped", gt=0
    )
    track_length_sigma_pct: float = setting(
        0.001,
        "1σ systematic error of the GIS grid's track length, shared by the balise and GNSS wheel scales",
        "%",
        ge=0,
    )
    wheel_alert_share: float = setting(
        0.003, "maintenance alert when the estimated diameter differs from run.json's by more", gt=0, lt=1
    )

    def __post_init__(self) -> None:
        check_ranges(self, "survey")
