"""Algorithm internals of a ``correct_odometry`` run, for tests and bench scripts only.

``Odometry.diagnostics`` holds one :class:`OdometryDiagnostics`; nothing here goes into the
pipeline's events or summary (those take :class:`~fieldlogs.pipeline.types.SlipEpisode`).
Indices are on the *aligned* cycles (pulses delayed onto the IMU: aligned k ↔ output
cycle k − ``delay_cycles``).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class EpisodeDiagnostics:
    """What the algorithm saw and decided for one episode (same order as the episodes)."""

    i_detect_aligned: int
    i_start_aligned: int
    i_end_aligned: int
    i_settled_aligned: int
    """End of the disturbance: the end, or the end of the fail-safe watch."""
    lookback_s: float
    """Detection − start point, aligned time [s]."""
    redetect_t: tuple[float, ...]
    """Detections that re-opened the episode or fell inside its fail-safe [s]."""
    echo_t: tuple[float, ...]
    """Detections ignored as the filters' echo of the slip's end [s]."""
    diff_at_detect_kmh_s: float
    """K·a_x − K·A_p at detection [km/h/s]."""
    ax_at_detect_kmh_s: float
    ap_at_detect_kmh_s: float
    v_pulse_at_detect_mps: float
    """1 s mean pulse speed at detection [m/s]."""
    residual_at_detect_kmh_s: float | None
    """Grade-compensated residual at detection (None where not defined) [km/h/s]."""
    psi0_rad: float
    """Roll at the start point (eq. 11) [rad]."""
    theta_end_rad: float
    """Pitch at the end of the correction [rad]."""
    gyro_bias_rad_s: float
    """Pitch-rate bias removed, travel frame [rad/s]."""
    theta_clipped: bool
    """|θ̄| at the start point exceeded arcsin(Ta/G) (the start point was not adhering)."""
    end_speed_error_mps: float | None
    """δ: 1 s mean inertial − pulse speed at re-adhesion (None without re-adhesion) [m/s];
    with a ground speed the filtered speed's."""
    ground_e_at_detect_mps: float | None = None
    """With a ground speed: 1 s mean pulse − ground speed at detection [m/s]."""
    ground_refused: int = 0
    """Ground values the cross-check refused (``fusion``)."""
    ground_reseated: int = 0
    """Times the filter re-seated on the ground speed (the inertial solution had left it)."""
    ground_share: float = 0.0
    """Share of the correction's cycles carried by a ground value."""
    inertial_dev_mps: float | None = None
    """Largest |1 s mean (inertial − ground speed)| over the correction [m/s]."""


@dataclass(frozen=True)
class OdometryDiagnostics:
    """Run-level internals of the correction."""

    delay_cycles: int
    """Pulse delay D used (SPEC value or the searched one) [cycles]."""
    episodes: tuple[EpisodeDiagnostics, ...] = ()
