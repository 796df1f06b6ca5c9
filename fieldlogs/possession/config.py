"""Settings of the possession check (``[possession]`` of a ``--config`` TOML file, beside the
pipeline's ``[gps]``).

Every setting carries its unit and, where it has one, the paper section it comes from; the
measurements that chose the values are in ``bench/NOTES.md`` ("Possession").
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fieldlogs.pipeline.config import GpsConfig, PipelineConfig, update_section
from schemas.errors import InputError


@dataclass(frozen=True)
class PossessionConfig:
    """Tuning of the possession alarms (``[possession]`` in a ``--config`` TOML file)."""

    notice_m: float = 30.0
    """Notice when the band's leading edge is this close to the section end [m] [S001 §6.2(b)]."""
    km_z: float = 3.0
    """The band is km ± (gis + km_z·σ) [–]."""
    gis_uncertainty_m: float = 0.5
    """Along-track error of the GIS grid and of map-matching [m]."""
    accel_noise_mps2: float = 0.3
    """White acceleration noise of the km filter (road-rail vehicles: ≤ 2 km/h/s) [m/s²]."""
    speed_sigma_mps: float = 5.0
    """Prior σ of the speed when the filter starts [m/s]."""
    untrusted_sigma_m: float = 1.0
    """Minimum σ (white part) of the km of a fix the trust filter did not trust; above it
    the RMS of the shortest trust window [m]."""
    fix1_sigma_m: float = 5.0
    """Minimum σ of the km of a fix without D-GPS (fix 1) or with a high HDOP [m]."""
    gate_z: float = 4.0
    """Fixes whose innovation exceeds this many σ are rejected (multipath) [–]."""
    restart_fixes: int = 3
    """That many consecutive rejected fixes lying on a straight line restart the filter from
    them (0 = never) [–] …"""
    restart_accel_mps2: float = 1.5
    """… but while the last accepted fix was trusted (less than ``restart_anchor_s`` before),
    only if the vehicle could have joined the line from the filter's state accelerating by at
    most this [m/s²]. Why: a multipath burst's plateau is a line too, and a filter built on
    trusted fixes is not the one that got lost (bench/NOTES.md, "Possession")."""
    restart_anchor_s: float = 10.0
    """How long a trusted fix anchors the filter (longer than a burst) [s]: restarts must be
    reachable from it, and while it shows the vehicle standing, fixes worse than the
    estimate (fix 1, high HDOP) are skipped (0 = no anchor)."""
    offset_free_m: float = 1.5
    """Lateral offset from the nearest track a good fix may have (2σ of the slow error);
    beyond it the excess counts as along-track noise too [m]."""
    max_speed_mps: float = 7.0
    """The filter's speed is kept within ± this (road-rail vehicles on rail: ≤ 25 km/h) [m/s]."""
    max_offset_m: float = 15.0
    """Fixes farther than this from every track of the line are no km measurement [m]."""
    lead_s: float = 60.0
    """Fixes before PTO on used for the trust filter and the km (approach on the road) [s]."""
    decision_target_s: float = 120.0
    """No up/down decision this long after PTO on → ``track_undecided`` notice [s] [S001 §3.1(e)] …"""
    suspect_llr: float = 0.0
    """… and a ``wrong_track_suspected`` alarm when the evidence of those seconds leans to
    another track than the plan's: its log-likelihood ratio against every other candidate
    exceeds this [–]. Why: the slow D-GPS error can hold the fixes near the midline longer than
    the field target, and a vehicle on the wrong track must not start work unwarned; the
    alarm says which way the evidence leans and how strongly (odds), it is not a decision."""
    step_s: float = 0.1
    """Evaluation step of the alarm rules [s]."""
    min_speed_mps: float = 0.3
    """The direction of travel is known above this speed (approach notice) [m/s]."""
    overrun_band_max_m: float = 15.0
    """The overrun alarm's band is km ± min(u, this) [m]: with degraded GPS (u larger) the
    judgement is held — an ``overrun_possible`` notice while only the full band leaves the
    section — as the paper's device holds its decision while the fixes fluctuate [S001 §7.3,
    fig. 17]; half the 30 m the sections are planned beyond the work [S001 §3.2(b)]."""
    uncertain_notice_m: float = 30.0
    """``position_uncertain`` notice when u exceeds this [m] [S001 §3.2(b)]."""
    rearm_s: float = 5.0
    """Episodes of the same alarm or notice closer than this are one [s]."""
    match_slack_s: float = 3600.0
    """A possession is a candidate when its time window ± this overlaps the on-rail period [s]."""
    standstill_s: float = 1.0
    """With a tacho: no pulse for this long (≈ 3 cm of wheel travel; 0.03 m/s at most) is a
    standstill, taken as certain: the km filter holds (speed 0, no process noise) until the
    next pulse [s]. Why: a stopped vehicle is the one thing GPS cannot tell from a slow one
    (bench/NOTES.md, "Possession")."""
    tacho_scale_sigma: float = 0.03
    """With a tacho: 1σ of its unknown scale error (a fraction of the speed) [–]. Why: a
    road-rail vehicle's rail-wheel odometer is not calibrated like a train's — wheel wear and a
    nominal diameter in run.json put a few % on it; the filter never learns the scale."""
    tacho_speed_floor_mps: float = 0.1
    """With a tacho: σ of a tacho speed is ``tacho_scale_sigma``·v + this [m/s] — one pulse
    (≈ 3 cm) over the 0.5 s difference, and the difference's error while the braking or
    traction force changes."""

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "config") -> PossessionConfig:
        return update_section(cls(), data, "possession", source)


def load_config(path: Path | None) -> tuple[GpsConfig, PossessionConfig]:
    """GPS and possession settings from a TOML file (``[gps]``, ``[possession]``; the other
    pipeline sections are accepted and ignored); defaults without a file."""
    if path is None:
        return GpsConfig(), PossessionConfig()
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InputError("no such config file", path=path) from exc
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not valid TOML: {exc}", path=path) from exc
    return config_from_dict(data, str(path))


def config_from_dict(data: dict[str, Any], source: str = "config") -> tuple[GpsConfig, PossessionConfig]:
    """:func:`load_config` on parsed sections (``{"gps": {...}, "possession": {...}}``);
    unknown keys and wrong types are InputErrors naming ``source``."""
    data = dict(data)
    section = data.pop("possession", {})
    if not isinstance(section, dict):
        raise InputError("'possession' must be a table", path=source)
    return PipelineConfig.from_dict(data, source=source).gps, PossessionConfig.from_dict(section, source)
