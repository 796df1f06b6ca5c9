"""A long run replayed in time windows: the memory of the replay is a window's, not the run's.

:func:`~fieldlogs.pipeline.run.run_pipeline` holds a whole run at once — the 100 Hz IMU
while its cycle means are built, then ≈ 35 per-cycle arrays — so a worker's memory grows
with the recording (≈ 170 MB + 32 MB per hour of log, bench/NOTES.md). A Parquet run
longer than ``1.5 × [window] length_h`` is replayed here as consecutive windows instead;
each window is an ordinary :func:`run_pipeline` on the rows of every stream with t in

    [keep_from − overlap, keep_to + lookahead)

read by time from the files' row groups (:meth:`fieldlogs.runs.handle.Run.window`), of which only
the cycles with keep_from ≤ t < keep_to are kept. The overlap lets the position settle
before the kept part begins (a balise pair, a GPS decision, the odometry's trailing filters
and pulse-delay lead, an open slip episode); the look-ahead covers what is decided after
the fact (the features' centred κ average and exit crossing, the smoother of the
corrections, a clock offset moving a stream's t back). A window starts undetermined like a
run, so a kept cycle the overlap could not settle is reported *undetermined*, never
guessed: the margin holds window by window exactly as it holds for a run (fail-safe), and
the run-wide checks (clock offsets, wheel scale, balise clock, the usability rule) are made
on each window's own data — a window the usability rule refuses refuses the run.

:func:`replay_windows` yields each window's kept part (a :class:`PipelineResult` of the
kept cycles) and :func:`replay_bounded` hands them to a consumer — ``trainpos run`` writes
them to its output files as they come, an audit worker keeps a 1 Hz trace — while only the
summary's mergeable parts (:class:`~fieldlogs.pipeline.summary.RunParts`), the events and,
for a simulated run, the comparison with its truth are kept: the worker's memory is then a
window's whatever the run's length. The summary is :func:`summarise_parts` of the merged
parts, the same function a whole run's goes through. A window's run-level notes (clock
offsets, repairs: t = 0 of its replay) are kept at its ``keep_from`` with the window in
``detail``. :func:`run_bounded` joins the parts into one result (tests, bench, callers that
want the whole table).

A long CSV run is first spooled to Parquet block by block (:meth:`fieldlogs.runs.handle.Run.spool`). A run
that cannot be read by window (a CSV stream the block parser declines, a Parquet column that
must be coerced, no tacho stream to define the cycles) is replayed whole.
"""

from __future__ import annotations

import json
import math
import tempfile
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.config import PipelineConfig, WindowConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.run import CLOCK_STREAMS, PipelineResult, run_clock_offsets, run_pipeline
from fieldlogs.pipeline.summary import RunParts, summarise_parts
from fieldlogs.pipeline.truth import compare_with_truth, truth_summary
from fieldlogs.pipeline.types import GpsAnalysis, Odometry
from fieldlogs.quality.clocks import ClockOffset
from fieldlogs.runs.handle import Run
from schemas.enums import EventType
from schemas.errors import InputError
from schemas.jsonable import jsonable
from schemas.logs import TACHO

__all__ = ["Kept", "Replayed", "Window", "plan_run", "plan_windows", "replay_bounded", "replay_windows", "run_bounded"]


@dataclass(frozen=True)
class Window:
    """One window of a long run's replay [s on the run's clock]."""

    index: int
    keep_from: float
    """First t whose cycle this window reports (−inf for the first window)."""
    keep_to: float
    """t from which the next window reports (+inf for the last)."""
    overlap_s: float
    lookahead_s: float

    @property
    def read_from(self) -> float:
        return self.keep_from - self.overlap_s

    @property
    def read_to(self) -> float:
        return self.keep_to + self.lookahead_s

    def keeps(self, t: np.ndarray) -> np.ndarray:
        """Which of the times ``t`` this window reports."""
        return np.asarray((t >= self.keep_from) & (t < self.keep_to))

    def holds(self, t: float) -> bool:
        """Whether this window reports time ``t``."""
        return self.keep_from <= t < self.keep_to


def long_enough(span_s: float, cfg: WindowConfig) -> bool:
    """Whether a run spanning ``span_s`` is replayed in windows: more than 1.5 lengths."""
    return cfg.length_h > 0 and math.isfinite(span_s) and span_s > 1.5 * cfg.length_h * 3600.0


def plan_windows(t_first: float, t_last: float, cfg: WindowConfig) -> list[Window]:
    """Windows of ``cfg.length_h`` covering [t_first, t_last], the last one between 0.5 and
    1.5 lengths; none (replay whole) when the run is at most 1.5 lengths long or
    ``length_h`` is 0. The first window reports everything before its end and the last
    everything after its start, so no row of the run falls outside every window."""
    length = cfg.length_h * 3600.0
    span = t_last - t_first
    if not long_enough(span, cfg):
        return []
    n = max(round(span / length), 2)
    edges = [-math.inf, *(t_first + k * length for k in range(1, n)), math.inf]
    overlap, ahead = cfg.overlap_min * 60.0, cfg.lookahead_min * 60.0
    return [Window(k, edges[k], edges[k + 1], overlap, ahead) for k in range(n)]


#: A tacho whose t spans more than this many times what its rows cover at its rate is not
#: windowed (the usability rule refuses it, with the reason, on the whole run).
SPAN_PER_ROWS = 10.0


def plan_run(run: Run, cfg: WindowConfig) -> list[Window]:
    """The windows of ``run`` (none: replay it whole): its tacho's span from the Parquet
    statistics, every stream readable by window (:meth:`Run.windowable`)."""
    if not run.has("tacho") or not run.windowable():
        return []
    span, rows = run.t_span("tacho"), run.rows("tacho")
    rate = TACHO.rate_hz or 10.0
    if span is None or rows is None or span[1] - span[0] > SPAN_PER_ROWS * rows / rate:
        return []  # a time base its rows do not cover (t in ms?): whole, where the usability rule says so
    return plan_windows(*span, cfg)


@dataclass
class Kept:
    """One window's kept part."""

    window: Window
    result: PipelineResult
    """The window's result restricted to its kept cycles (its summary empty: the run's is
    made from the windows' :attr:`parts`)."""
    parts: RunParts
    """The summary's parts of the kept span."""
    lead_m: float
    """Travel from the cycle before the kept span to its first cycle (0 for the first window)."""


def replay_windows(run: Run, network: Network, cfg: PipelineConfig, windows: list[Window]) -> Iterator[Kept]:
    """Each window's kept part, in time order (module docstring). Raises what
    :func:`run_pipeline` raises on a window, InputError when a stream cannot be read by time."""
    assert run.meta is not None
    offsets = _WindowOffsets(run, cfg, windows)
    try:
        for w in windows:
            view = _view(run, windows, w)
            part = run_pipeline(view, network, cfg, clock_offsets=offsets.chooser(w.index), summary=False)
            del view
            kept = _kept(w, part, run.meta.wheel_diameter_m)
            del part
            _give_back_memory()
            yield kept
    finally:
        run.close_windows()


def _view(run: Run, windows: list[Window], w: Window, streams: tuple[str, ...] | None = None) -> Run:
    """Window ``w`` of ``run``, read through the run's cursors (:meth:`Run.window`): the
    rows before the next window's start are not kept for it."""
    nxt = windows[w.index + 1].read_from if w.index + 1 < len(windows) else None
    view = run.window(w.read_from, w.read_to, streams, carry_from=nxt)
    if view is None:
        raise InputError("a stream could not be read by time window", path=run.folder)
    return view


#: Windows that must determine a stream's clock offset, in agreement, before a window that
#: could not determine its own takes it (one window's finding may be a short span's fluke).
MIN_AGREEING_WINDOWS = 2


def window_offsets(run: Run, cfg: PipelineConfig, windows: list[Window]) -> list[list[ClockOffset]]:
    """The clock offsets each window applies (:func:`choose_offset`), every window's clock
    check made first (a pass of its own over the clock streams; the replay itself makes a
    window's check once, in its own pipeline, and looks ahead only for a window that could
    not determine an offset: :class:`_WindowOffsets`)."""
    found = _WindowOffsets(run, cfg, windows)
    return [found.chosen(k, found.own(k)) for k in range(len(windows))]


class _WindowOffsets:
    """The clock offsets of a long run's windows: its own where a window's clock check
    determines one; else, when at least :data:`MIN_AGREEING_WINDOWS` other windows
    determined the stream's offset and they agree within ``clock.tolerance_s``, the one of
    those nearest to it (the earlier on a tie; ``from_t`` says which). A clock offset
    belongs to the recorder, not to a part of the run, so a window with too little motion
    to find it must not run on a wrong clock; but one window's finding alone is not taken
    for the others (on a 3-minute window of the tunnel sample run the GPS check "finds"
    −0.96 s; spread to its neighbours it put 5 % of their cycles outside the margin).

    A window's own check is made once: in its replay (:meth:`chooser`, on the streams its
    pipeline has cleaned) or, when an earlier window needs every window's finding because
    it determined nothing for a stream, by reading the later windows' clock streams ahead
    (their own cursors; the replay then reuses those findings)."""

    def __init__(self, run: Run, cfg: PipelineConfig, windows: list[Window]) -> None:
        self.run, self.cfg, self.windows = run, cfg, windows
        self.found: dict[int, list[ClockOffset]] = {}

    def chooser(self, k: int) -> Callable[[list[ClockOffset]], list[ClockOffset]]:
        """For :func:`run_pipeline`: window k's own findings → the offsets it applies."""

        def choose(own: list[ClockOffset]) -> list[ClockOffset]:
            self.found.setdefault(k, own)
            return self.chosen(k, self.found[k])

        return choose

    def own(self, k: int) -> list[ClockOffset]:
        """Window k's own findings, its clock streams read by a cursor of their own."""
        if k not in self.found:
            ahead = self.run.lookahead()
            try:
                for j, w in enumerate(self.windows):  # every window not replayed yet, in order
                    if j not in self.found:
                        view = _view(ahead, self.windows, w, CLOCK_STREAMS)
                        self.found[j] = run_clock_offsets(view, self.cfg)
                        del view
                        _give_back_memory()
            finally:
                ahead.close_windows()
        return self.found[k]

    def chosen(self, k: int, own: list[ClockOffset]) -> list[ClockOffset]:
        windows, cfg = self.windows, self.cfg
        if all(o.determined for o in own):
            return own
        found = [own if j == k else self.own(j) for j in range(len(windows))]
        first = windows[0].keep_to - cfg.window.length_h * 3600.0  # where the first window's part starts
        chosen = []
        for o in own:
            others = [(abs(j - k), j, x) for j, f in enumerate(found) if j != k for x in f if x.stream == o.stream]
            agreeing = [(d, j, x) for d, j, x in others if x.determined]
            spread = max((x.offset_s for _, _, x in agreeing), default=0.0) - min(
                (x.offset_s for _, _, x in agreeing), default=0.0
            )
            if o.determined or len(agreeing) < MIN_AGREEING_WINDOWS or spread > cfg.clock.tolerance_s:
                chosen.append(o)
                continue
            _, j, x = min(agreeing, key=lambda e: (e[0], e[1]))
            start = windows[j].keep_from
            chosen.append(replace(x, from_t=start if math.isfinite(start) else first))
        return chosen


@dataclass
class Replayed:
    """What :func:`replay_bounded` keeps of a run: everything but the per-cycle tables."""

    run_id: str
    summary: dict[str, Any]
    events: pd.DataFrame
    last_position: tuple[float, float] | None
    """(km, margin) of the last cycle with a km, for the console."""
    windows: int = 0
    """Windows the run was replayed in (0: whole)."""
    cycles: int = 0
    leads_m: list[float] = field(default_factory=list)
    """Each window's step into its first kept cycle (to join the distances)."""


@dataclass
class _Accumulated:
    parts: list[RunParts] = field(default_factory=list)
    events: list[pd.DataFrame] = field(default_factory=list)
    claimed: list[pd.DataFrame] = field(default_factory=list)
    leads: list[float] = field(default_factory=list)
    last_position: tuple[float, float] | None = None


def replay_bounded(
    run: Run, network: Network, cfg: PipelineConfig, consume: Callable[[PipelineResult], None]
) -> Replayed:
    """The run through the pipeline, whole or (:func:`plan_run`) window by window, each
    result — the whole run's, or each window's kept part — handed to ``consume`` as it is
    made and then dropped; returns the summary and the events. A long CSV run is spooled
    to Parquet first (:meth:`Run.spool`, in a temporary folder removed after)."""
    with tempfile.TemporaryDirectory(prefix="trainpos-spool-") as tmp:
        if _long_csv(run, cfg.window):
            run.spool(Path(tmp))
        return _replay(run, network, cfg, consume)


def _long_csv(run: Run, cfg: WindowConfig) -> bool:
    """A CSV tacho whose first and last t are more than 1.5 window lengths apart."""
    if run.stream_format("tacho") != "csv":
        return False
    span = run.t_span("tacho")  # from the file's first and last lines
    return span is not None and long_enough(span[1] - span[0], cfg)


def _replay(run: Run, network: Network, cfg: PipelineConfig, consume: Callable[[PipelineResult], None]) -> Replayed:
    windows = plan_run(run, cfg.window)
    if not windows:
        result = run_pipeline(run, network, cfg)
        consume(result)
        cycles = len(result.positions)
        last = _last_position(result.positions)
        return Replayed(result.run_id, result.summary, result.events, last, 0, cycles)
    acc = _Accumulated()
    assert run.meta is not None
    for kept in replay_windows(run, network, cfg, windows):
        res = kept.result
        acc.parts.append(kept.parts)
        acc.events.append(res.events)
        if res.truth is not None and len(res.truth):
            cmp = compare_with_truth(res.positions, res.truth)
            acc.claimed.append(cmp[cmp["claimed"]])
        acc.last_position = _last_position(res.positions) or acc.last_position
        acc.leads.append(kept.lead_m)
        consume(res)
        del kept, res
    events = pd.concat(acc.events, ignore_index=True).sort_values("t", kind="stable").reset_index(drop=True)
    parts = RunParts.merged(acc.parts)
    summary = summarise_parts(run, network, cfg, parts, events)
    summary["windows"] = {"count": len(windows), "length_h": cfg.window.length_h}
    if acc.claimed:
        summary["truth"] = truth_summary(pd.concat(acc.claimed, ignore_index=True))
    return Replayed(run.run_id, summary, events, acc.last_position, len(windows), parts.cycles, acc.leads)


def run_bounded(run: Run, network: Network, cfg: PipelineConfig | None = None) -> PipelineResult:
    """:func:`replay_bounded` with every part joined into one result (positions, odometry
    with one continuous distance, GPS fixes and decisions, truth, κ); a run replayed whole is
    :func:`run_pipeline`'s result itself. For callers that want the whole table."""
    cfg = cfg or PipelineConfig()
    parts: list[PipelineResult] = []
    done = replay_bounded(run, network, cfg, parts.append)
    if done.windows == 0:
        return parts[0]
    return _joined(done, parts)


def _joined(done: Replayed, parts: list[PipelineResult]) -> PipelineResult:
    odos = [p.odometry for p in parts]
    leads = done.leads_m
    odometry = Odometry(
        _continuous([o.d for o in odos], leads),
        np.concatenate([o.v for o in odos]),
        np.concatenate([o.slipping for o in odos]),
        _continuous([o.allowance for o in odos], [0.0] * len(odos)),
        [e for o in odos for e in o.episodes],
    )
    gps_parts = [p.gps for p in parts if p.gps is not None]
    gps = None
    if gps_parts:
        frames = [g.fixes for g in gps_parts if g.fixes is not None]
        gps = GpsAnalysis(
            pd.concat(frames, ignore_index=True) if frames else None,
            [d for g in gps_parts for d in g.decisions],
            [e for g in gps_parts for e in g.crossovers],
        )
    truths = [p.truth for p in parts if p.truth is not None and len(p.truth)]
    kappas = [p.kappa for p in parts]
    kappa = np.concatenate([k for k in kappas if k is not None]) if all(k is not None for k in kappas) else None
    return PipelineResult(
        done.run_id,
        pd.concat([p.positions for p in parts], ignore_index=True),
        done.events,
        done.summary,
        odometry,
        gps,
        kappa,
        pd.concat(truths, ignore_index=True) if truths else None,
    )


def _last_position(pos: pd.DataFrame) -> tuple[float, float] | None:
    km = pos["km_m"].to_numpy(dtype=float, na_value=np.nan)
    i = np.flatnonzero(np.isfinite(km))
    if not i.size:
        return None
    return float(km[i[-1]]), float(pos["margin_m"].to_numpy(dtype=float, na_value=np.nan)[i[-1]])


def _give_back_memory() -> None:
    """Free a finished window's cyclic garbage before the next one is read: a collection
    of the young generations only (a full one visits every object of the process — the
    DB, the modules — 0.1 s a window). Freed memory is not handed back to the system
    (``malloc_trim``, Arrow's ``release_unused``): the next window, the same size, reuses
    it instead of faulting in fresh pages (0.3–0.6 s of system time at 8–24 h, for
    10–15 MB more peak; bench/NOTES.md, "issue 34")."""
    import gc

    gc.collect(1)


def _kept(w: Window, part: PipelineResult, wheel_diameter_m: float | None) -> Kept:
    """The part of a window's result it reports: its kept cycles, events, episodes, GPS
    fixes and decisions, truth rows, and the summary's parts of the kept span."""
    pos = part.positions
    i = np.flatnonzero(w.keeps(pos["t"].to_numpy(dtype=float)))
    rows = slice(int(i[0]), int(i[-1]) + 1) if i.size else slice(0, 0)
    odo = part.odometry
    i0 = rows.start
    lead = float(odo.d[i0] - odo.d[i0 - 1]) if 0 < i0 < odo.d.size else 0.0
    d = odo.d[rows]
    odometry = Odometry(
        d.copy(),
        odo.v[rows].copy(),
        odo.slipping[rows].copy(),
        odo.allowance[rows].copy(),
        [e for e in odo.episodes if w.holds(e.t_start)],
        ground=odo.ground,
    )
    gps = part.gps
    if gps is not None:
        fixes = gps.fixes
        if fixes is not None and len(fixes):
            fixes = fixes[w.keeps(fixes["t"].to_numpy(dtype=float))].copy()
        gps = GpsAnalysis(
            fixes,
            [x for x in gps.decisions if w.holds(x.t)],
            [e for e in gps.crossovers if w.holds(e.t)],
        )
    truth = part.truth
    if truth is not None and len(truth):
        truth = truth[w.keeps(truth["t"].to_numpy(dtype=float))].copy()
    kept_pos = pos.iloc[rows].copy()  # not a view holding the window's whole frame
    travel = float(d[-1] - d[0]) + lead if d.size else 0.0
    parts = RunParts.of(kept_pos, odometry, gps, wheel_diameter_m, wheel_scale=part.wheel_scale, distance_m=travel)
    kappa = part.kappa[rows].copy() if part.kappa is not None and len(part.kappa) == len(pos) else None
    cycles = _kept_cycles(part.cycles, rows, len(pos))
    result = PipelineResult(
        part.run_id, kept_pos, _kept_events(part.events, w), part.summary, odometry, gps, kappa, truth, cycles
    )
    return Kept(w, result, parts, lead)


def _kept_cycles(cycles: Cycles | None, rows: slice, n: int) -> Cycles | None:
    """The kept cycles' pulse speed for the audit's trace (the rest of the cycles is not kept)."""
    if cycles is None or cycles.t.size != n:
        return None
    return Cycles(
        cycles.t[rows].copy(),
        cycles.pulses[rows].copy(),
        cycles.d_pulse[rows].copy(),
        cycles.v_pulse[rows].copy(),
        {},
        cycles.cab[rows].copy(),
        cycles.pto[rows].copy(),
        cycles.has_tacho,
        False,
        None if cycles.rotation is None else cycles.rotation[rows].copy(),
    )


#: Events a replay makes about the whole of what it was given, at t = 0: repairs of the
#: streams, the clock, wheel-scale and balise-clock checks.
RUN_NOTES = frozenset(
    str(t) for t in (EventType.INPUT_REPAIRED, EventType.CLOCK_OFFSET, EventType.WHEEL_SCALE, EventType.BALISE_CLOCK)
)


def _kept_events(ev: pd.DataFrame, w: Window) -> pd.DataFrame:
    """The events of the kept span, and the window's run-level notes (:data:`RUN_NOTES`)
    at its ``keep_from`` with the window's span in ``detail`` (the first window's stay at
    t = 0 as a whole run's), so a later window's findings are neither lost nor misdated."""
    t = ev["t"].to_numpy(dtype=float)
    notes = ev["type"].isin(RUN_NOTES).to_numpy() & (t == 0.0)
    if not math.isfinite(w.keep_from):
        notes[:] = False
    take = w.keeps(t) | notes
    out = ev[take].copy()
    if notes.any():
        sel = notes[take]
        span = [w.keep_from, None if math.isinf(w.keep_to) else w.keep_to]
        out.loc[sel, "t"] = w.keep_from
        out.loc[sel, "detail"] = [
            json.dumps({**json.loads(d), "window": jsonable(span)}, ensure_ascii=False, sort_keys=True)
            for d in out.loc[sel, "detail"]
        ]
    return pd.DataFrame(out)


def _continuous(parts: list[np.ndarray], leads: list[float]) -> np.ndarray:
    """Cumulative arrays of consecutive windows joined into one: each window's values
    continue from where the previous window's kept span ended, plus the step its own replay
    saw into its first kept cycle (``leads``). The first window keeps its own values."""
    out: list[np.ndarray] = []
    base: float | None = None
    for p, lead in zip(parts, leads, strict=True):
        if p.size:
            out.append(p if base is None else p - p[0] + base + lead)
            base = float(out[-1][-1])
    return np.concatenate(out) if out else np.zeros(0)
