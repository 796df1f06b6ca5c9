"""Simulation scenarios: typed dataclasses loaded from TOML (``tomllib``).

A scenario file overrides any subset of the knobs of ``fieldlogs/simulate/scenarios/default.toml``,
which documents every knob with its unit and default. Unknown keys and wrong types are
errors that name the file and the dotted key (``slip.depth``), so a typo never silently
falls back to a default. Integers are accepted where a float is expected; booleans are not
numbers. Pairs such as ``depth = [0.1, 0.4]`` are inclusive ranges a value is drawn from.
"""

from __future__ import annotations

import math
import tomllib
import typing
from dataclasses import MISSING, dataclass, field, fields, is_dataclass, replace
from datetime import datetime
from pathlib import Path
from typing import Any

from fieldlogs.simulate.scenario_cabs import CabRCfg, check_cab_r
from fieldlogs.simulate.scenario_net import NetworkCfg, check_network
from schemas.enums import CabDirection, Track, VehicleKind
from schemas.errors import UsageError
from schemas.frames import suggest
from schemas.radar import RUN_JSON_RADAR

DEFAULT_SCENARIO = Path(__file__).resolve().parent / "scenarios" / "default.toml"


class ScenarioError(UsageError):
    """A bad scenario: names the file and the dotted key (exit code 2)."""

    def __init__(self, message: str, *, path: str | Path | None = None, key: str | None = None) -> None:
        super().__init__(message, path=path)
        self.key = key

    def __str__(self) -> str:
        where = [p for p in (self.path, f"key '{self.key}'" if self.key else None) if p]
        return f"{', '.join(where)}: {self.message}" if where else self.message


@dataclass(frozen=True)
class RunCfg:
    run_id: str = ""
    vehicle_id: str = "SIM-01"
    vehicle_kind: str = "train"
    start_time: str = "2026-01-15T10:00:00+09:00"
    notes: str = ""


@dataclass(frozen=True)
class RouteCfg:
    line_code: str = ""
    track: str = ""
    path_km_m: tuple[float, ...] = ()
    start_cab: str = "F"
    margin_m: float = 150.0


@dataclass(frozen=True)
class RunningCfg:
    line_speed_kmh: float = 95.0
    design_speed_kmh: float = 0.0
    accel_kmh_s: float = 2.5
    brake_kmh_s: float = 3.0
    jerk_mps3: float = 0.3
    unbalanced_lateral_mps2: float = 0.8
    cant_max_mm: float = 105.0
    cant_coefficient: float = 11.8
    gauge_m: float = 1.067
    stop_at_stations: bool = True
    stations_km_m: tuple[float, ...] = ()
    stop_beyond_i1_m: float = 250.0
    dwell_s: float = 30.0
    reversal_dwell_s: float = 90.0
    standstill_start_s: float = 20.0
    standstill_end_s: float = 20.0
    rollback_m: float = 0.0
    rollback_min_gradient_permille: float = 0.0
    rollback_speed_mps: float = 0.5


@dataclass(frozen=True)
class RoadRailCfg:
    off_rail_before_s: float = 60.0
    off_rail_after_s: float = 60.0
    road_offset_m: float = 8.0
    transfer_s: float = 20.0


@dataclass(frozen=True)
class SensorsCfg:
    imu: bool = True
    tacho: bool = True
    gps: bool = True
    balise: bool = True
    radar: bool = False
    radar_if: bool = False
    truth: bool = True


@dataclass(frozen=True)
class ImuCfg:
    accel_white_kmh_s: float = 0.1
    gyro_white_deg_s: float = 0.1
    accel_bias_kmh_s: float = 0.1
    gyro_bias_deg_s: float = 0.05
    accel_drift_kmh_s: float = 0.02
    gyro_drift_deg_s: float = 0.005
    drift_tau_s: float = 600.0
    accel_lsb_mps2: float = 0.00785
    gyro_lsb_deg_s: float = 0.02


@dataclass(frozen=True)
class TachoCfg:
    teeth: int = 90
    wheel_diameter_m: float = 0.86
    wear_pct: tuple[float, float] = (0.0, 0.5)
    two_phase: bool = False


@dataclass(frozen=True)
class Episode:
    t0_s: float
    duration_s: float
    kind: str
    depth: float


@dataclass(frozen=True)
class SlipCfg:
    slips: int = 2
    slides: int = 2
    depth: tuple[float, float] = (0.1, 0.4)
    duration_s: tuple[float, float] = (1.0, 12.0)
    on_grade_curve: bool = True
    episodes: tuple[Episode, ...] = ()


@dataclass(frozen=True)
class GpsCfg:
    sigma_m: float = 0.75
    tau_s: float = 180.0
    multipath_per_hour: float = 6.0
    multipath_m: tuple[float, float] = (5.0, 30.0)
    multipath_s: tuple[float, float] = (2.0, 8.0)
    outages_km_m: tuple[tuple[float, float], ...] = ()
    reacquire_s: float = 10.0
    fix1_sigma_m: float = 4.0
    nsat: int = 12
    hdop: float = 0.9
    poor_sky_km_m: tuple[tuple[float, float], ...] = ()
    poor_sky_white_m: float = 1.0
    poor_sky_multipath_per_hour: float = 240.0
    poor_sky_fix1_share: float = 0.3
    poor_sky_fix1_spell_s: float = 8.0
    poor_sky_nsat: int = 6


@dataclass(frozen=True)
class RadarCfg:
    rate_hz: float = 3.0
    noise_pct: float = 0.5
    noise_min_mps: float = 0.05
    cutoff_mps: float = 0.3


@dataclass(frozen=True)
class RadarIfCfg:
    f0_hz: float = 24.06e9
    delta_f_hz: float = 12.75e6
    t_pri_s: float = 50e-6
    t_epi_s: float = 0.307
    height_m: float = 0.8
    depression_deg: float = 45.0
    beam_elev_deg: float = 7.5
    beam_az_deg: float = 3.0
    looks_toward: str = "F"
    track_bed: str = "ballast"
    slab_km_m: tuple[tuple[float, float], ...] = ()
    scatterers_per_m2: float = 400.0
    ballast_roughness_m: float = 0.02
    slab_reflectivity: float = 0.3
    strong_per_m: float = 1.0
    strong_gain: float = 4.0
    snr_db: float = 30.0
    dc_leak: float = 0.5
    adc_bits: int = 12
    vibration_mm: float = 0.0
    vibration_hz: float = 8.0


@dataclass(frozen=True)
class BaliseCfg:
    miss_probability: float = 0.0
    readers_x_m: tuple[float, ...] = ()


@dataclass(frozen=True)
class GnssRawCfg:
    enabled: bool = False
    systems: tuple[str, ...] = ("G", "E", "J")
    interval_s: float = 1.0
    antennas_x_m: tuple[float, ...] = (8.0, -8.0)
    antenna_z_m: float = 3.8
    corridor: str = "open"
    sbas: bool = False


@dataclass(frozen=True)
class Scenario:
    """Every knob of a simulated run (see ``fieldlogs/simulate/scenarios/default.toml``)."""

    name: str = "default"
    seed: int = 1
    noise: bool = True
    run: RunCfg = field(default_factory=RunCfg)
    route: RouteCfg = field(default_factory=RouteCfg)
    running: RunningCfg = field(default_factory=RunningCfg)
    road_rail: RoadRailCfg = field(default_factory=RoadRailCfg)
    sensors: SensorsCfg = field(default_factory=SensorsCfg)
    imu: ImuCfg = field(default_factory=ImuCfg)
    tacho: TachoCfg = field(default_factory=TachoCfg)
    slip: SlipCfg = field(default_factory=SlipCfg)
    gps: GpsCfg = field(default_factory=GpsCfg)
    radar: RadarCfg = field(default_factory=RadarCfg)
    radar_if: RadarIfCfg = field(default_factory=RadarIfCfg)
    balise: BaliseCfg = field(default_factory=BaliseCfg)
    gnss_raw: GnssRawCfg = field(default_factory=GnssRawCfg)
    network: NetworkCfg = field(default_factory=NetworkCfg)
    cab_r: CabRCfg = field(default_factory=CabRCfg)
    source: str = field(default="<default scenario>", compare=False)
    """Where it was loaded from (for messages); not a knob."""

    @property
    def is_road_rail(self) -> bool:
        return self.run.vehicle_kind == VehicleKind.ROAD_RAIL


# -- loading --------------------------------------------------------------------------------
def _type_name(tp: Any) -> str:
    origin = typing.get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is bool:
        return "true or false"
    if tp is str:
        return "a string"
    if is_dataclass(tp):
        return "a table"
    if origin is tuple:
        args = typing.get_args(tp)
        if len(args) == 2 and args[1] is Ellipsis:
            return f"an array of {_type_name(args[0]).removeprefix('an ').removeprefix('a ')}s"
        return f"an array of {len(args)} numbers"
    return str(tp)


def _scalar_ok(value: Any, tp: Any) -> bool:
    """Whether ``value`` (from TOML) is acceptable for the scalar type ``tp``."""
    if tp is bool or tp is str:
        return isinstance(value, tp)
    if tp is int:
        return isinstance(value, int) and not isinstance(value, bool)
    return isinstance(value, int | float) and not isinstance(value, bool)  # float


def _convert(value: Any, tp: Any, key: str, src: str) -> Any:
    def bad() -> ScenarioError:
        return ScenarioError(f"expected {_type_name(tp)}, got {value!r}", path=src, key=key)

    if is_dataclass(tp):
        if not isinstance(value, dict):
            raise bad()
        return _build(tp, value, key, src)  # type: ignore[arg-type]
    if tp in (bool, int, float, str):
        if not _scalar_ok(value, tp):
            raise bad()
        return float(value) if tp is float else value
    if typing.get_origin(tp) is tuple:
        args = typing.get_args(tp)
        if not isinstance(value, list):
            raise bad()
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(v, args[0], f"{key}[{i}]", src) for i, v in enumerate(value))
        if len(value) != len(args):
            raise bad()
        return tuple(_convert(v, a, f"{key}[{i}]", src) for i, (v, a) in enumerate(zip(value, args, strict=True)))
    raise TypeError(f"unsupported scenario type {tp!r}")  # pragma: no cover - programming error


def _build(cls: type, data: dict[str, Any], prefix: str, src: str) -> Any:
    hints = typing.get_type_hints(cls)
    known = {f.name: f for f in fields(cls) if f.name != "source"}
    for k in data:
        if k not in known:
            full = f"{prefix}.{k}" if prefix else k
            hint = suggest(k, list(known))
            msg = f"unknown key (did you mean '{hint}'?)" if hint else f"unknown key (known: {', '.join(known)})"
            raise ScenarioError(msg, path=src, key=full)
    kwargs: dict[str, Any] = {}
    for name, f in known.items():
        full = f"{prefix}.{name}" if prefix else name
        if name in data:
            kwargs[name] = _convert(data[name], hints[name], full, src)
        elif f.default is MISSING and f.default_factory is MISSING:
            raise ScenarioError("missing key", path=src, key=full)
    return cls(**kwargs)


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        out[k] = _merge(out[k], v) if isinstance(v, dict) and isinstance(out.get(k), dict) else v
    return out


def _check(s: Scenario) -> None:
    """Every knob inside its range; the first problem is raised naming its key."""
    checks = (
        _check_run,
        _check_positive,
        _check_non_negative,
        _check_bounds,
        _check_cabs,
        _check_spans,
        _check_episodes,
        _check_radar,
        _check_gnss_raw,
        _check_network,
    )
    for check in checks:
        problem = check(s)
        if problem is not None:
            raise ScenarioError(problem[1], path=s.source, key=problem[0])


Problem = tuple[str, str] | None
"""(key, message) of the first problem a check finds, or None."""


def _check_run(s: Scenario) -> Problem:
    kinds = [v.value for v in VehicleKind]
    if s.run.vehicle_kind not in kinds:
        return "run.vehicle_kind", f"must be one of {', '.join(kinds)}"
    try:
        st = datetime.fromisoformat(s.run.start_time)
    except ValueError:
        return "run.start_time", f"not an ISO 8601 time: {s.run.start_time!r}"
    if st.tzinfo is None:
        return "run.start_time", "needs a UTC offset, e.g. 2026-01-15T10:00:00+09:00"
    if not math.isfinite(s.road_rail.road_offset_m):
        return "road_rail.road_offset_m", "must be finite"
    if s.route.track not in ("", *(t.value for t in Track)):
        return "route.track", "must be U, D, S or empty"
    if s.route.start_cab not in [d.value for d in CabDirection]:
        return "route.start_cab", "must be F or R"
    if s.seed < 0:
        return "seed", "must be ≥ 0"
    return None


def _check_positive(s: Scenario) -> Problem:
    positive = {
        "running.line_speed_kmh": s.running.line_speed_kmh,
        "running.accel_kmh_s": s.running.accel_kmh_s,
        "running.brake_kmh_s": s.running.brake_kmh_s,
        "running.jerk_mps3": s.running.jerk_mps3,
        "running.gauge_m": s.running.gauge_m,
        "tacho.wheel_diameter_m": s.tacho.wheel_diameter_m,
        "tacho.teeth": s.tacho.teeth,
        "imu.drift_tau_s": s.imu.drift_tau_s,
        "gps.tau_s": s.gps.tau_s,
        "radar.rate_hz": s.radar.rate_hz,
    }
    return next(((k, f"must be > 0, got {v}") for k, v in positive.items() if not (math.isfinite(v) and v > 0)), None)


def _check_non_negative(s: Scenario) -> Problem:
    non_negative = {
        "route.margin_m": s.route.margin_m,
        "running.design_speed_kmh": s.running.design_speed_kmh,
        "running.unbalanced_lateral_mps2": s.running.unbalanced_lateral_mps2,
        "running.cant_max_mm": s.running.cant_max_mm,
        "running.cant_coefficient": s.running.cant_coefficient,
        "running.dwell_s": s.running.dwell_s,
        "running.reversal_dwell_s": s.running.reversal_dwell_s,
        "running.standstill_start_s": s.running.standstill_start_s,
        "running.standstill_end_s": s.running.standstill_end_s,
        "running.rollback_m": s.running.rollback_m,
        "road_rail.off_rail_before_s": s.road_rail.off_rail_before_s,
        "road_rail.off_rail_after_s": s.road_rail.off_rail_after_s,
        "road_rail.transfer_s": s.road_rail.transfer_s,
        "gps.poor_sky_white_m": s.gps.poor_sky_white_m,
        "gps.poor_sky_multipath_per_hour": s.gps.poor_sky_multipath_per_hour,
        "gps.sigma_m": s.gps.sigma_m,
        "gps.multipath_per_hour": s.gps.multipath_per_hour,
        "gps.reacquire_s": s.gps.reacquire_s,
        "gps.fix1_sigma_m": s.gps.fix1_sigma_m,
        "gps.hdop": s.gps.hdop,
        "radar.noise_pct": s.radar.noise_pct,
        "radar.noise_min_mps": s.radar.noise_min_mps,
        "slip.slips": s.slip.slips,
        "slip.slides": s.slip.slides,
        **{f"imu.{f.name}": getattr(s.imu, f.name) for f in fields(ImuCfg)},
    }
    bad = ((k, f"must be ≥ 0, got {v}") for k, v in non_negative.items() if not (math.isfinite(v) and v >= 0))
    return next(bad, None)


def _check_bounds(s: Scenario) -> Problem:
    if s.running.cant_max_mm >= 1000 * s.running.gauge_m:
        return "running.cant_max_mm", "must be smaller than the gauge"
    if not 0 <= s.balise.miss_probability <= 1:
        return "balise.miss_probability", "must be between 0 and 1"
    if not 0 <= s.gps.nsat <= 64:
        return "gps.nsat", "must be between 0 and 64"
    if not 0 <= s.gps.poor_sky_fix1_share < 1:
        return "gps.poor_sky_fix1_share", "must be ≥ 0 and < 1"
    if not (math.isfinite(s.gps.poor_sky_fix1_spell_s) and s.gps.poor_sky_fix1_spell_s >= 1):
        return "gps.poor_sky_fix1_spell_s", "must be ≥ 1 s"
    if not 4 <= s.gps.poor_sky_nsat <= 64:
        return "gps.poor_sky_nsat", "must be between 4 and 64"
    ranges = {
        "tacho.wear_pct": (s.tacho.wear_pct, -5.0, 5.0),
        "slip.depth": (s.slip.depth, 0.0, 0.9),
        "slip.duration_s": (s.slip.duration_s, 0.1, 600.0),
        "gps.multipath_m": (s.gps.multipath_m, 0.0, 1000.0),
        "gps.multipath_s": (s.gps.multipath_s, 0.1, 600.0),
    }
    for key, ((lo, hi), vmin, vmax) in ranges.items():
        if not (vmin <= lo <= hi <= vmax):
            return key, f"needs [low, high] with {vmin} ≤ low ≤ high ≤ {vmax}, got [{lo}, {hi}]"
    return None


def _check_cabs(s: Scenario) -> Problem:
    """Rolling back, a balise reader per cab and the R cab's own sensors."""
    if not 0 < s.running.rollback_speed_mps <= 2:
        return "running.rollback_speed_mps", "must be > 0 and ≤ 2 m/s (a train rolling back)"
    if len(s.balise.readers_x_m) not in (0, 2) or any(not abs(x) <= 50 for x in s.balise.readers_x_m):
        return "balise.readers_x_m", "[] or [x of the F cab's reader, x of the R cab's] within ±50 m"
    return check_cab_r(s.cab_r)


def _check_spans(s: Scenario) -> Problem:
    for key, spans in (("gps.outages_km_m", s.gps.outages_km_m), ("gps.poor_sky_km_m", s.gps.poor_sky_km_m)):
        for i, (a, b) in enumerate(spans):
            if not (math.isfinite(a) and math.isfinite(b) and a < b):
                return f"{key}[{i}]", f"needs [from, to] with from < to, got [{a}, {b}]"
    for key, vals in (("route.path_km_m", s.route.path_km_m), ("running.stations_km_m", s.running.stations_km_m)):
        if not all(math.isfinite(v) for v in vals):
            return key, "values must be finite"
    return None


def _check_episodes(s: Scenario) -> Problem:
    for i, ep in enumerate(s.slip.episodes):
        key = f"slip.episodes[{i}]"
        if ep.kind not in ("slip", "slide"):
            return f"{key}.kind", "must be 'slip' or 'slide'"
        if not (0 < ep.depth < 1):
            return f"{key}.depth", "must be between 0 and 1 (fraction of speed)"
        if not (ep.duration_s > 0 and ep.t0_s >= 0):
            return key, "needs t0_s ≥ 0 and duration_s > 0"
    return None


def _check_radar(s: Scenario) -> Problem:
    """The IF simulator's radar (raises at the first problem, like the other checks)."""

    def fail(key: str, msg: str) -> None:
        raise ScenarioError(msg, path=s.source, key=key)

    _check_radar_if(s.radar_if, fail)
    return None


def _check_radar_if(r: RadarIfCfg, fail: typing.Callable[[str, str], None]) -> None:
    """The IF simulator's radar inside run.json's plausible ranges (``schemas.radar.RUN_JSON_RADAR``)."""
    for f in RUN_JSON_RADAR:
        v = getattr(r, f.name)
        if not (math.isfinite(v) and f.min <= v <= f.max):
            fail(f"radar_if.{f.name}", f"must be between {f.min:g} and {f.max:g} {f.unit}, got {v}")
    if not 0 < r.depression_deg - r.beam_elev_deg < r.depression_deg + r.beam_elev_deg < 90:
        fail("radar_if.depression_deg", "depression ± beam_elev_deg must stay between 0 and 90 degrees")
    if r.looks_toward not in ("F", "R"):
        fail("radar_if.looks_toward", "must be F or R")
    _check_radar_scene(r, fail)


def _check_radar_scene(r: RadarIfCfg, fail: typing.Callable[[str, str], None]) -> None:
    """The simulated track bed, receiver and vibration knobs."""
    if r.track_bed not in ("ballast", "slab"):
        fail("radar_if.track_bed", "must be 'ballast' or 'slab'")
    for key in (
        "scatterers_per_m2",
        "ballast_roughness_m",
        "slab_reflectivity",
        "strong_per_m",
        "strong_gain",
        "dc_leak",
        "vibration_mm",
        "vibration_hz",
    ):
        v = getattr(r, key)
        if not (math.isfinite(v) and v >= 0):
            fail(f"radar_if.{key}", f"must be ≥ 0, got {v}")
    if not math.isfinite(r.snr_db) or not -20 <= r.snr_db <= 80:
        fail("radar_if.snr_db", f"must be between -20 and 80 dB, got {r.snr_db}")
    if not (r.adc_bits == 0 or 4 <= r.adc_bits <= 24):
        fail("radar_if.adc_bits", "must be 0 (no quantisation) or between 4 and 24")
    for i, (a, b) in enumerate(r.slab_km_m):
        if not (math.isfinite(a) and math.isfinite(b) and a < b):
            fail(f"radar_if.slab_km_m[{i}]", f"needs [from, to] with from < to, got [{a}, {b}]")


def _check_gnss_raw(s: Scenario) -> Problem:
    g = s.gnss_raw
    if not g.systems or any(x not in ("G", "E", "J") for x in g.systems):
        return "gnss_raw.systems", "each must be G, E or J (at least one)"
    steps = g.interval_s / 0.01
    if not (math.isfinite(g.interval_s) and 0.1 <= g.interval_s <= 60 and abs(steps - round(steps)) < 1e-6):
        return "gnss_raw.interval_s", "must be a multiple of 0.01 s between 0.1 and 60"
    if not 1 <= len(g.antennas_x_m) <= 4 or any(not (math.isfinite(x) and -10 <= x <= 10) for x in g.antennas_x_m):
        return "gnss_raw.antennas_x_m", "one to four antennas, each within ±10 m of the car centre"
    if not (math.isfinite(g.antenna_z_m) and 0 <= g.antenna_z_m <= 8):
        return "gnss_raw.antenna_z_m", "must be between 0 and 8 m above the rail"
    if g.corridor not in ("open", "mixed"):
        return "gnss_raw.corridor", "must be 'open' or 'mixed'"
    return None


def _check_network(s: Scenario) -> Problem:
    """The ``[network]`` knobs; on a network route the km-based knobs of one line do not apply."""
    if not s.network.active:
        return None
    km_knobs = {
        "route.path_km_m": s.route.path_km_m,
        "running.stations_km_m": s.running.stations_km_m,
        "gps.outages_km_m": s.gps.outages_km_m,
        "gps.poor_sky_km_m": s.gps.poor_sky_km_m,
    }
    for key, value in km_knobs.items():
        if value:
            return key, "a network route ([network] tracks/from_track) takes network.points and network.gnss_outages"
    return check_network(s.network)


def scenario_from_dict(data: dict[str, Any], source: str = "<dict>", *, base: dict[str, Any] | None = None) -> Scenario:
    """A checked scenario from a dict of overrides (same shape as the TOML file)."""
    merged = _merge(base if base is not None else default_dict(), data)
    # keys of the overrides are checked first so that messages name the override's source
    _build(Scenario, data, "", source)
    s: Scenario = replace(_build(Scenario, merged, "", source), source=source)
    _check(s)
    return s


def _read_toml(path: Path) -> dict[str, Any]:
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ScenarioError("no such scenario file", path=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"cannot read scenario: {exc}", path=path) from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"not valid TOML: {exc}", path=path) from None


def default_dict() -> dict[str, Any]:
    """The documented defaults (``default.toml``) as a plain dict."""
    return _read_toml(DEFAULT_SCENARIO)


def load_scenario(path: Path | None = None, overrides: dict[str, Any] | None = None) -> Scenario:
    """The default scenario, updated by the TOML file ``path`` and then by ``overrides``."""
    if path is None:
        data: dict[str, Any] = {}
        source = "<default scenario>"
    else:
        data = _read_toml(Path(path))
        source = str(path)
    s = scenario_from_dict(data, source)
    if overrides:
        s = scenario_from_dict(_merge(data, overrides), source)
    return s


__all__ = ["DEFAULT_SCENARIO", "Episode", "Scenario", "ScenarioError", "load_scenario", "scenario_from_dict"]
