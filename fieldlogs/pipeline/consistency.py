"""What the balise corrections say about the wheel's scale and the balise clock (issue 15).

Between two consecutive balise fixes i → j on one line (no other absolute fix between) the
dead reckoning runs D_ij metres; the correction at j, turned along the travel
(a_j = (computed − DB km)·k·cab: + the estimate was ahead), is

    a_j = e·N_ij + L·(v_j − c_i·c_j·v_i) + ε_j,

e the wheel's scale error (pulses e over the declared wheel: a turned wheel, run.json not
updated) and L the balise clock's offset (+ late: a telegram stamped L after the reader
passed the balise sets the DB km where the train is already v·L beyond it, and the next
correction sees the difference of the two speeds). A constant L at a constant speed is
invisible in a_j (it cancels); the speed changes between balises — stations, speed limits —
show it, and what they cannot show is held by the balise latency budget in the fix's
uncertainty (``balise.latency_budget_s`` × speed). ε holds the fix uncertainties, the slip
corrections' residuals and the wear noise.

N_ij = (S_j − S_i)·c_j is the signed travel from i to j along the travel at j (c the cab, S
the signed travel the estimate reckons on): D_ij, unless the train turned back between the
two fixes. A shuttle out to a terminus and back past its last balise runs D_ij but moves
only N_ij along the line, and the scale's error is e·N_ij: 1.6 km out to the far end, 109.7 km
back and 0.1 km out again between two up-direction balises 1.8 h apart (no balise fix on the
way back), N = −108.0 km against D = 111.7 km, a = −293 m
on a wheel 0.27 % over; fitted on D, six such intervals among 762 read e = −0.23 % and a
balise clock 0.61 ± 0.04 s late on a clean 24 h run (issue 21). Likewise fix i's v_i·L lies
along the travel at i, so it cancels against fix j's only when the cabs c_i and c_j agree.

:func:`balise_evidence` fits (e, L) by weighted least squares over the run's intervals (at
least ``MIN_INTERVALS``; weights 1/(1 m² + ΔA²), ΔA the slip budget the interval accrued), with
their σ from the residuals (cov = s²·(XᵀWX)⁻¹); with fewer intervals, or no speed change
between the balises, e alone (L = 0). The pipeline
(:mod:`fieldlogs.pipeline.run`) then

* moves the telegrams' t back by L̂ when |L̂| > ``clock.balise_tolerance_s`` and σ_L + B_L is at
  most half of it or a tenth of |L̂| (``balise_clock`` event), replays the aids and fits again
  (the speeds are read at the stamped times, so a large offset is found in steps; ``BALISE_PASSES``);
* refuses the balises when |L̂| − 2σ_L − B_L > ``clock.balise_tolerance_s`` but L̂ is not
  determined (``balise_clock`` event; the run stays undetermined rather than wrongly determined);

B_L = Σ_j |∂L̂/∂a_j|·ΔA_j is the part of L̂ the slip budgets can make: a slip, which comes in
an acceleration (wheel fast: a_j > 0 where Δv_j > 0), and a slide, in braking (wheel slow:
a_j < 0 where Δv_j < 0), both leave a correction of the sign of Δv_j — what a late clock
leaves. The slip/slide correction [S000] keeps that error within ΔA_j (the margin's own term)
but not below it, and σ_L, from the residuals of a few intervals (two degrees of freedom at
``MIN_INTERVALS``), does not see it: one slide in the braking before a balise read
L̂ = 0.27 ± 0.06 s on a correction of −4.8 m within a budget of 25 m, and every balise of the
run was refused (tests/fieldlogs/pipeline/test_balise_clock_slips.py). A clock offset is
judged only beyond what the slip budgets explain; what they hide is the same as what a run
without speed changes hides, held by the latency budget in the fixes' uncertainty. Without
slips (ΔA = 0) B_L = 0.
* judges the clock only on a wheel that measures right (|ê| ≤ ``margin.scale_check_pct``;
  a larger scale is first divided out of the pulses and the run replayed,
  :mod:`fieldlogs.pipeline.wheelscale`);
* widens the margin's distance share when an interval shows a scale error r_j =
  (|a_j| − 2·u_fix − ΔA_j)/D_j (beyond its fixes' noise and its slip budget) above
  ``margin.scale_check_pct`` (or the fitted |ê| is): p = distance_pct + 100·max(max_j r_j,
  |ê| + 3σ_e) for the whole run (``wheel_scale`` event) — the worst stretch, not the fit,
  since inertial slip corrections run part of the distance on the true scale; it never
  shrinks below the configured share. The check looks at the whole recorded run (a replay),
  as an onboard unit's calibration from earlier runs would.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from fieldlogs.pipeline.aids.registry import RunContext, position_aids
from fieldlogs.pipeline.config import ClockConfig, PipelineConfig
from fieldlogs.pipeline.engine import Solution, run_aids
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.positions import positions_frame
from fieldlogs.pipeline.types import Event, Fix
from schemas.enums import EventType, FixSource

#: Fewest balise-to-balise intervals for a fit of (e, L).
MIN_INTERVALS = 4
#: Fewest intervals for the scale alone (L = 0) when (e, L) cannot be fitted.
MIN_SCALE_INTERVALS = 2
#: Replays with the telegrams' t moved back (the fit is repeated on each replay).
BALISE_PASSES = 3
#: A large offset known to this share is moved back too (the replay's fit then refines it).
RELATIVE_SIGMA = 0.1
#: Intervals shorter than this carry no scale evidence worth the fix noise [m].
MIN_INTERVAL_M = 100.0


@dataclass(frozen=True)
class Interval:
    """One balise-to-balise stretch of dead reckoning."""

    t0: float
    t1: float
    dist_m: float
    along_m: float
    """Correction at its end along the travel (+ the estimate was ahead) [m]."""
    dv_mps: float
    """Speed at its end − speed at its start turned along the end's travel, v_j − c_i·c_j·v_i
    (module docstring) [m/s]."""
    allowance_m: float = 0.0
    """Slip-correction error budget accrued over it (eq. 13, the margin's own term) [m]."""
    net_m: float | None = None
    """Signed travel from its start to its end along the end's travel, (S_j − S_i)·c_j: what
    the wheel's scale error accrues on (module docstring) [m]; None: ``dist_m`` (no turn back)."""

    @property
    def scale_base_m(self) -> float:
        """The metres the scale error e accrues on: ``net_m``, or ``dist_m`` without it."""
        return self.dist_m if self.net_m is None else self.net_m


@dataclass(frozen=True)
class BaliseEvidence:
    """The fit of the module docstring."""

    scale: float
    """e: pulses over the declared wheel (0.05 = 5 % too many metres)."""
    scale_sigma: float
    lag_s: float
    """L: + the balise clock late [s]."""
    lag_sigma_s: float
    n: int
    rms_m: float
    lag_slip_s: float = 0.0
    """B_L: the part of L̂ the intervals' slip budgets can make, Σ_j |∂L̂/∂a_j|·ΔA_j [s]."""
    params: int = 2
    """p: the parameters fitted, 2 (e and L), or 1 for the scale alone (L = 0, σ_L infinite)."""

    @property
    def residual_dof(self) -> int:
        """n − p: the fit's residual degrees of freedom."""
        return self.n - self.params

    @property
    def lag_doubt_s(self) -> float:
        """σ_L + B_L: how far L̂ may lie from the clock's offset (module docstring) [s]."""
        return self.lag_sigma_s + self.lag_slip_s


def balise_intervals(fixes: list[Fix], travel: Travel) -> list[Interval]:
    """The stretches between consecutive balise fixes on one line (module docstring): the
    estimate the earlier balise fix alone dead-reckons to the later one's reference point,
    whatever feature or GPS fixes came between, against the later fix's km."""
    out: list[Interval] = []
    prev: Fix | None = None
    for f in fixes:
        if f.source == FixSource.NONE:
            prev = None
            continue
        if f.source != FixSource.BALISE or f.carried or not np.isfinite(f.km_m):
            continue
        if prev is not None and prev.line_code == f.line_code and f.d_ref - prev.d_ref >= MIN_INTERVAL_M:
            i0, i1 = _cycle(travel, prev.reference_t), _cycle(travel, f.reference_t)
            amount = float(travel.km(prev, f.s_ref)) - f.km_m
            c0, c1 = float(travel.motion[i0]), float(travel.motion[i1])
            along = amount * prev.k * c1
            dv = float(travel.v[i1]) - c0 * c1 * float(travel.v[i0])
            budget = travel.allowance_at(f.reference_t) - travel.allowance_at(prev.reference_t)
            net = (f.s_ref - prev.s_ref) * c1
            out.append(Interval(prev.reference_t, f.reference_t, f.d_ref - prev.d_ref, along, dv, budget, net))
        prev = f
    return out


def _cycle(travel: Travel, t: float) -> int:
    return min(int(np.searchsorted(travel.t, t, side="left")), travel.n - 1)


def fit_evidence(intervals: list[Interval]) -> BaliseEvidence | None:
    """Least squares a = e·N + L·Δv over ``intervals`` (None below MIN_INTERVALS)."""
    if len(intervals) < MIN_SCALE_INTERVALS:
        return None
    w = np.sqrt([1.0 / (1.0 + iv.allowance_m**2) for iv in intervals])  # 1 m fix noise ⊕ slip budget
    x = np.array([[iv.scale_base_m, iv.dv_mps] for iv in intervals]) * w[:, None]
    y = np.array([iv.along_m for iv in intervals]) * w
    xtx = x.T @ x
    if len(y) < MIN_INTERVALS or abs(float(np.linalg.det(xtx))) < 1e-6 * float(np.trace(xtx)) ** 2:
        # too few intervals, or no speed change between the balises: the scale alone (L = 0)
        d = x[:, 0]
        e = float(d @ y) / float(d @ d)
        res = y - e * d
        s2 = float(res @ res) / (len(y) - 1) if len(y) > 1 else float("inf")
        rms = float(np.sqrt(np.mean(res**2)))
        return BaliseEvidence(e, float(np.sqrt(s2 / float(d @ d))), 0.0, float("inf"), len(y), rms, params=1)
    beta = np.linalg.solve(xtx, x.T @ y)
    gain = np.linalg.solve(xtx, x.T) * w  # ∂β/∂a_j: the weighted least squares is linear in a
    res = y - x @ beta
    cov = float(res @ res) / (len(y) - 2) * np.linalg.inv(xtx)
    slip = float(np.abs(gain[1]) @ np.array([iv.allowance_m for iv in intervals]))
    return BaliseEvidence(
        float(beta[0]),
        float(np.sqrt(cov[0, 0])),
        float(beta[1]),
        float(np.sqrt(cov[1, 1])),
        len(y),
        float(np.sqrt(np.mean(res**2))),
        slip,
    )


def balise_evidence(fixes: list[Fix], travel: Travel) -> BaliseEvidence | None:
    """:func:`fit_evidence` of the run's :func:`balise_intervals`."""
    return fit_evidence(balise_intervals(fixes, travel))


def scale_rate(intervals: list[Interval], fix_uncertainty_m: float, lag_s: float = 0.0) -> float:
    """The largest wheel scale error an interval shows beyond its fixes' noise and its slip
    budget: max_j (|a_j − L·Δv_j| − 2·u_fix − ΔA_j) / D_j (0 without intervals; never negative).
    Per metre of D_j, not of N_j: the margin's distance share it widens grows with the unsigned
    travel, which is what has to hold |a_j| on a stretch that turned back."""
    rates = [
        (abs(iv.along_m - lag_s * iv.dv_mps) - 2.0 * fix_uncertainty_m - iv.allowance_m) / iv.dist_m for iv in intervals
    ]
    return max([0.0, *rates])


def checked_solution(ctx: RunContext, travel: Travel, cfg: PipelineConfig) -> tuple[Solution, list[Event]]:
    """The engine's solution after the balise checks of the module docstring, and their events."""
    sol, events = _balise_clock_checked(ctx, travel, cfg)
    intervals = balise_intervals(sol.fixes, travel)
    ev = fit_evidence(intervals)
    rate = scale_rate(intervals, cfg.balise.fix_uncertainty_m)
    if ev is not None and 100.0 * abs(ev.scale) > cfg.margin.scale_check_pct:
        rate = max(rate, abs(ev.scale) + 3.0 * ev.scale_sigma)
    if 100.0 * rate > cfg.margin.scale_check_pct:
        margin = replace(cfg.margin, distance_pct=cfg.margin.distance_pct + 100.0 * rate)
        sol = replace(sol, positions=positions_frame(travel, sol.fixes, margin, ctx.geometry))
        detail = {
            "largest_interval_scale_pct": round(100.0 * rate, 3),
            "fitted_scale_pct": None if ev is None else round(100.0 * ev.scale, 3),
            "intervals": len(intervals),
            "distance_pct": round(margin.distance_pct, 3),
            "action": "margin's distance share widened",
            "message": (
                f"wheel scale {100.0 * rate:.2f} % off the declared wheel between balises (run.json "
                f"wheel_diameter_m or teeth?): the margin grows by {margin.distance_pct:.2f} % of the distance"
            ),
        }
        events.append(Event(0.0, EventType.WHEEL_SCALE, detail=detail))
    return sol, events


def clock_action(ev: BaliseEvidence, cfg: ClockConfig, shifted: float, last_pass: bool) -> str | None:
    """What the balise clock check does with the fit ``ev`` (module docstring): "shift" the
    telegrams back by L̂, "refuse" the balises, or None (the clock is within tolerance, or its
    offset is not beyond what the fit's noise and the slip budgets explain). ``shifted``: the
    offset already moved back; ``last_pass``: no more shifts."""
    tol = cfg.balise_tolerance_s
    if cfg.max_lag_s <= 0 or abs(ev.lag_s) <= tol:
        return None
    precise = ev.lag_doubt_s <= max(0.5 * tol, RELATIVE_SIGMA * abs(ev.lag_s))
    if not last_pass and precise and abs(shifted + ev.lag_s) <= cfg.max_lag_s:
        return "shift"
    if abs(ev.lag_s) - 2.0 * ev.lag_sigma_s - ev.lag_slip_s > tol:
        return "refuse"
    return None


def _balise_clock_checked(ctx: RunContext, travel: Travel, cfg: PipelineConfig) -> tuple[Solution, list[Event]]:
    """The solution with the balise clock moved back (or the balises refused) as the module
    docstring says; at most one ``balise_clock`` event (the offset as finally applied)."""
    sol = run_aids(travel, position_aids(ctx), cfg.margin, ctx.geometry)
    shifted = 0.0
    detail: dict[str, Any] | None = None
    for k in range(BALISE_PASSES + 1):  # the last pass only judges what the shifts left
        ev = balise_evidence(sol.fixes, travel)
        tel = ctx.streams.get("balise")
        if ev is None or tel is None or 100.0 * abs(ev.scale) > cfg.margin.scale_check_pct:
            break  # a clock is judged on a wheel that measures right: the scale check speaks
        what = clock_action(ev, cfg.clock, shifted, k == BALISE_PASSES)
        if what == "shift":
            shifted += ev.lag_s
            ctx = replace(ctx, streams={**ctx.streams, "balise": tel.assign(t=tel["t"] - ev.lag_s)})
            action = "telegrams' t moved back by the offset"
        elif what == "refuse":
            ctx = replace(ctx, streams={**ctx.streams, "balise": None})
            action = "balises refused (offset not determined)"
        else:
            break
        offset = shifted if shifted else ev.lag_s
        detail = {"stream": "balise", "offset_s": round(offset, 3), "sigma_s": round(ev.lag_sigma_s, 3)}
        detail |= {"slip_budget_s": round(ev.lag_slip_s, 3), "intervals": ev.n, "action": action}
        sol = run_aids(travel, position_aids(ctx), cfg.margin, ctx.geometry)
        if ctx.streams.get("balise") is None:
            break
    if detail is None:
        return sol, []
    way = "late" if detail["offset_s"] > 0 else "early"
    detail["message"] = (
        f"balise clock {abs(detail['offset_s']):.2f} s {way} (the corrections follow the speed at the "
        f"telegrams over {detail['intervals']} balise intervals): {detail['action']}"
    )
    return sol, [Event(0.0, EventType.BALISE_CLOCK, detail=detail)]
