"""The correction start point i0 of a detection (SPEC §5.1, stage 3).

SPEC rule
    From the detection cycle minus ``lookback_s`` search backwards (at most
    ``SEARCH_SPAN_S``, never before the previous episode's end) for the last cycle at which
    the start-point condition (stage 2) held for ``hold_cycles``. If none is found the
    look-back point itself is used (``start_found`` False).

Residual detections
    Departure from the SPEC, for the second criterion only: a residual detection comes
    earlier after the onset than an eq. 1 one (0.4–1.3 s), so its look-back point is
    instead QUIET_MARGIN_S before the last cycle at which |r| was within QUIET_SHARE of the
    threshold (where the residual leaves its noise band), but never earlier than the SPEC
    look-back: as often before the onset as with the SPEC look-back, with shorter
    corrections and fewer fail-safes (bench/NOTES.md, "Odometry").

Ground-speed detections (criterion "radar")
    As residual detections, on e/thr of the ground-speed criterion (stage 2): QUIET_MARGIN_S
    before e last stayed within QUIET_SHARE of its threshold, never before the SPEC
    look-back. Starting early costs nothing there: the ground speed carries the
    correction, and before the onset it agrees with the adhering pulses.

Lobe rule (``criterion`` "residual-end")
    A slip shorter than the filter shows in r as two lobes of opposite sign (onset, then
    end) that cancel while both are in the window; when only the end lobe crosses the
    threshold, the look-back counts from the first cycle of the opposite lobe within H + M
    before (beyond half the threshold) and the kind is reversed — unless the detected lobe
    is more than LOBE_RATIO times the opposite one (one slip's lobes carry the same speed
    change; a far larger end lobe is a new, deep disturbance).

Lobe rule for eq. 1 (the kind only)
    Eq. 1 sees a disturbance as two lobes too: the wheel leaving the train's speed, then
    coming back to it, each of the sign of its acceleration against the body's — a slide's
    end lobe (the wheel re-accelerating to the train's speed) has a slip's sign. When the
    onset lobe opened no episode (it fell in the previous one's room or fail-safe watch) the
    end lobe is the first detection (network sample, route seed 2: a slide over 50.3–54.6 s,
    its onset inside a fail-safe watch, detected at its end lobe at 54.9 s and reported as a
    slip; bench/NOTES.md, "Slide label"). Such an onset is an end lobe, its kind reversed
    (:func:`ta_end_lobe`), when the latest cycle eq. 1 flagged within H + M before it had the
    opposite sign, that lobe follows none of the detected sign within H + M (else it is the
    end lobe of an earlier disturbance — the filters' echo of a corrected slide's end, route
    seed 67 — and the detection a new onset), and the detected lobe's peak over the next
    filter length is at most LOBE_RATIO times that lobe's. Its look-back stays the SPEC's: a
    start point inside the disturbance fails safe
    (:func:`fieldlogs.pipeline.odometry.episodes.start_trusted`).
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from fieldlogs.pipeline.config import OdometryConfig
from fieldlogs.pipeline.odometry.detection import Detections
from fieldlogs.pipeline.odometry.signals import BoolArray, IntArray
from fieldlogs.pipeline.odometry.streams import AlignedStreams
from fieldlogs.pipeline.types import DetectionCriterion, FloatArray
from schemas.units import kmh_s_to_mps2

#: How far before the look-back point the start-point search may go [s].
SEARCH_SPAN_S = 3.0
#: Residual detections: the look-back point is QUIET_MARGIN_S before the residual last
#: stayed within QUIET_SHARE of its threshold.
QUIET_SHARE = 0.25
QUIET_MARGIN_S = 1.0
#: The end lobe of a shallow slip is at most this many times its onset lobe (the same speed
#: change; the residual's echo of the onset adds to the end lobe) [–].
LOBE_RATIO = 4.0


def lookback_point(
    s: AlignedStreams, d: Detections, cfg: OdometryConfig, det: int, kind: DetectionCriterion
) -> tuple[DetectionCriterion, int]:
    """The criterion of the detection at ``det`` (an onset of ``kind``: "ta", "residual" or
    "radar") and its look-back point."""
    lookback = round(cfg.lookback_s / s.cyc)
    if kind == "ta":
        return "ta", det - lookback
    if kind == "radar" and d.ground_e is not None and d.ground_thr is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = d.ground_e / d.ground_thr
        return "radar", quiet_before(ratio, det, det - lookback, 1.0, s.cyc)
    thr = kmh_s_to_mps2(cfg.residual_threshold_kmh_s)
    crit, ref = lobe(d.residual, det, d.horizon, s.filters.M, thr)
    return crit, quiet_before(d.residual, ref, ref - lookback, thr, s.cyc)


def start_point(s: AlignedStreams, d: Detections, det: int, back: int, floor: int) -> tuple[int, bool]:
    """Start point i0 for the detection at ``det`` with look-back point ``back``: the last
    cycle ≤ ``back`` where the start-point condition held, within SEARCH_SPAN_S and not
    before ``floor``; and whether one was found."""
    lo = max(floor, back - round(SEARCH_SPAN_S / s.cyc))
    if back < lo:
        return max(min(det - 1, floor), 0), False
    j = int(d.last_hold[back])
    if j >= lo:
        return j, True
    return back, False


def lobe(
    res: FloatArray, det: int, horizon: int, m: int, thr: float
) -> tuple[Literal["residual", "residual-end"], int]:
    """Criterion of a residual detection at ``det`` and the cycle its look-back counts from.

    If the residual had the opposite sign (beyond half the threshold ``thr``) within the
    horizon + filter length ``m`` before ``det``, rising from its noise band there, and the
    detected lobe's peak over the next filter length is at most LOBE_RATIO times that
    lobe's, the look-back counts from the first cycle of that lobe and the kind is
    reversed (the kind and start point are settled a filter length after ``det``: the
    correction is retroactive anyway)."""
    lo = max(det - horizon - m, 0)
    with np.errstate(invalid="ignore"):
        opp = np.flatnonzero(np.sign(res[det]) * res[lo:det] < -0.5 * thr)
    if opp.size == 0:
        return "residual", det
    lobe_ = lo + _last_run(opp)
    first = int(lobe_[0])
    with np.errstate(invalid="ignore"):  # a lobe rises from the noise band, a drift does not
        rose = bool((np.abs(res[lo:first]) <= QUIET_SHARE * thr).any())
    if not _like_its_onset(res, det, lobe_, m):
        return "residual", det
    return ("residual-end", first) if rose else ("residual", det)


def ta_end_lobe(diff: FloatArray, ta_mask: BoolArray, det: int, horizon: int, m: int) -> bool:
    """The eq. 1 onset at ``det`` is the end lobe of a disturbance (module docstring, "Lobe
    rule for eq. 1"): the latest cycle ``ta_mask`` flags within the horizon + filter length
    ``m`` before it has the opposite sign of ``diff`` (K·a_x − K·A_p); that lobe — the
    flagged cycles since the last one of the detected sign — follows none of the detected
    sign within the same span, and the detected lobe is like it (:func:`_like_its_onset`).
    Its kind is then the opposite of its sign. A lobe is told by the sign, not by
    consecutive cycles: ``ta_mask`` may drop a cycle inside one (route seed 67)."""
    span, sgn = horizon + m, np.sign(diff[det])
    lo = max(det - span, 0)
    flagged = lo + np.flatnonzero(ta_mask[lo:det])
    if flagged.size == 0 or np.sign(diff[flagged[-1]]) != -sgn:
        return False  # nothing before it, or a lobe of its own sign: an onset
    own = flagged[np.sign(diff[flagged]) == sgn]
    opp = flagged[flagged > own[-1]] if own.size else flagged
    lo = max(int(opp[0]) - span, 0)
    before = lo + np.flatnonzero(ta_mask[lo : opp[0]])
    if (np.sign(diff[before]) == sgn).any():
        return False  # that lobe is itself the end of an earlier disturbance (route seed 67)
    return _like_its_onset(diff, det, opp, m)


def _last_run(idx: IntArray) -> IntArray:
    """The last run of consecutive values of the increasing ``idx``."""
    brk = np.flatnonzero(np.diff(idx) != 1)
    return idx[int(brk[-1]) + 1 :] if brk.size else idx


def _like_its_onset(sig: FloatArray, det: int, lobe_: IntArray, m: int) -> bool:
    """The lobe detected at ``det`` peaks over the next filter length ``m`` at most LOBE_RATIO
    times the opposite lobe on the cycles ``lobe_``: one disturbance's lobes carry the same
    speed change, a far larger end lobe is a new, deep disturbance (bench/NOTES.md, "Odometry")."""
    sgn = np.sign(sig[det])
    with np.errstate(invalid="ignore"):
        peak_opp = float(np.nanmax(-sgn * sig[lobe_]))
        peak_end = float(np.nanmax(sgn * sig[det : det + m]))
    return peak_end <= LOBE_RATIO * peak_opp


def quiet_before(res: FloatArray, ref: int, back: int, thr: float, cyc: float) -> int:
    """Look-back point of a residual detection: QUIET_MARGIN_S before the last cycle
    before ``ref`` at which |r| was within QUIET_SHARE of the threshold ``thr`` (the onset
    is where the residual leaves its noise band), but not before ``back``."""
    quiet = QUIET_SHARE * thr
    lo = max(back, 0)
    with np.errstate(invalid="ignore"):
        q = np.flatnonzero(np.abs(res[lo:ref]) <= quiet)
    if q.size == 0:
        return back
    return max(lo + int(q[-1]) - round(QUIET_MARGIN_S / cyc), back)
