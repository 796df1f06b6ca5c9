"""The onboard positioning pipeline of SPEC §5 on a recorded run: :func:`run_pipeline`.

Data flow of :func:`run_pipeline` (each stage vectorised over the run, except the engine's
loop over the few moments an aid speaks):

1. streams cleaned as the onboard unit would see them (sorted, no missing or repeated t;
   each repair an ``input_repaired`` event);
2. :func:`~fieldlogs.pipeline.cycles.build_cycles`: tacho, IMU (cycle means), cab and PTO on
   the 100 ms cycle grid;
3. speed aids (:data:`~fieldlogs.pipeline.aids.registry.SPEED_AIDS`, e.g. the radar [S004] from its
   IF samples) on the cycle grid, then :func:`~fieldlogs.pipeline.odometry.correct.correct_odometry`:
   pulse odometry with slip/slide episodes detected and corrected inertially [S000 §3.1]
   and, with a ground speed, by it;
4. products the aids share: the GPS analysis (trust, map-matching, up/down decisions,
   crossovers [S001 §4.2]), the curvature trace with the feature tables [S000 §3.2] and the
   run's raw GNSS inputs (``gnss_obs``/``gnss_nav``, solved on a track when an aid asks [S002]);
5. position aids built by the registry (:mod:`fieldlogs.pipeline.aids`) and applied in time
   order by the engine (:mod:`fieldlogs.pipeline.engine`), which records the fixes, and the
   balise checks (:mod:`fieldlogs.pipeline.consistency`); a wheel scale they find is divided
   out of the pulses and stages 3–5 replayed (:mod:`fieldlogs.pipeline.wheelscale`);
6. per-cycle positions with their margins (:mod:`fieldlogs.pipeline.positions`), the events
   frame and the summary (:mod:`fieldlogs.pipeline.summary`), and the truth comparison when
   the run has a ``truth`` stream.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.aids.features import FeatureUnit
from fieldlogs.pipeline.aids.gnss import GnssUnit
from fieldlogs.pipeline.aids.registry import RunContext, speed_aids
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import Cycles, build_cycles
from fieldlogs.pipeline.geometry import VehicleGeometry
from fieldlogs.pipeline.gps.analysis import analyse_gps
from fieldlogs.pipeline.imugap import imu_gaps, with_gap_allowance
from fieldlogs.pipeline.odometry.correct import correct_odometry
from fieldlogs.pipeline.rollback import Rollback, detect_rollbacks, inferred_rotation
from fieldlogs.pipeline.summary import episode_events, events_frame, summarise
from fieldlogs.pipeline.truth import compare_with_truth, truth_summary
from fieldlogs.pipeline.types import Event, Fix, GpsAnalysis, Odometry
from fieldlogs.pipeline.wheelscale import scaled_cycles, wheel_corrected
from fieldlogs.quality.clocks import ClockOffset, clock_offsets
from fieldlogs.quality.dbfit import require_db_fit
from fieldlogs.quality.limits import masked
from fieldlogs.quality.tacho import cumulative_again
from fieldlogs.quality.usability import Purpose, require_usable
from fieldlogs.runs.handle import Run
from schemas.enums import CabDirection, EventType, VehicleKind
from schemas.frames import FIRST_DATA_LINE

__all__ = ["PipelineConfig", "PipelineResult", "run_pipeline"]

#: Streams the pipeline reads.
STREAMS = ("tacho", "imu", "balise", "gps", "cab", "truth", "radar", "radar_if")
#: Clock offsets given to :func:`run_pipeline`: those to apply, or a function of those the
#: run's own check finds giving those to apply (a window of a long run,
#: :mod:`fieldlogs.pipeline.windows`, borrows what it could not determine).
Offsets = list[ClockOffset] | Callable[[list[ClockOffset]], list[ClockOffset]]
#: Streams the clock check reads (:func:`fieldlogs.quality.clocks.clock_offsets`).
CLOCK_STREAMS = ("tacho", "imu", "gps", "cab")


@dataclass
class PipelineResult:
    run_id: str
    positions: pd.DataFrame
    events: pd.DataFrame
    summary: dict[str, Any]
    odometry: Odometry
    gps: GpsAnalysis | None = None
    kappa: np.ndarray | None = None
    truth: pd.DataFrame | None = field(default=None, repr=False)
    cycles: Cycles | None = field(default=None, repr=False)
    gnss: GnssUnit | None = field(default=None, repr=False)
    """The run's raw GNSS inputs and the track solutions the aid computed (None without)."""
    wheel_scale: float = 1.0
    """The scale the pulse distance was divided by (:mod:`fieldlogs.pipeline.wheelscale`)."""
    fixes: list[Fix] = field(default_factory=list, repr=False)
    """The engine's estimates in time order (the per-cycle positions are evaluated from them)."""


def clean_stream(frame: pd.DataFrame | None, name: str, events: list[Event]) -> pd.DataFrame | None:
    """Mask the samples outside the sensor's declared range (:mod:`fieldlogs.quality.limits`),
    sort by t and drop rows without t or with a repeated t (first kept), as an onboard unit
    would see the stream; every change is reported as an ``input_repaired`` event."""
    if frame is None or frame.empty:
        return frame
    frame = within_limits(frame, name, events)
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    if t.size and np.isfinite(t).all() and (np.diff(t) > 0).all():
        return frame  # the normal case: nothing to repair, no copy
    n0 = len(frame)
    frame = frame[frame["t"].notna()]
    unsorted = bool((frame["t"].diff() < 0).any())
    frame = frame.sort_values("t", kind="stable")
    frame = frame[~frame["t"].duplicated(keep="first")]
    if unsorted or len(frame) != n0:
        detail = {"stream": name, "rows_in": n0, "rows_used": len(frame), "sorted": unsorted}
        events.append(Event(0.0, EventType.INPUT_REPAIRED, detail=detail))
    return frame.reset_index(drop=True)


def within_limits(frame: pd.DataFrame, name: str, events: list[Event]) -> pd.DataFrame:
    """``frame`` without its rows outside the declared physical limits, each stream's masking
    an ``input_repaired`` event naming the columns, counts, worst values and file lines."""
    frame_in = frame
    frame, bad = masked(name, frame)
    if bad is None:
        return frame
    lines = (bad.rows[:20] + FIRST_DATA_LINE).tolist()
    detail = {
        "stream": name,
        "rows_in": len(frame_in),
        "rows_used": len(frame),
        "out_of_range": bad.columns,
        "worst": {k: f"{v:.6g}" for k, v in bad.worst.items()},
        "lines": lines,
        "action": "rows outside the sensor's declared range masked (not used)",
    }
    events.append(Event(0.0, EventType.INPUT_REPAIRED, detail=detail))
    return frame


def counter_resets_bridged(tacho: pd.DataFrame | None, events: list[Event]) -> pd.DataFrame | None:
    """A pulse counter that was reset (it drops below half its count and stays low) counts on
    from where it was: each reset adds the count before it to every later row, as an onboard
    unit keeps its distance through a counter reset (``logs repair`` does the same to the
    file). Without this the dead reckoning would stand still until the count caught up and the
    next balise would read as a correction of kilometres. Each bridge is an ``input_repaired``
    event naming the rows."""
    if tacho is None or len(tacho) < 2:
        return tacho
    p = tacho["pulses"].to_numpy(dtype=float, na_value=np.nan)
    ok = np.flatnonzero(np.isfinite(p))
    fixed, resets = cumulative_again(p[ok])
    if resets.size == 0:
        return tacho
    out = tacho.copy()
    full = p.copy()
    full[ok] = fixed
    out["pulses"] = pd.array(np.round(full), dtype="Int64")
    rows = (ok[resets] + FIRST_DATA_LINE).tolist()
    detail = {"stream": "tacho", "counter_resets": len(rows), "rows": rows[:20], "bridged": True}
    events.append(Event(0.0, EventType.INPUT_REPAIRED, detail=detail))
    return out


def clocks_aligned(
    streams: dict[str, pd.DataFrame | None],
    wheel_diameter_m: float | None,
    teeth: int | None,
    cfg: PipelineConfig,
    events: list[Event],
    offsets: Offsets | None = None,
) -> dict[str, pd.DataFrame | None]:
    """The IMU and GPS on the tacho's clock: a determined offset beyond ``clock.tolerance_s``
    (:func:`fieldlogs.quality.clocks.clock_offsets`, the check ``logs check`` reports as
    ``log.clock_offset``, or ``offsets`` when given: a window of a long run borrows what it
    could not determine, :mod:`fieldlogs.pipeline.windows`; or a function of the offsets the
    check finds giving those to apply) moves the stream's t back by it, each a
    ``clock_offset`` event."""
    out = dict(streams)
    if offsets is None or callable(offsets):
        own = clock_offsets(streams, wheel_diameter_m, teeth, cfg.clock, cfg.cycle_s)
        offsets = own if offsets is None else offsets(own)
    for o in offsets:
        frame = out.get(o.stream)
        if not o.beyond_tolerance or frame is None:
            continue
        out[o.stream] = frame.assign(t=frame["t"] - o.offset_s)
        detail = {
            "stream": o.stream,
            "offset_s": round(o.offset_s, 3),
            "sigma_s": round(o.sigma_s, 3),
            "corr": round(o.corr, 3),
            "action": "t moved back by the offset",
            "message": o.message,
        }
        if o.from_t is not None:
            detail["determined_from_t"] = o.from_t
        events.append(Event(0.0, EventType.CLOCK_OFFSET, detail=detail))
    return out


def clean_streams(run: Run, events: list[Event], names: tuple[str, ...] = STREAMS) -> dict[str, pd.DataFrame | None]:
    """Stage 1 of the module docstring: the streams as the onboard unit sees them (sorted, no
    missing or repeated t, pulse counter resets bridged), each repair an event."""
    streams = {n: clean_stream(run.stream(n), n, events) for n in names}
    streams["tacho"] = counter_resets_bridged(streams["tacho"], events)
    return streams


def run_clock_offsets(run: Run, cfg: PipelineConfig) -> list[ClockOffset]:
    """The clock offsets :func:`prepare_run` would find on ``run`` (its cleaned streams)."""
    assert run.meta is not None
    streams = clean_streams(run, [], CLOCK_STREAMS)
    return clock_offsets(streams, run.meta.wheel_diameter_m, run.meta.teeth, cfg.clock, cfg.cycle_s)


def prepare_run(
    run: Run, network: Network, cfg: PipelineConfig, offsets: Offsets | None = None
) -> tuple[RunContext, list[Event]]:
    """Stages 1–4 of the module docstring: the context the aids are built from, and the
    ``input_repaired`` events of the cleaning; raises FindingsError when run.json is unusable.
    ``offsets``: the clock offsets to apply instead of those the run's own check finds (or
    a function of those, :data:`Offsets`).
    The IMU stream is released once its cycle means are built, unless the caller had loaded
    it (:meth:`Run.release`: the memory of a long run is then its cycles, not its samples)."""
    keep_imu = run.loaded("imu")
    require_usable(run, Purpose.POSITIONING)  # never a "determined" km the run cannot support
    require_db_fit(run, network)  # nor one on another network's DB
    assert run.meta is not None
    pre: list[Event] = []
    streams = clean_streams(run, pre)
    streams["balise"] = own_reader(streams.get("balise"))
    streams = clocks_aligned(streams, run.meta.wheel_diameter_m, run.meta.teeth, cfg, pre, offsets)
    t_end = max((float(s["t"].iloc[-1]) for s in streams.values() if s is not None and len(s)), default=0.0)
    cycles = build_cycles(
        tacho=streams["tacho"],
        imu=streams["imu"],
        cab=streams["cab"],
        wheel_diameter_m=run.meta.wheel_diameter_m,
        teeth=run.meta.teeth,
        t_end=t_end,
        cycle_s=cfg.cycle_s,
        uses_pto=run.meta.vehicle_kind == VehicleKind.ROAD_RAIL,
    )
    rollbacks = tuple(detect_rollbacks(cycles))  # a tacho without its sense: the IMU's (fail-safe)
    if rollbacks:
        cycles = replace(cycles, rotation=inferred_rotation(cycles, list(rollbacks)))
    if not keep_imu:
        streams["imu"] = None  # read only through the cycles from here on
        run.release("imu")
    gnss = GnssUnit.for_run(run, network, cfg.gnss)
    return context_on(cycles, run, network, cfg, streams, gnss, rollbacks), pre


def own_reader(balise: pd.DataFrame | None) -> pd.DataFrame | None:
    """The telegrams of the unit's own balise reader: on a vehicle with one per cab (the stream's
    ``reader`` column) the F cab's — the unit's own cab, F for unit F and, in its mirrored view,
    for unit R too (:mod:`fieldlogs.pipeline.units`) [S003 §2]; without the column, all."""
    if balise is None or "reader" not in balise.columns:
        return balise
    reader = balise["reader"].astype("string")
    return balise[(reader.isna() | (reader == CabDirection.FORWARD.value)).to_numpy(dtype=bool)].reset_index(drop=True)


def context_on(
    cycles: Cycles,
    run: Run,
    network: Network,
    cfg: PipelineConfig,
    streams: dict[str, pd.DataFrame | None],
    gnss: GnssUnit | None,
    rollbacks: tuple[Rollback, ...] = (),
) -> RunContext:
    """Stages 3–4 of the module docstring on ``cycles``: what :func:`prepare_run` builds after
    the cycles, and again on the cycles with the wheel scale divided out
    (:mod:`fieldlogs.pipeline.wheelscale`)."""
    assert run.meta is not None
    ground = next((g for a in speed_aids(streams, run.radar) if (g := a.on_cycles(cycles)) is not None), None)
    # pulses only when the run has no IMU (correct_odometry falls back by itself)
    odo = correct_odometry(cycles, cfg.odometry, ground)
    gaps = imu_gaps(cycles, cfg.margin.imu_gap_s, cfg.odometry.min_speed_kmh / 3.6)
    odo = with_gap_allowance(odo, gaps, cfg.margin.imu_gap_share)
    gps = analyse_gps(streams["gps"], network, cfg.gps, cycles)
    features = FeatureUnit(cycles, odo, network, cfg.feature) if cycles.has_imu and cycles.has_tacho else None
    geometry = VehicleGeometry.of(run.meta.vehicle)
    return RunContext(
        network, cfg, streams, cycles, odo, gps, features, geometry=geometry, gnss=gnss, imu_gaps=tuple(gaps),
        rollbacks=rollbacks,
    )  # fmt: skip


def run_pipeline(
    run: Run,
    network: Network,
    cfg: PipelineConfig | None = None,
    *,
    clock_offsets: Offsets | None = None,
    summary: bool = True,
) -> PipelineResult:
    """Replay a run through the onboard logic; raises FindingsError when run.json is unusable.
    ``clock_offsets``: applied instead of those the run's own clock check finds (or a
    function of those giving the ones to apply, :data:`Offsets`). ``summary``: False for a
    result whose summary is not wanted (a window of a long run: the run's is made from the
    windows' parts, :mod:`fieldlogs.pipeline.windows`), then empty."""
    cfg = cfg or PipelineConfig()
    ctx, pre = prepare_run(run, network, cfg, clock_offsets)
    first = ctx

    def rescaled(scale: float) -> RunContext:
        return context_on(
            scaled_cycles(first.cycles, scale), run, network, cfg, first.streams, first.gnss, first.rollbacks
        )

    ctx, scale, sol, checks = wheel_corrected(ctx, rescaled, cfg)
    odo = ctx.odometry
    events = pre + checks + sol.events + episode_events(odo, sol.positions["km_m"].to_numpy())
    events.sort(key=lambda e: e.t)
    ev_frame = events_frame(events)
    truth = ctx.streams["truth"]
    figures: dict[str, Any] = {}
    if summary:
        figures = summarise(run, network, cfg, sol.positions, ev_frame, odo, ctx.gps, wheel_scale=scale)
        if truth is not None and len(truth):
            figures["truth"] = truth_summary(compare_with_truth(sol.positions, truth))
    kappa = ctx.features.kappa if ctx.features is not None else None
    return PipelineResult(
        run.run_id, sol.positions, ev_frame, figures, odo, ctx.gps, kappa, truth, ctx.cycles, ctx.gnss, scale, sol.fixes
    )
