"""The ``[gnss]`` section of the configuration tree: the GNSS aid of the pipeline and
``trainpos gnss position`` [S002] (SPEC §5.6).

Masks and solver settings map onto :class:`fieldlogs.gnss.position.PositionConfig`
(:func:`position_config`); the rest are the aid's rules (:mod:`fieldlogs.pipeline.aids.gnss`):
when an epoch corrects the km, when it may set the initial position, and when fits on another
track are evidence against the track in force. Measurements behind the defaults:
bench/NOTES.md, "GNSS in the pipeline".
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

from schemas.settings import SettingError, check_ranges, setting

if TYPE_CHECKING:
    from fieldlogs.gnss.position import PositionConfig

#: Systems the GNSS core computes (GPS, Galileo, QZSS).
GNSS_SYSTEMS = ("G", "E", "J")


@dataclass(frozen=True)
class GnssConfig:
    """Track-constrained GNSS positioning from raw pseudoranges [S002, SPEC §5.6]."""

    enabled: bool = setting(True, "use gnss_obs + gnss_nav when the run has them (false: the aid stays silent)")
    systems: tuple[str, ...] = setting(GNSS_SYSTEMS, "satellite systems used: G GPS, E Galileo, J QZSS")
    elevation_mask_deg: float = setting(10.0, "satellites below this elevation are not used", "deg", ge=0, lt=90)
    cn0_mask_dbhz: float = setting(30.0, "observations with a lower C/N0 are not used", "dB-Hz", ge=0)
    smoothing_s: float = setting(100.0, "carrier-smoothing window of the code (Hatch); 0 = raw code", "s", ge=0)
    max_divergence_mps: float = setting(
        0.1, "a satellite whose code drifts from its carrier faster than this is dropped; 0 = off", "m/s", ge=0
    )
    clock_coasting: bool = setting(True, "re-solve epochs the satellites alone cannot carry with a predicted clock")
    sbas: bool = setting(True, "apply the run's SBAS/MSAS messages (gnss_sbas) where it has them")
    pr_difference_tol_m: float = setting(
        8.0, "tolerance of the pseudorange differences between two antennas (pre-check)", "m", gt=0
    )
    max_pdop: float = setting(6.0, "the unconstrained solution counts as available up to this PDOP", gt=0)
    correction_gain_m: float = setting(
        2.0, "an epoch corrects the km when its uncertainty is at least this much below the margin", "m", ge=0
    )
    allow_initial: bool = setting(True, "GNSS may set the initial position on a GPS-decided track (flagged)")
    initial_max_uncertainty_m: float = setting(
        50.0, "largest uncertainty of an epoch that sets the initial position", "m", gt=0
    )
    direction_min_travel_m: float = setting(
        50.0, "the km direction of an initial position needs two epochs at least this much travel apart", "m", gt=0
    )
    track_window_s: float = setting(60.0, "evidence window of the fits on the other tracks of the line", "s", gt=0)
    track_min_epochs: int = setting(20, "epochs with a fit on both tracks needed in the window before judging", ge=1)
    track_chi2: float = setting(
        10.83, "the other track fits far better: median test-statistic excess above this (χ²₁ at 10⁻³)", gt=0
    )
    track_share: float = setting(0.9, "… and the share of epochs where the other track fits better", gt=0, le=1)
    split_epochs: int = setting(
        5,
        "network candidates (after a facing switch): epochs counted as independent evidence — judged from this "
        "many epochs on, when the median excess × this count is above track_chi2",
        ge=1,
    )

    def __post_init__(self) -> None:
        check_ranges(self, "gnss")
        bad = [s for s in self.systems if s not in GNSS_SYSTEMS]
        if bad or not self.systems:
            raise SettingError(
                f"'gnss.systems' = {list(self.systems)!r}: each must be one of {', '.join(GNSS_SYSTEMS)} (at least one)"
            )


def position_config(cfg: GnssConfig, systems: tuple[str, ...] | None = None) -> PositionConfig:
    """The GNSS core's masks and solver settings from the ``[gnss]`` section."""
    from fieldlogs.gnss.position import PositionConfig  # the solver stack, only when solving

    return PositionConfig(
        systems=tuple(systems or cfg.systems),
        elevation_mask_deg=cfg.elevation_mask_deg,
        cn0_mask_dbhz=cfg.cn0_mask_dbhz,
        pr_difference_tol_m=cfg.pr_difference_tol_m,
        max_pdop=cfg.max_pdop,
        clock_coasting=cfg.clock_coasting,
        smoothing_s=cfg.smoothing_s or None,
        max_divergence_mps=cfg.max_divergence_mps or None,
        use_sbas=cfg.sbas,
    )
