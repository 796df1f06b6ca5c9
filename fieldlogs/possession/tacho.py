"""What the km filter takes from a road-rail vehicle's tachometer, when the run has one.

GPS alone cannot tell a stopped vehicle from a slow one. A ``tacho`` stream (with run.json
``wheel_diameter_m``, ``teeth``; pulses → metres by :func:`fieldlogs.pipeline.cycles.build_cycles`,
k = π·D/teeth) is used while on rail only (on the road the rail wheels do not run), and only
what it surely says — it is an *unsigned* speed with an unknown scale error of a few % (a
road-rail odometer is not calibrated like a train's):

* **standstill** — no pulse for ``standstill_s`` (1 s) — is certain: from then to the next
  pulse the km filter *holds* (:mod:`fieldlogs.possession.kmfilter`);
* **moving** — once a second (:data:`TACHO_MEAS_S`), the speed by pulses, the second-order
  backward difference over w = :data:`TACHO_DIFF_S`::

      v(t) = (3·d(t) − 4·d(t − w) + d(t − 2w)) / 2w

  (causal and exact under constant acceleration, so braking does not make it lag), is a
  measurement of |dkm/dt|.

A tacho that fails :func:`tacho_problem` — the shared validator
:func:`fieldlogs.quality.tacho.review_tacho` (t not increasing; pulses missing, negative or
decreasing; no pulse at all; not ~10 Hz; an impossible speed; no wheel diameter or teeth) —
or cannot be read is not used at all: a false standstill would freeze the km of a moving
vehicle; the result says so and names the row (:func:`tacho_unused`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.masks import true_runs
from fieldlogs.pipeline.cycles import build_cycles
from fieldlogs.possession.config import PossessionConfig
from fieldlogs.quality.tacho import TachoLimits, review_tacho, unusable_reason

FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]

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
        out: FloatArray = np.where(k > 0, tq - before[kk] - inside, tq)
        return out

    def holding(self, tq: npt.ArrayLike) -> BoolArray:
        """Whether each ``tq`` lies in a standstill."""
        tq = np.asarray(tq, dtype=float)
        if not self.hold.size:
            return np.zeros(tq.shape, bool)
        k = np.searchsorted(self.hold[:, 0], tq, side="right") - 1
        inside: BoolArray = (k >= 0) & (tq < self.hold[np.clip(k, 0, None), 1])
        return inside


def tacho_problem(
    tacho: pd.DataFrame, wheel_diameter_m: float | None, teeth: int | None, cfg: PossessionConfig
) -> str | None:
    """Why a tacho stream cannot serve the km filter (None: it can): the first problem of
    :func:`fieldlogs.quality.tacho.review_tacho` other than a speed jump, with rows not ~10 Hz
    (median spacing over :data:`TACHO_GAP_S`) and a speed over twice ``max_speed_mps`` by pulses
    over :data:`TACHO_MEAS_S` (a wrong wheel diameter or teeth) counted as problems. Rows are
    file lines (the header is line 1)."""
    limits = TachoLimits(
        max_median_step_s=TACHO_GAP_S,
        max_speed_mps=2.0 * cfg.max_speed_mps,
        max_speed_label="twice max_speed_mps",
        speed_window_s=TACHO_MEAS_S,
    )
    return unusable_reason(review_tacho(tacho, wheel_diameter_m, teeth, limits))


def tacho_unused(why: str) -> dict[str, Any]:
    """:attr:`fieldlogs.possession.results.RunCheck.tacho` of a tacho stream that could not serve."""
    return {"used": False, "note": f"tacho not used: {why}; km from GPS only"}


def _standstills(t: FloatArray, still: BoolArray) -> FloatArray:
    """(k, 2) intervals of the rows flagged ``still``: from the first such row to the next row
    (when no gap follows), else one median step after the last."""
    n = t.size
    if not still.any():
        return np.array([], dtype=float).reshape(0, 2)
    a, b = true_runs(still)  # b: first row after each run (n at the end)
    dt_med = float(np.median(np.diff(t))) if n > 1 else 0.1
    bb = np.clip(b, 0, n - 1)
    joined = (b < n) & (t[bb] - t[np.clip(b - 1, 0, None)] <= TACHO_GAP_S)
    end = np.where(joined, t[bb], t[b - 1] + dt_med)
    return np.column_stack([t[a], end])


def tacho_track(tacho: pd.DataFrame, wheel_diameter_m: float, teeth: int, cfg: PossessionConfig) -> Tacho:
    """Standstills and 1 Hz speeds of a tacho stream that :func:`tacho_problem` accepts
    (pulses → metres by :func:`fieldlogs.pipeline.cycles.build_cycles`)."""
    c = build_cycles(tacho=tacho, imu=None, cab=None, wheel_diameter_m=wheel_diameter_m, teeth=teeth)
    t, d = c.t, c.d_pulse
    # contiguous stretches of rows: nothing is known across a gap
    seg0 = np.maximum.accumulate(np.where(np.r_[True, np.diff(t) > TACHO_GAP_S], t, -np.inf))
    pulse = np.r_[False, np.diff(d) > 0]
    last_pulse = np.maximum.accumulate(np.where(pulse, t, -np.inf))
    still = t - np.maximum(last_pulse, seg0) >= cfg.standstill_s - 1e-9
    hold = _standstills(t, still)
    w = TACHO_DIFF_S
    v = (3.0 * d - 4.0 * np.interp(t - w, t, d) + np.interp(t - 2 * w, t, d)) / (2.0 * w)
    sec = np.floor(t / TACHO_MEAS_S + 1e-9)
    first = np.r_[True, sec[1:] != sec[:-1]]
    use = first & ~still & (t - 2 * w >= seg0 - 1e-9)
    return Tacho(t[use], np.fmax(v[use], 0.0), hold)
