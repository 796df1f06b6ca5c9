"""The IMU's crossover signature as an aid: which track after a crossover's facing turnout
[SPEC §8.3; S001 §7 (b), (c)].

A crossover (渡り線) joins two parallel tracks a spacing d apart through two turnouts 1:n: over
its ride the heading turns by +α = atan(1/n) at the first turnout and back by −α at the second,
so the heading after it is the track's again and the one mark the ride leaves is a **lateral
displacement** y = ∫ sin ψ ds ≈ d toward the other track (S001 §7 (b): the offset from the base
track grows by the spacing; (c): the heading against the track); the through route shows none.
The turnout test (:mod:`fieldlogs.pipeline.aids.track_imu`) cannot look at a short crossover's
first turnout when the margins reach its far turnout, whose reverse curve cancels the heading;
this test waits for the whole ride instead.

**Window.** Candidates of one split at a facing switch with a crossover branch (all with the
same ``switch_id`` and ``split_d``). The crossover's candidate, seen on the crossover track,
gives the travel d_toe at which the dead-reckoned point passed the toe (its pos beyond the
crossover's entry) and d_exit = d_toe + the crossover's length. With m_t the margin at d_toe,
the true toe lies within d_toe ± m_t: the window starts at the last cycle at or before
d_toe − m_t (the true toe b ∈ [d_toe − m_t − d_start, d_toe + m_t − d_start] beyond it) and
ends at the first cycle at which the crossover's candidate, with its margin m (plus its
``extra_m``), lies wholly beyond the crossover's far end: had the train taken the crossover,
the whole ride is inside. No test when that margin exceeds ``track_select.imu_max_margin_m``;
none when the train stood still (a cycle without travel: an unseen rollback of a tachometer
without sense would make the unsigned travel no path) or reversed (a change of the sense of
motion) inside the window, when the yaw rate is missing on a cycle, or when a candidate's
interval leaves its track.

**Measurement.** Over the window's cycles i (time tᵢ, travel dᵢ, yaw rate ωᵢ, + turning left),
ψᵢ = Σ_{k<i} ωₖ Δtₖ and

    y = Σᵢ sin(ψᵢ + ½ ωᵢ Δtᵢ) · Δdᵢ

(+ to the left of the travel direction: a yaw rate turns the travel direction as it turns the
body, whichever way the body faces).

**Expectation.** Candidate j (its track and dead-reckoned pos p at the window's end, margin m)
expects the lateral distance of its centreline point at p' ∈ {p − m, p, p + m} from the line
through the true window start P_s along the track's tangent t_s there (the toe track's
centreline, a distance b ∈ {b_lo, b_mid, b_hi} before the toe, b over the interval above):
μ = t_s × (P(p') − P_s) (the plane cross product), every point in one local plane. The
expected span S_j = [min μ, max μ] over those nine pairs (the geometry, not an assumed
straight track: a curved through route has its own μ); on straight parallel tracks S_j is
the point 0 (through) or ±d (crossover).

**Error.** With a yaw-rate bias b (1σ b_g, ``track_select.gyro_bias_dps``) and white noise of
density q (``gyro_noise_dps_rthz``), the heading error at the middle of cycle i is
b·τᵢ + Σ_{k<i} eₖ + ½eᵢ (τᵢ the time from the window's start, var eₖ = q²Δtₖ), so
y's error (sin linearised, |cos ψ| ≤ 1) is b·K + Σₖ eₖ (d_end − d̄ₖ), d̄ₖ the travel at the
middle of cycle k, K = Σᵢ τᵢ Δdᵢ:

    σ² = (b_g·K)² + q² Σₖ Δtₖ (d_end − d̄ₖ)² + σ_geo²

(σ_geo: ``track_select.crossover_geometry_m``, the tracks' spacing tolerance, car-body motion
and the odometry's scale error on d). The test is the turnout test's: the generalised
log-likelihood ratio LLR_ab = (D_b − D_a)/(2σ²), D_j = min over μ ∈ S_j of (y − μ)²; b is
dropped when LLR_ab ≥ A + ln(1 + w·√(2/π)/σ) (A = ln((1 − β)/α), Wald's threshold; w the
widest span: :func:`fieldlogs.pipeline.aids.track_imu.look_threshold` with one look): the true
track is dropped with probability at most α/(1 − β) per crossover. At 10 m/s over a 1:10
crossover 4 m apart with m = 10 m the window is ≈ 80 m long (8 s), σ ≈ 0.41 m, and the LLR ≈ 47.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from dbtools.topology import BEGIN, END
from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.track_imu import heading_llr, kept, look_threshold, resolve
from fieldlogs.pipeline.config import MarginConfig, TrackSelectConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import TrackLines, one_split, rebased, to_plane
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.types import Fix, FloatArray, Hypothesis
from schemas.enums import TrackKind

#: A point and unit tangent in one plane: (x, y, tx, ty) [m].
Pose = tuple[float, float, float, float]
#: A window's first and last cycle and the true toe's distance beyond its start (low, middle, high) [m].
Window = tuple[int, int, tuple[float, float, float]]


@dataclass(frozen=True)
class Crossover:
    """A point switch with a crossover track on one branch: what the test needs."""

    toe_track: str
    """The track on the switch's toe side (``a1_track``)."""
    toe_end: str
    """Its end at the switch."""
    track_id: str
    """The crossover track."""
    entry: str
    """The crossover track's end at this switch."""


def crossovers(switches: pd.DataFrame, tracks: pd.DataFrame) -> dict[str, Crossover]:
    """Point switches with a branch on a track of kind crossover, by switch id."""
    kinds = dict(zip(tracks["track_id"].astype(str), tracks["kind"].astype(str), strict=True))
    out: dict[str, Crossover] = {}
    for row in switches.to_dict("records"):
        if row.get("type") != "point":
            continue
        for b in ("b1", "b2"):
            tid = str(row.get(f"{b}_track"))
            if kinds.get(tid) == TrackKind.CROSSOVER.value:
                out[str(row["switch_id"])] = Crossover(
                    str(row["a1_track"]), str(row["a1_end"]), tid, str(row[f"{b}_end"])
                )
    return out


def lateral_displacement(t: FloatArray, d: FloatArray, wz: FloatArray) -> float:
    """y = Σᵢ sin(ψᵢ + ½ωᵢΔtᵢ)·Δdᵢ over the cycles ``t``, ``d``, ``wz`` (module docstring)."""
    dt, dd, w = np.diff(t), np.diff(d), wz[:-1]
    turn = w * dt
    psi = np.concatenate([[0.0], np.cumsum(turn)[:-1]])
    return float(np.sum(np.sin(psi + 0.5 * turn) * dd))


def displacement_sigma(t: FloatArray, d: FloatArray, cfg: TrackSelectConfig) -> float:
    """σ of y over the cycles ``t``, ``d``: √((b_g·K)² + q²·Σ Δt (d_end − d̄)² + σ_geo²) (module docstring)."""
    dt, dd = np.diff(t), np.diff(d)
    tau = t[:-1] + 0.5 * dt - t[0]
    k_bias = float(np.sum(tau * dd))
    rest = d[-1] - 0.5 * (d[:-1] + d[1:])
    b, q = math.radians(cfg.gyro_bias_dps), math.radians(cfg.gyro_noise_dps_rthz)
    return math.sqrt((b * k_bias) ** 2 + q * q * float(np.sum(dt * rest * rest)) + cfg.crossover_geometry_m**2)


def start_poses(lines: TrackLines, cx: Crossover, backs: tuple[float, ...]) -> list[Pose]:
    """The toe track's centreline point and unit tangent (toward the toe) ``backs`` metres
    before the toe, in the plane centred at the toe track's origin."""
    tl = lines[cx.toe_track]
    sign = 1.0 if cx.toe_end == END else -1.0
    out: list[Pose] = []
    for back in backs:
        x, y, tx, ty = tl.point(tl.length_m - back if cx.toe_end == END else back)
        out.append((x, y, sign * tx, sign * ty))
    return out


def expected_span(
    lines: TrackLines, origin: tuple[float, float], starts: list[Pose], h: Hypothesis, m: float
) -> tuple[float, float] | None:
    """[min, max] of μ = t_s × (P(p') − P_s) over the start poses and p' ∈ {p − m, p, p + m}
    (module docstring); None when the interval leaves the candidate's track or it has no centreline."""
    tl = lines[h.track_id]
    lo, hi = h.pos_m - m - h.extra_m, h.pos_m + m + h.extra_m
    if lo < 0.0 or hi > tl.length_m or tl.xy.shape[0] < 2:
        return None
    pts = np.array([tl.point(p)[:2] for p in (lo, h.pos_m, hi)])
    ends = to_plane(origin, tl, pts)
    mu = [tx * (ey - y) - ty * (ex - x) for x, y, tx, ty in starts for ex, ey in ends]
    return min(mu), max(mu)


@dataclass(eq=False)
class TrackCrossoverAid:
    """The crossover signature test (module docstring)."""

    wz: FloatArray
    """Yaw rate per cycle [rad/s]."""
    switches: dict[str, Crossover]
    lines: TrackLines
    cfg: TrackSelectConfig
    margin: MarginConfig
    name: str = "track_crossover"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    done: set[tuple[str, float]] = field(default_factory=set)
    exit_d: dict[tuple[str, float], float] = field(default_factory=dict)
    """Per split: the dead-reckoned travel d at the crossover's far end."""

    def observations(self) -> list[Observation]:
        return []

    def _split(self, fix: Fix | None) -> tuple[str, float] | None:
        """The one split all of ``fix``'s candidates came out of, at a switch with a crossover branch."""
        key = one_split(fix)
        return None if key is None or key[0] not in self.switches or key in self.done else key

    def _exit(self, key: tuple[str, float], fix: Fix, view: EngineView) -> float | None:
        """d at the crossover's far end, from its candidate while on the crossover (kept)."""
        if key not in self.exit_d:
            cx = self.switches[key[0]]
            for h in rebased(fix.hyps, fix.s_ref, view.s):
                if h.track_id == cx.track_id:
                    left = self.lines[cx.track_id].length_m - h.pos_m if cx.entry == BEGIN else h.pos_m
                    self.exit_d[key] = view.d + left
        return self.exit_d.get(key)

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        key = self._split(fix)
        if fix is None or key is None:
            return None
        d_exit = self._exit(key, fix, view)
        if d_exit is None:
            return None
        tr = view.travel
        cap = self.cfg.imu_max_margin_m
        i_a = int(np.searchsorted(tr.d, d_exit))
        i_b = min(int(np.searchsorted(tr.d, d_exit + cap, side="right")) + 1, tr.n)
        if i_a >= tr.n:
            return None
        w = slice(i_a, i_b)
        need = margin_m(fix, tr.d[w], tr.allowance[w], self.margin) + max(h.extra_m for h in fix.hyps)
        ok = (tr.d[w] - d_exit >= need) & (need <= cap)
        if not ok.any():
            if i_b < tr.n or bool((need > cap).any()):
                self.done.add(key)  # the margin outgrew the cap: no test
            return None
        i = i_a + int(np.argmax(ok))
        return Observation(max(float(tr.t[i]), view.t), key)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        key: tuple[str, float] = obs.payload
        self.done.add(key)
        if fix is None or one_split(fix) != key:
            return Outcome()
        tr = view.travel
        sid, split_d = key
        window = self._window(tr, fix, key, view)
        if window is None:
            return Outcome()
        i0, i1, backs = window
        t, d, wz = tr.t[i0 : i1 + 1], tr.d[i0 : i1 + 1], self.wz[i0 : i1 + 1]
        if not np.isfinite(wz).all():
            return Outcome()
        y, sigma = lateral_displacement(t, d, wz), displacement_sigma(t, d, self.cfg)
        cx = self.switches[sid]
        origin = self.lines[cx.toe_track].origin
        starts = start_poses(self.lines, cx, backs)
        m = float(margin_m(fix, view.d, tr.allowance_at(view.t), self.margin))
        spans = [expected_span(self.lines, origin, starts, h, m) for h in rebased(fix.hyps, fix.s_ref, view.s)]
        if any(s is None for s in spans):
            return Outcome()
        known = [s for s in spans if s is not None]
        keep = kept(heading_llr(y, known, sigma), look_threshold(self.cfg.threshold, 1, known, sigma))
        detail: dict[str, Any] = {
            "evidence": "imu_crossover",
            "switch_id": sid,
            "displacement_m": round(y, 3),
            "sigma_m": round(sigma, 3),
            "after_switch_m": round(view.d - split_d, 2),
        }
        return resolve(fix, keep, view, self.lines, detail)

    def _window(self, tr: Travel, fix: Fix, key: tuple[str, float], view: EngineView) -> Window | None:
        """The window's first and last cycle and the true toe's distance b beyond its start (low,
        middle, high: module docstring); None at a standstill or a reversal inside."""
        d_toe = self.exit_d[key] - self.lines[self.switches[key[0]].track_id].length_m
        j = min(int(np.searchsorted(tr.d, d_toe)), tr.n - 1)
        m_t = float(margin_m(fix, d_toe, float(tr.allowance[j]), self.margin))
        i0 = max(int(np.searchsorted(tr.d, d_toe - m_t, side="right")) - 1, 0)
        i1 = view.i if tr.t[view.i] <= view.t else view.i - 1
        if i1 - i0 < 2:
            return None
        if (np.diff(tr.d[i0 : i1 + 1]) <= 0.0).any() or np.unique(tr.motion[i0 : i1 + 1]).size > 1:
            return None
        b_lo = max(d_toe - m_t - float(tr.d[i0]), 0.0)
        b_hi = d_toe + m_t - float(tr.d[i0])
        return i0, i1, (b_lo, 0.5 * (b_lo + b_hi), b_hi)
