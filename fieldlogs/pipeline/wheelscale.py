"""The wheel's scale error the balise intervals show, divided out of the pulses (issue 15).

The balise check (:mod:`fieldlogs.pipeline.consistency`) fits a_j = e·D_ij + L·(v_j − v_i) and
judges the balise clock only on a wheel that measures right (|ê| ≤ ``margin.scale_check_pct``).
A wheel turned to a smaller diameter (run.json not updated) therefore left a late or early
balise clock unjudged: the margin's distance share was widened for the wheel, while the
clock's v·L at each balise went unseen. Here a fitted |ê| beyond ``margin.scale_check_pct``
and beyond ``SIGNIFICANCE``·σ_e divides the pulse distance and speed by
s = Π_k (1 + ê_k) — the declared wheel's metres per pulse times 1/s, as a corrected run.json
would give — and the odometry, the aids and the balise check are replayed on those pulses
(``margin.wheel_rescale``). Each replay fits again: the slip/slide corrections run part of
the distance on the inertial or ground speed, not the pulses, so one fit sees only part of
the scale (the fit's D counts every metre, the scale error only the pulse-driven ones); the
passes shrink what is left until |ê| ≤ ``margin.scale_check_pct``, and the last replay's
check judges the clock and widens the margin for whatever scale is still left, as on any run.

A pass stops (the last solution stands, with its checks) when the fit is missing, within the
check, not significant, has fewer than ``MIN_RESCALE_DOF`` residual degrees of freedom (σ_e of
one residual says nothing: two intervals whose slip budgets were 56 and 102 m, one holding a slide
the odometry could not correct, fitted −4.98 ± 1.13 % on a true wheel, which was divided out and
left 153 determined cycles beyond their margin — bench/NOTES.md, "Slip margin"; the check below
still widens the margin for such a fit), or would take |s − 1| beyond ``MAX_SCALE`` (a
mistyped diameter or teeth count is for run.json, not for this correction); after
``WHEEL_PASSES`` rescalings the last replay stands. A rescaled run says so in one
``wheel_scale`` event (``scale_pct`` = 100·(s − 1), the fits of each pass).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from fieldlogs.pipeline.aids.registry import RunContext
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.consistency import balise_evidence, checked_solution
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.engine import Solution
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.types import Event
from schemas.enums import EventType

#: Rescalings at most (each followed by a replay and a fit).
WHEEL_PASSES = 4
#: A fitted scale is divided out when |ê| ≥ this many σ_e (the replay's fit checks what is left).
SIGNIFICANCE = 3.0
#: Fewest residual degrees of freedom of a fit whose scale is divided out (module docstring).
MIN_RESCALE_DOF = 2
#: Largest scale divided out: |s − 1| (a 25 % error is a wrong run.json, not a turned wheel).
MAX_SCALE = 0.25


def scaled_cycles(cycles: Cycles, scale: float) -> Cycles:
    """``cycles`` with the pulse distance and speed divided by ``scale`` (the counts kept)."""
    return replace(cycles, d_pulse=cycles.d_pulse / scale, v_pulse=cycles.v_pulse / scale)


def wheel_corrected(
    ctx: RunContext, rescaled: Callable[[float], RunContext], cfg: PipelineConfig
) -> tuple[RunContext, float, Solution, list[Event]]:
    """The checked solution (:func:`~fieldlogs.pipeline.consistency.checked_solution`) after the
    rescalings of the module docstring: the context it ran on, the scale s divided out (1: none),
    the solution and its events. ``rescaled(s)``: the run's context on its pulses divided by s."""
    travel = Travel.of(ctx.cycles, ctx.odometry, ctx.network)
    sol, events = checked_solution(ctx, travel, cfg)
    scale = 1.0
    fits: list[float] = []
    for _ in range(WHEEL_PASSES if cfg.margin.wheel_rescale else 0):
        ev = balise_evidence(sol.fixes, travel)
        if ev is None or 100.0 * abs(ev.scale) <= cfg.margin.scale_check_pct or ev.residual_dof < MIN_RESCALE_DOF:
            break
        if not abs(ev.scale) >= SIGNIFICANCE * ev.scale_sigma or abs(scale * (1.0 + ev.scale) - 1.0) > MAX_SCALE:
            break
        scale *= 1.0 + ev.scale
        fits.append(round(100.0 * ev.scale, 3))
        ctx = rescaled(scale)
        travel = Travel.of(ctx.cycles, ctx.odometry, ctx.network)
        sol, events = checked_solution(ctx, travel, cfg)
    if not fits:
        return ctx, scale, sol, events
    pct = 100.0 * (scale - 1.0)
    detail = {
        "scale_pct": round(pct, 3),
        "pass_fits_pct": fits,
        "action": "pulse distance divided by the scale, aids replayed",
        "message": (
            f"wheel scale {pct:+.2f} % off the declared wheel between balises (run.json wheel_diameter_m "
            f"or teeth?): the pulse distance was divided by {scale:.4f} and the run replayed"
        ),
    }
    return ctx, scale, sol, [Event(0.0, EventType.WHEEL_SCALE, detail=detail), *events]
