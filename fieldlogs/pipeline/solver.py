"""The cycle loop: aids (balises, feature points, GPS, slip fail-safe) applied in time order.

Between two absolute fixes the position is pure dead reckoning on the corrected travel,
``km = km_fix + k·(S − S_fix)``, so the loop only has to visit the moments when an aid
has something to say: balise telegrams, GPS decisions, the fail-safe end of a slip
correction, and the evaluation point of the next feature point ahead (which depends on
the current estimate, hence the loop is sequential). Per-cycle positions and margins are
then evaluated vectorised from the list of fixes — the same numbers a per-cycle loop
would produce, without a Python step per 100 ms.
"""

from __future__ import annotations

import heapq
import itertools
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

import numpy as np
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.balise import BaliseUnit
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.cycles import Cycles
from fieldlogs.pipeline.metric import IDENTITY, TrackMetric, track_metric
from fieldlogs.pipeline.types import (
    Event,
    FeatureOutcome,
    Fix,
    FloatArray,
    GpsAnalysis,
    Odometry,
    TrackDecision,
)
from schemas.enums import PositionState

#: Order of simultaneous events: rail on/off and fail-safe first, then telegrams, GPS, features.
PRIO_RAIL, PRIO_FAILSAFE, PRIO_BALISE, PRIO_GPS, PRIO_FEATURE = -1, 0, 1, 2, 3
#: Sources of absolute fixes whose position is good enough to compute a correction % from.
ABSOLUTE_SOURCES = ("balise", "feature")


class FeatureAid(Protocol):
    """What the loop needs from the feature-point unit."""

    def next_evaluation(self, fix: Fix, after_i: int, km_est: FloatArray) -> tuple[int, Any] | None:
        """Cycle at which the next feature ahead can be evaluated under ``fix`` (and a
        candidate handle), or None when no feature lies ahead."""

    def evaluate(self, candidate: Any, fix: Fix, km_est: FloatArray, i_eval: int) -> FeatureOutcome:
        """Run the diagnostics on the κ trace around the candidate."""


@dataclass
class Solution:
    positions: pd.DataFrame
    events: list[Event]
    fixes: list[Fix] = field(default_factory=list)


def signed_travel(cycles: Cycles, odo: Odometry) -> FloatArray:
    """S = Σ cab·Δd: travel toward the vehicle's F end (+) or R end (−)."""
    dd = np.diff(odo.d, prepend=odo.d[0] if odo.d.size else 0.0)
    return np.cumsum(cycles.cab.astype(float) * dd)


def solve(
    cycles: Cycles,
    odo: Odometry,
    telegrams: pd.DataFrame | None,
    balise_unit: BaliseUnit,
    cfg: PipelineConfig,
    *,
    gps: GpsAnalysis | None = None,
    features: FeatureAid | None = None,
    network: Network | None = None,
) -> Solution:
    """Apply the aids in time order; with ``network``, dead reckoning runs along each
    track's own length (see :mod:`fieldlogs.pipeline.metric`)."""
    t = cycles.t
    d = odo.d
    s_trav = signed_travel(cycles, odo)
    heap: list[tuple[float, int, int, str, Any, int]] = []
    seq = itertools.count()

    def push(tt: float, prio: int, kind: str, payload: Any, version: int = -1) -> None:
        heapq.heappush(heap, (tt, prio, next(seq), kind, payload, version))

    if telegrams is not None:
        for row in telegrams.astype(object).where(telegrams.notna(), None).to_dict("records"):
            push(float(row["t"]), PRIO_BALISE, "balise", row)
    for ep in odo.episodes:
        if ep.failsafe:
            push(ep.t_end, PRIO_FAILSAFE, "failsafe", ep)
    # road-rail vehicles: a position only exists while on rail (PTO on); going off rail
    # forgets it, going on rail again starts undetermined
    pto_change = np.flatnonzero(np.diff(cycles.pto.astype(np.int8))) + 1
    for i in pto_change:
        push(float(t[i]), PRIO_RAIL, "on_rail" if cycles.pto[i] else "off_rail", None)
    if gps is not None:
        for dec in gps.decisions:
            push(dec.t, PRIO_GPS, "gps_decision", dec)
        for ev in gps.crossovers:
            push(ev.t, PRIO_GPS, "crossover", ev)

    events: list[Event] = []
    fixes: list[Fix] = []
    fix: Fix | None = None
    version = 0
    last_abs: Fix | None = None
    crossover_pending = False

    def at(tt: float) -> tuple[int, float, float]:
        """Cycle index at or after ``tt`` and travel d, S interpolated at ``tt``."""
        i = int(min(np.searchsorted(t, tt, side="left"), t.size - 1))
        return i, float(np.interp(tt, t, d)), float(np.interp(tt, t, s_trav))

    def allowance_at(tt: float) -> float:
        return float(np.interp(tt, t, odo.allowance))

    def metric(f: Fix) -> TrackMetric:
        return track_metric(network, f.line_code, f.track) if network is not None and f.line_code else IDENTITY

    def km_estimate(f: Fix) -> FloatArray:
        return km_along(f, s_trav, metric(f))

    def schedule_feature(after_i: int) -> None:
        if features is None or fix is None or fix.state != PositionState.DETERMINED:
            return
        nxt = features.next_evaluation(fix, after_i, km_estimate(fix))
        if nxt is not None:
            i_eval, cand = nxt
            push(float(t[i_eval]), PRIO_FEATURE, "feature", cand, version)

    def apply(new: Fix, ev: Event) -> None:
        """Make ``new`` the current fix; fill in the correction % of ``ev``."""
        nonlocal fix, version, last_abs
        if ev.correction_m is not None and last_abs is not None and last_abs.line_code == new.line_code:
            dist = new.d_ref - last_abs.d_ref
            if dist > 0:
                ev.correction_pct = abs(ev.correction_m) / dist * 100.0
                ev.detail["distance_since_correction_m"] = round(dist, 2)
        new.allowance_ref_m = (
            allowance_at(new.t_effective) if new.source != "feature" else float(np.interp(new.d_ref, d, odo.allowance))
        )
        fix = new
        fixes.append(new)
        version += 1
        if new.source in ABSOLUTE_SOURCES:
            last_abs = new

    if t.size:
        while heap:
            tt, _prio, _n, kind, payload, ver = heapq.heappop(heap)
            if tt > t[-1] + 1e-9:
                break
            i, d_now, s_now = at(tt)
            km_now = float(km_along(fix, s_now, metric(fix))) if fix is not None else None
            if kind in ("on_rail", "off_rail"):
                events.append(Event(tt, kind, km_now))
                if kind == "off_rail" and fix is not None:
                    fix = None
                    fixes.append(
                        Fix(
                            tt,
                            s_now,
                            d_now,
                            np.nan,
                            np.nan,
                            "",
                            "",
                            1,
                            "none",
                            np.nan,
                            state=PositionState.UNDETERMINED,
                        )
                    )
                    version += 1
                    last_abs = None
                continue
            if cycles.pto[i] == 0:
                continue  # off rail: telegrams, GPS decisions and features do not apply
            if kind == "balise":
                evs, new = balise_unit.on_telegram(payload, i, tt, d_now, s_now, int(cycles.cab[i]), fix, km_now)
                events.extend(evs)
                if new is not None and evs:
                    apply(new, evs[-1])
                    schedule_feature(i)
            elif kind == "failsafe":
                events.append(
                    Event(
                        tt,
                        "failsafe",
                        km_now,
                        detail={
                            "reason": "slip/slide correction exceeded the maximum correction time",
                            "t_start": payload.t_start,
                            "kind": payload.kind,
                        },
                    )
                )
                if fix is not None:
                    fix = replace(fix, t_effective=tt, state=PositionState.UNCERTAIN, uncertain_since_d=d_now)
                    fixes.append(fix)
                    version += 1
            elif kind == "feature":
                if ver != version or fix is None:
                    continue  # the fix changed since this evaluation was scheduled
                out = features.evaluate(payload, fix, km_estimate(fix), i) if features else None
                if out is None:
                    continue
                if out.accepted and out.i_ref is not None and out.km_db is not None:
                    s_ref, d_ref = float(s_trav[out.i_ref]), float(d[out.i_ref])
                    km_comp = float(km_along(fix, s_ref, metric(fix)))
                    ev = Event(
                        tt,
                        "feature_correction",
                        out.km_db,
                        km_comp - out.km_db,
                        detail={"feature_id": out.feature_id, **out.detail},
                    )
                    events.append(ev)
                    new = Fix(
                        tt,
                        s_ref,
                        d_ref,
                        out.km_db,
                        out.km_db + (fix.km_equipment_m - fix.km_m),
                        fix.line_code,
                        fix.track,
                        fix.k,
                        "feature",
                        max(out.uncertainty_m or 0.0, cfg.feature.fix_uncertainty_m),
                    )
                    apply(new, ev)
                else:
                    events.append(
                        Event(
                            tt,
                            "feature_refused",
                            km_now,
                            detail={"feature_id": out.feature_id, "failed": out.failed, **out.detail},
                        )
                    )
                schedule_feature(i)
            elif kind == "crossover":
                events.append(payload)
                crossover_pending = True
            elif kind == "gps_decision":
                dec = payload
                if fix is None:
                    if cfg.gps.allow_initial and dec.km_dir != 0:
                        k = dec.km_dir * int(cycles.cab[i])
                        ev = Event(
                            tt,
                            "initial_position_gps",
                            dec.km_m,
                            detail={"line_code": dec.line_code, "track": dec.track, **dec.evidence},
                        )
                        events.append(ev)
                        apply(
                            Fix(
                                tt,
                                s_now,
                                d_now,
                                dec.km_m,
                                dec.km_m,
                                dec.line_code,
                                dec.track,
                                k,
                                "gps",
                                cfg.gps.initial_uncertainty_m,
                            ),
                            ev,
                        )
                        schedule_feature(i)
                    else:
                        events.append(
                            Event(
                                tt,
                                "track_decision",
                                dec.km_m,
                                detail={"line_code": dec.line_code, "track": dec.track, **dec.evidence},
                            )
                        )
                        later = _direction_evidence(gps, dec, cfg.gps.km_dir_min_m) if cfg.gps.allow_initial else None
                        if later is not None:  # standing at the decision: initialise once it moves
                            push(later.t, PRIO_GPS, "gps_decision", later)
                elif dec.line_code == fix.line_code and dec.track != fix.track:
                    if crossover_pending:
                        # A balise-given track is only overruled by GPS in a fail-safe way:
                        # the new track is shown but the position is uncertain until the
                        # next initial pair confirms it (a false crossover must never
                        # produce a determined wrong track).
                        confirmed_by_gps_only = fix.source == "gps"
                        events.append(
                            Event(
                                tt,
                                "track_change",
                                km_now,
                                detail={
                                    "from": fix.track,
                                    "to": dec.track,
                                    "confirmed": confirmed_by_gps_only,
                                    **dec.evidence,
                                },
                            )
                        )
                        fix = replace(fix, t_effective=tt, track=dec.track)
                        if not confirmed_by_gps_only:
                            fix = replace(fix, state=PositionState.UNCERTAIN, uncertain_since_d=d_now)
                        fixes.append(fix)
                        version += 1
                        crossover_pending = False
                        schedule_feature(i)
                    else:
                        events.append(
                            Event(
                                tt,
                                "gps_track_disagrees",
                                km_now,
                                detail={"track": fix.track, "gps_track": dec.track, **dec.evidence},
                            )
                        )
                else:
                    events.append(
                        Event(
                            tt,
                            "track_decision",
                            km_now,
                            detail={"line_code": dec.line_code, "track": dec.track, "agrees": True, **dec.evidence},
                        )
                    )
                    crossover_pending = False

    positions = _positions(cycles, odo, s_trav, fixes, cfg, metric)
    events.sort(key=lambda e: e.t)
    return Solution(positions, events, fixes)


def _direction_evidence(gps: GpsAnalysis | None, dec: TrackDecision, min_km_m: float) -> TrackDecision | None:
    """After a decision taken while standing (no km direction), the first later trusted fix
    on the decided track whose km differs from the decision's by ``min_km_m``: the decision
    again, at that time and km, with the direction the km moved in."""
    if gps is None or gps.fixes is None or len(gps.fixes) == 0:
        return None
    f = gps.fixes
    track_col = "decided_track" if "decided_track" in f.columns else "track"
    ok = (f["t"].to_numpy(dtype=float) > dec.t) & f["trusted"].to_numpy(dtype=bool)
    ok &= (f[track_col].astype("string").fillna("") == dec.track).to_numpy(dtype=bool)
    km = f["km_m"].to_numpy(dtype=float, na_value=np.nan)
    moved = ok & np.isfinite(km) & (np.abs(km - dec.km_m) >= min_km_m)
    if not moved.any():
        return None
    j = int(np.argmax(moved))
    return replace(
        dec,
        t=float(f["t"].iloc[j]),
        km_m=float(km[j]),
        km_dir=1 if km[j] > dec.km_m else -1,
        evidence={**dec.evidence, "direction_from_t": dec.t},
    )


def km_along(fix: Fix, s: FloatArray | float, m: TrackMetric) -> FloatArray:
    """Dead reckoning from ``fix``: travel S − S_ref along the track's own length, as km."""
    return m.km_of_c(m.c_of_km(fix.km_m) + fix.k * (np.asarray(s, dtype=float) - fix.s_ref))


def _positions(
    cycles: Cycles,
    odo: Odometry,
    s_trav: FloatArray,
    fixes: list[Fix],
    cfg: PipelineConfig,
    metric: Callable[[Fix], TrackMetric],
) -> pd.DataFrame:
    """Per-cycle state, km and margin from the fixes in force (vectorised)."""
    t, d = cycles.t, odo.d
    n = t.size
    state = np.full(n, PositionState.UNDETERMINED.value, dtype=object)
    line = np.full(n, None, dtype=object)
    track = np.full(n, None, dtype=object)
    source = np.full(n, "none", dtype=object)
    km = np.full(n, np.nan)
    km_eq = np.full(n, np.nan)
    margin = np.full(n, np.nan)
    if fixes:
        t_eff = np.array([f.t_effective for f in fixes])
        idx = np.searchsorted(t_eff, t, side="right") - 1
        has = idx >= 0
        j = np.clip(idx, 0, None)
        d_ref = np.array([f.d_ref for f in fixes])[j]
        eq_off = np.array([f.km_equipment_m - f.km_m for f in fixes])[j]
        unc = np.array([f.uncertainty_m for f in fixes])[j]
        a_ref = np.array([f.allowance_ref_m for f in fixes])[j]
        unc_d = np.array([np.nan if f.uncertain_since_d is None else f.uncertain_since_d for f in fixes])[j]
        est = np.full(n, np.nan)
        for jj in np.unique(j[has]):  # dead reckoning along the track's own length, per fix in force
            sel = has & (j == jj)
            est[sel] = km_along(fixes[jj], s_trav[sel], metric(fixes[jj]))
        mg = unc + cfg.margin.distance_pct / 100.0 * np.abs(d - d_ref) + np.maximum(odo.allowance - a_ref, 0.0)
        uncertain_extra = np.where(
            np.isfinite(unc_d), cfg.margin.uncertain_growth_pct / 100.0 * np.abs(d - np.nan_to_num(unc_d)), 0.0
        )
        has &= np.array([f.state != PositionState.UNDETERMINED for f in fixes])[j]
        km = np.where(has, est, np.nan)
        km_eq = np.where(has, est + eq_off, np.nan)
        margin = np.where(has, mg + uncertain_extra, np.nan)
        state = np.where(has, np.array([str(f.state) for f in fixes], dtype=object)[j], state)
        line = np.where(has, np.array([f.line_code for f in fixes], dtype=object)[j], None)
        track = np.where(has, np.array([f.track for f in fixes], dtype=object)[j], None)
        source = np.where(has, np.array([f.source for f in fixes], dtype=object)[j], "none")
    return pd.DataFrame(
        {
            "t": t,
            "state": state,
            "line_code": pd.array(line, dtype="string"),
            "track": pd.array(track, dtype="string"),
            "km_m": km,
            "km_equipment_m": km_eq,
            "speed_mps": odo.v,
            "margin_m": margin,
            "last_fix_source": pd.array(source, dtype="string"),
        }
    )
