"""Feature-point (curve) unit: curves as virtual balises [S000 §3.2, §4.3.2; SPEC §5.3].

Curvature
    κ = (ωz − b) / v per cycle (v = corrected speed, unsigned; b the yaw-gyro bias, the mean
    of ωz over the latest standstill — ``yaw_bias_*`` of the config — 0 before the first
    standstill: uncorrected, b/v moves the lower-limit crossings of a train braking through a
    curve by tens of metres along the transition). The yaw rate keeps its sign when
    the vehicle runs reversed (the body turns the same way as the path), so κ is the
    curvature *in the travel direction*, positive turning left (SPEC §4.1). κ is smoothed
    with a centred moving average of ``n`` cycles (the odd number nearest to
    ``kappa_smoothing_s``). Centred, not trailing: a trailing average would delay the
    crossings by (n − 1)/2 cycles (≈ 9 m at 20 m/s); the unit evaluates a feature only
    ``search_margin_m`` after its exit, so it has the n/2 later samples (evaluation uses no
    sample after the evaluation cycle). κ of cycle i stands for the middle of the cycle,
    travel ``x_i = (d_{i−1} + d_i)/2`` (IMU cycle means and the backward-difference speed).

Feature table
    Six rows per curve [S000 Table 1], attributes as seen running in the track's normal
    direction (D/S: km increasing, U: decreasing). In travel coordinates ``u = σ·km``
    (σ = ±1 km per metre of travel = fix.k × cab) the rows met in travel order are 1…6
    when σ equals the track's normal direction, else 6…1 with left/right swapped (a left
    curve seen one way is a right curve seen the other way; the lower-limit crossings are
    the same points, only their roles swap). Below, r1…r6 are the rows in travel order.

Scheduling (``next_evaluation``)
    Search margin w = max(``search_margin_m``, fix uncertainty + ``search_growth_pct`` % of
    the travel since the fix + slip allowance accrued since the fix). The next feature is
    the nearest one whose correction point r4 is not behind the fix's reference point and
    whose exit-check end r6 is not yet passed by w; it is evaluated at the first cycle
    where the estimate has passed r6 by w (the train has then surely left the feature if
    the estimate is within its margin). Cab reversals are followed segment by segment. The
    estimate is read through the engine's windowed view (``km_between``), forward in chunks
    of doubling length, and evaluation reads only its search window: a feature costs the
    distance to it, not the length of the run.

Diagnostics (``evaluate``), each named in refusal events
    Window: cycles whose estimate lies in [r1 − w, r6 + w]. Runs of κ ≥ κ_lo or κ ≤ −κ_lo,
    κ_lo = (1 − tol)/R, same-sign runs closer than ``crossing_merge_m`` merged (noise
    chatter); the entry and exit crossings are interpolated linearly between samples. Of
    the runs wholly inside the window, the one whose estimated crossings lie closest to r3
    and r4 is the curve (either sign, so a mirrored DB attribute fails ``sign`` rather than
    finding nothing). With x_e, x_x the entry/exit crossings (travel) and h = n·v·Δt/2 the
    smoothing half-width:

    * ``start_point``: the window is complete (the log starts before it), a curve was found,
      the cab direction is constant and ωz present over the feature span
      [x_e − (r3 − r1) − h, x_x + (r6 − r4) + h], and that span ends before the evaluation
      cycle (no look-ahead);
    * ``entry_straight``: over x ∈ [x_e − (r3 − r1), x_e − (r3 − r2)] (the DB's entry
      straight, placed by the DB row spacing from the detected crossing) every |κ| ≤
      ``straight_kappa_max`` + the spread the smoothing gives the transition's start,
      min(s·q²/4h, κ_R·q/2h), q = max(0, h − distance to r2), s = κ_lo/(r3 − r2);
    * ``sign``: the run's sign equals the expected one (+ left);
    * ``upper_limit``: max |κ| in the run ≤ (1 + tol)/R;
    * ``length``: |(x_x − x_e) − |r4 − r3|| ≤ max(``length_tolerance``·|r4 − r3|,
      ``length_tolerance_min_m``);
    * ``exit_straight``: as the entry straight over [x_x + (r5 − r4), x_x + (r6 − r4)];
    * ``no_slip``: no cycle of the feature span has a slip/slide correction running;
    * ``min_speed``: v ≥ ``min_speed_kmh`` on every cycle of the feature span.

    A curve *without transitions* (r2 = r3 or r4 = r5, a plain arc between straights) is a
    step of κ from 0 to 1/R at the row: the centred average ramps it over w = n·v·Δt and its
    lower-limit crossing lies (½ − tol)·n cycles inside the curve (about 0.3·w). The step is
    placed back there (:meth:`FeatureUnit._ends`, exact for a step in the cycle means) and
    stands for the crossing in every diagnostic and as the correction point: the straights
    end at the step, where the smoothing spread q/(2h)/R is exactly the ramp's κ, and the
    length is measured step to step. An arc whose body is shorter than w at the window's
    highest speed is not judged (the ramps overlap; no event).

    The correction point is the exit crossing: ``i_ref`` = the cycle whose travel is
    nearest x_x (quantisation ≤ v·Δt/2, reported as ``ref_offset_m``), ``km_db`` = the km
    of r4 (DB row 4, or row 3 when running reversed); the solver's correction amount is
    then computed km − DB km at ``i_ref``. The correction's uncertainty is the larger of
    ``fix_uncertainty_m`` and ``crossing_z`` σ of the crossing, σ_x = σ_ω / (v·s) with s the
    κ slope of the DB exit transition (a κ error δ moves the crossing by δ/s), plus
    ``clock_budget_s``·v (an IMU clock offset L within the clock tolerance, not corrected,
    moves the crossing by L·v). Without an exit transition s is the smoothed step's ramp,
    1/(R·w): σ_x = σ_ω·R·n·Δt.

    ``detail`` of the outcome: direction (normal/reversed), attribute (in the travel
    direction), R_m, lower/upper_kappa, search_margin_m, db_length_m, length_m,
    length_tol_m, max_kappa, measured_sign, measured_radius_m (1 / median |κ| over the
    middle half of the body), entry/exit_straight_max_kappa, km_est_exit_m (estimate at the
    exit crossing), ref_offset_m, t_exit, min_speed_kmh, uncertainty_m, and ``reason`` when
    ``start_point`` failed. ωz and v are taken from the same cycle (no latency model).

One unit per run: it remembers which features it evaluated (so one is not evaluated twice
in the same direction without a cab reversal in between).
"""

from __future__ import annotations

import bisect
import itertools
import math
from collections.abc import Callable, Generator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from dbtools.masks import sign_runs
from dbtools.network import Network
from fieldlogs.pipeline.aid import drained
from fieldlogs.pipeline.aids.feature_table import Candidate, FeatureTable, line_feature_tables
from fieldlogs.pipeline.config import FeatureConfig
from fieldlogs.pipeline.cycles import Cycles, moving_average, standstill_mean
from fieldlogs.pipeline.types import FeatureOutcome, Fix, FloatArray, Odometry

#: Below this speed κ = ωz / v is not computed (NaN): the division only amplifies noise [m/s].
KAPPA_MIN_SPEED_MPS = 0.5
#: Cycles read in the first chunk of the scheduling scan (then doubling): ~4 min at 10 Hz.
SCAN_CHUNK = 2048
#: ``km_between(i0, i1)``: the estimate in force on cycles [i0, i1) (the engine's view).
KmBetween = Callable[[int, int], FloatArray]
#: Diagnostic names, in the order they are reported.
DIAGNOSTICS = (
    "start_point",
    "entry_straight",
    "sign",
    "upper_limit",
    "length",
    "exit_straight",
    "no_slip",
    "min_speed",
)


@dataclass(eq=False)
class FeatureUnit:
    """Curvature trace, feature tables, scheduling and diagnostics (module docstring)."""

    cycles: Cycles = field(repr=False)
    odo: Odometry = field(repr=False)
    network: Network = field(repr=False)
    cfg: FeatureConfig
    kappa: FloatArray = field(init=False, repr=False)
    """Smoothed κ per cycle [1/m], left positive in the travel direction (NaN: no data)."""
    yaw_bias: FloatArray = field(init=False, repr=False)
    """Yaw-rate bias subtracted from ωz per cycle (standstill mean, causal) [rad/s]."""
    tables: dict[tuple[str, str], FeatureTable] = field(init=False, repr=False)
    skipped: list[dict[str, Any]] = field(init=False, default_factory=list)
    """Features left out of the table (not six rows, no curve row, …) and why."""

    def __post_init__(self) -> None:
        c, o = self.cycles, self.odo
        n = c.n
        self._d = np.asarray(o.d, dtype=float)
        self._v = np.asarray(o.v, dtype=float)
        self._x = self._d - 0.5 * np.diff(self._d, prepend=self._d[0] if n else 0.0)
        dt = float(np.median(np.diff(c.t))) if n > 1 else 0.1
        self._dt = dt if dt > 0 else 0.1
        half = max(round(self.cfg.kappa_smoothing_s / self._dt / 2.0), 0)
        self.n_smooth = 2 * half + 1
        wz = c.imu.get("wz", np.full(n, np.nan)) if c.has_imu else np.full(n, np.nan)
        self._wz_ok = np.isfinite(wz)
        cfg = self.cfg
        self.yaw_bias, self._bias_known = standstill_mean(
            c.t, c.v_pulse, wz, cfg.yaw_bias_settle_s, cfg.yaw_bias_window_s, cfg.yaw_bias_min_s
        )
        wz = wz - self.yaw_bias
        with np.errstate(invalid="ignore", divide="ignore"):
            raw = np.where((self._v >= KAPPA_MIN_SPEED_MPS) & self._wz_ok, wz / self._v, np.nan)
        padded = np.concatenate([raw, np.full(half, np.nan)])
        self.kappa = moving_average(padded, self.n_smooth)[half:] if n else raw
        self._half_m = 0.5 * self.n_smooth * self._v * self._dt
        cab = np.asarray(c.motion, dtype=np.int64)
        self._cab = np.where(cab < 0, -1, 1)
        self._segment = np.concatenate([[0], np.cumsum(self._cab[1:] != self._cab[:-1])]) if n else np.zeros(0, int)
        self._changes = np.flatnonzero(self._cab[1:] != self._cab[:-1]) + 1
        self._change_list: list[int] = self._changes.tolist()
        self._allow = np.asarray(o.allowance, dtype=float)
        self.available = bool(n and c.has_imu and np.isfinite(self.kappa).any())
        self.tables, self.skipped = line_feature_tables(self.network)
        self._exits: dict[tuple[tuple[str, str], int], list[float]] = {}
        """u of row 6 per table and direction, ascending (:meth:`evaluation_not_before`, on first use)."""
        self._done: dict[tuple[str, str, str, int], int] = {}

    @property
    def dt(self) -> float:
        """The cycle time the κ smoothing counts in [s]."""
        return self._dt

    # -- scheduling ---------------------------------------------------------------------
    def margin(self, fix: Fix, idx: npt.ArrayLike) -> FloatArray:
        """Search margin w at cycles ``idx`` under ``fix`` [m]."""
        i = np.asarray(idx)
        grown = (
            fix.uncertainty_m
            + self.cfg.search_growth_pct / 100.0 * np.abs(self._d[i] - fix.d_ref)
            + np.maximum(self._allow[i] - fix.allowance_ref_m, 0.0)
        )
        return np.asarray(np.maximum(grown, self.cfg.search_margin_m), dtype=float)

    def next_evaluation(
        self, fix: Fix, after_i: int, km_between: KmBetween, table: FeatureTable | None = None, k: int | None = None
    ) -> tuple[int, Candidate] | None:
        """Cycle and candidate of the next feature ahead (module docstring), or None.
        ``km_between(i0, i1)`` is the estimate on cycles [i0, i1): the scan reads only as far
        ahead as the feature lies (:meth:`_first_passed`). ``table`` and ``k`` (position per
        metre of body-forward travel) default to the fix's line/track and its k; a track's
        own table with a candidate's pos as ``km_between`` and its kp runs the same scan
        along a network track (:mod:`fieldlogs.pipeline.aids.track_features`)."""
        return drained(self.evaluation_scan(fix, after_i, km_between, table, k))

    def evaluation_not_before(self, fix: Fix, after_i: int, km_between: KmBetween, slope: float) -> int:
        """A cycle :meth:`next_evaluation` of the fix's own line/track is not before (its run
        length n: it finds none), read from one estimate and the travel only. ``slope`` bounds the
        estimate's km per metre of travel (|Δkm| ≤ slope·|ΔS|; the fix's metric,
        :attr:`~fieldlogs.pipeline.metric.TrackMetric.max_slope`).

        A feature is evaluated where u − u₆ ≥ w ≥ ``search_margin_m`` (u = σ·km, the scan's
        condition), and only one not passed by the margin w₀ at ``after_i`` is looked for:
        u₆ > u₀ − w₀. Each metre of travel moves u by at most ``slope``, and S by at most the
        unsigned travel d, so no cycle of the first cab segment with
        d < d₀ + (min u₆ + search_margin_m − u₀)/slope − 1 m evaluates one (the metre covers
        rounding); a later segment's cycles are after its start."""
        n = self._d.size
        tab = (fix.line_code, fix.track)
        if not self.available or tab not in self.tables or not 0 <= after_i < n:
            return after_i
        changes = self._change_list
        j = bisect.bisect_right(changes, after_i)
        s1 = changes[j] if j < len(changes) else n
        sdir = int(fix.k * self._cab[after_i])
        u0 = sdir * float(km_between(after_i, after_i + 1)[0])
        if not math.isfinite(u0):
            return after_i
        d0, cfg = float(self._d[after_i]), self.cfg
        grown = fix.uncertainty_m + cfg.search_growth_pct / 100.0 * abs(d0 - fix.d_ref)
        w0 = max(grown + max(float(self._allow[after_i]) - fix.allowance_ref_m, 0.0), cfg.search_margin_m)
        exits = self._exits.get((tab, sdir))
        if exits is None:
            exits = self._exits[(tab, sdir)] = sorted(self.tables[tab].travel_rows(sdir)[0][:, 5].tolist())
        j = bisect.bisect_right(exits, u0 - w0 - 1.0)
        if j == len(exits):
            return s1
        reach = (exits[j] + cfg.search_margin_m - u0) / slope - 1.0
        if not reach > 0.0:
            return after_i
        return min(int(self._d.searchsorted(d0 + reach, side="left")), s1)

    def evaluation_scan(
        self,
        fix: Fix,
        after_i: int,
        km_between: KmBetween,
        table: FeatureTable | None = None,
        k: int | None = None,
        chunk: int = SCAN_CHUNK,
    ) -> Generator[int, None, tuple[int, Candidate] | None]:
        """:meth:`next_evaluation` as a resumable scan (:class:`~fieldlogs.pipeline.aid.Resume`):
        it yields each cycle it reaches with the feature not yet passed (the evaluation is not
        before it) and returns the result; its first chunk reads ``chunk`` cycles."""
        table = self.tables.get((fix.line_code, fix.track)) if table is None else table
        k = fix.k if k is None else k
        n = self._d.size
        if not self.available or table is None or not 0 <= after_i < n:
            return None
        i_ref = min(int(np.searchsorted(self._d, fix.d_ref, side="left")), n - 1)
        bounds = [after_i, *self._changes[self._changes > after_i].tolist(), n]
        for s0, s1 in itertools.pairwise(bounds):
            sdir = int(k * self._cab[s0])
            u_all, km_all, sign_all = table.travel_rows(sdir)
            seg_first = int(self._changes[self._changes <= s0][-1]) if (self._changes <= s0).any() else 0
            i_start = max(i_ref, seg_first)
            u_start = sdir * km_between(i_start, i_start + 1)[0]
            u_now = sdir * km_between(s0, s0 + 1)[0]
            w_now = float(self.margin(fix, s0))
            ok = (u_all[:, 3] > u_start) & (u_all[:, 5] + w_now > u_now)
            seg = int(self._segment[s0])
            for j in np.flatnonzero(ok)[np.argsort(u_all[ok, 5], kind="stable")]:
                fid = str(table.feature_id[j])
                if self._done.get((table.line_code, table.track, fid, sdir)) == seg:
                    continue
                i_eval = yield from self._first_passed(fix, sdir, float(u_all[j, 5]), (s0, s1, chunk), km_between)
                if i_eval is None:
                    break  # not reached in this segment; farther features neither
                cand = Candidate(
                    fid,
                    table.line_code,
                    table.track,
                    sdir,
                    sdir != table.normal,
                    u_all[j].copy(),
                    km_all[j].copy(),
                    float(table.radius_m[j]),
                    int(sign_all[j]),
                    float(self.margin(fix, i_eval)),
                    seg,
                )
                return i_eval, cand
        return None

    def _first_passed(
        self, fix: Fix, sdir: int, u6: float, span: tuple[int, int, int], km_between: KmBetween
    ) -> Generator[int, None, int | None]:
        """First cycle of [s0, s1) = ``span[:2]`` where the estimate u = sdir·km has passed ``u6``
        by the search margin, or None. Read in chunks of doubling length from ``s0`` (the first
        ``span[2]`` cycles), so the cost is in the distance to that cycle, not in the run's
        length; yields the first cycle of each chunk after the first."""
        s0, s1, step = span
        a = s0
        while a < s1:
            if a > s0:
                yield a
            b = min(a + step, s1)
            u = sdir * km_between(a, b)
            passed = np.flatnonzero(u - u6 >= self.margin(fix, np.arange(a, b)))
            if passed.size:
                return a + int(passed[0])
            a, step = b, 2 * step
        return None

    # -- diagnostics --------------------------------------------------------------------
    def evaluate(self, candidate: Candidate, fix: Fix, km_between: KmBetween, i_eval: int) -> FeatureOutcome:
        """Run the diagnostics of the module docstring on the κ trace up to ``i_eval``; the
        estimate is read over the search window only (``km_between`` as in
        :meth:`next_evaluation`)."""
        c, cfg = candidate, self.cfg
        self._done[(c.line_code, c.track, c.feature_id, c.sdir)] = c.segment
        k_lo, k_hi = (1.0 - cfg.tolerance) / c.radius_m, (1.0 + cfg.tolerance) / c.radius_m
        detail: dict[str, Any] = {
            "line_code": c.line_code,
            "track": c.track,
            "direction": "reversed" if c.reversed else "normal",
            "attribute": "left" if c.sign > 0 else "right",
            "R_m": c.radius_m,
            "lower_kappa": k_lo,
            "upper_kappa": k_hi,
            "search_margin_m": round(c.margin_m, 2),
            "db_length_m": round(float(c.u[3] - c.u[2]), 2),
        }
        failed: list[str] = []

        def out(i_ref: int | None = None) -> FeatureOutcome:
            order = [n for n in DIAGNOSTICS if n in failed]
            unc = self._crossing_uncertainty(i_ref, c, k_lo) if i_ref is not None else None
            if unc is not None:
                detail["uncertainty_m"] = round(unc, 2)
            return FeatureOutcome(
                not order, c.feature_id, c.line_code, c.track, i_ref, float(c.km[3]), order, detail, unc
            )

        window = self._window(c, km_between, i_eval)
        if window is None:
            detail["reason"] = "search window incomplete (log starts inside it or direction changed)"
            failed.append("start_point")
            return out()
        i_lo, i_a, i_hi, ue = window
        if self._arc_unjudged(c, i_a, i_hi, detail):
            failed.append("start_point")
            return out()
        best = self._curve(c, ue, i_lo, i_a, i_hi, k_lo)
        if best is None:
            detail["reason"] = "no curve (pair of lower-limit crossings) in the search window"
            failed.append("start_point")
            self._slip_speed(np.arange(i_a, i_hi + 1), failed, detail)
            return out()
        xe, xx, sgn = best
        pe, px = self._ends(c, xe, xx)
        ia, ib = self._span(c, pe, px)
        span = np.arange(ia, ib)
        i_ref = self._nearest_cycle(px)
        ue_ref = float(c.sdir * km_between(i_ref, i_ref + 1)[0])
        self._measure(c, ue_ref, (xe, xx), (pe, px), sgn, i_ref, detail)
        reasons = self._span_problems(ia, ib, i_hi)
        if reasons:
            detail["reason"] = "; ".join(reasons)
            failed.append("start_point")
        failed += self._shape_failures(c, pe, px, sgn, k_lo, k_hi, detail)
        self._slip_speed(span, failed, detail)
        return out(i_ref)

    def _window(self, c: Candidate, km_between: KmBetween, i_eval: int) -> tuple[int, int, int, FloatArray] | None:
        """First and last cycle of the search window: estimate in [r1 − w, r6 + w], causal
        (every smoothed sample complete before ``i_eval``); None when the window's start is
        not in the data (log starts inside it, or the direction changed). Returned with the
        first cycle read, ``i_lo``, and u = sdir·km on cycles [i_lo, i_eval]."""
        d, u, w = self._d, c.u, c.margin_m
        i_hi = i_eval - self.n_smooth // 2
        d_lo = d[i_eval] - max(c.sdir * km_between(i_eval, i_eval + 1)[0] - (u[0] - w), 0.0) - 20.0
        i_lo = int(np.searchsorted(d, d_lo, side="left"))
        ue = c.sdir * km_between(i_lo, i_eval + 1)
        before = np.flatnonzero(ue < u[0] - w)
        if before.size == 0 or i_hi <= i_lo + before[-1] + 2:
            return None
        return i_lo, i_lo + int(before[-1]) + 1, i_hi, ue

    def _curve(
        self, c: Candidate, ue: FloatArray, i_lo: int, i_a: int, i_hi: int, k_lo: float
    ) -> tuple[float, float, int] | None:
        """(entry crossing, exit crossing, sign) of the lower-limit run wholly inside the
        window whose estimated crossings lie closest to r3 and r4 (``ue[i − i_lo]`` is u at
        cycle i)."""
        d, x, kap, u = self._d, self._x, self.kappa, c.u
        best: tuple[float, float, float, int] | None = None
        for j0, j1, sgn in sign_runs(kap[i_a : i_hi + 1], x[i_a : i_hi + 1], k_lo, self.cfg.crossing_merge_m):
            if j0 < 1 or j1 > i_hi - i_a:
                continue  # a crossing outside the window
            xe = _cross(x, kap, i_a + j0 - 1, i_a + j0, k_lo, sgn)
            xx = _cross(x, kap, i_a + j1 - 1, i_a + j1, k_lo, sgn)
            ie = i_a + j0
            ui = ue[ie - i_lo]
            cost = abs(ui + (xe - d[ie]) - u[2]) + abs(ui + (xx - d[ie]) - u[3])
            if best is None or cost < best[0]:
                best = (cost, xe, xx, sgn)
        return None if best is None else best[1:]

    def _arc_unjudged(self, c: Candidate, i_a: int, i_hi: int, detail: dict[str, Any]) -> bool:
        """A curve with an end without transition whose body L = r4 − r3 is shorter than the
        smoothing length w = n·v·Δt at the highest speed of the window: the two ramps of the
        smoothed steps overlap, the body never reaches 1/R and the step model of
        :meth:`_ends` does not hold — not judged (``detail["not_judged"]``, with w as
        ``smoothing_m``). Curves with both transitions are never affected."""
        if not _steps(c.u) or i_hi < i_a:
            return False
        w = self.n_smooth * self._dt * float(np.nanmax(self._v[i_a : i_hi + 1]))
        detail["smoothing_m"] = round(w, 2)
        if float(c.u[3] - c.u[2]) >= w:
            return False
        detail["not_judged"] = True
        detail["reason"] = f"curve without transitions shorter than the κ smoothing ({w:.1f} m at the speed run)"
        return True

    def _ends(self, c: Candidate, xe: float, xx: float) -> tuple[float, float]:
        """Travel of the DB curve's entry and exit (rows r3, r4) from the lower-limit crossings
        x_e, x_x. With a transition the crossing is the row (a linear ramp stays linear under
        the centred average). Without one (r2 = r3 or r4 = r5) κ steps from 0 to 1/R at the
        row, and the raw κ of cycle j (its mean over the cycle, standing for x_j) is
        clip(j + ½ − s, 0, 1)/R for a step at fractional cycle s; the centred average of n
        cycles is then ((i − s)/n + ½)/R on the ramp, which reaches (1 − tol)/R at
        i = s + (½ − tol)·n. So the step lies (½ − tol)·n cycles before the entry crossing
        and after the exit crossing (about 0.3·w, 6 m at 20 m/s with 1 s smoothing), read
        back to travel through the cycles' own x (exact at any speed profile up to the
        variation of v within one cycle)."""
        cut = (0.5 - self.cfg.tolerance) * self.n_smooth
        pe = self._shift_cycles(xe, -cut) if c.u[2] <= c.u[1] else xe
        px = self._shift_cycles(xx, cut) if c.u[4] <= c.u[3] else xx
        return pe, px

    def _shift_cycles(self, x0: float, cycles: float) -> float:
        """Travel ``cycles`` (fractional) cycles from travel ``x0``, linear between cycles."""
        x = self._x
        j = int(np.clip(np.searchsorted(x, x0, side="right"), 1, x.size - 1))
        dx = float(x[j] - x[j - 1])
        s = (j - 1) + ((x0 - float(x[j - 1])) / dx if dx > 0 else 0.0) + cycles
        k = int(np.clip(np.floor(s), 0, x.size - 2))
        return float(x[k] + (s - k) * (x[k + 1] - x[k]))

    def _span(self, c: Candidate, xe: float, xx: float) -> tuple[int, int]:
        """Cycles [ia, ib) of the feature span [x_e − (r3 − r1) − h, x_x + (r6 − r4) + h]."""
        x, u = self._x, c.u
        span_lo, span_hi = xe - (u[2] - u[0]), xx + (u[5] - u[3])
        ia, ib = int(np.searchsorted(x, span_lo, side="left")), int(np.searchsorted(x, span_hi, side="right"))
        h_max = float(np.nanmax(self._half_m[ia:ib])) if ib > ia else 0.0
        ia = int(np.searchsorted(x, span_lo - h_max, side="left"))
        ib = int(np.searchsorted(x, span_hi + h_max, side="right"))
        return ia, ib

    def _nearest_cycle(self, xx: float) -> int:
        """The cycle whose travel is nearest the exit crossing (the correction point)."""
        d = self._d
        i_x = int(np.clip(np.searchsorted(d, xx), 1, d.size - 1))
        return i_x if abs(d[i_x] - xx) <= abs(d[i_x - 1] - xx) else i_x - 1

    def _measure(
        self,
        c: Candidate,
        ue_ref: float,
        crossings: tuple[float, float],
        ends: tuple[float, float],
        sgn: int,
        i_ref: int,
        detail: dict[str, Any],
    ) -> None:
        """What was measured of the curve (``detail``; ``ue_ref`` = u at ``i_ref``): the body
        between the ``crossings``, the length and the exit between the curve's ``ends``
        (:meth:`_ends`)."""
        d, x, cfg = self._d, self._x, self.cfg
        (xe, xx), (pe, px) = crossings, ends
        body = np.abs(self.kappa[int(np.searchsorted(x, xe)) : int(np.searchsorted(x, xx))])
        body = body[np.isfinite(body)]
        middle = body[body.size // 4 : body.size - body.size // 4]
        db_len = float(c.u[3] - c.u[2])
        detail.update(
            measured_radius_m=round(1.0 / float(np.median(middle)), 1) if middle.size else None,
            max_kappa=float(np.max(body)) if body.size else float("nan"),
            measured_sign=int(sgn),
            length_m=round(px - pe, 2),
            length_tol_m=round(max(cfg.length_tolerance * db_len, cfg.length_tolerance_min_m), 2),
            km_est_exit_m=round(float(c.sdir * (ue_ref - (d[i_ref] - px))), 2),
            ref_offset_m=round(float(d[i_ref] - px), 3),
            t_exit=float(self.cycles.t[i_ref]),
        )

    def _span_problems(self, ia: int, ib: int, i_hi: int) -> list[str]:
        """Why the feature span [ia, ib) cannot be judged (the ``start_point`` diagnostic)."""
        if ia <= 0 or ib > i_hi + 1:
            return ["feature span not inside the data available at the evaluation point"]
        reasons = []
        if not self._wz_ok[ia:ib].all():
            reasons.append("yaw rate missing in the feature span")
        if ib > ia and (self._cab[ia:ib] != self._cab[ia]).any():
            reasons.append("cab direction changed during the feature")
        return reasons

    def _shape_failures(
        self, c: Candidate, xe: float, xx: float, sgn: int, k_lo: float, k_hi: float, detail: dict[str, Any]
    ) -> list[str]:
        """entry_straight, sign, upper_limit, length, exit_straight (module docstring)."""
        u, R, cfg = c.u, c.radius_m, self.cfg
        db_len = float(u[3] - u[2])
        tol = max(cfg.length_tolerance * db_len, cfg.length_tolerance_min_m)
        ent = self._straight(
            xe - (u[2] - u[0]), xe - (u[2] - u[1]), xe - (u[2] - u[1]), k_lo / max(u[2] - u[1], 1e-9), R
        )
        ext = self._straight(
            xx + (u[4] - u[3]), xx + (u[5] - u[3]), xx + (u[4] - u[3]), k_lo / max(u[4] - u[3], 1e-9), R
        )
        detail["entry_straight_max_kappa"], detail["exit_straight_max_kappa"] = ent[1], ext[1]
        checks = (
            ("entry_straight", ent[0]),
            ("sign", sgn == c.sign),
            ("upper_limit", detail["max_kappa"] <= k_hi),
            ("length", abs((xx - xe) - db_len) <= tol),
            ("exit_straight", ext[0]),
        )
        return [name for name, ok in checks if not ok]

    def _crossing_uncertainty(self, i_ref: int, c: Candidate, k_lo: float) -> float:
        """Uncertainty of the exit crossing as a correction [m]: max(fix_uncertainty_m,
        crossing_z · σ_ω / (v · κ_lo / (r5 − r4))) + clock_budget_s · v (config docstrings:
        an IMU clock offset within the clock tolerance moves the crossing by up to that); no
        transition in the DB (r5 = r4): the smoothed step's ramp, slope s = 1/(R·w) with
        w = n·v·Δt, so σ_x = σ_ω·R·n·Δt; the step is a fixed (½ − tol)·n cycles from the
        crossing (:meth:`_ends`), so its place has the crossing's error."""
        cfg = self.cfg
        transition = float(c.u[4] - c.u[3])
        v = float(self._v[i_ref])
        clock_m = cfg.clock_budget_s * max(v, 0.0)
        if v <= 0.0:
            return cfg.fix_uncertainty_m + clock_m
        sigma = cfg.yaw_rate_sigma_rad_s
        if not self._bias_known[i_ref]:  # no standstill yet: the bias is unknown
            sigma = float(np.hypot(sigma, cfg.yaw_bias_sigma_rad_s))
        slope = k_lo / transition if transition > 0.0 else 1.0 / (c.radius_m * self.n_smooth * v * self._dt)
        return max(cfg.fix_uncertainty_m, cfg.crossing_z * sigma / (v * slope)) + clock_m

    def _straight(self, x0: float, x1: float, x_ts: float, slope: float, radius: float) -> tuple[bool, float | None]:
        """Is |κ| straight over travel [x0, x1]? (ok, max |κ|); the tolerance near the
        transition start ``x_ts`` grows by the smoothing spread of the transition. A DB
        straight of zero length passes; a missing sample fails."""
        if x1 - x0 <= 0.0:
            return True, None
        lo, hi = np.searchsorted(self._x, [x0, x1])
        k = self.kappa[lo:hi]
        if k.size == 0 or not np.isfinite(k).all():
            return False, None
        h = np.maximum(self._half_m[lo:hi], 1e-9)
        q = np.maximum(h - np.abs(self._x[lo:hi] - x_ts), 0.0)
        spread = np.minimum(slope * q * q / (4.0 * h), q / (2.0 * h) / radius)
        ak = np.abs(k)
        return bool((ak <= self.cfg.straight_kappa_max + spread).all()), float(ak.max())

    def _slip_speed(self, span: npt.NDArray[np.int_], failed: list[str], detail: dict[str, Any]) -> None:
        span = span[(span >= 0) & (span < self._d.size)]
        if span.size == 0:
            return
        if self.odo.slipping[span].any():
            failed.append("no_slip")
        v_min = float(self._v[span].min())
        detail["min_speed_kmh"] = round(v_min * 3.6, 2)
        if not v_min * 3.6 >= self.cfg.min_speed_kmh:
            failed.append("min_speed")


def _steps(u: FloatArray) -> bool:
    """Has the curve (rows r1…r6 in travel order) an end without transition (r2 = r3 or r4 = r5)?"""
    return bool(u[2] <= u[1] or u[4] <= u[3])


def _cross(x: FloatArray, k: FloatArray, i0: int, i1: int, level: float, sgn: int) -> float:
    """Travel where sgn·κ passes ``level`` between samples i0 and i1 (linear; x[i1] if unknown)."""
    a, b = sgn * k[i0], sgn * k[i1]
    if not (np.isfinite(a) and np.isfinite(b)) or a == b:
        return float(x[i1])
    f = float(np.clip((level - a) / (b - a), 0.0, 1.0))
    return float(x[i0] + f * (x[i1] - x[i0]))
