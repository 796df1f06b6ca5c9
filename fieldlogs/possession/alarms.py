"""The alarm rules of the possession check over one on-rail period [S001 §3, §4.2.4, §6, §7.3;
SPEC §5.5].

Everything is evaluated as the onboard alarm device would have seen it, causally, on a
``step_s`` (0.1 s) grid while the PTO says the vehicle is on rail, from the km filter's band
km ± u (:mod:`fieldlogs.possession.kmfilter`).

**Matching the run to the plan.** The period's line is the line most of its matched fixes
lie on. Candidates: possessions of that line whose time window (earliest to latest of the
planned and actual times) overlaps the period ± ``match_slack_s``. The *governing*
possession is the candidate covering the km at PTO on (preferring one already started, then
the lowest work number); after a track decision on another track the candidate of that
track covering the km is taken if there is one — otherwise that is a wrong-track alarm.

**Alarms** (:class:`~schemas.enums.AlarmType`; each with t, wall-clock time = run.json
start_time + t, km, decided track, work number and evidence; one per episode, episodes
closer than ``rearm_s`` merged):

* ``wrong_track`` — an up/down decision (line, track) that no candidate possession of that
  line and track covering the vehicle's km allows, at the decision time [S001 §3.1(e)];
* ``wrong_track_suspected`` — still undecided ``decision_target_s`` after PTO on while the
  evidence leans to another track than the plan's: that track is the likeliest with a
  log-likelihood ratio > ``suspect_llr`` (with the odds). Fail-safe: the device must warn
  before work starts on the track, and a slow D-GPS error can hold the fixes near the
  midline longer than that; the decision itself still waits for its 1:1000 evidence;
* ``overrun`` — as soon as the band km ± min(u, ``overrun_band_max_m``) is not inside
  [km_from, km_to]; cleared when it is inside again. With degraded GPS (u above 15 m) the
  wider band leaving the section is an ``overrun_possible`` notice — the judgement held
  while the fixes fluctuate, as the paper's device does [S001 §7.3, fig. 17] — and the
  alarm comes when km is within 15 m of the end;
* ``released_on_rail`` — the governing possession's ``released_at`` passes while on rail
  (or the vehicle goes on rail after it) [S001 §4.2.4];
* ``not_started`` — on rail while the governing possession is not started (no
  ``started_at`` yet), or with no candidate possession at all [S001 §4.2.4].

**Notices** (:class:`~schemas.enums.NoticeType`): ``approaching_end`` — the leading edge of
the band (km + u moving up, km − u moving down, speed ≥ ``min_speed_mps``) within
``notice_m`` (30 m) of that end of the section [S001 §6.2(b)]; ``overrun_possible`` (above);
``track_undecided`` (no decision ``decision_target_s`` after PTO on [S001 §3.1(e)]);
``crossover`` (RMS of the offset from the base track [S001 §7]); ``position_uncertain`` (u
above ``uncertain_notice_m``, the paper's 30 m longitudinal target [S001 §3.2(b)]);
``position_undetermined`` (no km at PTO on).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

import numpy as np
import numpy.typing as npt

from dbtools.masks import merge_runs, true_runs
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.pipeline.gps.analysis import TrackOdds
from fieldlogs.pipeline.types import TrackDecision
from fieldlogs.possession.config import PossessionConfig
from fieldlogs.possession.kmfilter import bool_column, km_noise, track_km
from fieldlogs.possession.periods import RailPeriod, period_line
from fieldlogs.possession.plan import Possession, PossessionState
from fieldlogs.possession.results import Alarm, PeriodResult, Timeline, wall
from schemas.enums import AlarmType, NoticeType

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


def episodes(mask: BoolArray, t: FloatArray, merge_s: float) -> list[tuple[int, int]]:
    """(first, last) index of each run of True, runs closer than ``merge_s`` merged."""
    starts, ends = merge_runs(*true_runs(mask), t, merge_s)
    return [(int(s), int(e) - 1) for s, e in zip(starts, ends, strict=True)]


def _rel(start: datetime, when: datetime | None) -> float:
    return np.nan if when is None else (when - start).total_seconds()


def _rank(p: Possession, km: float, when: datetime) -> tuple[int, float, int, str]:
    """Order of candidates: covering the km, nearest, started, lowest work number."""
    dist = 0.0 if not math.isfinite(km) else max(p.km_from_m - km, km - p.km_to_m, 0.0)
    started = p.state_at(when) == PossessionState.STARTED
    return (0 if dist == 0.0 and math.isfinite(km) else 1, dist, 0 if started else 1, p.work_no)


@dataclass(frozen=True)
class _Band:
    """The km filter's band on the period's grid, and the measurements it was made of."""

    tg: FloatArray
    km: FloatArray
    v: FloatArray
    u: FloatArray
    since: FloatArray
    fix_t: FloatArray
    fix_km: FloatArray
    fix_trusted: BoolArray

    @property
    def known(self) -> BoolArray:
        known: BoolArray = np.isfinite(self.km)
        return known


def _band(period: RailPeriod, line: str | None, gps_cfg: GpsConfig, cfg: PossessionConfig) -> _Band:
    """The km filter over the period's measurements (approach included), on the grid."""
    t_on, t_off, fixes = period.t_on, period.t_off, period.gps.fixes
    white, bias = km_noise(fixes, gps_cfg, cfg) if len(fixes) else (np.zeros(0), np.zeros(0))
    ft = fixes["t"].to_numpy(dtype=float) if len(fixes) else np.zeros(0)
    fkm = fixes["km_m"].to_numpy(dtype=float, na_value=np.nan) if len(fixes) else np.zeros(0)
    meas = np.isfinite(fkm) & (ft <= t_off)
    if len(fixes):
        meas &= (fixes["offset_m"].abs() <= cfg.max_offset_m).fillna(False).to_numpy(dtype=bool)
        if line is not None:
            meas &= (fixes["line_code"].astype(str) == line).to_numpy(dtype=bool)
    trusted = bool_column(fixes, "trusted") if len(fixes) else np.zeros(0, dtype=bool)
    tacho = period.tacho.between(t_on, t_off) if period.tacho is not None else None
    kt = track_km(ft[meas], fkm[meas], white[meas], bias[meas], trusted[meas], cfg, tacho)
    n = max(math.ceil((t_off - t_on) / cfg.step_s - 1e-9), 1)
    tg: FloatArray = t_on + np.arange(n, dtype=np.float64) * cfg.step_s
    km, v, s_km, since = kt.at(tg)
    u = cfg.gis_uncertainty_m + cfg.km_z * s_km
    return _Band(tg, km, v, u, since, ft[meas], fkm[meas], trusted[meas])


class _Sink:
    """Collects the period's alarms and notices with their time, km and decided track."""

    def __init__(self, start: datetime, band: _Band, decisions: list[TrackDecision]) -> None:
        self.start, self.band, self.decisions = start, band, decisions
        self.alarms: list[Alarm] = []
        self.notices: list[Alarm] = []

    def decided_at(self, tt: float) -> str | None:
        cur = None
        for d in self.decisions:
            if d.t <= tt + 1e-9:
                cur = d.track
        return cur

    def km_at(self, tt: float) -> float | None:
        tg, km = self.band.tg, self.band.km
        i = int(np.clip(np.searchsorted(tg, tt, side="right") - 1, 0, tg.size - 1))
        return float(km[i]) if np.isfinite(km[i]) else None

    def add(self, typ: AlarmType | NoticeType, tt: float, work: str | None, evidence: dict[str, Any]) -> None:
        to = self.alarms if isinstance(typ, AlarmType) else self.notices
        to.append(Alarm(typ, float(tt), wall(self.start, tt), self.km_at(tt), self.decided_at(tt), work, evidence))


def _candidates(
    possessions: list[Possession], line: str | None, period: RailPeriod, start: datetime, cfg: PossessionConfig
) -> list[Possession]:
    lo_t = start + timedelta(seconds=period.t_on) - timedelta(seconds=cfg.match_slack_s)
    hi_t = start + timedelta(seconds=period.t_off + cfg.match_slack_s)
    return [
        p for p in possessions if (line is None or p.line_code == line) and p.window[0] <= hi_t and p.window[1] >= lo_t
    ]


def _segments(
    sink: _Sink, cands: list[Possession], gov: Possession | None, t_on: float
) -> list[tuple[float, Possession | None]]:
    """(from t, governing possession): the one at PTO on, then after each decision on another
    track the candidate of that track covering the km — or a ``wrong_track`` alarm."""
    segments: list[tuple[float, Possession | None]] = [(t_on, gov)]
    for d in sink.decisions:
        cur = segments[-1][1]
        if cur is not None and (d.line_code, d.track) == (cur.line_code, cur.track):
            continue
        kd = sink.km_at(d.t)
        alt = [p for p in cands if (p.line_code, p.track) == (d.line_code, d.track) and kd is not None and p.covers(kd)]
        if alt:
            when = sink.start + timedelta(seconds=d.t)
            segments.append((d.t, min(alt, key=lambda p: _rank(p, np.nan if kd is None else kd, when))))
        elif cur is not None:
            sink.add(
                AlarmType.WRONG_TRACK,
                d.t,
                cur.work_no,
                {
                    "planned_line_code": cur.line_code,
                    "planned_track": cur.track,
                    "decided_line_code": d.line_code,
                    "decided_track": d.track,
                    "after_on_rail_s": round(d.t - t_on, 2),
                    **d.evidence,
                },
            )
    return segments


class _Sections:
    """The governing possession's section and times at every grid time."""

    def __init__(self, segments: list[tuple[float, Possession | None]], tg: FloatArray, start: datetime) -> None:
        self.seg_t = np.array([s[0] for s in segments])
        self.seg_p = [s[1] for s in segments]
        seg_p = self.seg_p
        k = np.clip(np.searchsorted(self.seg_t, tg, side="right") - 1, 0, len(seg_p) - 1)
        self.k = k
        self.has: BoolArray = np.array([p is not None for p in seg_p])[k]
        self.kf: FloatArray = np.array([p.km_from_m if p else np.nan for p in seg_p])[k]
        self.kt: FloatArray = np.array([p.km_to_m if p else np.nan for p in seg_p])[k]
        self.st: FloatArray = np.array([_rel(start, p.started_at) if p else np.nan for p in seg_p])[k]
        self.rl: FloatArray = np.array([_rel(start, p.released_at) if p else np.nan for p in seg_p])[k]
        self.works = [p.work_no if p else None for p in seg_p]

    def work_at(self, i: int) -> str | None:
        return self.works[int(self.k[i])]

    def possession_at(self, i: int) -> Possession:
        p = self.seg_p[int(self.k[i])]
        assert p is not None
        return p

    def timeline(self, t_off: float) -> list[tuple[float, float, str, float, float]]:
        seg_end = [*self.seg_t[1:].tolist(), t_off]
        return [
            (float(a), float(b), p.work_no, p.km_from_m, p.km_to_m)
            for a, b, p in zip(self.seg_t.tolist(), seg_end, self.seg_p, strict=True)
            if p is not None
        ]


def _state_alarms(sink: _Sink, sec: _Sections, tg: FloatArray, t_on: float, cfg: PossessionConfig) -> None:
    """``not_started`` while the governing possession is not started; ``released_on_rail``
    once its ``released_at`` has passed."""
    for a, b in episodes(sec.has & ~(tg >= sec.st), tg, cfg.rearm_s):
        p = sec.possession_at(a)
        evidence = {
            "state": PossessionState.NOT_STARTED.value,
            "started_at": p.started_at,
            "planned_start": p.planned_start,
            "until_t": round(float(tg[b]) + cfg.step_s, 2),
        }
        sink.add(AlarmType.NOT_STARTED, tg[a], p.work_no, evidence)
    for a, b in episodes(sec.has & (tg >= sec.rl), tg, cfg.rearm_s):
        p = sec.possession_at(a)
        evidence = {
            "released_at": p.released_at,
            "on_rail_since_t": round(t_on, 2),
            "until_t": round(float(tg[b]) + cfg.step_s, 2),
        }
        sink.add(AlarmType.RELEASED_ON_RAIL, max(float(sec.rl[a]), t_on), p.work_no, evidence)


def _overrun_rules(sink: _Sink, sec: _Sections, band: _Band, cfg: PossessionConfig) -> None:
    """``overrun`` alarms on the capped band, ``overrun_possible`` notices on the full one."""
    tg, km, u = band.tg, band.km, band.u
    lo_edge, hi_edge = km - u, km + u
    ua = np.fmin(u, cfg.overrun_band_max_m)
    on = sec.has & band.known
    over = on & ~((km - ua >= sec.kf) & (km + ua <= sec.kt))
    possible = on & ~over & ~((lo_edge >= sec.kf) & (hi_edge <= sec.kt))
    for typ, cond in ((AlarmType.OVERRUN, over), (NoticeType.OVERRUN_POSSIBLE, possible)):
        for a, b in episodes(cond, tg, cfg.rearm_s):
            up = hi_edge[a] - sec.kt[a] >= sec.kf[a] - lo_edge[a]
            beyond = np.where(up, km + ua - sec.kt, sec.kf - km + ua)[a : b + 1]
            evidence = {
                "end": "km_to_m" if up else "km_from_m",
                "boundary_km_m": float(sec.kt[a] if up else sec.kf[a]),
                "uncertainty_m": float(u[a]),
                "beyond_m": float(beyond[0]),
                "max_beyond_m": float(np.nanmax(beyond)),
                "since_fix_s": float(band.since[a]),
                "until_t": round(float(tg[b]) + cfg.step_s, 2),
            }
            sink.add(typ, tg[a], sec.work_at(a), evidence)


def _band_notices(sink: _Sink, sec: _Sections, band: _Band, cfg: PossessionConfig) -> None:
    """``approaching_end`` (leading edge within ``notice_m`` of an end) and ``position_uncertain``."""
    tg, km, u, v = band.tg, band.km, band.u, band.v
    lo_edge, hi_edge, kf, kt = km - u, km + u, sec.kf, sec.kt
    moving_up, moving_down = v >= cfg.min_speed_mps, v <= -cfg.min_speed_mps
    for end, cond, dist in (
        ("km_to_m", sec.has & moving_up & (hi_edge <= kt) & (kt - hi_edge <= cfg.notice_m), kt - km),
        ("km_from_m", sec.has & moving_down & (lo_edge >= kf) & (lo_edge - kf <= cfg.notice_m), km - kf),
    ):
        for a, _b in episodes(cond, tg, 2 * cfg.rearm_s):
            evidence = {
                "end": end,
                "boundary_km_m": float(kt[a] if end == "km_to_m" else kf[a]),
                "distance_m": float(dist[a]),
                "uncertainty_m": float(u[a]),
                "speed_mps": float(abs(v[a])),
            }
            sink.add(NoticeType.APPROACHING_END, tg[a], sec.work_at(a), evidence)
    for a, b in episodes(band.known & (u > cfg.uncertain_notice_m), tg, cfg.rearm_s):
        evidence = {
            "uncertainty_m": float(u[a]),
            "since_fix_s": float(band.since[a]),
            "until_t": round(float(tg[b]) + cfg.step_s, 2),
        }
        sink.add(NoticeType.POSITION_UNCERTAIN, tg[a], sec.work_at(a), evidence)


def _leans_elsewhere(gov: Possession, lean: TrackOdds | None, cfg: PossessionConfig) -> bool:
    if lean is None:
        return False
    return (lean.line_code, lean.track) != (gov.line_code, gov.track) and lean.llr > cfg.suspect_llr


def _undecided_rules(sink: _Sink, period: RailPeriod, gov: Possession | None, cfg: PossessionConfig) -> None:
    """``track_undecided`` notice ``decision_target_s`` after PTO on without a decision, and
    ``wrong_track_suspected`` when the evidence then leans to another track than the plan's."""
    t_target = period.t_on + cfg.decision_target_s
    decisions = sink.decisions
    if period.t_off <= t_target or any(d.t <= t_target for d in decisions):
        return
    undecided = {"after_on_rail_s": cfg.decision_target_s, "decided_at_t": decisions[0].t if decisions else None}
    sink.add(NoticeType.TRACK_UNDECIDED, t_target, gov.work_no if gov else None, undecided)
    lean = period.odds[0] if period.odds else None
    if gov is None or lean is None or not _leans_elsewhere(gov, lean, cfg):
        return
    evidence = {
        "planned_line_code": gov.line_code,
        "planned_track": gov.track,
        "likeliest_line_code": lean.line_code,
        "likeliest_track": lean.track,
        "odds": round(math.exp(min(lean.llr, 50.0)), 2),
        "llr": round(lean.llr, 2),
        "n_fixes": lean.n_fixes,
        "mean_offset_m": round(lean.mean_offset_m, 3),
        "sigma_m": round(lean.sigma_m, 3),
        **undecided,
    }
    sink.add(AlarmType.WRONG_TRACK_SUSPECTED, t_target, gov.work_no, evidence)


def _start_rules(sink: _Sink, band: _Band, gov: Possession | None, line: str | None, t_on: float) -> None:
    """``position_undetermined`` without a km at PTO on; ``not_started`` without any candidate."""
    first = np.flatnonzero(band.known)
    if not first.size or first[0] > 0:
        known_from: dict[str, Any] = {"km_known_from_t": float(band.tg[first[0]]) if first.size else None}
        sink.notices.append(
            Alarm(
                NoticeType.POSITION_UNDETERMINED,
                t_on,
                wall(sink.start, t_on),
                None,
                None,
                gov.work_no if gov else None,
                known_from,
            )
        )
    if gov is None:
        evidence: dict[str, Any] = {"reason": f"no possession on line {line or '?'} at this time", "line_code": line}
        sink.add(AlarmType.NOT_STARTED, t_on, None, evidence)


def evaluate_period(
    period: RailPeriod,
    possessions: list[Possession],
    start: datetime,
    gps_cfg: GpsConfig,
    cfg: PossessionConfig,
) -> tuple[PeriodResult, list[Alarm], list[Alarm]]:
    """The alarm rules of the module docstring over one on-rail period (pure: no I/O);
    returns the period's result, its alarms and its notices."""
    t_on, t_off = period.t_on, period.t_off
    fixes = period.gps.fixes
    line = period_line(fixes, t_on, cfg.max_offset_m) if len(fixes) else None
    band = _band(period, line, gps_cfg, cfg)
    decisions = [d for d in period.gps.decisions if t_on - 1e-9 <= d.t <= t_off]
    crossovers = [c for c in period.gps.crossovers if t_on - 1e-9 <= c.t <= t_off]
    sink = _Sink(start, band, decisions)
    cands = _candidates(possessions, line, period, start, cfg)
    first = np.flatnonzero(band.known)
    km_on = float(band.km[first[0]]) if first.size else float("nan")
    wall_on = start + timedelta(seconds=t_on)
    gov = min(cands, key=lambda p: _rank(p, km_on, wall_on)) if cands else None
    segments = _segments(sink, cands, gov, t_on)
    _start_rules(sink, band, gov, line, t_on)
    sec = _Sections(segments, band.tg, start)
    _state_alarms(sink, sec, band.tg, t_on, cfg)
    _overrun_rules(sink, sec, band, cfg)
    _band_notices(sink, sec, band, cfg)
    _undecided_rules(sink, period, gov, cfg)
    n = band.tg.size
    for c in crossovers:
        i = int(np.clip(np.searchsorted(band.tg, c.t) - 1, 0, n - 1))
        sink.add(NoticeType.CROSSOVER, c.t, sec.work_at(i), dict(c.detail))
    timeline = Timeline(band.tg, band.km, band.u, band.fix_t, band.fix_km, band.fix_trusted, sec.timeline(t_off))
    result = PeriodResult(t_on, t_off, line, gov.work_no if gov else None, decisions, crossovers, timeline, period.gps)
    return result, sink.alarms, sink.notices
