"""Settings of the possession check (``[possession]`` of a ``--config`` TOML file, beside the
pipeline's ``[gps]``).

Every setting carries its unit and, where it has one, the paper section it comes from; the
measurements that chose the values are in ``bench/NOTES.md`` ("Possession").
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fieldlogs.pipeline.config import GpsConfig, PipelineConfig
from schemas.errors import InputError
from schemas.settings import check_ranges, section_from_dict, setting


@dataclass(frozen=True)
class PossessionConfig:
    """Tuning of the possession alarms [S001 §3, §6, §7] (``[possession]`` of a ``--config`` file).

    The km filter's band is km ± (gis + km_z·σ). A multipath burst's plateau is a line too,
    so while a trusted fix anchors the filter (``restart_anchor_s``) a restart must be
    reachable from it (``restart_accel_mps2``). The slow D-GPS error can hold the fixes near
    the midline longer than the field target, and a vehicle on the wrong track must not start
    work unwarned: ``wrong_track_suspected`` says which way the evidence leans after
    ``decision_target_s`` (odds), it is not a decision. With degraded GPS the overrun
    judgement is held (``overrun_band_max_m``), as the paper's device holds its decision while
    the fixes fluctuate [S001 §7.3, fig. 17]. With a tacho a stopped vehicle — the one thing
    GPS cannot tell from a slow one — is taken as certain (``standstill_s``); a road-rail
    vehicle's rail-wheel odometer is not calibrated like a train's, so its scale stays
    uncertain (``tacho_scale_sigma``).
    """

    notice_m: float = setting(
        30.0, "notice when the band's leading edge is this close to the end [S001 §6.2(b)]", "m", ge=0
    )
    km_z: float = setting(3.0, "the band is km ± (gis + km_z·σ)", gt=0)
    gis_uncertainty_m: float = setting(0.5, "along-track error of the GIS grid and of map-matching", "m", ge=0)
    accel_noise_mps2: float = setting(0.3, "white acceleration noise of the km filter", "m/s²", gt=0)
    speed_sigma_mps: float = setting(5.0, "prior σ of the speed when the filter starts", "m/s", gt=0)
    untrusted_sigma_m: float = setting(1.0, "least σ of the km of an untrusted fix", "m", gt=0)
    fix1_sigma_m: float = setting(5.0, "least σ of the km of a fix without D-GPS or with a high HDOP", "m", gt=0)
    gate_z: float = setting(4.0, "fixes whose innovation exceeds this many σ are rejected (multipath)", gt=0)
    restart_fixes: int = setting(3, "that many rejected fixes on a straight line restart the filter; 0 = never", ge=0)
    restart_accel_mps2: float = setting(
        1.5, "while anchored, a restart line must be reachable accelerating by at most this", "m/s²", gt=0
    )
    restart_anchor_s: float = setting(10.0, "how long a trusted fix anchors the filter; 0 = no anchor", "s", ge=0)
    offset_free_m: float = setting(1.5, "lateral offset a good fix may have before it counts as noise", "m", ge=0)
    max_speed_mps: float = setting(7.0, "the filter's speed is kept within ± this", "m/s", gt=0)
    max_offset_m: float = setting(15.0, "fixes farther than this from every track are no km measurement", "m", gt=0)
    lead_s: float = setting(60.0, "fixes before PTO on used for the trust filter and the km", "s", ge=0)
    decision_target_s: float = setting(
        120.0, "no up/down decision this long after PTO on → track_undecided notice [S001 §3.1(e)]", "s", gt=0
    )
    suspect_llr: float = setting(
        0.0, "… and wrong_track_suspected when the evidence leans to another track by this LLR", ge=0
    )
    step_s: float = setting(0.1, "evaluation step of the alarm rules", "s", gt=0)
    min_speed_mps: float = setting(0.3, "the direction of travel is known above this speed", "m/s", ge=0)
    overrun_band_max_m: float = setting(
        15.0, "the overrun alarm's band is km ± min(u, this); wider → overrun_possible notice", "m", gt=0
    )
    uncertain_notice_m: float = setting(30.0, "position_uncertain notice when u exceeds this [S001 §3.2(b)]", "m", gt=0)
    rearm_s: float = setting(5.0, "episodes of the same alarm or notice closer than this are one", "s", ge=0)
    match_slack_s: float = setting(
        3600.0, "a possession is a candidate when its window ± this overlaps the on-rail period", "s", ge=0
    )
    standstill_s: float = setting(1.0, "with a tacho: no pulse for this long is a certain standstill", "s", gt=0)
    tacho_scale_sigma: float = setting(0.03, "with a tacho: 1σ of its unknown scale error (share of the speed)", ge=0)
    tacho_speed_floor_mps: float = setting(
        0.1, "with a tacho: σ of a tacho speed is tacho_scale_sigma·v + this", "m/s", gt=0
    )

    def __post_init__(self) -> None:
        check_ranges(self, "possession")

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> PossessionConfig:
        return section_from_dict(cls(), data, "possession", source)


def config_from_dict(data: dict[str, Any], source: str = "config") -> tuple[GpsConfig, PossessionConfig]:
    """The GPS and possession sections of parsed TOML (``{"gps": {...}, "possession": {...}}``);
    unknown keys and wrong types are InputErrors naming ``source``."""
    data = dict(data)
    section = data.pop("possession", {})
    if not isinstance(section, dict):
        raise InputError("'possession' must be a table", path=source)
    return PipelineConfig.from_dict(data, source=source).gps, PossessionConfig.from_dict(section, source)
