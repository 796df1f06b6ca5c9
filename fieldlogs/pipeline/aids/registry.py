"""The registry of the positioning engine's aids (:data:`POSITION_AIDS`, :data:`SPEED_AIDS`) and
the run context their factories look at (:mod:`fieldlogs.pipeline.aids`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property

import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.aid import Aid, SpeedAid
from fieldlogs.pipeline.aids.balise import BaliseAid, BaliseDb, Telegram, telegram_rows
from fieldlogs.pipeline.aids.balise_group import BaliseGroupAid, group_table
from fieldlogs.pipeline.aids.failsafe import FailsafeAid
from fieldlogs.pipeline.aids.feature_aid import FeatureAid
from fieldlogs.pipeline.aids.features import FeatureUnit
from fieldlogs.pipeline.aids.gnss import GnssAid, GnssUnit
from fieldlogs.pipeline.aids.gps import GpsAid
from fieldlogs.pipeline.aids.radar import RadarSpeedAid
from fieldlogs.pipeline.aids.radar_if import RadarIfSpeedAid
from fieldlogs.pipeline.aids.rail import RailAid
from fieldlogs.pipeline.aids.rollback import RollbackAid
from fieldlogs.pipeline.aids.topology import TopologyAid
from fieldlogs.pipeline.aids.track_balise import TrackBaliseAid
from fieldlogs.pipeline.aids.track_crossover import TrackCrossoverAid, crossovers
from fieldlogs.pipeline.aids.track_features import TrackFeatureAid, TrackFeatureFixAid, track_feature_tables
from fieldlogs.pipeline.aids.track_gnss import TrackGnssAid
from fieldlogs.pipeline.aids.track_gps import NetworkFixes, TrackGpsAid
from fieldlogs.pipeline.aids.track_gps_along import TrackGpsAlongAid
from fieldlogs.pipeline.aids.track_gps_initial import TrackGpsInitialAid
from fieldlogs.pipeline.aids.track_imu import TrackImuAid, turnouts
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.geometry import VehicleGeometry
from fieldlogs.pipeline.hypotheses import track_lines
from fieldlogs.pipeline.imugap import ImuGap, ImuGapAid
from fieldlogs.pipeline.rollback import Rollback
from fieldlogs.pipeline.types import FloatArray, GpsAnalysis, Odometry
from schemas.enums import BaliseKind
from schemas.radar import RadarParams


@dataclass(frozen=True)
class RunContext:
    """What the aid factories may look at."""

    network: Network
    cfg: PipelineConfig
    streams: dict[str, pd.DataFrame | None]
    cycles: Cycles
    odometry: Odometry
    gps: GpsAnalysis | None
    features: FeatureUnit | None
    geometry: VehicleGeometry = field(default_factory=VehicleGeometry)
    gnss: GnssUnit | None = None
    imu_gaps: tuple[ImuGap, ...] = ()
    rollbacks: tuple[Rollback, ...] = ()
    """Starts the IMU saw rolling back against the cab (:mod:`fieldlogs.pipeline.rollback`)."""

    @cached_property
    def telegrams(self) -> list[Telegram]:
        """The run's balise telegrams as rows (:func:`~fieldlogs.pipeline.aids.balise.telegram_rows`),
        made once for every balise aid, each of which hears its own kinds."""
        tel = self.streams.get("balise")
        return [] if tel is None else telegram_rows(tel)


def _rail(ctx: RunContext) -> Aid | None:
    return RailAid(ctx.cycles.t, ctx.cycles.pto)


def _failsafe(ctx: RunContext) -> Aid | None:
    return FailsafeAid(ctx.odometry.episodes)


def _rollback(ctx: RunContext) -> Aid | None:
    return RollbackAid(ctx.rollbacks) if ctx.rollbacks else None


def _imu_gap(ctx: RunContext) -> Aid | None:
    return ImuGapAid(list(ctx.imu_gaps), ctx.cfg.margin.imu_gap_share) if ctx.imu_gaps else None


def _has_topology(ctx: RunContext) -> bool:
    net = ctx.network
    return net.cached(("registry", "has_topology"), lambda: len(net.connections) > 0)


def _topology(ctx: RunContext) -> Aid | None:
    if not _has_topology(ctx):
        return None  # a line-only DB: no candidates to carry, every output as before
    return TopologyAid(track_lines(ctx.network), ctx.cfg.margin)


def _network_telegrams(ctx: RunContext, kind: BaliseKind) -> list[Telegram] | None:
    """The run's balise telegrams on a network DB when one is of ``kind`` (None: none of
    ``kind``, or no topology): an aid for ``kind`` only where it has something to hear."""
    if not _has_topology(ctx):
        return None
    rows = ctx.telegrams
    return rows if any(row["kind"] == kind for row in rows) else None


def _balise_group(ctx: RunContext) -> Aid | None:
    tel = _network_telegrams(ctx, BaliseKind.G)
    if tel is None:
        return None
    groups = ctx.network.cached("balise_groups", lambda: group_table(ctx.network))
    return BaliseGroupAid(groups, track_lines(ctx.network), ctx.cfg.balise, tel, ctx.geometry.reader_x_m)


def _track_balise(ctx: RunContext) -> Aid | None:
    tel = _network_telegrams(ctx, BaliseKind.I2)
    if tel is None:
        return None
    db = ctx.network.cached("balise_db", lambda: BaliseDb.from_network(ctx.network))
    return TrackBaliseAid(db, track_lines(ctx.network), ctx.cfg.balise, ctx.cfg.margin, tel, ctx.geometry.reader_x_m)


def _track_imu(ctx: RunContext) -> Aid | None:
    wz = ctx.cycles.imu.get("wz") if ctx.cycles.has_imu else None
    if wz is None or not _has_topology(ctx):
        return None
    sw = ctx.network.cached("turnouts", lambda: turnouts(ctx.network.switches))
    return TrackImuAid(wz, sw, track_lines(ctx.network), ctx.cfg.track_select, ctx.cfg.margin)


def _track_crossover(ctx: RunContext) -> Aid | None:
    wz = ctx.cycles.imu.get("wz") if ctx.cycles.has_imu else None
    if wz is None or not _has_topology(ctx):
        return None
    net = ctx.network
    cx = net.cached("crossovers", lambda: crossovers(net.switches, net.tracks))
    return TrackCrossoverAid(wz, cx, track_lines(net), ctx.cfg.track_select, ctx.cfg.margin) if cx else None


def _track_features(ctx: RunContext) -> Aid | None:
    wz = ctx.cycles.imu.get("wz") if ctx.cycles.has_imu else None
    if wz is None or not _has_topology(ctx) or not ctx.cfg.track_select.feature_headings:
        return None
    lines = track_lines(ctx.network)
    tables = track_feature_tables(ctx.network, lines)
    return TrackFeatureAid(tables, lines, wz, ctx.cfg.track_select, ctx.cfg.margin) if tables else None


def _track_feature_fix(ctx: RunContext) -> Aid | None:
    if ctx.features is None or not _has_topology(ctx):
        return None
    lines = track_lines(ctx.network)
    own = track_feature_tables(ctx.network, lines).own
    return TrackFeatureFixAid(ctx.features, own, lines) if own else None


def _network_fixes(ctx: RunContext) -> NetworkFixes | None:
    """The run's trusted GPS fixes on a network DB with its tracks and settings, what every GPS
    aid on the network's tracks holds (None: no trusted fix, or no topology)."""
    g = ctx.gps
    if g is None or g.fixes is None or not len(g.fixes) or not _has_topology(ctx):
        return None
    t, lat, lon = _fix_columns(g.fixes, "trusted")
    if not t.size:
        return None
    return NetworkFixes(t, lat, lon, track_lines(ctx.network), ctx.cfg.track_select, ctx.cfg.gps)


def _fix_columns(fixes: pd.DataFrame, flag: str) -> tuple[FloatArray, FloatArray, FloatArray]:
    """t, lat and lon of the GPS fixes whose ``flag`` column is set (each column masked: no frame copy)."""
    mask = fixes[flag].to_numpy(dtype=bool)
    t, lat, lon = (fixes[c].to_numpy(dtype=float)[mask] for c in ("t", "lat", "lon"))
    return t, lat, lon


def _track_gps(ctx: RunContext) -> Aid | None:
    f = _network_fixes(ctx)
    return None if f is None else TrackGpsAid(**vars(f), antenna_x_m=ctx.geometry.gps_antenna_x_m)


def _track_gps_along(ctx: RunContext) -> Aid | None:
    f = _network_fixes(ctx)
    if f is None or ctx.gps is None:
        return None
    usable = _fix_columns(ctx.gps.fixes, "usable")
    x_a = ctx.geometry.gps_antenna_x_m
    return TrackGpsAlongAid(**vars(f), margin=ctx.cfg.margin, antenna_x_m=x_a, usable=usable)


def _track_gps_initial(ctx: RunContext) -> Aid | None:
    f = _network_fixes(ctx)
    return None if f is None else TrackGpsInitialAid(**vars(f), antenna_x_m=ctx.geometry.gps_antenna_x_m)


def _track_gnss(ctx: RunContext) -> Aid | None:
    g = ctx.gnss
    if g is None or g.inputs is None or not _has_topology(ctx):
        return None
    return TrackGnssAid(g, g.epoch_times(), track_lines(ctx.network), g.cfg)


def _balise(ctx: RunContext) -> Aid | None:
    db = ctx.network.cached("balise_db", lambda: BaliseDb.from_network(ctx.network))
    return BaliseAid(db, ctx.cfg.balise, ctx.telegrams, ctx.geometry.reader_x_m)


def _gps(ctx: RunContext) -> Aid | None:
    return GpsAid(ctx.gps, ctx.cfg.gps, ctx.geometry.gps_antenna_x_m) if ctx.gps is not None else None


def _features(ctx: RunContext) -> Aid | None:
    return FeatureAid(ctx.features) if ctx.features is not None else None


def _gnss(ctx: RunContext) -> Aid | None:
    g = ctx.gnss
    if g is None or (g.inputs is None and g.problem is None):
        return None  # no raw GNSS in the run (or the aid switched off)
    return GnssAid(g, ctx.cfg.margin, ctx.gps)


POSITION_AIDS: tuple[Callable[[RunContext], Aid | None], ...] = (
    _rail,
    _failsafe,
    _rollback,
    _imu_gap,
    _balise,
    _gps,
    _features,
    _gnss,
    _topology,
    _balise_group,
    _track_balise,
    _track_imu,
    _track_crossover,
    _track_features,
    _track_feature_fix,
    _track_gps,
    _track_gps_along,
    _track_gps_initial,
    _track_gnss,
)
"""Position aids in registry order (simultaneous observations are ordered by priority)."""


def position_aids(ctx: RunContext) -> list[Aid]:
    return [a for f in POSITION_AIDS if (a := f(ctx)) is not None]


Streams = dict[str, pd.DataFrame | None]


def _radar_if(streams: Streams, radar: RadarParams | None) -> SpeedAid | None:
    frame = streams.get("radar_if")
    return RadarIfSpeedAid(frame, radar) if frame is not None and len(frame) and radar is not None else None


def _radar(streams: Streams, radar: RadarParams | None) -> SpeedAid | None:
    frame = streams.get("radar")
    return RadarSpeedAid(frame) if frame is not None and len(frame) >= 2 else None


SPEED_AIDS: tuple[Callable[[Streams, RadarParams | None], SpeedAid | None], ...] = (_radar_if, _radar)
"""Ground-speed aids for the odometry, best first (the first one with data is used); each
factory sees the run's streams and its run.json ``radar`` block."""


def speed_aids(streams: Streams, radar: RadarParams | None = None) -> list[SpeedAid]:
    return [a for f in SPEED_AIDS if (a := f(streams, radar)) is not None]
