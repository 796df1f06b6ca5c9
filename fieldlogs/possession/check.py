"""Possession alarms for road-rail vehicles [S001 §3, §4.2.4, §6; SPEC §5.5].

A road-rail vehicle's run (``gps``, ``cab.pto``; often no tacho or IMU — a ``tacho`` is used
when present, see below) is checked against a possession plan (:mod:`fieldlogs.possession.plan`).
Everything is evaluated as the onboard alarm device would have seen it, causally, on a
``step_s`` (0.1 s) grid while the PTO says the vehicle is on rail.

**On rail** = PTO on (``cab.pto``, carried forward; off before the first event). A run
without any PTO value counts as on rail throughout (fail-safe). Each on-rail period is
analysed on its own (the GPS decision state starts afresh, as the vehicle may come back on
another track); the fixes of the ``lead_s`` before PTO on (the approach on the road) feed the
trust filter and the km estimate but are no evidence for the up/down decision.

**Up/down decision** = the pipeline's GPS analysis (:mod:`fieldlogs.pipeline.gps`): a
sequential likelihood-ratio test on the mean offset of *trusted* D-GPS fixes (5/15/30 s RMS
filter), decided as soon as the evidence suffices, otherwise *undecided* — never guessed.
No decision ``decision_target_s`` (120 s, the field target [S001 §3.1(e)]) after PTO on is a
``track_undecided`` notice; if the evidence of those seconds nonetheless leans to another
track than the plan's (:func:`fieldlogs.pipeline.gps.track_odds`: that track is the likeliest,
log-likelihood ratio > ``suspect_llr``), a ``wrong_track_suspected`` alarm too — fail-safe:
the paper's device must warn before the vehicle starts work on the track, and a slow D-GPS
error can hold the fixes near the midline longer than that (the decision itself still waits
for its 1:1000 evidence and is never guessed). Crossovers (RMS of the offset from the base track [S001 §7]) are
notices; the decision that follows a crossover is checked like any other.

**km and its uncertainty.** A 1-D constant-velocity Kalman filter along the line's
kilometrage (state km, dkm/dt; white acceleration noise ``accel_noise_mps2``, speed kept
within ± ``max_speed_mps``) is updated at every map-matched fix (km of the foot of the
perpendicular on the nearest GIS segment, :mod:`dbtools.gis.matching`) within
``max_offset_m`` of a track of the line. Each fix's error is split into a white part (the
filter's R) and a slow part (bias) that no filter can average out:

=====================================  ===========================================  ==============
fix                                    white σ                                      bias σ
=====================================  ===========================================  ==============
trusted (5/15/30 s RMS filter)         ``noise_white_m`` of the GPS model (0.25 m)  ``noise_sigma_m`` (0.75 m)
usable D-GPS, not trusted              max(``untrusted_sigma_m``, 5 s RMS / √12)     ``noise_sigma_m``
fix 1 or high HDOP                     the same                                     ``fix1_sigma_m`` (5 m)
=====================================  ===========================================  ==============

(no RMS history yet, e.g. after a gap, counts as ``untrusted_sigma_m`` on D-GPS and as
``fix1_sigma_m`` without: a D-GPS fix is as good as D-GPS usually is, the gate keeps the
bad ones out, and weighing it as fix 1 let the filter dead-reckon past a vehicle that
braked to a stop; fix 1 and high-HDOP fixes keep the whole 5 s RMS: the RMS of 2-D second
differences is √12 × the per-axis white noise that makes it, but a multipath burst's offset
is no white noise — on D-GPS the gate, not a wider R, keeps it out, while without D-GPS the
slow error makes the gate wide); the white σ is at least the fix's offset
from the nearest track beyond ``offset_free_m`` (an on-rail fix far from every track is
probably as wrong along it — the trust filter passes such fixes when a multipath burst
ramps up smoothly). A fix whose innovation exceeds ``gate_z`` σ is rejected (multipath);
``restart_fixes`` consecutive rejected fixes on a straight line at a possible speed restart
the filter from them (a burst that slipped through must not leave it lost). A trusted fix
*anchors* the filter for ``restart_anchor_s`` (10 s): meanwhile a restart needs a line the
vehicle could have joined from the anchored state (``restart_accel_mps2``), and a vehicle the
anchor shows standing skips fixes whose slow error alone exceeds the estimate's (fix 1, high
HDOP) — a multipath burst by a standing vehicle otherwise widened the gate with its
high-HDOP fixes, bent the filter with the next one and restarted it on its plateau: a
false overrun 28 m before the end in good sky. The estimate
carries the bias variance bvar ← (1 − K)·bvar + K·bias² (K the km gain: the biases of the
fixes it is made of, as if fully correlated). Between fixes the filter predicts (dead
reckoning on its velocity — from the fixes, and the tacho's speeds when there is one): this
is what gives the alarm its timing with 1 Hz GPS — the band is evaluated every ``step_s``
(0.1 s), not only at fixes::

    u(t) = gis_uncertainty_m + km_z · √(P_km(t) + bvar)      (≈ 2.9 m on trusted fixes)

**Tachometer (optional).** GPS alone cannot tell a stopped vehicle from a slow one: braking
to a stop ~30 m before a section end while the fixes degrade, the filter dead-reckoned on
its GPS speed past the vehicle, a multipath burst along the track seemed to confirm it, and
the band crossed the end (false overruns in ``bench/bench_possession.py``). A ``tacho``
stream (with run.json ``wheel_diameter_m``, ``teeth``; pulses → metres by
:func:`fieldlogs.pipeline.cycles.build_cycles`) is used while on rail only (on the road the
rail wheels do not run), and only what it surely says — it is an *unsigned* speed with an
unknown scale error of a few % (a road-rail odometer is not calibrated like a train's):

* **standstill** — no pulse for ``standstill_s`` (1 s) — is certain: from then to the next
  pulse the filter *holds*. Its start is a perfect measurement speed = 0 (km moves back along
  its correlation with the speed), and the dynamics run on the moving time (time outside
  standstills): no dead reckoning, no process noise, so the band cannot grow. A fix whose bias
  variance exceeds the estimate's (fix 1 on a good estimate) is skipped there — fusing it
  could only widen the band — and rejected fixes never restart the filter while stopped (the
  speed is known, so it cannot have been bent; agreeing outliers are a steady multipath offset);
* **moving** — once a second, the speed by pulses (second-order backward difference over
  0.5 s: causal and without lag under constant braking) is a measurement of |dkm/dt| with
  σ = ``tacho_scale_sigma`` (3 %) · v + ``tacho_speed_floor_mps`` (0.1 m/s). Its sign is that
  of the filter's predicted speed, used only when that speed is sure (|v| ≥ ``km_z`` σ_v and
  ≥ ``min_speed_mps``); else, e.g. just after a standstill, the fixes must give the direction
  first. Why not the cab direction: it gives km direction only through the vehicle's facing,
  which no log holds and would have to be learned, and a missing or stale cab event would then
  push the km the wrong way with the tacho's precision; the filter's own sign can only sharpen
  what the fixes already say.

A tacho that fails :func:`tacho_problem` (t not increasing; pulses missing, negative or
decreasing; no pulse at all; not ~10 Hz; an impossible speed; no wheel diameter or teeth) or
cannot be read is not used at all — a false standstill would freeze the km of a moving
vehicle — and the result says so (``RunCheck.tacho``, JSON ``"tacho": {"used", "note"}``).
Without a usable tacho the filter is exactly the GPS-only one above.

**Matching the run to the plan.** The period's line is the line most of its matched fixes
lie on. Candidates: possessions of that line whose time window (earliest to latest of the
planned and actual times) overlaps the period ± ``match_slack_s``. The *governing*
possession is the candidate covering the km at PTO on (preferring one already started, then
the lowest work number); after a track decision on another track the candidate of that
track is taken if there is one — otherwise that is a wrong-track alarm.

**Alarms** (each with t, wall-clock time = run.json start_time + t, km, decided track, work
number and evidence; one per episode, episodes closer than ``rearm_s`` merged):

* ``wrong_track`` — an up/down decision (line, track) that no candidate possession of that
  line and track covering the vehicle's km allows, at the decision time;
* ``wrong_track_suspected`` — still undecided ``decision_target_s`` after PTO on while the
  evidence leans to another track than the plan's (above; with the odds);
* ``overrun`` — as soon as the band km ± min(u, ``overrun_band_max_m``) is not inside
  [km_from, km_to] (so on good fixes ~u ≈ 3 m before the true crossing); cleared when it is
  inside again. With degraded GPS (u above 15 m) the wider band leaving the section is an
  ``overrun_possible`` notice — the judgement held while the fixes fluctuate, as the
  paper's device does [S001 §7.3, fig. 17] — and the alarm comes when km is within 15 m of
  the end. Why: a vehicle braking to a stop 25–30 m before the end while GPS degrades
  made the whole band cross the end on correct runs (measured in ``bench/bench_possession.py``);
  a true overrun is still alarmed before the crossing (the band's 15 m lead);
* ``released_on_rail`` — the governing possession's ``released_at`` passes while on rail
  (or the vehicle goes on rail after it);
* ``not_started`` — on rail while the governing possession is not started (no
  ``started_at`` yet), or with no candidate possession at all.

**Notices**: ``approaching_end`` — the leading edge of the band (km + u moving up, km − u
moving down, speed ≥ ``min_speed_mps``) within ``notice_m`` (30 m) of that end of the
section [S001 §6.2(b)]; ``overrun_possible`` (above); ``track_undecided``; ``crossover``;
``position_uncertain`` (u above ``uncertain_notice_m``, the paper's 30 m longitudinal target [S001 §3.2(b)]);
``position_undetermined`` (no km at PTO on).
"""

from __future__ import annotations

import math
import tomllib
from collections import Counter
from dataclasses import dataclass, field
from datetime import datetime, timedelta
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.matching import TrackIndex, track_index_for
from dbtools.network import Network
from fieldlogs.io import Run
from fieldlogs.pipeline.config import GpsConfig, PipelineConfig, update_section
from fieldlogs.pipeline.cycles import build_cycles
from fieldlogs.pipeline.gps import TrackOdds, analyse_gps, track_odds, trust_filter
from fieldlogs.pipeline.types import Event, GpsAnalysis, TrackDecision
from fieldlogs.possession.plan import Plan, Possession, PossessionState
from schemas.errors import InputError
from schemas.jsonable import jsonable

FloatArray = npt.NDArray[np.float64]
#: Decimals of the alarms' evidence in JSON (mm, ms).
EVIDENCE_DIGITS = 3
BoolArray = npt.NDArray[np.bool_]

ALARM_TYPES = ("wrong_track", "wrong_track_suspected", "overrun", "released_on_rail", "not_started")
NOTICE_TYPES = (
    "approaching_end",
    "overrun_possible",
    "track_undecided",
    "crossover",
    "position_uncertain",
    "position_undetermined",
)


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
    most this [m/s²]. Why: a multipath burst's plateau is a line too — a vehicle standing
    28 m before the end 'jumped' 15 m in a second and was alarmed as overrunning (measured in
    ``bench/bench_possession.py``); a filter built on trusted fixes is not the one that got lost."""
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
    next pulse [s]. Why: a stopped vehicle is the one thing GPS cannot tell from a slow one,
    and dead reckoning past it while the fixes are degraded was the cause of the remaining
    false overruns (measured in ``bench/bench_possession.py``)."""
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


# ------------------------------------------------------------------------------ results
@dataclass
class Alarm:
    """An alarm or a notice."""

    type: str
    t: float
    time: str
    km_m: float | None
    track: str | None
    work_no: str | None
    evidence: dict[str, Any] = field(default_factory=dict)

    def to_json(self) -> dict[str, Any]:
        return {
            "type": self.type,
            "t": round(self.t, 2),
            "time": self.time,
            "km_m": _r(self.km_m, 2),
            "track": self.track,
            "work_no": self.work_no,
            "evidence": jsonable(self.evidence, EVIDENCE_DIGITS),
        }


@dataclass
class Timeline:
    """What the plot of one on-rail period needs."""

    t: FloatArray
    km: FloatArray
    u: FloatArray
    fix_t: FloatArray
    fix_km: FloatArray
    fix_trusted: BoolArray
    sections: list[tuple[float, float, str, float, float]]
    """(t from, t to, work_no, km_from, km_to) of the governing possession."""


@dataclass
class PeriodResult:
    t_on: float
    t_off: float
    line_code: str | None
    work_no: str | None
    decisions: list[TrackDecision]
    crossovers: list[Event]
    timeline: Timeline
    gps: GpsAnalysis | None = field(default=None, repr=False)

    def decision_json(self, start: datetime) -> dict[str, Any] | None:
        if not self.decisions:
            return None
        d = self.decisions[0]
        return {
            "t": round(d.t, 2),
            "time": wall(start, d.t),
            "line_code": d.line_code,
            "track": d.track,
            "after_on_rail_s": round(d.t - self.t_on, 2),
            "evidence": jsonable(d.evidence, EVIDENCE_DIGITS),
        }


@dataclass
class RunCheck:
    """Result of checking one run against the plan."""

    run: str
    run_id: str
    start_time: datetime
    possessions: list[str]
    periods: list[PeriodResult]
    alarms: list[Alarm]
    notices: list[Alarm]
    tacho: dict[str, Any] = field(default_factory=lambda: {"used": False, "note": "no tacho stream"})
    """Whether the km filter used a tacho, and why not (``{"used", "note"}``)."""

    @property
    def track_decision(self) -> dict[str, Any] | None:
        """The first up/down decision after going on rail (first on-rail period that has one)."""
        for p in self.periods:
            d = p.decision_json(self.start_time)
            if d is not None:
                return d
        return None

    def to_json(self) -> dict[str, Any]:
        return {
            "run": self.run,
            "run_id": self.run_id,
            "possessions": self.possessions,
            "track_decision": self.track_decision,
            "alarms": [a.to_json() for a in self.alarms],
            "notices": [n.to_json() for n in self.notices],
            "tacho": dict(self.tacho),
            "on_rail": [
                {
                    "t_on": round(p.t_on, 2),
                    "t_off": round(p.t_off, 2),
                    "time_on": wall(self.start_time, p.t_on),
                    "time_off": wall(self.start_time, p.t_off),
                    "line_code": p.line_code,
                    "work_no": p.work_no,
                    "track_decision": p.decision_json(self.start_time),
                }
                for p in self.periods
            ],
        }


def checks_json(checks: list[RunCheck]) -> dict[str, Any]:
    """The documented JSON shape ``{"runs": [...]}``."""
    return {"runs": [c.to_json() for c in checks]}


def wall(start: datetime, t: float) -> str:
    """Wall-clock time of run time t (ISO 8601 with the run's offset, ms)."""
    return (start + timedelta(seconds=float(t))).isoformat(timespec="milliseconds")


def _r(v: float | None, nd: int) -> float | None:
    return None if v is None or not math.isfinite(v) else round(float(v), nd)


# ------------------------------------------------------------------------------ tacho
TACHO_MEAS_S = 1.0
"""A tacho speed measurement enters the km filter once a second (the GPS rate: speed changes
slowly, and the per-event loop stays short)."""
TACHO_DIFF_S = 0.5
"""Speed by pulses = the second-order backward difference (3·d(t) − 4·d(t − w) + d(t − 2w)) / 2w
over w = this: causal and exact under constant acceleration, so braking does not make it lag
(a plain 1 s mean lags 0.5 s, 0.3 m/s at 2 km/h/s) [s]."""
TACHO_GAP_S = 0.35
"""Tacho rows farther apart than this are a gap: no standstill or speed across it [s]."""


@dataclass
class Tacho:
    """What the km filter takes from a tachometer (module docstring): unsigned speeds at about
    1 Hz and the standstill intervals ``[from, to)``, both only where the tacho says so."""

    t: FloatArray
    speed: FloatArray
    """Speed by pulses [m/s], unsigned (≥ 0)."""
    hold: FloatArray
    """(k, 2): standstills, sorted and disjoint — from ``standstill_s`` after the last pulse to
    the next pulse (or the last row)."""

    def between(self, t0: float, t1: float) -> Tacho:
        """Only what falls in [t0, t1] (the tacho counts rail-wheel travel: on rail only)."""
        keep = (self.t >= t0) & (self.t <= t1)
        h = np.clip(self.hold, t0, t1)
        return Tacho(self.t[keep], self.speed[keep], h[h[:, 1] > h[:, 0]])

    def moving_time(self, tq: npt.ArrayLike) -> FloatArray:
        """``tq`` minus the standstill time before it: the clock the filter's dynamics run on."""
        tq = np.asarray(tq, dtype=float)
        a, b = self.hold[:, 0], self.hold[:, 1]
        dur = b - a
        before = np.concatenate([[0.0], np.cumsum(dur)])
        k = np.searchsorted(a, tq, side="right")  # holds that started at or before tq
        kk = np.clip(k - 1, 0, None)
        inside = np.minimum(tq - a[kk], dur[kk]) if a.size else np.zeros(tq.shape)
        return np.where(k > 0, tq - before[kk] - inside, tq)

    def holding(self, tq: npt.ArrayLike) -> BoolArray:
        """Whether each ``tq`` lies in a standstill."""
        tq = np.asarray(tq, dtype=float)
        k = np.searchsorted(self.hold[:, 0], tq, side="right") - 1
        return (k >= 0) & (tq < self.hold[np.clip(k, 0, None), 1]) if self.hold.size else np.zeros(tq.shape, bool)


def tacho_problem(
    tacho: pd.DataFrame, wheel_diameter_m: float | None, teeth: int | None, cfg: PossessionConfig
) -> str | None:
    """Why a tacho stream cannot serve the km filter (None: it can). A wrong standstill would
    hold the filter while the vehicle moves, so anything doubtful makes it unusable: t not
    strictly increasing, a missing, negative or decreasing pulse count (a counter reset), no
    pulse at all, too slow a rate, no usable wheel diameter / teeth, or a speed no road-rail
    vehicle reaches on rail. Rows are file lines (the header is line 1)."""
    if wheel_diameter_m is None or not math.isfinite(wheel_diameter_m) or wheel_diameter_m <= 0:
        return f"run.json wheel_diameter_m {wheel_diameter_m!r} is not a positive number"
    if teeth is None or teeth <= 0:
        return f"run.json teeth {teeth!r} is not a positive number"
    missing = [c for c in ("t", "pulses") if c not in tacho.columns]
    if missing:
        return f"no column {', '.join(missing)}"
    if len(tacho) < 2:
        return "fewer than 2 rows"
    t = tacho["t"].to_numpy(dtype=float, na_value=np.nan)
    p = tacho["pulses"].to_numpy(dtype=float, na_value=np.nan)
    for bad, what in (
        (~np.isfinite(t), "t is missing"),
        (~np.isfinite(p), "pulses is missing"),
        (p < 0, "pulses is negative"),
    ):
        if bad.any():
            return f"{what} at row {int(np.flatnonzero(bad)[0]) + 2}"
    dt, dp = np.diff(t), np.diff(p)
    for bad, what in ((dt <= 0, "t does not increase"), (dp < 0, "pulses decrease (counter reset?)")):
        if bad.any():
            return f"{what} at row {int(np.flatnonzero(bad)[0]) + 3}"
    if not (dp > 0).any():
        return "no pulse at all (sensor or cable?)"
    if float(np.median(dt)) > TACHO_GAP_S:
        return f"rows {float(np.median(dt)):.2f} s apart, not a 10 Hz stream"
    metres = np.pi * wheel_diameter_m / teeth
    w = max(round(TACHO_MEAS_S / float(np.median(dt))), 1)
    fast = float(np.max((p[w:] - p[:-w]) * metres / (t[w:] - t[:-w]))) if p.size > w else 0.0
    if fast > 2.0 * cfg.max_speed_mps:
        return f"{fast:.1f} m/s by pulses, over twice max_speed_mps (wheel_diameter_m or teeth wrong?)"
    return None


def tacho_track(tacho: pd.DataFrame, wheel_diameter_m: float, teeth: int, cfg: PossessionConfig) -> Tacho:
    """Standstills and 1 Hz speeds of a tacho stream that :func:`tacho_problem` accepts
    (pulses → metres by :func:`fieldlogs.pipeline.cycles.build_cycles`)."""
    c = build_cycles(tacho=tacho, imu=None, cab=None, wheel_diameter_m=wheel_diameter_m, teeth=teeth)
    t, d = c.t, c.d_pulse
    n = t.size
    # contiguous stretches of rows: nothing is known across a gap
    seg0 = np.maximum.accumulate(np.where(np.r_[True, np.diff(t) > TACHO_GAP_S], t, -np.inf))
    pulse = np.r_[False, np.diff(d) > 0]
    last_pulse = np.maximum.accumulate(np.where(pulse, t, -np.inf))
    still = t - np.maximum(last_pulse, seg0) >= cfg.standstill_s - 1e-9
    hold = np.array([], dtype=float).reshape(0, 2)
    if still.any():
        m = np.r_[0, still.astype(np.int8), 0]
        a = np.flatnonzero(np.diff(m) == 1)
        b = np.flatnonzero(np.diff(m) == -1)  # first row after each run (n at the end)
        dt_med = float(np.median(np.diff(t))) if n > 1 else 0.1
        bb = np.clip(b, 0, n - 1)
        joined = (b < n) & (t[bb] - t[np.clip(b - 1, 0, None)] <= TACHO_GAP_S)
        end = np.where(joined, t[bb], t[b - 1] + dt_med)
        hold = np.column_stack([t[a], end])
    w = TACHO_DIFF_S
    v = (3.0 * d - 4.0 * np.interp(t - w, t, d) + np.interp(t - 2 * w, t, d)) / (2.0 * w)
    sec = np.floor(t / TACHO_MEAS_S + 1e-9)
    first = np.r_[True, sec[1:] != sec[:-1]]
    use = first & ~still & (t - 2 * w >= seg0 - 1e-9)
    return Tacho(t[use], np.fmax(v[use], 0.0), hold)


# ------------------------------------------------------------------------------ km filter
@dataclass
class KmTrack:
    """Kalman-filter states after each accepted fix — and, with a tacho, after each tacho
    speed and standstill start (module docstring)."""

    t: FloatArray
    km: FloatArray
    v: FloatArray
    p00: FloatArray
    p01: FloatArray
    p11: FloatArray
    bvar: FloatArray
    """Variance of the slow (bias) GPS error carried by the estimate [m²]."""
    trusted: BoolArray
    q: float
    n_rejected: int = 0
    tacho: Tacho | None = None
    tau: FloatArray | None = None
    """With a tacho: the moving time (:meth:`Tacho.moving_time`) of each state."""
    fix_t: FloatArray | None = None
    """With a tacho: the time of the last accepted fix at each state."""

    def at(self, tq: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """(km, speed, km σ, seconds since the last accepted fix) predicted at ``tq``; NaN before
        the first fix. The prediction runs on the moving time: it stands still in a standstill."""
        tq = np.asarray(tq, dtype=float)
        if self.t.size == 0:
            nan = np.full(tq.shape, np.nan)
            return nan, nan, nan, nan
        j = np.searchsorted(self.t, tq, side="right") - 1
        ok = j >= 0
        jj = np.clip(j, 0, None)
        dt = np.where(ok, tq - self.t[jj], np.nan)
        since = dt
        if self.tacho is not None and self.tau is not None and self.fix_t is not None:
            dt = np.where(ok, self.tacho.moving_time(tq) - self.tau[jj], np.nan)
            since = np.where(ok, tq - self.fix_t[jj], np.nan)
        km = self.km[jj] + self.v[jj] * dt
        var = self.p00[jj] + 2 * dt * self.p01[jj] + dt * dt * self.p11[jj] + self.q * dt**3 / 3.0
        sig = np.sqrt(var + self.bvar[jj])
        return np.where(ok, km, np.nan), np.where(ok, self.v[jj], np.nan), np.where(ok, sig, np.nan), since


FIX, SPEED, HOLD = 2, 1, 0
"""Event kinds of the km filter; at one time a standstill starts first, then speed, then fix."""


def track_km(
    t: FloatArray,
    z: FloatArray,
    white: FloatArray,
    bias: FloatArray,
    trusted: BoolArray,
    cfg: PossessionConfig,
    tacho: Tacho | None = None,
) -> KmTrack:
    """Run the constant-velocity filter over the km measurements (sorted by t).

    ``white``: σ of the independent part of each measurement (the filter's R); ``bias``: σ
    of its slow part, which no filter can average out — the estimate carries
    bvar ← (1 − K)·bvar + K·bias² (K the km gain of the update), i.e. the biases of the
    fixes it is made of, weighted as the filter weights them (conservative: as if fully
    correlated).

    ``tacho`` (on-rail part only): the dynamics run on its moving time (no prediction, no
    process noise in a standstill); a standstill's start is a perfect measurement speed = 0;
    a fix in a standstill whose bias variance exceeds the estimate's variance is skipped (it
    could only widen the band), and rejected fixes there never restart the filter; a tacho
    speed is a measurement of |dkm/dt| signed by the filter's predicted speed, used only when
    that sign is sure (module docstring).
    """
    q = cfg.accel_noise_mps2**2
    n = t.size
    if tacho is None:
        kind = np.full(n, FIX, dtype=np.int8)
        idx = np.arange(n)
        et = t
        tau = t
        hold = np.zeros(n, dtype=bool)
        tf = t
    else:
        kind = np.repeat(np.array([FIX, SPEED, HOLD], dtype=np.int8), [n, tacho.t.size, len(tacho.hold)])
        idx = np.concatenate([np.arange(n), np.arange(tacho.t.size), np.arange(len(tacho.hold))])
        et = np.concatenate([t, tacho.t, tacho.hold[:, 0]])
        order = np.lexsort((kind, et))
        kind, idx, et = kind[order], idx[order], et[order]
        tau = tacho.moving_time(et)
        hold = tacho.holding(et)
        tf = tacho.moving_time(t)
    ne = et.size
    out = {k: np.empty(ne) for k in ("t", "km", "v", "p00", "p01", "p11", "bvar", "tau", "fix_t")}
    tr = np.zeros(ne, dtype=bool)
    m = 0
    rejected = 0
    run: list[int] = []  # consecutive rejected fixes
    x0 = x1 = p00 = p01 = p11 = bv = 0.0
    t_last = tau_last = t_fix = -np.inf
    anchor = _NO_ANCHOR  # (km, speed, P00, P11, moving time) at the last accepted trusted fix
    last_trusted = False
    for e in range(ne):
        i = int(idx[e])
        if kind[e] != FIX:
            if m == 0:
                continue
            y0, c00, c01, c11 = _predict(x0, x1, p00, p01, p11, float(tau[e]) - tau_last, q)
            if kind[e] == HOLD:
                x0, x1, p00, p01, p11 = _stop(y0, x1, c00, c01, c11)
            else:
                assert tacho is not None
                vt = float(tacho.speed[i])
                if vt > cfg.tacho_speed_floor_mps and abs(x1) < max(cfg.min_speed_mps, cfg.km_z * math.sqrt(c11)):
                    continue  # moving, direction not sure yet: the fixes must tell it first
                # H = [0, 1], z = |v| signed as the predicted speed, R = (scale·|v| + floor)²
                s = c11 + (cfg.tacho_scale_sigma * vt + cfg.tacho_speed_floor_mps) ** 2
                k0, k1 = c01 / s, c11 / s
                innov = math.copysign(vt, x1) - x1
                x0 = y0 + k0 * innov
                x1 = min(max(x1 + k1 * innov, -cfg.max_speed_mps), cfg.max_speed_mps)
                p00, p01, p11 = c00 - k0 * c01, (1 - k1) * c01, (1 - k1) * c11
        else:
            r = float(white[i]) ** 2
            b2 = float(bias[i]) ** 2
            if m == 0:
                x0, x1 = float(z[i]), 0.0
                p00, p01, p11, bv = r, 0.0, cfg.speed_sigma_mps**2, b2
                if hold[e]:
                    x0, x1, p00, p01, p11 = _stop(x0, x1, p00, p01, p11)
            else:
                if float(t[i]) - t_fix <= 0:
                    continue
                y0, c00, c01, c11 = _predict(x0, x1, p00, p01, p11, float(tau[e]) - tau_last, q)
                innov = float(z[i]) - y0
                s = c00 + r
                anchored = float(tau[e]) - anchor[4] < cfg.restart_anchor_s
                still = anchored and abs(anchor[1]) < cfg.min_speed_mps
                if (hold[e] or still) and b2 > c00 + bv:
                    # stopped (tacho, or trusted fixes moments ago): a fix whose slow error alone
                    # is worse than the estimate (fix 1, high HDOP) would only widen the band —
                    # and the gate with it, for the multipath burst that made it
                    continue
                if innov * innov > cfg.gate_z**2 * (s + bv + b2):
                    # an outlier (multipath): the state stays the prediction from the last accepted
                    # fix — unless the rejected fixes agree among themselves, i.e. the filter lost the
                    # vehicle (a burst that slipped through bent its speed): restart from them
                    rejected += 1
                    run.append(i)
                    # — not in a standstill: the speed is known there, so it cannot have been bent,
                    # and rejected fixes that agree while stopped are a steady multipath offset
                    prior = anchor if anchored else None
                    restart = None if hold[e] else _restart(tf, z, white, bias, run, cfg, prior)
                    if restart is None:
                        continue
                    x0, x1, p00, p01, p11, bv = restart
                    anchor = _NO_ANCHOR
                    run = []
                else:
                    run = []
                    k0, k1 = c00 / s, c01 / s
                    x0 = y0 + k0 * innov
                    x1 = min(max(x1 + k1 * innov, -cfg.max_speed_mps), cfg.max_speed_mps)
                    p00, p01, p11 = (1 - k0) * c00, (1 - k0) * c01, c11 - k1 * c01
                    bv = (1 - k0) * bv + k0 * b2
                    if trusted[i]:
                        anchor = (x0, x1, p00, p11, float(tau[e]))
            t_fix = float(t[i])
            last_trusted = bool(trusted[i])
        t_last, tau_last = float(et[e]), float(tau[e])
        out["t"][m], out["km"][m], out["v"][m] = t_last, x0, x1
        out["p00"][m], out["p01"][m], out["p11"][m], out["bvar"][m] = p00, p01, p11, bv
        out["tau"][m], out["fix_t"][m] = tau_last, t_fix
        tr[m] = last_trusted
        m += 1
    return KmTrack(
        out["t"][:m],
        out["km"][:m],
        out["v"][:m],
        out["p00"][:m],
        out["p01"][:m],
        out["p11"][:m],
        out["bvar"][:m],
        tr[:m],
        q,
        rejected,
        tacho,
        out["tau"][:m] if tacho is not None else None,
        out["fix_t"][:m] if tacho is not None else None,
    )


#: The km filter's anchor before any trusted fix, and after a restart: never in force.
_NO_ANCHOR: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, -math.inf)


def _predict(
    x0: float, x1: float, p00: float, p01: float, p11: float, dt: float, q: float
) -> tuple[float, float, float, float]:
    """Constant-velocity prediction over dt: F = [[1, dt], [0, 1]], Q = q·[[dt³/3, dt²/2],
    [dt²/2, dt]]; returns (km, P00, P01, P11) (the speed is unchanged)."""
    return (
        x0 + x1 * dt,
        p00 + 2 * dt * p01 + dt * dt * p11 + q * dt**3 / 3.0,
        p01 + dt * p11 + q * dt * dt / 2.0,
        p11 + q * dt,
    )


def _stop(x0: float, x1: float, p00: float, p01: float, p11: float) -> tuple[float, float, float, float, float]:
    """The update by a perfect measurement speed = 0 (a standstill): km moves back along its
    correlation with the speed, and the speed and its variance become 0."""
    if p11 > 0.0:
        x0, p00 = x0 - p01 / p11 * x1, max(p00 - p01 * p01 / p11, 0.0)
    return x0, 0.0, p00, 0.0, 0.0


def _restart(
    t: FloatArray,
    z: FloatArray,
    white: FloatArray,
    bias: FloatArray,
    run: list[int],
    cfg: PossessionConfig,
    prior: tuple[float, float, float, float, float] | None = None,
) -> tuple[float, float, float, float, float, float] | None:
    """A new state from the last ``restart_fixes`` rejected fixes when a straight line fits
    them within 1.5 × their noise at a possible speed — and, given an anchored ``prior``
    (km, speed, P00, P11, time), one the vehicle could have joined (:func:`_reachable`);
    None otherwise."""
    k = cfg.restart_fixes
    if k < 2 or len(run) < k:
        return None
    idx = np.array(run[-k:])
    tt = t[idx] - t[idx[-1]]
    zz = z[idx]
    a = np.vstack([np.ones(k), tt]).T
    coef, *_ = np.linalg.lstsq(a, zz, rcond=None)
    resid = float(np.sqrt(np.mean((zz - a @ coef) ** 2)))
    noise = max(1.0, float(np.median(white[idx])))
    if resid > 1.5 * noise or abs(coef[1]) > cfg.max_speed_mps:
        return None
    if prior is not None and not _reachable(tt + float(t[idx[-1]]), coef, resid, prior, cfg.restart_accel_mps2):
        return None
    p00 = resid**2 + noise**2
    p11 = max(1.0, 2.0 * p00 / max(float(np.sum(tt**2)), 1.0))
    return float(coef[0]), float(coef[1]), p00, 0.0, p11, float(np.max(bias[idx] ** 2))


def _reachable(
    t: FloatArray, coef: FloatArray, resid: float, prior: tuple[float, float, float, float, float], accel: float
) -> bool:
    """Could a vehicle in the state ``prior`` = (km, speed, P00, P11, time) have joined the
    line ``coef`` = (km at t[-1], speed) by its first fix t[0], accelerating by at most
    ``accel``? Speed and position each within 3σ (the prior's and the line's, the line's
    per-fix error its RMS residual, at least 0.5 m) plus what that acceleration allows."""
    x0, v0, p00, p11, t0 = prior
    k = t.size
    dt = max(float(t[0]) - t0, 0.0)
    s2 = max(resid * resid, 0.25)
    tc = t - t.mean()
    sxx = max(float(np.sum(tc * tc)), 1e-9)
    v_var = s2 / sxx
    z_var = s2 * (1.0 / k + float(tc[0]) ** 2 / sxx)
    v1 = float(coef[1])
    z1 = float(coef[0]) + v1 * float(t[0] - t[-1])
    speed_ok = abs(v1 - v0) <= accel * dt + 3.0 * math.sqrt(max(p11, 0.0) + v_var)
    z_sd = math.sqrt(max(p00, 0.0) + 0.25 * dt * dt * (max(p11, 0.0) + v_var) + z_var)
    place_ok = abs(z1 - (x0 + 0.5 * (v0 + v1) * dt)) <= 0.25 * accel * dt * dt + 3.0 * z_sd
    return speed_ok and place_ok


def km_noise(fixes: pd.DataFrame, gps_cfg: GpsConfig, cfg: PossessionConfig) -> tuple[FloatArray, FloatArray]:
    """(white σ, bias σ) of the km of each fix (module docstring)."""
    n = len(fixes)
    rms_cols = sorted((c for c in fixes.columns if c.startswith("rms_")), key=lambda c: float(c[4:]))
    # the shortest window: the quality of the last seconds
    rms = fixes[rms_cols[0]].to_numpy(dtype=float, na_value=np.nan) if rms_cols else np.full(n, np.nan)
    off = np.abs(fixes["offset_m"].to_numpy(dtype=float, na_value=np.nan)) if "offset_m" in fixes else np.zeros(n)
    trusted = _bool(fixes, "trusted")
    dgps = _bool(fixes, "usable") | trusted
    # an on-rail fix far from the track is as wrong along the track, likely: the offset bounds σ
    excess = np.fmax(off - cfg.offset_free_m, 0.0)
    bias = np.where(dgps, gps_cfg.noise_sigma_m, cfg.fix1_sigma_m)
    # the RMS of 2-D second differences is √12 × the per-axis white noise that makes it; a
    # D-GPS fix's burst offset is no white noise: the gate, not a wider R, must keep it out.
    # Without D-GPS (fix 1, high HDOP) the slow error is large and the gate wide: keep R wide.
    scale = np.where(dgps, 1.0 / np.sqrt(12.0), 1.0)
    # no RMS history yet (after a gap): a D-GPS fix is as good as D-GPS usually is — the gate
    # keeps out the bad ones; without D-GPS nothing is known
    unknown = np.where(dgps, cfg.untrusted_sigma_m, cfg.fix1_sigma_m)
    noisy = np.fmax(cfg.untrusted_sigma_m, np.where(np.isfinite(rms), rms * scale, unknown))
    white = np.fmax(np.where(trusted, gps_cfg.noise_white_m, noisy), excess)
    return white, bias


def _bool(frame: pd.DataFrame, name: str) -> BoolArray:
    if name not in frame.columns:
        return np.zeros(len(frame), dtype=bool)
    return frame[name].fillna(False).to_numpy(dtype=bool)


# ------------------------------------------------------------------------------ evaluation
@dataclass
class RailPeriod:
    """One on-rail period and the GPS analysis of its fixes (from ``t_on − lead_s``)."""

    t_on: float
    t_off: float
    gps: GpsAnalysis
    tacho: Tacho | None = None
    """The run's usable tacho (:func:`tacho_track`), None without one; only its on-rail part is used."""
    odds: list[TrackOdds] = field(default_factory=list)
    """The up/down test's statistics over the first ``decision_target_s`` on rail
    (:func:`fieldlogs.pipeline.gps.track_odds`, likeliest first): where the evidence leans."""


def episodes(mask: BoolArray, t: FloatArray, merge_s: float) -> list[tuple[int, int]]:
    """(first, last) index of each run of True, runs closer than ``merge_s`` merged."""
    if not mask.any():
        return []
    m = np.concatenate([[False], mask, [False]]).astype(np.int8)
    starts = np.flatnonzero(np.diff(m) == 1)
    ends = np.flatnonzero(np.diff(m) == -1) - 1
    out: list[tuple[int, int]] = []
    for s, e in zip(starts, ends, strict=True):
        if out and t[s] - t[out[-1][1]] < merge_s:
            out[-1] = (out[-1][0], int(e))
        else:
            out.append((int(s), int(e)))
    return out


def _rel(start: datetime, when: datetime | None) -> float:
    return np.nan if when is None else (when - start).total_seconds()


def _rank(p: Possession, km: float, when: datetime) -> tuple[int, float, int, str]:
    dist = 0.0 if not math.isfinite(km) else max(p.km_from_m - km, km - p.km_to_m, 0.0)
    started = p.state_at(when) == PossessionState.STARTED
    return (0 if dist == 0.0 and math.isfinite(km) else 1, dist, 0 if started else 1, p.work_no)


def _period_line(fixes: pd.DataFrame, t_on: float, max_offset: float) -> str | None:
    ok = fixes["km_m"].notna() & (fixes["offset_m"].abs() <= max_offset) & fixes["line_code"].notna()
    on = ok & (fixes["t"] >= t_on)
    sel = fixes.loc[on if on.any() else ok, "line_code"]
    if sel.empty:
        return None
    return str(Counter(sel.astype(str)).most_common(1)[0][0])


def evaluate_period(
    period: RailPeriod,
    possessions: list[Possession],
    start: datetime,
    gps_cfg: GpsConfig,
    cfg: PossessionConfig,
) -> tuple[PeriodResult, list[Alarm], list[Alarm]]:
    """The alarm rules of the module docstring over one on-rail period (pure: no I/O)."""
    t_on, t_off = period.t_on, period.t_off
    fixes = period.gps.fixes
    line = _period_line(fixes, t_on, cfg.max_offset_m) if len(fixes) else None
    # --- km filter over the period's measurements (approach included)
    white, bias = km_noise(fixes, gps_cfg, cfg) if len(fixes) else (np.zeros(0), np.zeros(0))
    ft = fixes["t"].to_numpy(dtype=float) if len(fixes) else np.zeros(0)
    fkm = fixes["km_m"].to_numpy(dtype=float, na_value=np.nan) if len(fixes) else np.zeros(0)
    meas = np.isfinite(fkm) & (ft <= t_off)
    if len(fixes):
        meas &= (fixes["offset_m"].abs() <= cfg.max_offset_m).fillna(False).to_numpy(dtype=bool)
        if line is not None:
            meas &= (fixes["line_code"].astype(str) == line).to_numpy(dtype=bool)
    trusted = _bool(fixes, "trusted") if len(fixes) else np.zeros(0, dtype=bool)
    tacho = period.tacho.between(t_on, t_off) if period.tacho is not None else None
    kt = track_km(ft[meas], fkm[meas], white[meas], bias[meas], trusted[meas], cfg, tacho)
    n = max(math.ceil((t_off - t_on) / cfg.step_s - 1e-9), 1)
    tg: FloatArray = t_on + np.arange(n, dtype=np.float64) * cfg.step_s
    km, v, s_km, since = kt.at(tg)
    u = cfg.gis_uncertainty_m + cfg.km_z * s_km
    known = np.isfinite(km)
    wall_on = start + timedelta(seconds=t_on)

    decisions = [d for d in period.gps.decisions if t_on - 1e-9 <= d.t <= t_off]
    crossovers = [c for c in period.gps.crossovers if t_on - 1e-9 <= c.t <= t_off]
    alarms: list[Alarm] = []
    notices: list[Alarm] = []

    def decided_at(tt: float) -> str | None:
        cur = None
        for d in decisions:
            if d.t <= tt + 1e-9:
                cur = d.track
        return cur

    def km_at(tt: float) -> float | None:
        i = int(np.clip(np.searchsorted(tg, tt, side="right") - 1, 0, n - 1))
        return float(km[i]) if np.isfinite(km[i]) else None

    def add(kind: list[Alarm], typ: str, tt: float, work: str | None, evidence: dict[str, Any]) -> None:
        kind.append(Alarm(typ, float(tt), wall(start, tt), km_at(tt), decided_at(tt), work, evidence))

    # --- candidates and the governing possession
    lo_t, hi_t = wall_on - timedelta(seconds=cfg.match_slack_s), start + timedelta(seconds=t_off + cfg.match_slack_s)
    cands = [
        p for p in possessions if (line is None or p.line_code == line) and p.window[0] <= hi_t and p.window[1] >= lo_t
    ]
    first = np.flatnonzero(known)
    km_on = float(km[first[0]]) if first.size else float("nan")
    gov = min(cands, key=lambda p: _rank(p, km_on, wall_on)) if cands else None
    segments: list[tuple[float, Possession | None]] = [(t_on, gov)]
    for d in decisions:
        cur = segments[-1][1]
        if cur is not None and (d.line_code, d.track) == (cur.line_code, cur.track):
            continue
        kd = km_at(d.t)
        alt = [p for p in cands if (p.line_code, p.track) == (d.line_code, d.track) and kd is not None and p.covers(kd)]
        if alt:
            when = start + timedelta(seconds=d.t)
            segments.append((d.t, min(alt, key=lambda p: _rank(p, np.nan if kd is None else kd, when))))
        elif cur is not None:
            add(
                alarms,
                "wrong_track",
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
    if not first.size or first[0] > 0:
        notices.append(
            Alarm(
                "position_undetermined",
                t_on,
                wall(start, t_on),
                None,
                None,
                gov.work_no if gov else None,
                {"km_known_from_t": float(tg[first[0]]) if first.size else None},
            )
        )
    if gov is None:
        add(
            alarms,
            "not_started",
            t_on,
            None,
            {"reason": f"no possession on line {line or '?'} at this time", "line_code": line},
        )
    # --- per-grid section and times of the governing possession
    seg_t = np.array([s[0] for s in segments])
    seg_p = [s[1] for s in segments]
    k = np.clip(np.searchsorted(seg_t, tg, side="right") - 1, 0, len(seg_p) - 1)
    has = np.array([p is not None for p in seg_p])[k]
    kf = np.array([p.km_from_m if p else np.nan for p in seg_p])[k]
    kt_ = np.array([p.km_to_m if p else np.nan for p in seg_p])[k]
    st = np.array([_rel(start, p.started_at) if p else np.nan for p in seg_p])[k]
    rl = np.array([_rel(start, p.released_at) if p else np.nan for p in seg_p])[k]
    works = [p.work_no if p else None for p in seg_p]

    def work_at(i: int) -> str | None:
        return works[int(k[i])]

    not_started = has & ~(tg >= st)
    for a, b in episodes(not_started, tg, cfg.rearm_s):
        p = seg_p[int(k[a])]
        assert p is not None
        add(
            alarms,
            "not_started",
            tg[a],
            p.work_no,
            {
                "state": PossessionState.NOT_STARTED.value,
                "started_at": p.started_at,
                "planned_start": p.planned_start,
                "until_t": round(float(tg[b]) + cfg.step_s, 2),
            },
        )
    released = has & (tg >= rl)
    for a, b in episodes(released, tg, cfg.rearm_s):
        p = seg_p[int(k[a])]
        assert p is not None
        t_alarm = max(float(rl[a]), t_on)
        add(
            alarms,
            "released_on_rail",
            t_alarm,
            p.work_no,
            {
                "released_at": p.released_at,
                "on_rail_since_t": round(t_on, 2),
                "until_t": round(float(tg[b]) + cfg.step_s, 2),
            },
        )
    lo_edge, hi_edge = km - u, km + u
    ua = np.fmin(u, cfg.overrun_band_max_m)
    over = has & known & ~((km - ua >= kf) & (km + ua <= kt_))
    possible = has & known & ~over & ~((lo_edge >= kf) & (hi_edge <= kt_))
    for typ, cond, out in (("overrun", over, alarms), ("overrun_possible", possible, notices)):
        for a, b in episodes(cond, tg, cfg.rearm_s):
            up = hi_edge[a] - kt_[a] >= kf[a] - lo_edge[a]
            beyond = np.where(up, km + ua - kt_, kf - km + ua)[a : b + 1]
            add(
                out,
                typ,
                tg[a],
                work_at(a),
                {
                    "end": "km_to_m" if up else "km_from_m",
                    "boundary_km_m": float(kt_[a] if up else kf[a]),
                    "uncertainty_m": float(u[a]),
                    "beyond_m": float(beyond[0]),
                    "max_beyond_m": float(np.nanmax(beyond)),
                    "since_fix_s": float(since[a]),
                    "until_t": round(float(tg[b]) + cfg.step_s, 2),
                },
            )
    # --- notices
    moving_up, moving_down = v >= cfg.min_speed_mps, v <= -cfg.min_speed_mps
    for end, cond, dist in (
        ("km_to_m", has & moving_up & (hi_edge <= kt_) & (kt_ - hi_edge <= cfg.notice_m), kt_ - km),
        ("km_from_m", has & moving_down & (lo_edge >= kf) & (lo_edge - kf <= cfg.notice_m), km - kf),
    ):
        for a, _b in episodes(cond, tg, 2 * cfg.rearm_s):
            add(
                notices,
                "approaching_end",
                tg[a],
                work_at(a),
                {
                    "end": end,
                    "boundary_km_m": float(kt_[a] if end == "km_to_m" else kf[a]),
                    "distance_m": float(dist[a]),
                    "uncertainty_m": float(u[a]),
                    "speed_mps": float(abs(v[a])),
                },
            )
    for a, b in episodes(known & (u > cfg.uncertain_notice_m), tg, cfg.rearm_s):
        add(
            notices,
            "position_uncertain",
            tg[a],
            work_at(a),
            {
                "uncertainty_m": float(u[a]),
                "since_fix_s": float(since[a]),
                "until_t": round(float(tg[b]) + cfg.step_s, 2),
            },
        )
    t_target = t_on + cfg.decision_target_s
    if t_off > t_target and not any(d.t <= t_target for d in decisions):
        undecided = {"after_on_rail_s": cfg.decision_target_s, "decided_at_t": decisions[0].t if decisions else None}
        add(notices, "track_undecided", t_target, gov.work_no if gov else None, undecided)
        lean = period.odds[0] if period.odds else None
        if (
            gov is not None
            and lean is not None
            and (lean.line_code, lean.track) != (gov.line_code, gov.track)
            and lean.llr > cfg.suspect_llr
        ):
            add(
                alarms,
                "wrong_track_suspected",
                t_target,
                gov.work_no,
                {
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
                },
            )
    for c in crossovers:
        add(notices, "crossover", c.t, work_at(int(np.clip(np.searchsorted(tg, c.t) - 1, 0, n - 1))), dict(c.detail))
    seg_end = [*seg_t[1:].tolist(), t_off]
    sections = [
        (float(a), float(b), p.work_no, p.km_from_m, p.km_to_m)
        for a, b, p in zip(seg_t.tolist(), seg_end, seg_p, strict=True)
        if p is not None
    ]
    timeline = Timeline(tg, km, u, ft[meas], fkm[meas], trusted[meas], sections)
    result = PeriodResult(t_on, t_off, line, gov.work_no if gov else None, decisions, crossovers, timeline, period.gps)
    return result, alarms, notices


def check_periods(
    periods: list[RailPeriod],
    possessions: list[Possession],
    start: datetime,
    gps_cfg: GpsConfig | None = None,
    cfg: PossessionConfig | None = None,
    *,
    run: str = "",
    run_id: str = "",
    tacho_note: dict[str, Any] | None = None,
) -> RunCheck:
    """Alarms and notices of a run given its on-rail periods (pure: no I/O); ``tacho_note``
    is :attr:`RunCheck.tacho` (default: used when a period carries one)."""
    gps_cfg = gps_cfg or GpsConfig()
    cfg = cfg or PossessionConfig()
    results, alarms, notices = [], [], []
    for p in periods:
        r, a, n = evaluate_period(p, possessions, start, gps_cfg, cfg)
        results.append(r)
        alarms += a
        notices += n
    alarms.sort(key=lambda a: (a.t, a.type))
    notices.sort(key=lambda a: (a.t, a.type))
    works = sorted({s[2] for r in results for s in r.timeline.sections} | {r.work_no for r in results if r.work_no})
    if tacho_note is None:
        used = any(p.tacho is not None for p in periods)
        tacho_note = {"used": used, "note": None if used else "no tacho stream"}
    return RunCheck(run, run_id, start, works, results, alarms, notices, tacho_note)


# ------------------------------------------------------------------------------ a run
def rail_periods(cab: pd.DataFrame | None, t_end: float, t_start: float = 0.0) -> list[tuple[float, float]]:
    """(t_on, t_off) of every PTO-on period; the whole run when there is no PTO value."""
    if cab is None or not len(cab) or "pto" not in cab.columns or cab["pto"].isna().all():
        return [(t_start, t_end)] if t_end > t_start else []
    c = cab[cab["t"].notna()].sort_values("t", kind="stable")
    t = c["t"].to_numpy(dtype=float)
    pto = c["pto"].astype("Float64").ffill().fillna(0).to_numpy(dtype=float) > 0.5
    out: list[tuple[float, float]] = []
    on_since: float | None = None
    for tt, p in zip(t, pto, strict=True):
        if p and on_since is None:
            on_since = float(tt)
        elif not p and on_since is not None:
            if tt > on_since:
                out.append((on_since, float(tt)))
            on_since = None
    if on_since is not None and t_end > on_since:
        out.append((on_since, t_end))
    return out


def parse_start_time(run: Run) -> datetime:
    """run.json ``start_time`` as an aware datetime (InputError otherwise: the run cannot be
    related to the plan)."""
    raw = run.field("start_time")
    path = run.folder / "run.json"
    if not raw:
        raise InputError("start_time is missing: the run cannot be related to the plan", path=path)
    try:
        start = datetime.fromisoformat(str(raw).strip())
    except ValueError as exc:
        raise InputError(f"start_time {raw!r} is not an ISO 8601 time", path=path) from exc
    if start.tzinfo is None:
        raise InputError(f"start_time {raw!r} has no UTC offset: the run cannot be related to the plan", path=path)
    return start


def _stream(run: Run, name: str) -> pd.DataFrame | None:
    frame = run.stream(name)
    if frame is None and run.has(name):
        bad = [f for f in run.stream_findings(name) if f.rule == "log.unreadable_stream"]
        raise InputError(bad[0].message if bad else "stream cannot be read", path=run.stream_file(name))
    return frame


def with_degraded_fixes(ga: GpsAnalysis, index: TrackIndex, gps_cfg: GpsConfig) -> GpsAnalysis:
    """Map-match the fixes the GPS analysis does not use (fix 1, high HDOP) so that they can
    serve as coarse km measurements; adds a ``degraded`` column. The up/down decision is untouched."""
    f = ga.fixes.copy()
    t = f["t"].to_numpy(dtype=float)
    lat, lon = f["lat"].to_numpy(dtype=float), f["lon"].to_numpy(dtype=float)
    usable = f["usable"].to_numpy(dtype=bool)
    inc = np.ones(t.size, dtype=bool)
    inc[1:] = t[1:] > t[:-1]
    deg = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(t) & (f["fix"].to_numpy() >= 1) & ~usable & inc
    f["degraded"] = deg
    if deg.any():
        both = usable | deg
        x, y = index.to_xy(np.where(both, lat, np.nan), np.where(both, lon, np.nan))
        _, rms = trust_filter(t, x, y, both, gps_cfg)
        for w, r in rms.items():
            col = f"rms_{w}"
            if col in f.columns:
                f.loc[deg, col] = r[deg]
        rows = np.flatnonzero(deg)
        m = index.match_xy(x[rows], y[rows], max_offset_m=gps_cfg.max_offset_m)
        m = m[m["best"].to_numpy()]
        at = rows[m["fix"].to_numpy()]
        f.loc[at, "km_m"] = m["km_m"].to_numpy()
        f.loc[at, "offset_m"] = m["offset_m"].to_numpy()
        f.loc[at, "line_code"] = m["line_code"].astype(str).to_numpy()
        f.loc[at, "track"] = m["track"].astype(str).to_numpy()
    return GpsAnalysis(f, ga.decisions, ga.crossovers)


def check_run(
    run: Run,
    network: Network,
    possessions: list[Possession],
    gps_cfg: GpsConfig | None = None,
    cfg: PossessionConfig | None = None,
) -> RunCheck:
    """Read a run's GPS, cab and (if any) tacho streams, analyse each on-rail period, apply the rules.

    Raises InputError when run.json, its start_time or a needed stream (gps, cab) cannot be
    read; an unreadable tacho is only a note (the km filter then uses the GPS alone).
    """
    gps_cfg = gps_cfg or GpsConfig()
    cfg = cfg or PossessionConfig()
    if run.meta is None:
        bad = [f for f in run.findings if f.severity == "error"]
        raise InputError(bad[0].message if bad else "run.json is invalid", path=run.folder / "run.json")
    start = parse_start_time(run)
    gps = _stream(run, "gps")
    cab = _stream(run, "cab")
    tacho = run.stream("tacho")
    unreadable = None
    if tacho is None and run.has("tacho"):
        bad = [f for f in run.stream_findings("tacho") if f.rule == "log.unreadable_stream"]
        unreadable = bad[0].message if bad else "the stream cannot be read"
    res = check_streams(
        gps,
        cab,
        start,
        network,
        possessions,
        gps_cfg,
        cfg,
        run=str(run.folder),
        run_id=run.run_id,
        tacho=tacho,
        wheel_diameter_m=run.field("wheel_diameter_m"),
        teeth=run.field("teeth"),
    )
    if unreadable is not None:
        res.tacho = _tacho_unused(unreadable)
    return res


def _tacho_unused(why: str) -> dict[str, Any]:
    """:attr:`RunCheck.tacho` of a tacho stream that could not serve."""
    return {"used": False, "note": f"tacho not used: {why}; km from GPS only"}


def check_streams(
    gps: pd.DataFrame | None,
    cab: pd.DataFrame | None,
    start: datetime,
    network: Network,
    possessions: list[Possession],
    gps_cfg: GpsConfig | None = None,
    cfg: PossessionConfig | None = None,
    *,
    run: str = "",
    run_id: str = "",
    tacho: pd.DataFrame | None = None,
    wheel_diameter_m: float | None = None,
    teeth: int | None = None,
) -> RunCheck:
    """:func:`check_run` on stream frames (``gps``, ``cab``, ``tacho`` as in ``schemas.logs``;
    ``wheel_diameter_m`` and ``teeth`` from run.json). Without a tacho, or with one
    :func:`tacho_problem` rejects, the km comes from the GPS alone (said in ``RunCheck.tacho``)."""
    gps_cfg = gps_cfg or GpsConfig()
    cfg = cfg or PossessionConfig()
    track: Tacho | None = None
    if tacho is None:
        note: dict[str, Any] = {"used": False, "note": "no tacho stream"}
    else:
        problem = tacho_problem(tacho, wheel_diameter_m, teeth, cfg)
        if problem is None:
            assert wheel_diameter_m is not None and teeth is not None
            track = tacho_track(tacho, float(wheel_diameter_m), int(teeth), cfg)
            note = {"used": True, "note": None}
        else:
            note = _tacho_unused(problem)
    if gps is not None:
        gps = gps[gps["t"].notna()].sort_values("t", kind="stable").reset_index(drop=True)
    if cab is not None:
        cab = cab[cab["t"].notna()].sort_values("t", kind="stable").reset_index(drop=True)
    present = [s for s in (gps, cab) if s is not None and len(s)]
    t_end = max((float(s["t"].iloc[-1]) for s in present), default=0.0)
    t_start = min((float(s["t"].iloc[0]) for s in present), default=0.0)
    spans = rail_periods(cab, t_end, t_start)
    cycles = build_cycles(tacho=None, imu=None, cab=cab, wheel_diameter_m=1.0, teeth=1, t_end=t_end)
    if cab is None or "pto" not in cab.columns or cab["pto"].isna().all():
        cycles.pto[:] = 1
    index = track_index_for(network)
    periods = []
    for t_on, t_off in spans:
        if gps is not None and len(gps):
            tt = gps["t"].to_numpy(dtype=float)
            sl = gps[(tt >= t_on - cfg.lead_s) & (tt <= t_off)].reset_index(drop=True)
        else:
            sl = None
        ga = analyse_gps(sl, network, gps_cfg, cycles, index=index)
        odds = track_odds(ga.fixes, index, gps_cfg, t_on, t_on + cfg.decision_target_s)
        periods.append(RailPeriod(t_on, t_off, with_degraded_fixes(ga, index, gps_cfg), track, odds))
    return check_periods(periods, possessions, start, gps_cfg, cfg, run=run, run_id=run_id, tacho_note=note)


@dataclass
class PossessionReport:
    """What ``trainpos possession check`` shows: every run's check and the plan's warnings."""

    checks: list[RunCheck]
    plan: Plan
    db: str

    @property
    def n_alarms(self) -> int:
        return sum(len(c.alarms) for c in self.checks)

    def to_json(self) -> dict[str, Any]:
        return checks_json(self.checks)


def check_files(
    run_dirs: list[Path], db_path: Path, plan_path: Path, config_path: Path | None = None
) -> PossessionReport:
    """Read the DB, the plan (FindingsError on plan errors) and every run, and check each run.

    InputError (exit 2) when the DB, the plan, the config or a run cannot be read.
    """
    from dbtools.database import read_network
    from fieldlogs.io import read_run
    from fieldlogs.possession.plan import load_plan

    gps_cfg, cfg = load_config(config_path)
    network = read_network(Path(db_path))
    plan = load_plan(Path(plan_path), network)
    runs = [read_run(Path(r)) for r in run_dirs]
    checks = [check_run(r, network, plan.possessions, gps_cfg, cfg) for r in runs]
    return PossessionReport(checks, plan, str(db_path))
