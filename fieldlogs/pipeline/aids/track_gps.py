"""GPS offsets from each candidate track as an aid: which branch after a facing switch [SPEC §8.3; S001 §4.2].

While the estimate is ambiguous, every trusted GPS fix (:mod:`fieldlogs.pipeline.gps`) is
compared with each candidate: r_j = the signed offset (left of body-forward) of the antenna from
candidate j's centreline at the candidate's dead-reckoned position. The GPS error is a slow
bias b common to the fixes of the evidence (σ_b = ``gps.noise_sigma_m``; its correlation
time is long against a switch's evidence) plus white noise σ_w (``gps.noise_white_m``), so
the n offsets r of the true candidate have covariance C = σ_w²·I + σ_b²·11ᵀ and

    Q_j = rᵀC⁻¹r = (Σr² − σ_b²(Σr)²/(σ_w² + n·σ_b²)) / σ_w²     (Sherman–Morrison).

The log-likelihood ratio of a against b is ½(Q_b − Q_a); b is dropped once some a reaches
Wald's A = ln((1 − β)/α) (``track_select``), the sequential test S001 runs for up/down. A
bias saturates the evidence: two tracks 4 m apart separate (LLR → (c² − 2bc)/(2σ_b²)), two
tracks within the bias do not, and the position stays ambiguous. The sums restart at every
change of the candidate set.

**Multipath steps.** The model holds a bias that is constant over the evidence; a multipath step
toward the neighbouring track (a station roof, the simulator's ``network.multipath``: 2–4 m,
lasting hundreds of metres) shortly after the split breaks it: the true candidate's offsets
jump, the wrong branch, diverging through the same metres, changes less, and with a 4 m step
beside tracks 4.5 m apart the fixes lie on the wrong track — no test on them can decide right.
So every fix's offsets are compared with the last fix's (at most ``gps.max_gap_s`` before; at
a split, the offset from the track the candidates came from): when *no* candidate's offset
can have changed by white noise alone (every |Δr_j| > ``track_select.gps_jump_sigma``·σ_w·√2),
the fix jumped, and a candidate set that began less than ``gps.jump_hold_s`` after a jump, or
saw one, is not decided by GPS at all (the IMU, a balise group or a later split decide).
And the model must fit: under the hypothesis that candidate j is the true track Q_j ~ χ²(n);
when even the best candidate's Q exceeds χ²(n)'s 1 − α quantile (α = ``track_select.alpha``),
no candidate explains the fixes, and the evidence restarts from the latest one. Nor does the
test decide on fewer than ``track_select.gps_min_fixes`` fixes: a step of about the branches'
divergence over one second (2 m, 1–2 s past the toe of a 1:9 turnout) passes for noise on the
wrong branch, and only the following fixes show that neither branch has a constant offset. A fix joins
the evidence only after ``MIN_SPACING_M`` of travel
since the last one used: at a standstill the slow error does not decorrelate from fix to fix
(the simulator's and the S001 D-GPS error is Gauss–Markov with τ ≈ 3 min), so a train standing
18 m past a toe, where the branches are 0.8 m apart, would otherwise count the same error a
hundred times as independent noise and decide on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.track_imu import kept, resolve
from fieldlogs.pipeline.config import GpsConfig, TrackSelectConfig
from fieldlogs.pipeline.hypotheses import TrackLines
from fieldlogs.pipeline.types import Fix, FloatArray, Hypothesis

#: Travel between two fixes used as evidence [m] (module docstring).
MIN_SPACING_M = 1.0


def offset(lines: TrackLines, h: Hypothesis, pos: float, lat: float, lon: float) -> float:
    """Signed offset [m] (+ left of the track's begin→end direction) of (lat, lon) from the
    centreline of ``h``'s track at ``pos``."""
    tl = lines[h.track_id]
    if tl.xy.shape[0] < 2:
        return float("nan")
    x, y, ux, uy = tl.point(pos)
    px, py = tl.plane(np.array([lat]), np.array([lon]))
    return float(-(float(px[0]) - x) * uy + (float(py[0]) - y) * ux)


def quad(r: FloatArray, sigma_w: float, sigma_b: float) -> float:
    """Q = rᵀC⁻¹r for C = σ_w²·I + σ_b²·11ᵀ (module docstring)."""
    n = r.size
    return float((np.sum(r * r) - sigma_b**2 * np.sum(r) ** 2 / (sigma_w**2 + n * sigma_b**2)) / sigma_w**2)


def chi2_upper(p: float, n: int) -> float:
    """The χ²(n) quantile p by Wilson and Hilferty (1931): n·(1 − 2/(9n) + z_p·√(2/(9n)))³, z_p
    the standard normal quantile (stdlib; SciPy stays out of ``trainpos run``). Slightly above
    the exact value for small n (n = 1, p = 0.9999: 16.2 against 15.1), so a restart is, if
    anything, later."""
    z = NormalDist().inv_cdf(p)
    a = 2.0 / (9.0 * n)
    return float(n * (1.0 - a + z * math.sqrt(a)) ** 3)


def gps_llr(offsets: FloatArray, sigma_w: float, sigma_b: float) -> FloatArray:
    """LLR[a, b] = ½(Q_b − Q_a) for the (candidates × fixes) offsets."""
    q = np.array([quad(row, sigma_w, sigma_b) for row in offsets])
    return np.asarray(0.5 * (q[None, :] - q[:, None]), dtype=float)


@dataclass(eq=False)
class NetworkFixes:
    """What every GPS aid on a network's tracks holds: the run's trusted fixes, the tracks and
    the settings."""

    t: FloatArray
    lat: FloatArray
    lon: FloatArray
    """Trusted fixes, in time order."""
    lines: TrackLines
    cfg: TrackSelectConfig
    gps: GpsConfig


@dataclass(eq=False)
class TrackGpsAid(NetworkFixes):
    """The GPS offset test (module docstring)."""

    antenna_x_m: float = 0.0
    name: str = "track_gps"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    key: tuple[tuple[int, str], ...] = ()
    rows: list[list[float]] = field(default_factory=list)
    last_d: float = float("-inf")
    """Unsigned travel at the last fix used."""
    set_t: float = float("-inf")
    """Time the current candidate set began."""
    prev: tuple[float, list[float]] | None = None
    """(t, offsets) of the last fix seen, for the jump test."""
    jump_t: float = float("-inf")
    """Time of the last jump seen."""

    def observations(self) -> list[Observation]:
        return []

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or not fix.hyps:
            return None
        j = int(np.searchsorted(self.t, view.t, side="right"))
        return Observation(float(self.t[j]), j) if j < self.t.size else None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        if fix is None or not fix.hyps:
            self.prev = None
            return Outcome()
        j: int = obs.payload
        off = self._offsets(fix, view, float(self.lat[j]), float(self.lon[j]))
        if self._jumped(view.t, off):
            self.jump_t = view.t
        if len(fix.hyps) < 2:
            self.key = ()
            return Outcome()
        key = tuple((h.hid, h.track_id) for h in fix.hyps)
        if tuple(k[0] for k in key) != tuple(k[0] for k in self.key):
            self.rows, self.last_d, self.set_t = [], float("-inf"), view.t  # a new candidate set: start again
        self.key = key
        if self.jump_t >= self.set_t - self.gps.jump_hold_s:
            return Outcome()  # a jump in or just before this evidence: no GPS decision on it (docstring)
        if view.d - self.last_d < MIN_SPACING_M:
            return Outcome()  # standing: no independent evidence
        self.last_d = view.d
        self.rows.append(off)
        r = np.asarray(self.rows, dtype=float).T
        if not np.isfinite(r).all():
            return Outcome()
        sw, sb = max(self.gps.noise_white_m, 1e-3), self.gps.noise_sigma_m
        q = np.array([quad(row, sw, sb) for row in r])
        if float(q.min()) > chi2_upper(1.0 - self.cfg.alpha, r.shape[1]):
            self.rows = self.rows[-1:]  # no candidate explains the fixes: start again from this one
            return Outcome()
        if r.shape[1] < self.cfg.gps_min_fixes:
            return Outcome()  # too few fixes for a multipath step to show (docstring)
        llr = np.asarray(0.5 * (q[None, :] - q[:, None]), dtype=float)
        detail: dict[str, Any] = {
            "evidence": "gps",
            "fixes": int(r.shape[1]),
            "llr": round(float(np.max(llr)), 2),
            "after_switch_m": _after(fix, view.d),
        }
        return resolve(fix, kept(llr, self.cfg.threshold), view, self.lines, detail)

    def _jumped(self, t: float, off: list[float]) -> bool:
        """No candidate's offset can have moved by noise since the last fix (every |Δr_j| beyond
        ``gps_jump_sigma``·σ_w·√2, the last fix at most ``gps.max_gap_s`` before; a single
        previous offset — the track the candidates split from — is compared with each)."""
        prev, self.prev = self.prev, (t, off)
        if prev is None or t - prev[0] > self.gps.max_gap_s:
            return False
        before = prev[1] * len(off) if len(prev[1]) == 1 else prev[1]
        if len(before) != len(off):
            return False
        limit = self.cfg.gps_jump_sigma * max(self.gps.noise_white_m, 1e-3) * float(np.sqrt(2.0))
        return bool(np.all(np.abs(np.asarray(off, dtype=float) - np.asarray(before, dtype=float)) > limit))

    def _offsets(self, fix: Fix, view: EngineView, lat: float, lon: float) -> list[float]:
        out = []
        for h in fix.hyps:
            pos = h.pos_m + h.kp * (view.s - fix.s_ref) + h.kp * self.antenna_x_m
            out.append(h.kp * offset(self.lines, h, pos, lat, lon))  # + left of body-forward
        return out


def _after(fix: Fix, d: float) -> float | None:
    split = [h.split_d for h in fix.hyps if h.split_d is not None]
    return round(d - max(split), 2) if split else None
