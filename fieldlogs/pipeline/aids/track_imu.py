"""The IMU's turnout signature as an aid: which branch after a facing switch [SPEC §8.3; S001 §7 (c)].

From the toe, the diverging branch of a turnout 1:n turns by the frog angle α = atan(1/n)
over its lead (the curve of radius R, length ≈ R·α; yaw rate ωz ≈ v/R), toward the diverging
side; the through branch does not turn. With the candidates of one split (all on branches of
the same switch), once the travel has passed the toe by R·α plus the margin m at the split,
the yaw rate (+ turning left, body frame) integrated over the travel window
[split − m, split + R·α + m] gives the heading change Δψ = Σ ωz·Δt; candidate b expects
μ_b = +α (diverging, left), −α (diverging, right) or 0 (through). With

    σ² = (b_g·T)² + q²·T + σ_geo²

(gyro bias b_g, white-noise density q over the window's duration T, and the geometry's own
spread σ_geo: ``track_select.gyro_*``, ``heading_geometry_deg``), the log-likelihood ratio of
a against b is LLR_ab = ((Δψ − μ_b)² − (Δψ − μ_a)²) / (2σ²); b is dropped when some a reaches
Wald's A = ln((1 − β)/α) (``track_select.alpha``, ``beta``). One test per split; no test
without the switch's number and radius or when m exceeds ``track_select.imu_max_margin_m``,
and none when a branch is shorter than 2·R·α + m + m_end (m_end the margin at the window's
end): the true window, up to R·α + m + m_end beyond the toe, could then reach the branch's
own far turnout (a crossover's reverse curve, R·α before its end), whose opposite turn would
cancel the signature — a 60 m crossover of 1:10 turnouts (R·α = 20 m) is tested only while
m + m_end ≤ 20 m.
A crossover's first turnout is such a facing switch (S001 §7 (c): the heading against the track).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.topology import with_hyps
from fieldlogs.pipeline.config import MarginConfig, TrackSelectConfig
from fieldlogs.pipeline.hypotheses import TrackLines, rebased
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.types import Event, Fix, FloatArray, Hypothesis
from schemas.enums import EventType, Side


@dataclass(frozen=True)
class Turnout:
    """What the test needs of a point switch."""

    angle: float
    """Frog angle α = atan(1/n) [rad]."""
    lead_m: float
    """R·α [m]."""
    heading: dict[str, float]
    """Branch track → expected heading change from the toe [rad]."""


def turnouts(switches: pd.DataFrame) -> dict[str, Turnout]:
    """Point switches with a switch number and a diverging radius."""
    out: dict[str, Turnout] = {}
    for row in switches.to_dict("records"):
        n, r, side = row.get("switch_number"), row.get("diverging_radius_m"), row.get("diverging_side")
        if row.get("type") != "point" or pd.isna(n) or pd.isna(r) or pd.isna(side):
            continue
        a = math.atan(1.0 / float(n))
        div, thr = ("b1", "b2") if side == Side.LEFT.value else ("b2", "b1")
        turn = a if side == Side.LEFT.value else -a
        out[str(row["switch_id"])] = Turnout(
            a, float(r) * a, {str(row[f"{div}_track"]): turn, str(row[f"{thr}_track"]): 0.0}
        )
    return out


def heading_llr(dpsi: float, expected: list[float], sigma: float) -> FloatArray:
    """LLR[a, b] = ((Δψ − μ_b)² − (Δψ − μ_a)²) / (2σ²)."""
    r2 = (dpsi - np.asarray(expected, dtype=float)) ** 2
    return np.asarray((r2[None, :] - r2[:, None]) / (2.0 * sigma * sigma), dtype=float)


def kept(llr: FloatArray, threshold: float) -> list[int]:
    """Candidates no other one beats by ``threshold``."""
    return [b for b in range(llr.shape[0]) if not (llr[:, b] >= threshold).any()]


@dataclass(eq=False)
class TrackImuAid:
    """The turnout signature test (module docstring)."""

    wz: FloatArray
    """Yaw rate per cycle [rad/s]."""
    switches: dict[str, Turnout]
    lines: TrackLines
    cfg: TrackSelectConfig
    margin: MarginConfig
    name: str = "track_imu"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    done: set[tuple[str, float]] = field(default_factory=set)

    def observations(self) -> list[Observation]:
        return []

    def _split(self, fix: Fix) -> tuple[str, float, Turnout] | None:
        sw = {h.switch_id for h in fix.hyps}
        d0 = {h.split_d for h in fix.hyps}
        if len(fix.hyps) < 2 or len(sw) != 1 or len(d0) != 1:
            return None
        sid, split_d = next(iter(sw)), next(iter(d0))
        if sid is None or split_d is None or sid not in self.switches or (sid, split_d) in self.done:
            return None
        to = self.switches[sid]
        if any(h.track_id not in to.heading for h in fix.hyps):
            return None
        return sid, split_d, to

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        hit = None if fix is None else self._split(fix)
        if fix is None or hit is None:
            return None
        sid, split_d, to = hit
        tr = view.travel
        i0 = int(np.searchsorted(tr.d, split_d))
        m = float(margin_m(fix, split_d, tr.allowance[min(i0, tr.n - 1)], self.margin))
        if m > self.cfg.imu_max_margin_m:
            self.done.add((sid, split_d))
            return None
        i1 = int(np.searchsorted(tr.d, split_d + to.lead_m + m))
        if i1 >= tr.n:
            return None
        m_end = float(margin_m(fix, float(tr.d[i1]), tr.allowance[i1], self.margin))
        if any(self.lines[h.track_id].length_m < 2.0 * to.lead_m + m + m_end for h in fix.hyps):
            self.done.add((sid, split_d))  # the window may reach the branch's far turnout: no test
            return None
        return Observation(max(float(tr.t[i1]), view.t), (sid, split_d, m))

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        sid, split_d, m = obs.payload
        self.done.add((sid, split_d))
        if fix is None or len(fix.hyps) < 2 or {(h.switch_id, h.split_d) for h in fix.hyps} != {(sid, split_d)}:
            return Outcome()
        tr, to = view.travel, self.switches[sid]
        sel = (tr.d >= split_d - m) & (tr.d <= split_d + to.lead_m + m) & (tr.t <= view.t)
        idx = np.flatnonzero(sel)
        if idx.size < 2:
            return Outcome()
        dt = float(np.median(np.diff(tr.t))) if tr.n > 1 else 0.1
        dpsi = float(np.nansum(self.wz[idx]) * dt)
        dur = float(idx.size * dt)
        c = self.cfg
        sigma = math.sqrt(
            (math.radians(c.gyro_bias_dps) * dur) ** 2
            + math.radians(c.gyro_noise_dps_rthz) ** 2 * dur
            + math.radians(c.heading_geometry_deg) ** 2
        )
        expected = [to.heading[h.track_id] for h in fix.hyps]
        keep = kept(heading_llr(dpsi, expected, sigma), c.threshold)
        detail: dict[str, Any] = {
            "evidence": "imu",
            "switch_id": sid,
            "heading_change_deg": round(math.degrees(dpsi), 3),
            "sigma_deg": round(math.degrees(sigma), 3),
            "after_switch_m": round(view.d - split_d, 2),
        }
        return resolve(fix, keep, view, self.lines, detail)


def resolve(fix: Fix, keep: list[int], view: EngineView, lines: TrackLines, detail: dict[str, Any]) -> Outcome:
    """The estimate with only candidates ``keep`` (indexes into ``fix.hyps``): a
    ``track_resolved`` event when one remains, ``hypothesis_dropped`` for each one dropped."""
    if len(keep) == len(fix.hyps) or not keep:
        return Outcome()
    hyps = rebased(fix.hyps, fix.s_ref, view.s)
    left: list[Hypothesis] = [hyps[j] for j in keep]
    events = [
        Event(view.t, EventType.HYPOTHESIS_DROPPED, None, detail={**detail, "track_id": h.track_id})
        for j, h in enumerate(hyps)
        if j not in keep
    ]
    new = with_hyps(fix, left, view.t, view.s, lines)
    if len(left) == 1:
        ev = {**detail, "track_id": left[0].track_id, "candidates": [h.track_id for h in hyps]}
        events.append(Event(view.t, EventType.TRACK_RESOLVED, new.km_m, detail=ev))
    return Outcome(events, new)
