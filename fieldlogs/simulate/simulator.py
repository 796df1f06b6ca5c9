"""The field-log simulator's entry points: :func:`simulate_run` and :func:`simulate_to_folder` (the pieces
and their seeding: :mod:`fieldlogs.simulate`)."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pandas as pd

from dbtools.database import read_network
from dbtools.network import Network
from fieldlogs.runs.meta import RunMeta
from fieldlogs.runs.typed import LogFormat
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.events import balise_events, cab_events, reader_events, track_balises
from fieldlogs.simulate.kinematics import BodyKinematics, body_kinematics
from fieldlogs.simulate.netsim import NetworkPlan, network_plan
from fieldlogs.simulate.running import Motion, cant_model, plan_motion
from fieldlogs.simulate.scenario import Scenario, ScenarioError, load_scenario
from fieldlogs.simulate.sensors import (
    gps_stream,
    imu_stream,
    radar_stream,
    tacho_stream,
    truth_stream,
    wheel_distance,
    wheel_draw,
)
from fieldlogs.simulate.slip import SlipEpisode, place_episodes, wheel_factor
from fieldlogs.simulate.track import TrackGeometry, TrackLookupError
from schemas.enums import BaliseKind, Track, VehicleKind


class SimulatedRun(NamedTuple):
    streams: dict[str, pd.DataFrame]
    meta: RunMeta


@dataclass
class SimulationSummary:
    path: Path
    run_id: str
    line_code: str
    track: str
    duration_s: float
    distance_m: float
    rows: dict[str, int]
    slip_episodes: list[SlipEpisode]
    wheel_diameter_true_m: float


def _pick_route(network: Network, scenario: Scenario) -> tuple[str, str]:
    gis = network.gis
    lines = sorted(set(gis["line_code"].dropna().astype(str)))
    line = scenario.route.line_code or (lines[0] if lines else "")
    if line not in lines:
        raise ScenarioError(
            f"line '{line}' is not in the DB {network.origin} (lines: {', '.join(lines) or 'none'})",
            path=scenario.source,
            key="route.line_code",
        )
    tracks = set(gis.loc[gis["line_code"] == line, "track"].astype(str))
    track = scenario.route.track
    if not track:
        track = next(t for t in (Track.DOWN, Track.SINGLE, Track.UP) if t in tracks)
    if track not in tracks:
        raise ScenarioError(
            f"line '{line}' has no track '{track}' in the DB (tracks: {', '.join(sorted(tracks))})",
            path=scenario.source,
            key="route.track",
        )
    return line, str(track)


def _stations(balises: pd.DataFrame, geom: TrackGeometry, scenario: Scenario) -> list[float]:
    if scenario.running.stations_km_m:
        return list(scenario.running.stations_km_m)
    i1 = balises[balises["kind"] == BaliseKind.I1].drop_duplicates("station_code")
    km = i1["km_actual_m"].to_numpy(dtype=float) + geom.normal_sign * scenario.running.stop_beyond_i1_m
    return sorted(float(k) for k in km if geom.km_min <= k <= geom.km_max)


def _route(
    network: Network, scenario: Scenario
) -> tuple[NetworkPlan | None, TrackGeometry, Scenario, pd.DataFrame, list[float], str, str]:
    """The run's route: over the network's tracks (``[network]``, :mod:`.netsim`: the scenario is
    rewritten in route coordinates) or along one line/track; its geometry, balises and stops."""
    if scenario.network.active:
        plan = network_plan(network, scenario)
        return plan, plan.geom, plan.scenario, plan.balises, [], "", ""
    line, track, geom, balises = _line_route(network, scenario)
    stations = [] if scenario.is_road_rail else _stations(balises, geom, scenario)
    return None, geom, scenario, balises, stations, line, track


def _line_route(network: Network, scenario: Scenario) -> tuple[str, str, TrackGeometry, pd.DataFrame]:
    """Line, track, geometry and balises of a run along one line/track (``[route]``)."""
    line, track = _pick_route(network, scenario)
    path = scenario.route.path_km_m
    try:
        geom = TrackGeometry.from_network(network, line, track, (min(path), max(path)) if path else None)
    except TrackLookupError as exc:
        raise ScenarioError(str(exc), path=scenario.source, key="route.path_km_m") from None
    return line, track, geom, track_balises(network.s003_balises, line, track)


def simulate_run(network: Network, scenario: Scenario, seed: int | None = None) -> SimulatedRun:
    """Simulate one run over ``network`` (see module docstring); ``seed`` overrides the scenario's."""
    seed = scenario.seed if seed is None else seed
    # one child per concern; new concerns are appended so the earlier children stay the same
    names = ("wheel", "slip", "imu", "gps", "radar", "balise", "radar_if", "gnss_raw", "cab_r")
    rngs = dict(zip(names, np.random.default_rng(seed).spawn(len(names)), strict=True))
    plan, geom, scenario, balises, stations, line, track = _route(network, scenario)
    motion = plan_motion(geom, scenario, stations)
    d_true, wear = wheel_draw(scenario, rngs["wheel"])
    episodes = place_episodes(scenario, motion, geom, rngs["slip"])
    factor, slipping = wheel_factor(episodes, motion.t)
    sensors = scenario.sensors
    streams: dict[str, pd.DataFrame] = {}
    rolled = wheel_distance(motion, factor)
    if sensors.tacho:
        streams["tacho"] = tacho_stream(rolled, motion, d_true, scenario.tacho.teeth, scenario.tacho.two_phase)
    kin = body_kinematics(geom, cant_model(scenario), motion) if sensors.imu else None
    if kin is not None:
        true = {"ax": kin.ax, "ay": kin.ay, "az": kin.az, "wx": kin.wx, "wy": kin.wy, "wz": kin.wz}
        streams["imu"] = imu_stream(true, motion, scenario, rngs["imu"])
    if sensors.balise and not scenario.is_road_rail:
        streams["balise"] = _telegrams(balises, motion, geom, scenario, rngs["balise"])
    outages: list[tuple[float, float]] = []
    if sensors.gps:
        streams["gps"], outages = gps_stream(motion, geom, scenario, rngs["gps"])
    streams["cab"] = cab_events(motion)
    if sensors.truth:
        streams["truth"] = truth_stream(motion, slipping, line, track)
    if sensors.radar:
        streams["radar"] = radar_stream(motion, scenario, rngs["radar"])
    meta = _meta(network, scenario, seed, line, track, geom, motion, d_true, wear, episodes, outages, rolled)
    if plan is not None:  # a network route: truth with track_id/pos_m, multipath, run.json route
        plan.finish(streams, motion, slipping, meta, seed)
    if sensors.radar_if:
        from fieldlogs.simulate.radar import radar_if_stream  # numba: only when asked for

        streams["radar_if"], meta.extra["radar"] = radar_if_stream(motion, geom, scenario, rngs["radar_if"])
    if scenario.gnss_raw.enabled:
        _add_raw_gnss(streams, meta, (scenario, motion, geom, plan), rngs["gnss_raw"])
    _add_readers(meta, scenario)
    _add_cab_r(streams, meta, (scenario, motion, geom, plan, kin), rngs["cab_r"])
    return SimulatedRun(streams, meta)


def _add_cab_r(
    streams: dict[str, pd.DataFrame],
    meta: RunMeta,
    src: tuple[Scenario, Motion, TrackGeometry, NetworkPlan | None, BodyKinematics | None],
    rng: np.random.Generator,
) -> None:
    """The R cab's own sensors with ``[cab_r] sensors = true`` (:mod:`fieldlogs.simulate.cab_r`)."""
    if src[0].cab_r.sensors:
        from fieldlogs.simulate.cab_r import CabR, add_cab_r

        add_cab_r(streams, meta, CabR(*src), rng)


def _telegrams(
    balises: pd.DataFrame, motion: Motion, geom: TrackGeometry, scenario: Scenario, rng: np.random.Generator
) -> pd.DataFrame:
    """The balise stream: one reader at the reference point, or one per cab (``balise.readers_x_m``)."""
    miss = scenario.balise.miss_probability
    if not scenario.balise.readers_x_m:
        return balise_events(balises, motion, rng, miss)
    lo, hi = geom.sigma(geom.km_min), geom.sigma(geom.km_max)
    return reader_events(
        balises, motion, lambda s: geom.km_at(np.clip(s, lo, hi)), rng, miss, scenario.balise.readers_x_m
    )


def _add_readers(meta: RunMeta, scenario: Scenario) -> None:
    """run.json vehicle ``balise_reader`` (the F cab's) and ``balise_reader_r`` (the R cab's), with
    a reader per cab."""
    if not scenario.balise.readers_x_m:
        return
    from fieldlogs.simulate.gnss.trainsim import vehicle_block

    block = meta.vehicle or vehicle_block(
        meta.vehicle_id, meta.vehicle_kind, [], scenario.tacho.wheel_diameter_m, scenario.tacho.teeth
    )
    x_f, x_r = scenario.balise.readers_x_m
    meta.vehicle = {**block, "balise_reader": {"x_m": x_f, "y_m": 0.0}, "balise_reader_r": {"x_m": x_r, "y_m": 0.0}}


def _add_raw_gnss(
    streams: dict[str, pd.DataFrame],
    meta: RunMeta,
    src: tuple[Scenario, Motion, TrackGeometry, NetworkPlan | None],
    rng: np.random.Generator,
) -> None:
    """gnss_obs, gnss_nav and the run.json vehicle and gnss blocks (``fieldlogs.simulate.gnss.trainsim``);
    on a network route its ``network.multipath`` reflectors."""
    from fieldlogs.recorders.timebase import iso_to_gps
    from fieldlogs.simulate.gnss.trainsim import RawGnssSpec, raw_gnss, vehicle_block

    scenario, motion, geom, plan = src
    g = scenario.gnss_raw
    spec = RawGnssSpec(
        g.systems, g.interval_s, g.antennas_x_m, g.antenna_z_m, g.corridor, scenario.noise,
        iso_to_gps(scenario.run.start_time), scenario.gps.outages_km_m, g.sbas,
        None if plan is None else plan.reflectors(),
    )  # fmt: skip
    raw = raw_gnss(motion, geom, spec, rng)
    streams["gnss_obs"], streams["gnss_nav"] = raw.obs, raw.nav
    if raw.sbas is not None:
        streams["gnss_sbas"] = raw.sbas
    meta.vehicle = vehicle_block(
        meta.vehicle_id, meta.vehicle_kind, raw.receivers, scenario.tacho.wheel_diameter_m, scenario.tacho.teeth
    )
    meta.gnss = raw.gnss_block
    meta.extra["sim_truth"]["gnss_raw"] = {
        "receivers": [
            {
                "receiver": r.name,
                "x_m": r.forward_m,
                "clock_bias_s": r.clock_bias_s,
                "clock_drift_sps": r.clock_drift_sps,
            }
            for r in raw.receivers
        ],
        "corridor": g.corridor,
        "systems": list(g.systems),
    }
    if raw.reflection is not None:
        meta.extra["sim_truth"]["gnss_raw"]["reflection"] = raw.reflection


def _meta(
    network: Network,
    scenario: Scenario,
    seed: int,
    line: str,
    track: str,
    geom: TrackGeometry,
    motion: Motion,
    d_true: float,
    wear: float,
    episodes: list[SlipEpisode],
    outages: list[tuple[float, float]],
    rolled: np.ndarray,
) -> RunMeta:
    run = scenario.run
    first = motion.moves[0]
    path = [round(float(geom.km_at(first.sigma0)), 3)] + [round(float(geom.km_at(m.sigma1)), 3) for m in motion.moves]
    sim_truth = {
        "seed": seed,
        "scenario": scenario.name,
        "scenario_source": scenario.source,
        "line_code": line,
        "track": track,
        "path_km_m": path,
        "f_end_toward": "increasing_km" if motion.facing > 0 else "decreasing_km",
        "stops_km_m": [round(k, 3) for k in motion.stops_km],
        "duration_s": round(motion.duration_s, 2),
        "distance_m": round(float(motion.p[-1]), 3),
        "wheel_rolled_m": round(float(rolled[-1]), 3),
        "wheel_diameter_true_m": round(d_true, 6),
        "wheel_wear_pct": round(wear, 4),
        "slip_episodes": [e.to_json() for e in episodes],
        "gps_outages_s": [[a, b] for a, b in outages],
        "noise": scenario.noise,
    }
    notes = run.notes or f"simulated run: scenario '{scenario.name}', seed {seed}"
    return RunMeta(
        run_id=run.run_id or f"SIM-{line}-{track}-{seed}",
        vehicle_id=run.vehicle_id,
        vehicle_kind=VehicleKind(run.vehicle_kind).value,
        wheel_diameter_m=scenario.tacho.wheel_diameter_m,
        teeth=scenario.tacho.teeth,
        start_time=run.start_time,
        db_version=network.meta.get("db_version"),
        notes=notes,
        extra={"sim_truth": sim_truth},
    )


def simulate_to_folder(
    db_path: Path,
    out: Path,
    scenario: Scenario | None = None,
    *,
    seed: int | None = None,
    fmt: LogFormat = "parquet",
    force: bool = False,
    inputs: Iterable[Path | str] = (),
) -> SimulationSummary:
    """Read the onboard DB, simulate and write the run folder atomically (the output rule of
    :mod:`dbtools.atomic`: never over the DB or another of ``inputs``)."""
    scenario = scenario if scenario is not None else load_scenario()
    network = read_network(Path(db_path))
    streams, meta = simulate_run(network, scenario, seed)
    write_run(Path(out), meta, streams, fmt=fmt, force=force, inputs=[Path(db_path), *inputs])
    st = meta.extra["sim_truth"]
    return SimulationSummary(
        path=Path(out),
        run_id=meta.run_id,
        line_code=st["line_code"],
        track=st["track"],
        duration_s=st["duration_s"],
        distance_m=st["distance_m"],
        rows={k: len(v) for k, v in streams.items()},
        slip_episodes=[SlipEpisode(**e) for e in st["slip_episodes"]],
        wheel_diameter_true_m=st["wheel_diameter_true_m"],
    )
