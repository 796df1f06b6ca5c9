"""One validator of a tachometer stream (``t``, cumulative ``pulses``; run.json
``wheel_diameter_m``, ``teeth``), used by ``logs check`` and by ``possession check``.

:func:`review_tacho` returns every problem it finds as a :class:`TachoFinding` — what is wrong,
a one-line reason naming the first file line, and the rows — in a fixed order:

1. run.json ``wheel_diameter_m`` or ``teeth`` missing or not a positive number;
2. a column ``t`` or ``pulses`` missing; fewer than 2 rows (nothing else is checked then);
3. ``t`` missing, ``pulses`` missing or negative, ``t`` not strictly increasing (file order);
4. the count dropping (on the rows with t and pulses, in time order, repeated t dropped): a
   *reset* when it drops below :data:`RESET_FRACTION` of the previous count and stays below
   that count at the next row (the counter restarted near 0), else a *decrease* (a glitch);
5. no pulse at all; rows farther apart than a limit (not the declared 10 Hz stream); a speed
   over a window of about 1 s, Δpulses · k / Δt with k = π·D/teeth metres per pulse
   (:func:`schemas.units.metres_per_pulse`), above a limit (D or teeth wrong);
6. *speed jumps*: the pulse speed's change between consecutive rows, Δv / Δt, above
   ``max_accel_mps2`` plus the quantisation of two pulses per cycle (2·k / Δt²) — wheel slip,
   slide or a counter glitch.

Checks with a limit of None are not made. ``logs check`` turns 4 and 6 into findings (its
other checks cover the rest for every stream); the possession km filter refuses a stream with
any problem of 1–5 (:func:`unusable_reason`): a false standstill would freeze the km of a
moving vehicle, while a speed jump is what wheels do.

Rows are positional indexes into the frame; messages name file lines (header = line 1, see
:mod:`fieldlogs.runs.handle`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from enum import StrEnum
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from schemas.frames import FIRST_DATA_LINE
from schemas.logs import LOG_STREAMS
from schemas.units import metres_per_pulse
from schemas.vehicle import ANY_WHEEL_DIAMETER_M, TEETH_RANGE

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]

#: A pulse count dropping below this fraction of the previous one, and staying below that
#: previous count at the next sample, is a counter reset (the counter restarted near 0).
#: Other drops, including a single low sample that recovers, are glitches: reported, never
#: repaired.
RESET_FRACTION = 0.5
#: The declared rate of a tacho stream [Hz] (:data:`schemas.logs.LOG_STREAMS`).
TACHO_RATE_HZ = float(LOG_STREAMS["tacho"].rate_hz or 10.0)


def time_order(t: npt.NDArray[Any]) -> tuple[IntArray, FloatArray]:
    """(positional rows with a usable t in time order, their t), duplicates of t dropped."""
    pos = np.flatnonzero(~np.isnan(t))
    tv = t[pos]
    if len(tv) > 1 and (np.diff(tv) < 0).any():
        order = np.argsort(tv, kind="stable")
        pos, tv = pos[order], tv[order]
    if len(tv) > 1:
        keep = np.concatenate(([True], np.diff(tv) > 0))
        pos, tv = pos[keep], tv[keep]
    return pos, tv


def pulse_resets(p: npt.NDArray[Any]) -> tuple[IntArray, IntArray]:
    """Indices ``i`` (into ``p``, in time order, no NaN) where the count drops: (resets, other drops)."""
    drop = np.flatnonzero(np.diff(p) < 0) + 1
    nxt = np.minimum(drop + 1, len(p) - 1)
    stays_low = (drop == len(p) - 1) | (p[nxt] < p[drop - 1])
    is_reset = (p[drop] < RESET_FRACTION * p[drop - 1]) & stays_low
    return drop[is_reset], drop[~is_reset]


def cumulative_again(p: npt.NDArray[Any]) -> tuple[npt.NDArray[Any], IntArray]:
    """Pulses made cumulative across resets: each reset adds the count before it to all later rows.

    ``p`` in time order without NaN; returns (fixed counts, reset indices).
    """
    resets, _ = pulse_resets(p)
    offsets = np.zeros(len(p), dtype=p.dtype)
    offsets[resets] = p[resets - 1]
    return p + np.cumsum(offsets), resets


#: The count, in time order with its resets bridged, may stay below an earlier count at this
#: many rows at most (single glitches that recover): more, and the dead reckoning would stand
#: still for that long, or the stream is not one counter (rows shuffled before a reset).
MAX_ROWS_BELOW = 10
#: A count that steps back and stays back (two rows or more below an earlier count) freezes
#: the dead reckoning until it catches up, losing the step: more than this in all [m] is
#: refused (a single low row that recovers loses nothing).
MAX_LOST_M = 1.0
#: No rail vehicle runs faster than this by pulses over about 1 s [m/s]; faster after the
#: resets are bridged means a drop was bridged that was no reset (phantom distance).
MAX_COUNTER_SPEED_MPS = 120.0


def counter_problem(t: npt.NDArray[Any], p: npt.NDArray[Any], metres: float | None) -> str | None:
    """Why a tacho stream, as the pipeline uses it — sorted by ``t`` (repeated t dropped, first
    kept), resets bridged by :func:`cumulative_again` — is not the count of one wheel; None when
    it is. ``t``, ``p`` in file order; ``metres`` per pulse (None: the speed is not checked).

    1. a negative count (a counter counts up from 0);
    2. the bridged count below its running maximum c_max(i) = max_{j≤i} c(j) at more than
       :data:`MAX_ROWS_BELOW` rows;
    3. with ``metres`` = k: the steps back that last two rows or more, Σ (c_max(i) − c(i) +
       c(i+1) − c(i))·k at their first rows i (the depth of the step, which the dead
       reckoning d = k·c_max loses) above :data:`MAX_LOST_M`;
    4. with k: (c(i+w) − c(i))·k / (t(i+w) − t(i)) over w ≈ 1 s above
       :data:`MAX_COUNTER_SPEED_MPS`.
    """
    pos, tv = time_order(np.asarray(t, dtype=float))
    pv = np.asarray(p, dtype=float)[pos]
    ok = np.isfinite(pv)
    pos, tv, pv = pos[ok], tv[ok], pv[ok]
    if pv.size < 2:
        return None
    neg = np.flatnonzero(pv < 0)
    if neg.size:
        return f"pulses is negative at {neg.size} rows (first row {_line(pos[neg].min())}): a counter counts up from 0"
    c, resets = cumulative_again(pv)
    c_max = np.maximum.accumulate(c)
    below = np.flatnonzero(c < c_max)
    bridged = f" with {resets.size} counter reset(s) bridged" if resets.size else ""
    if below.size > MAX_ROWS_BELOW:
        return (
            f"pulses, in time order{bridged}, stay below an earlier count "
            f"at {below.size} rows (first row {_line(pos[below[0]])}): not one cumulative counter"
        )
    if metres is None or tv.size < 3:
        return None
    lost = _lost_steps(c, c_max, below) * metres
    if lost > MAX_LOST_M:
        return (
            f"pulses, in time order{bridged}, step back below an earlier count and stay back "
            f"(first row {_line(pos[below[0]])}): the dead reckoning would lose {lost:.3g} m"
        )
    w = max(round(1.0 / float(np.median(np.diff(tv)))), 1)
    if c.size <= w:
        return None
    speed = (c[w:] - c[:-w]) * metres / (tv[w:] - tv[:-w])
    k = int(np.argmax(speed))
    if speed[k] <= MAX_COUNTER_SPEED_MPS:
        return None
    after = f" after bridging {resets.size} counter reset(s)" if resets.size else ""
    return (
        f"{speed[k]:.4g} m/s by pulses{after} at row {_line(pos[k + w])}, over {MAX_COUNTER_SPEED_MPS:g} m/s: "
        "a drop that was no reset, or a count that jumps"
    )


def _lost_steps(c: FloatArray, c_max: FloatArray, below: IntArray) -> float:
    """Σ (c_max − c + the next row's count) at the first row of each run of two or more rows
    below ``c_max`` [pulses]."""
    if below.size < 2:
        return 0.0
    first = np.concatenate(([True], np.diff(below) > 1))
    last = np.concatenate((np.diff(below) > 1, [True]))
    starts = below[first & ~last]  # runs of one row (a glitch that recovers) lose nothing
    # the depth of the step, plus the row's own count that the step hid (the next row's)
    return float((c_max[starts] - c[starts] + np.maximum(c[starts + 1] - c[starts], 0.0)).sum())


class TachoIssue(StrEnum):
    """What :func:`review_tacho` can find (module docstring, in its order)."""

    WHEEL_DIAMETER = "wheel_diameter"
    TEETH = "teeth"
    NO_COLUMN = "no_column"
    TOO_SHORT = "too_short"
    T_MISSING = "t_missing"
    PULSES_MISSING = "pulses_missing"
    PULSES_NEGATIVE = "pulses_negative"
    T_NOT_INCREASING = "t_not_increasing"
    PULSE_RESET = "pulse_reset"
    PULSE_DECREASE = "pulse_decrease"
    NO_PULSE = "no_pulse"
    WRONG_RATE = "wrong_rate"
    IMPOSSIBLE_SPEED = "impossible_speed"
    SPEED_JUMP = "speed_jump"


#: Problems a stream may have and still be what the wheels did (wheel slip, slide).
WHEEL_EVENTS = frozenset({TachoIssue.SPEED_JUMP})


def _no_rows() -> IntArray:
    return np.zeros(0, dtype=np.int64)


@dataclass(frozen=True)
class TachoFinding:
    """One problem of a tacho stream."""

    issue: TachoIssue
    reason: str
    """One line: what is wrong, naming the first file line where it is."""
    rows: IntArray = field(default_factory=_no_rows)
    """Positional rows of the frame where it is (file line = row + FIRST_DATA_LINE), first first."""
    detail: Callable[[int], str] | None = None
    """Message of the k-th row, with its values (``logs check`` findings)."""
    value: Callable[[int], Any] | None = None
    """The offending value at the k-th row."""
    limit: Any = None


@dataclass(frozen=True)
class TachoLimits:
    """Limits of :func:`review_tacho` (None: that check is not made)."""

    max_accel_mps2: float | None = None
    """Pulse-speed change above this (plus the quantisation of two pulses) is a speed jump [m/s²]."""
    gap_s: float = 3.0 / TACHO_RATE_HZ
    """Rows farther apart than this give no speed for the speed-jump check [s]."""
    max_median_step_s: float | None = None
    """A median row spacing above this is not the declared 10 Hz stream [s]."""
    max_speed_mps: float | None = None
    """A speed by pulses (over ``speed_window_s``) above this is impossible [m/s] …"""
    max_speed_label: str = "max_speed_mps"
    """… and is called this in the reason."""
    speed_window_s: float = 1.0
    """Window of that speed [s]."""


def _line(row: int | np.integer[Any]) -> int:
    return int(row) + FIRST_DATA_LINE


def _wheel(wheel_diameter_m: float | None, teeth: int | None) -> Iterator[TachoFinding]:
    lo, hi = ANY_WHEEL_DIAMETER_M
    if wheel_diameter_m is None or not math.isfinite(wheel_diameter_m) or wheel_diameter_m <= 0:
        msg = f"run.json wheel_diameter_m {wheel_diameter_m!r} is not a positive number"
        yield TachoFinding(TachoIssue.WHEEL_DIAMETER, msg, value=lambda _k: wheel_diameter_m, limit=0)
    elif not lo <= wheel_diameter_m <= hi:
        msg = f"run.json wheel_diameter_m {wheel_diameter_m:.6g} m is not a rail wheel's ({lo:g}–{hi:g} m)"
        yield TachoFinding(TachoIssue.WHEEL_DIAMETER, msg, value=lambda _k: wheel_diameter_m, limit=[lo, hi])
    t_lo, t_hi = TEETH_RANGE
    if teeth is None or teeth <= 0:
        msg = f"run.json teeth {teeth!r} is not a positive number"
        yield TachoFinding(TachoIssue.TEETH, msg, value=lambda _k: teeth, limit=0)
    elif not t_lo <= teeth <= t_hi:
        msg = f"run.json teeth {teeth} is not {t_lo}–{t_hi} pulses per revolution"
        yield TachoFinding(TachoIssue.TEETH, msg, value=lambda _k: teeth, limit=[t_lo, t_hi])


def _values(t: FloatArray, p: FloatArray) -> Iterator[TachoFinding]:
    """Missing or negative values and t not increasing, in file order."""
    for issue, bad, what in (
        (TachoIssue.T_MISSING, ~np.isfinite(t), "t is missing"),
        (TachoIssue.PULSES_MISSING, ~np.isfinite(p), "pulses is missing"),
        (TachoIssue.PULSES_NEGATIVE, p < 0, "pulses is negative"),
    ):
        rows = np.flatnonzero(bad)
        if rows.size:
            yield TachoFinding(issue, f"{what} at row {_line(rows[0])}", rows)
    with np.errstate(invalid="ignore"):
        back = np.flatnonzero(np.diff(t) <= 0) + 1
    if back.size:
        yield TachoFinding(TachoIssue.T_NOT_INCREASING, f"t does not increase at row {_line(back[0])}", back)


def _drops(pos: IntArray, p: FloatArray) -> Iterator[TachoFinding]:
    """Resets and other decreases of the count (``p`` in time order, no NaN)."""
    resets, decs = pulse_resets(p)
    if resets.size:
        yield TachoFinding(
            TachoIssue.PULSE_RESET,
            f"pulses decrease (counter reset?) at row {_line(pos[resets[0]])}",
            pos[resets],
            lambda k: (
                f"pulse counter reset from {p[resets[k] - 1]:.0f} to {p[resets[k]]:.0f} "
                "(logs repair makes it cumulative again)"
            ),
            lambda k: int(p[resets[k]]),
        )
    if decs.size:
        yield TachoFinding(
            TachoIssue.PULSE_DECREASE,
            f"pulses decrease (counter reset?) at row {_line(pos[decs[0]])}",
            pos[decs],
            lambda k: f"pulse count decreases from {p[decs[k] - 1]:.0f} to {p[decs[k]]:.0f} (must never decrease)",
            lambda k: int(p[decs[k]]),
        )


def _rate_and_speed(tv: FloatArray, p: FloatArray, metres: float | None, limits: TachoLimits) -> Iterator[TachoFinding]:
    """No pulse at all, too slow a stream, an impossible speed (time order, no NaN)."""
    dt, dp = np.diff(tv), np.diff(p)
    if not (dp > 0).any():
        yield TachoFinding(TachoIssue.NO_PULSE, "no pulse at all (sensor or cable?)")
    if not dt.size:
        return
    step = float(np.median(dt))
    if limits.max_median_step_s is not None and step > limits.max_median_step_s:
        reason = f"rows {step:.2f} s apart, not a {TACHO_RATE_HZ:g} Hz stream"
        yield TachoFinding(TachoIssue.WRONG_RATE, reason, value=lambda _k: step, limit=limits.max_median_step_s)
    if limits.max_speed_mps is None or metres is None:
        return
    w = max(round(limits.speed_window_s / step), 1)
    fast = float(np.max((p[w:] - p[:-w]) * metres / (tv[w:] - tv[:-w]))) if p.size > w else 0.0
    if fast > limits.max_speed_mps:
        reason = f"{fast:.1f} m/s by pulses, over {limits.max_speed_label} (wheel_diameter_m or teeth wrong?)"
        yield TachoFinding(TachoIssue.IMPOSSIBLE_SPEED, reason, value=lambda _k: fast, limit=limits.max_speed_mps)


def _speed_jumps(
    pos: IntArray, tv: FloatArray, p: FloatArray, metres: float, limits: TachoLimits
) -> Iterator[TachoFinding]:
    """Pulse-speed changes above ``max_accel_mps2`` + 2·k/Δt² (time order, no NaN)."""
    if limits.max_accel_mps2 is None or len(pos) < 3:
        return
    nominal = 1.0 / TACHO_RATE_HZ
    dt, dp = np.diff(tv), np.diff(p)
    ok = (dp >= 0) & (dt <= limits.gap_s + 1e-9)
    v = np.where(ok, dp * metres / dt, np.nan)
    mid = 0.5 * (dt[1:] + dt[:-1])
    acc = np.diff(v) / mid
    limit = limits.max_accel_mps2 + 2.0 * metres / nominal**2
    with np.errstate(invalid="ignore"):
        jump = np.flatnonzero(np.abs(acc) > limit)
    if not jump.size:
        return
    # acc[j] is between v[j] and v[j+1], i.e. ending at sample j+2
    yield TachoFinding(
        TachoIssue.SPEED_JUMP,
        f"pulse-derived speed jumps at row {_line(pos[jump[0] + 2])}",
        pos[jump + 2],
        lambda k: (
            f"pulse-derived speed jumps from {v[jump[k]]:.2f} to {v[jump[k] + 1]:.2f} m/s "
            f"({acc[jump[k]]:+.1f} m/s², limit {limit:.1f}): wheel slip/slide or counter glitch"
        ),
        lambda k: float(acc[jump[k]]),
        limit,
    )


def review_tacho(
    frame: pd.DataFrame, wheel_diameter_m: float | None, teeth: int | None, limits: TachoLimits = TachoLimits()
) -> list[TachoFinding]:
    """Every problem of a tacho stream, in the order of the module docstring."""
    found = list(_wheel(wheel_diameter_m, teeth))
    missing = [c for c in ("t", "pulses") if c not in frame.columns]
    if missing:
        return [*found, TachoFinding(TachoIssue.NO_COLUMN, f"no column {', '.join(missing)}")]
    if len(frame) < 2:
        return [*found, TachoFinding(TachoIssue.TOO_SHORT, "fewer than 2 rows")]
    t_all = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    p_all = frame["pulses"].to_numpy(dtype=float, na_value=np.nan)
    found += _values(t_all, p_all)
    pos, tv = time_order(np.where(np.isnan(p_all), np.nan, t_all))
    p = p_all[pos]
    found += _drops(pos, p)
    wheel_ok = not any(f.issue in (TachoIssue.WHEEL_DIAMETER, TachoIssue.TEETH) for f in found)
    metres = metres_per_pulse(wheel_diameter_m, teeth) if wheel_ok and wheel_diameter_m and teeth else None
    found += _rate_and_speed(tv, p, metres, limits)
    if metres is not None:
        found += _speed_jumps(pos, tv, p, metres, limits)
    return found


#: Problems ranked as the km filter meets them; a reset and a decrease are one kind (the first row wins).
_RANK = {issue: i for i, issue in enumerate(TachoIssue)}
_RANK[TachoIssue.PULSE_DECREASE] = _RANK[TachoIssue.PULSE_RESET]


def unusable_reason(findings: list[TachoFinding]) -> str | None:
    """Why the stream cannot serve dead reckoning sample by sample: the reason of the first
    problem other than a wheel event (:data:`WHEEL_EVENTS`), None when there is none."""
    blocking = [f for f in findings if f.issue not in WHEEL_EVENTS]
    if not blocking:
        return None
    first = min(blocking, key=lambda f: (_RANK[f.issue], int(f.rows[0]) if f.rows.size else -1))
    return first.reason
