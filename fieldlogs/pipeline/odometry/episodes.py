"""Stage 3: the episodes — start point, inertial correction, re-adhesion, speed update.

Each detection onset (stage 2), in time order, either opens an episode corrected from its
start point (:mod:`~fieldlogs.pipeline.odometry.start_point`, integrated by
:mod:`~fieldlogs.pipeline.odometry.integration`), or — too close to the previous one — is
its echo, its re-opening or part of its fail-safe. The loop is a fold: each step is a pure
function of the episodes so far and the onset.

Re-adhesion
    Departure from the SPEC (per-cycle pulse speed within β·t of the inertial speed and
    |a_x − A_p| ≤ Ta), which fails for shallow slips: |a_x − A_p| never exceeds Ta there,
    and a loose β·t lets a few tenths of a m/s of speed excess "re-adhere" while still
    slipping. Here: the first cycle after the detection at which the 1 s mean inertial
    speed and the 1 s mean pulse speed ``vp1`` have agreed within ``readhesion_tol_kmh`` +
    β·(t − t0) for ``readhesion_hold_s``. The 1 s means are quiet to ±0.03 m/s, so the
    tolerance can follow the inertial error: 0.1 m/s (quantisation, and wheel wear up to
    0.5 % of v0) + 0.15 km/h/s·t. Holding 1 s stands in for the acceleration condition (a
    crossing of the two speeds does not hold), without the 3.9 s filter's lag
    (measurements: bench/NOTES.md, "Odometry"). From there the distance continues on the
    pulses with a constant offset (continuous, never decreasing). A correction still
    running ``max_correction_s`` after i0 ends there as a *fail-safe* episode: the distance
    continues on the pulses and the solver makes the position uncertain. A correction
    whose data end first is *truncated*.

Re-opening and echoes
    A new start point needs ``lookback_s`` of room after the previous episode's end ie (after
    a fail-safe also a full filter window and the fail-safe watch, so that θ0 and v0 come
    from data of after the disturbance). A detection without that room is
    * after a re-adhesion, with the speeds agreeing ever since: the filters' echo of the
      slip's end — ignored (``echo_t``);
    * after a re-adhesion otherwise: proof that the re-adhesion was premature — the
      previous correction is re-opened and continues from its own start point;
    * after a fail-safe: no correction — the distance stays on the pulses (``redetect_t``).
      The position is made uncertain again there (``SlipEpisode.after_failsafe_t``,
      :mod:`fieldlogs.pipeline.aids.failsafe`): a balise group may have made it determined
      while the wheel slid on. Unless the fail-safe's own watch re-adhered after it, the
      detection gets a watch of its own (``rewatches``, allowance only), on an integration
      from its look-back point when that point adhered, the speeds' agreement counted only
      after the detection (before it they agree: the point precedes the onset; route seed
      107 left 15 cycles beyond their margin otherwise): the fail-safe's watch compares with
      an inertial speed integrated from a start 10–30 s back, which has drifted from any
      speed by then, and ends at its time limit with the wheel perhaps sliding on (network
      sample, route seed 2: a slide from 50.3 s, detected at 51.5 s inside the watch that
      ended at 51.8 s, 15 m under-counted; bench/NOTES.md, "Slip margin").
    A residual onset whose reference u(k − H) lies within the previous episode (or its
    fail-safe watch) is ignored: the residual then compares with slipping pulses. A
    correction lasts ≈ look-back 1–2 s + slip + 1.2 s, so slips longer than ≈ 7.5 s end as
    fail-safe.

Untrusted start (departure from S000, which corrects from the look-back point whatever it
holds)
    A start point that did not adhere — |θ̄| beyond arcsin(Ta/G) (``StartAttitude.clipped``),
    or none found and the look-back point flagged by eq. 1 or the residual — gives v0 and θ0
    of slipping pulses, an error ½·Δa·T² does not bound (route seed 2: a slide detected at
    its end lobe, v0 10.2 m/s against 15.4 true, θ̄ clipped at 35 ‰, 63 m taken off 136 m of
    travel against a 22.8 m budget, 29 cycles claimed on the wrong track). Such a correction
    fails safe at its start i0: no corrected cycle, the distance on the pulses, its watch
    from i0 (:func:`start_trusted`).

Re-adhesion speed update (``readhesion_speed_update``)
    Not in the papers. Once re-adhered the wheel measures the ground speed again, so the
    difference δ of the 1 s mean inertial and pulse speeds at ie is the inertial speed
    error accumulated since i0 (known to ±0.03 m/s: one pulse per second), and the
    correction, retroactive anyway, is closed on it: δ·(t − t0)/T is subtracted from the
    inertial speed (a ramp from 0 at i0, where the speed came from adhering pulses, to δ at
    ie, T = t_ie − t0), which changes the episode distance by −½·δ·T (exactly
    −δ·Σ_k (t_k − t0)·dt_k / T over the cycles of the correction). Why: the inertial errors
    grow with time, the episode distance with speed, so a long correction at low speed is
    off by a few per cent although its speed ends only 0.2–0.3 m/s off. A linear ramp is
    the conditional mean of the distance error given δ when the error is a constant
    acceleration error (θ0, accelerometer bias change: ½·δ·T); a residual gyro bias gives
    ⅓·δ·T, an angle random walk ⅜·δ·T, a v0 error δ·T: the ramp sits in the middle
    (measurements: bench/NOTES.md, "Odometry"). Bounded: by the re-adhesion condition
    |δ| ≤ ``readhesion_tol_kmh`` + β·T, so a re-adhesion declared on a still slightly
    slipping wheel moves the distance by at most (0.1 + 0.042·T)·T/2 m (2.6 m at 10 s,
    against eq. 13's 22.8 m, which stays the allowance). Scale: v0 and the pulse speed at
    ie both carry the wheel's diameter error (wear), so the update closes the correction in
    the pulses' scale, that of the rest of the odometry (the solver's correction
    percentage removes it); the inertial increments alone are in true scale. Fail-safe and
    truncated episodes (no re-adhesion) keep their speeds.

With a ground speed (the radar [S004], stage 1b)
    Departure from S000 (inertial bridging only): the correction's speed is the inertial
    solution fused with the ground speed by their variances (:mod:`.fusion`); the
    re-adhesion test compares the pulses with that speed (1 s means within
    ``ground.tolerance``, held ``readhesion_hold_s``) instead of with the drifting inertial
    one; and the correction fails safe only when its error budget (:mod:`.fusion`) reaches
    eq. 13's at ``max_correction_s``, or at ``ground_max_correction_s``: a radar-carried
    correction does not drift, so a slip far longer than 7.5 s re-adheres. The speed update
    is not used (the speed is measured, not integrated). Ground-speed onsets (stage 2) open
    episodes like eq. 1 onsets.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.detection import Detections
from fieldlogs.pipeline.odometry.fusion import Fusion, agreement, budget_path, fuse, ground_share, smooth
from fieldlogs.pipeline.odometry.ground import GroundSpeed
from fieldlogs.pipeline.odometry.integration import Integration, integrate
from fieldlogs.pipeline.odometry.signals import BoolArray, held, ma, readonly
from fieldlogs.pipeline.odometry.start_point import lookback_point, start_point, ta_end_lobe
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.odometry.watch import (
    Watch,
    hold_cycles,
    readhesion_tolerance,
    watch_failsafe,
    watch_fused,
)
from fieldlogs.pipeline.types import DetectionCriterion, FloatArray, SlipKind, slip_budget_m


@dataclass(frozen=True, eq=False)
class Episode:
    """One correction on the aligned cycles (index k ↔ output cycle k − delay)."""

    kind: SlipKind
    criterion: DetectionCriterion
    i_detect: int
    i_start: int
    """Start point i0."""
    i_end: int
    """Re-adhesion, fail-safe or last cycle ie."""
    i_settled: int
    """End of the disturbance: ie, or the end of the fail-safe watch."""
    start_found: bool
    readhered: bool
    failsafe: bool
    truncated: bool
    """The data ended before re-adhesion or fail-safe."""
    integration: Integration
    agree: BoolArray
    """The 1 s mean inertial and pulse speeds agree, cycles i0..i_lim."""
    v_in: FloatArray
    """Inertial speed on cycles i0..ie, after the speed update [m/s]."""
    theta_end: float
    """Pitch at ie [rad]."""
    end_speed_error: float
    """δ: 1 s mean inertial − pulse speed at re-adhesion (NaN when not re-adhered) [m/s]."""
    speed_update_m: float
    """Distance change by the re-adhesion speed update (0 when not applied) [m]."""
    watch: Watch | None
    """A fail-safe's watch (:mod:`.watch`), from ie: on the integration, with a ground speed on
    the filtered speed (None for the other episodes, and for all when ``failsafe_watch_s`` is 0)."""
    rewatches: tuple[Watch, ...] = ()
    """Watches of the detections after a fail-safe that no correction could follow, each on an
    integration from the detection's own look-back point (:func:`_rewatched`)."""
    start_trusted: bool = True
    """The start point adhered (:func:`start_trusted`); when not, the episode failed safe at
    i0 (always true with a ground speed, which carries the correction by its own measurement)."""
    redetect_t: tuple[float, ...] = ()
    """Detections inside the episode's room that re-opened it or fell in its fail-safe [s]."""
    echo_t: tuple[float, ...] = ()
    """Detections ignored as the filters' echo of the slip's end [s]."""
    fusion: Fusion | None = None
    """With a ground speed: the filtered speed over the integration (else None)."""
    budget: FloatArray | None = None
    """With a ground speed: the error budget B from i0 to each cycle up to ie [m]."""
    ground_share: float = 0.0
    """Share of the correction's cycles carried by a ground value."""


def find_episodes(
    s: AlignedStreams, d: Detections, cfg: OdometryConfig, ground: GroundSpeed | None = None
) -> tuple[Episode, ...]:
    """Stage 3: the episodes in time order (``ground``: corrections fused with it)."""
    found: tuple[Episode, ...] = ()
    pos = 0
    while (j := int(np.searchsorted(d.onsets, pos))) < d.onsets.size:
        found, pos = _step(s, d, cfg, ground, found, int(d.onsets[j]), _kind(d, j))
    return found


def _kind(d: Detections, j: int) -> DetectionCriterion:
    """Which criterion's onset the j-th onset is (the ground speed's first, then eq. 1)."""
    if d.is_ground_onset is not None and d.is_ground_onset[j]:
        return "radar"
    return "ta" if d.is_ta_onset[j] else "residual"


def _floor(s: AlignedStreams, prev: Episode | None) -> int:
    """Earliest start point after ``prev``: its end, after a fail-safe also a filter window
    and the watch."""
    if prev is None:
        return s.warm
    if prev.failsafe:
        return max(prev.i_end + s.filters.M, prev.i_settled + 1)
    return prev.i_end + 1


def _step(
    s: AlignedStreams,
    d: Detections,
    cfg: OdometryConfig,
    g: GroundSpeed | None,
    found: tuple[Episode, ...],
    det: int,
    kind: DetectionCriterion,
) -> tuple[tuple[Episode, ...], int]:
    """The episodes after the onset at ``det``, and the cycle from which to look for the next."""
    prev = found[-1] if found else None
    if prev is not None and kind == "residual" and det - d.horizon - s.filters.M <= prev.i_settled:
        return found, det + 1  # the residual's reference lies in the previous episode
    floor = _floor(s, prev)
    if prev is None or det - round(cfg.lookback_s / s.cyc) >= floor:
        crit, back = lookback_point(s, d, cfg, det, kind)
        i0, ok = start_point(s, d, det, back, floor)
        extend = 0.0 if g is None else cfg.ground_max_correction_s - cfg.max_correction_s + cfg.failsafe_watch_s
        ep = _correct(s, d, cfg, g, integrate(s, d, cfg, i0, extend), det, ok, det, crit)
        return (*found, ep), max(ep.i_end, det) + 1  # a fail-safe at its start ends before det
    t_det = float(s.t[det])
    if prev.readhered and _agrees(prev, det):
        # the filters' echo of the slip's end: the speeds still agree
        return (*found[:-1], replace(prev, echo_t=(*prev.echo_t, t_det))), det + 1
    redetect = (*prev.redetect_t, t_det)
    if prev.failsafe:
        return (*found[:-1], _rewatched(s, d, cfg, g, replace(prev, redetect_t=redetect), det, kind)), det + 1
    # premature re-adhesion: re-open the correction from its own start point
    again = _correct(s, d, cfg, g, prev.integration, prev.i_detect, prev.start_found, det, prev.criterion)
    return (*found[:-1], replace(again, redetect_t=redetect)), again.i_end + 1


def _rewatched(
    s: AlignedStreams,
    d: Detections,
    cfg: OdometryConfig,
    g: GroundSpeed | None,
    ep: Episode,
    det: int,
    kind: DetectionCriterion,
) -> Episode:
    """``ep`` (a fail-safe) with a watch of its own for the detection at ``det`` that no
    correction can follow (module docstring, "Re-opening and echoes"), unless ``ep``'s watch
    re-adhered after ``det`` (that watch then saw the disturbance out) or runs on a ground
    speed."""
    if g is not None or cfg.failsafe_watch_s <= 0:
        return ep
    own = ep.watch
    if own is not None and own.readhered and det <= own.end:
        return ep
    _, back = lookback_point(s, d, cfg, det, kind)
    i0 = max(back, ep.i_end, s.warm)
    ig = integrate(s, d, cfg, i0)
    if not start_trusted(d, ig, False):  # inside the disturbance: an earlier watch covers it
        return ep
    w = watch_failsafe(s, cfg, ig, i0, after=det)
    return ep if w is None else replace(ep, rewatches=(*ep.rewatches, w))


def _agrees(ep: Episode, det: int) -> bool:
    """Pulse and inertial speeds of ``ep`` still agree from its re-adhesion up to cycle
    ``det`` (False when det is past the integrated span)."""
    i0 = ep.i_start
    if det - i0 >= ep.agree.size:
        return False
    return bool(ep.agree[ep.i_end - i0 : det - i0 + 1].all())


def _correct(
    s: AlignedStreams,
    d: Detections,
    cfg: OdometryConfig,
    g: GroundSpeed | None,
    ig: Integration,
    det: int,
    start_found: bool,
    after: int,
    criterion: DetectionCriterion,
) -> Episode:
    """The episode detected at ``det`` corrected by ``ig`` (fused with ``g`` when given);
    re-adhesion is looked for after cycle ``after`` (later than ``det`` when a premature
    one was re-opened)."""
    if g is not None:
        return _correct_ground(s, d, cfg, g, ig, det, start_found, after, criterion)
    i0, i_lim = ig.i0, ig.i_lim
    m = i_lim - i0 + 1
    sl = slice(i0, i_lim + 1)
    tt = s.t[sl] - s.t[i0]
    lead = s.vp[max(i0 - s.filters.P + 1, 0) : i0]  # the 1 s mean starts on adhering pulses
    v1 = ma(np.concatenate([lead, ig.v_in[:m]]), s.filters.P)[lead.size :]
    with np.errstate(invalid="ignore"):
        agree = np.abs(v1 - s.vp1[sl]) <= readhesion_tolerance(cfg) + cfg.beta_mps2 * tt
    # a start point that did not adhere gives v0 and θ0 of slipping pulses, which eq. 13's
    # budget does not bound: the correction cannot be trusted and fails safe at its start
    trusted = start_trusted(d, ig, start_found)
    end = _end(s, cfg, ig, agree, after) if trusted else (i0, False, True)
    ie, readhered, failsafe = end
    m_end = ie - i0 + 1
    end_err = float(v1[m_end - 1] - s.vp1[ie]) if readhered else float("nan")
    v_in, update_m = _speed_update(s, cfg, i0, ie, ig.v_in[:m_end], end_err if readhered else float("nan"))
    w = watch_failsafe(s, cfg, ig, ie) if failsafe and cfg.failsafe_watch_s > 0 else None
    ep = _episode(s, d, ig, det, criterion, start_found, end, w, agree, v_in, end_err, update_m)
    return ep if trusted else replace(ep, start_trusted=False)


def start_trusted(d: Detections, ig: Integration, start_found: bool) -> bool:
    """The correction's start point i0 adhered: |θ̄| within arcsin(Ta/G) (``clipped``: more is
    no gradient but the pulses slipping), and i0 found by the start-point search or, the
    look-back point used instead, flagged by neither eq. 1 nor the residual."""
    if ig.start.clipped:
        return False
    return start_found or not (bool(d.ta_mask[ig.i0]) or bool(d.residual_mask[ig.i0]))


def _episode(
    s: AlignedStreams,
    d: Detections,
    ig: Integration,
    det: int,
    criterion: DetectionCriterion,
    start_found: bool,
    end: tuple[int, bool, bool],
    watch: Watch | None,
    agree: BoolArray,
    v_in: FloatArray,
    end_err: float,
    update_m: float,
    fusion: Fusion | None = None,
    budget: FloatArray | None = None,
) -> Episode:
    """The episode record; after a fail-safe it lasts (``i_settled``) while its watch
    finds the pulses still disagreeing."""
    ie, readhered, failsafe = end
    m_end = ie - ig.i0 + 1
    return Episode(
        kind=_disturbance(s, d, det, criterion),
        criterion=criterion,
        i_detect=det,
        i_start=ig.i0,
        i_end=ie,
        i_settled=ie if watch is None else max(ie, watch.end),
        start_found=start_found,
        readhered=readhered,
        failsafe=failsafe,
        truncated=not readhered and not failsafe,
        integration=ig,
        agree=readonly(agree),
        v_in=readonly(v_in),
        theta_end=float(ig.theta[m_end - 1]),
        end_speed_error=end_err,
        speed_update_m=update_m,
        watch=watch,
        fusion=fusion,
        budget=None if budget is None else readonly(budget[:m_end]),
        ground_share=0.0 if fusion is None else ground_share(fusion, m_end),
    )


def _end(
    s: AlignedStreams, cfg: OdometryConfig, ig: Integration, agree: BoolArray, after: int
) -> tuple[int, bool, bool]:
    """End ie of a correction: (re-adhesion after ``after``, True, False), else (the time
    limit, False, True) — a fail-safe —, else (the last cycle, False, False)."""
    i0 = ig.i0
    cond = held(agree, hold_cycles(cfg, s.cyc))
    cond[: max(after - i0 + 1, 0)] = False
    hit = np.flatnonzero(cond)
    if hit.size:
        return i0 + int(hit[0]), True, False
    if s.t[ig.i_lim] - s.t[i0] >= cfg.max_correction_s - 1e-9:
        return ig.i_lim, False, True
    return s.n - 1, False, False


def _speed_update(
    s: AlignedStreams, cfg: OdometryConfig, i0: int, ie: int, v_in: FloatArray, end_err: float
) -> tuple[FloatArray, float]:
    """The inertial speed on i0..ie with the ramp δ·(t − t0)/T removed, and the distance
    change; unchanged (and 0) when off, without re-adhesion (δ NaN) or for T = 0."""
    duration = float(s.t[ie] - s.t[i0])
    if not (cfg.readhesion_speed_update and duration > 0 and np.isfinite(end_err)):
        return v_in, 0.0
    ramp = end_err * (s.t[i0 : ie + 1] - s.t[i0]) / duration
    update_m = -float(np.dot(ramp[1:], s.dt[i0 + 1 : ie + 1]))
    return np.maximum(v_in - ramp, 0.0), update_m


def _disturbance(s: AlignedStreams, d: Detections, det: int, criterion: DetectionCriterion) -> SlipKind:
    """The kind of the disturbance detected at ``det``: by the sign of its signal there
    (:func:`_sense`), reversed at an end lobe — the residual's (criterion "residual-end") or
    eq. 1's (:func:`~.start_point.ta_end_lobe`)."""
    end = criterion == "residual-end" or (
        criterion == "ta" and ta_end_lobe(s.diff, d.ta_mask, det, d.horizon, s.filters.M)
    )
    return "slip" if (_sense(s, d, det, criterion) < 0) != end else "slide"


def _sense(s: AlignedStreams, d: Detections, det: int, criterion: DetectionCriterion) -> float:
    """Signed disturbance at detection, < 0 for a slip (travel frame; the ground speed's
    e = pulse − ground is > 0 for a slip)."""
    if criterion == "ta":
        return float(s.diff[det])
    if criterion == "radar" and d.ground_e is not None:
        return -float(d.ground_e[det])
    return float(d.residual[det])


def _correct_ground(
    s: AlignedStreams,
    d: Detections,
    cfg: OdometryConfig,
    g: GroundSpeed,
    ig: Integration,
    det: int,
    start_found: bool,
    after: int,
    criterion: DetectionCriterion,
) -> Episode:
    """``_correct`` with a ground speed: the fused speed, the re-adhesion test on it and the
    fail-safe on the error budget (:mod:`.fusion`)."""
    i0 = ig.i0
    f = fuse(s, g, cfg, ig)
    lead = s.vp[max(i0 - s.filters.P + 1, 0) : i0]
    a = agreement(s, cfg, f, lead)
    budget = budget_path(s, g, cfg, f, g.pulse_m)
    end = _end_ground(s, cfg, f, a.agree, budget, after)
    ie, readhered, failsafe = end
    m_end = ie - i0 + 1
    end_err = float(a.v1[m_end - 1] - s.vp1[ie]) if readhered else float("nan")
    w = watch_fused(s, cfg, f, ie) if failsafe and cfg.failsafe_watch_s > 0 else None
    return _episode(s, d, ig, det, criterion, start_found, end, w, a.agree, smooth(f, m_end), end_err, 0.0, f, budget)


def _end_ground(
    s: AlignedStreams, cfg: OdometryConfig, f: Fusion, agree: BoolArray, budget: FloatArray, after: int
) -> tuple[int, bool, bool]:
    """``_end`` with a ground speed: the limit is where the budget reaches eq. 13's at
    ``max_correction_s`` or the time ``ground_max_correction_s``."""
    i0 = f.i0
    t = s.t[i0 : i0 + f.size] - s.t[i0]
    b_max = slip_budget_m(cfg.max_correction_s, cfg.delta_a_mps2)
    over = np.flatnonzero((budget >= b_max - 1e-9) | (t >= cfg.ground_max_correction_s - 1e-9))
    lim = int(over[0]) if over.size else None
    cond = held(agree, hold_cycles(cfg, s.cyc))
    cond[: max(after - i0 + 1, 0)] = False
    if lim is not None:
        cond[lim + 1 :] = False
    hit = np.flatnonzero(cond)
    if hit.size:
        return i0 + int(hit[0]), True, False
    if lim is not None:
        return i0 + lim, False, True
    return s.n - 1, False, False
