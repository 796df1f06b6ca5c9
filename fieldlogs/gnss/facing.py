"""Which way the vehicle's F end faces on a given track, from its own GNSS fixes [S002].

The constrained solution puts the vehicle's *reference point* on the track: each antenna sits
``along_m`` ahead of it toward the F end (and ``lateral_m`` to its left), so the solution
needs the facing d (+1: the F end toward increasing km, −1: decreasing). With the track
given (``gnss position --line --track``) no pipeline decides it: the fixes' motion does.

Between consecutive epochs with an ``ok`` solution the reference point moves Δkm (the sign of
Δkm does not depend on the facing assumed: a facing error shifts every km by the same
2·along). The running direction r (+1: toward the F end) comes from the run's ``cab`` stream
(F → +1, R → −1, the last event at or before the step), else the F end is assumed to lead
(r = +1, said so). The vote of a step is sign(Δkm)·r weighted by |Δkm|; steps shorter than
3·√(σ₁² + σ₂²) are noise and left out. d = the sign of the votes' sum when the steps kept
cover at least ``MIN_TRAVEL_M`` and agree (|Σ votes| ≥ ``MIN_AGREEMENT``·Σ|Δkm|); otherwise —
a static receiver, a vehicle shunting back and forth without a cab stream — the facing is
**unknown** and stated so (``position_report`` then solves both facings, reports the mean km
and widens the stated bound by half their difference).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from schemas.enums import CabDirection

#: Travel the kept steps must cover before the motion decides the facing [m].
MIN_TRAVEL_M = 20.0
#: Share of that travel that must agree in direction.
MIN_AGREEMENT = 0.8


@dataclass(frozen=True)
class FacingDecision:
    """d = +1 / −1, or 0 when unknown; how it was decided; the travel that decided it."""

    direction: int
    source: str
    travel_m: float


def _running(t: np.ndarray, cab: pd.DataFrame | None) -> np.ndarray:
    """+1 (running toward the F end) or −1 at each t from the held ``cab`` events (+1 before the first)."""
    if cab is None or not len(cab):
        return np.ones(t.size)
    c = cab.dropna(subset=["t", "direction"]).sort_values("t", kind="stable")
    sign = np.where(c["direction"].to_numpy(str) == CabDirection.REVERSE.value, -1.0, 1.0)
    k = np.searchsorted(c["t"].to_numpy(float), t, side="right") - 1
    return np.where(k >= 0, sign[np.maximum(k, 0)], 1.0)


def facing_from_motion(best: pd.DataFrame, cab: pd.DataFrame | None) -> FacingDecision:
    """The facing from ``best`` (per epoch: ``t``, ``km_m``, ``sigma_m`` of an ok solution,
    solved with any facing) and the run's ``cab`` stream (module docstring)."""
    b = best.sort_values("t", kind="stable")
    t, km, sig = (b[c].to_numpy(float) for c in ("t", "km_m", "sigma_m"))
    dkm = np.diff(km)
    noise = 3.0 * np.hypot(sig[1:], sig[:-1])
    keep = np.isfinite(dkm) & (np.abs(dkm) > np.nan_to_num(noise, nan=np.inf))
    run_sign = _running(0.5 * (t[1:] + t[:-1]), cab)[keep]
    votes = np.sign(dkm[keep]) * run_sign * np.abs(dkm[keep])
    travel = float(np.abs(dkm[keep]).sum())
    how = (
        "the fixes' motion and the cab stream"
        if cab is not None and len(cab)
        else ("the fixes' motion, the F end assumed leading (no cab stream)")
    )
    if travel < MIN_TRAVEL_M or abs(float(votes.sum())) < MIN_AGREEMENT * travel:
        why = "static" if travel < MIN_TRAVEL_M else "motion both ways"
        return FacingDecision(0, f"unknown ({why}: {travel:.0f} m of travel)", travel)
    return FacingDecision(1 if votes.sum() > 0 else -1, how, travel)
