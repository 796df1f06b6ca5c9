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
Wald's A = ln((1 − β)/α) (``track_select.alpha``, ``beta``).

**Looks.** The signature need not be waited for whole: the test looks every ``LOOK_M`` of travel
x past the split, over the window [split − m, split + x], up to the full window x = R·α + m
(L = ⌈(R·α + m)/``LOOK_M``⌉ looks). The toe lies within ±m of the dead-reckoned split, so at
look x branch b has turned by μ ∈ S_b = μ_b·[clip((x − m)/(R·α), 0, 1), clip((x + m)/(R·α), 0, 1)]
(the lead's heading grows linearly from the toe); the generalised LLR is
LLR_ab = (D_b − D_a)/(2σ²), D_j = min over μ ∈ S_j of (Δψ − μ)². Against the true branch b
(true μ* ∈ S_b, so D_b ≤ (Δψ − μ*)²) the generalised LR's mean is at most 1 + w·√(2/π)/σ
(w the width of S_a: the LR at the span's near end, of mean 1, plus ∫|∂LR/∂μ|dμ, each of mean
√(2/π)/σ), so b is dropped at a look only when LLR_ab ≥ A + ln L + ln(1 + w·√(2/π)/σ): by
Markov's inequality per look and the union over the L looks, the true branch is dropped with
probability at most e^−A = α/(1 − β) per split, as with the one test at the window's end
(where S is the point μ_b, w = 0). A 1:10 diverging branch at 10 m/s with m = 3 m is then
resolved 8 m past the split instead of 23 m, the through branch at 14 m.

No test
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
from fieldlogs.pipeline.hypotheses import TrackLines, one_split, rebased
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.types import Event, Fix, FloatArray, Hypothesis
from schemas.enums import EventType, Side

#: Travel between two looks at one split's heading change [m] (module docstring, *looks*).
LOOK_M = 2.0


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


def heading_llr(dpsi: float, expected: list[float] | list[tuple[float, float]], sigma: float) -> FloatArray:
    """LLR[a, b] = (D_b − D_a) / (2σ²), D_j = min over μ in candidate j's expected span of (Δψ − μ)²
    (a number μ_j: the span [μ_j, μ_j], D_j = (Δψ − μ_j)²)."""
    span = np.array([(e, e) if isinstance(e, float | int) else e for e in expected], dtype=float).reshape(-1, 2)
    r2 = (dpsi - np.clip(dpsi, span[:, 0], span[:, 1])) ** 2
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
    look: dict[tuple[str, float], int] = field(default_factory=dict)
    """Per split: the number of its next look."""

    def observations(self) -> list[Observation]:
        return []

    def _split(self, fix: Fix) -> tuple[str, float, Turnout] | None:
        key = one_split(fix)
        if key is None or key[0] not in self.switches or key in self.done:
            return None
        sid, split_d = key
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
        x_end = to.lead_m + m
        i1 = min(int(np.searchsorted(tr.d, split_d + x_end)), tr.n - 1)
        m_end = float(margin_m(fix, float(tr.d[i1]), tr.allowance[i1], self.margin))
        if any(self.lines[h.track_id].length_m < 2.0 * to.lead_m + m + m_end for h in fix.hyps):
            self.done.add((sid, split_d))  # the window may reach the branch's far turnout: no test
            return None
        looks = max(math.ceil(x_end / LOOK_M), 1)
        k = self.look.get((sid, split_d), 1)
        x = min(k * LOOK_M, x_end)
        i = int(np.searchsorted(tr.d, split_d + x))
        if i >= tr.n:
            return None
        return Observation(max(float(tr.t[i]), view.t), (sid, split_d, m, x, k >= looks, looks))

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        sid, split_d, m, x, final, looks = obs.payload
        self.look[(sid, split_d)] = self.look.get((sid, split_d), 1) + 1
        if final:
            self.done.add((sid, split_d))
        if fix is None or one_split(fix) != (sid, split_d):
            return Outcome()
        tr, to = view.travel, self.switches[sid]
        sel = (tr.d >= split_d - m) & (tr.d <= split_d + x) & (tr.t <= view.t)
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
        spans = [expected_span(to.heading[h.track_id], to.lead_m, x, m) for h in fix.hyps]
        keep = kept(heading_llr(dpsi, spans, sigma), look_threshold(c.threshold, looks, spans, sigma))
        detail: dict[str, Any] = {
            "evidence": "imu",
            "switch_id": sid,
            "heading_change_deg": round(math.degrees(dpsi), 3),
            "sigma_deg": round(math.degrees(sigma), 3),
            "after_switch_m": round(view.d - split_d, 2),
        }
        return resolve(fix, keep, view, self.lines, detail)


def expected_span(turn: float, lead_m: float, x: float, m: float) -> tuple[float, float]:
    """The heading change a branch turning by ``turn`` over ``lead_m`` shows after ``x`` of travel
    past the dead-reckoned toe, the true toe within ±``m`` of it: turn·clip(u/lead, 0, 1) for
    u ∈ [x − m, x + m] (module docstring, *looks*), as (low, high)."""
    a, b = (turn * min(max(u / max(lead_m, 1e-9), 0.0), 1.0) for u in (x - m, x + m))
    return (min(a, b), max(a, b))


def look_threshold(threshold: float, looks: int, spans: list[tuple[float, float]], sigma: float) -> float:
    """Wald's A raised for ``looks`` looks at one split and for the widest expected span w:
    A + ln L + ln(1 + w·√(2/π)/σ) (module docstring, *looks*)."""
    w = max(hi - lo for lo, hi in spans)
    return threshold + math.log(looks) + math.log1p(w * math.sqrt(2.0 / math.pi) / sigma)


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
