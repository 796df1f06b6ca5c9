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
change of the candidate set. A fix joins the evidence only after ``MIN_SPACING_M`` of travel
since the last one used: at a standstill the slow error does not decorrelate from fix to fix
(the simulator's and the S001 D-GPS error is Gauss–Markov with τ ≈ 3 min), so a train standing
18 m past a toe, where the branches are 0.8 m apart, would otherwise count the same error a
hundred times as independent noise and decide on it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
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

    def observations(self) -> list[Observation]:
        return []

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or len(fix.hyps) < 2:
            return None
        j = int(np.searchsorted(self.t, view.t, side="right"))
        return Observation(float(self.t[j]), j) if j < self.t.size else None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        if fix is None or len(fix.hyps) < 2:
            return Outcome()
        key = tuple((h.hid, h.track_id) for h in fix.hyps)
        if tuple(k[0] for k in key) != tuple(k[0] for k in self.key):
            self.rows = []  # a new candidate set: the evidence starts again
            self.last_d = float("-inf")
        self.key = key
        if view.d - self.last_d < MIN_SPACING_M:
            return Outcome()  # standing: no independent evidence
        self.last_d = view.d
        j: int = obs.payload
        self.rows.append(self._offsets(fix, view, float(self.lat[j]), float(self.lon[j])))
        r = np.asarray(self.rows, dtype=float).T
        if not np.isfinite(r).all():
            return Outcome()
        llr = gps_llr(r, max(self.gps.noise_white_m, 1e-3), self.gps.noise_sigma_m)
        detail: dict[str, Any] = {
            "evidence": "gps",
            "fixes": int(r.shape[1]),
            "llr": round(float(np.max(llr)), 2),
            "after_switch_m": _after(fix, view.d),
        }
        return resolve(fix, kept(llr, self.cfg.threshold), view, self.lines, detail)

    def _offsets(self, fix: Fix, view: EngineView, lat: float, lon: float) -> list[float]:
        out = []
        for h in fix.hyps:
            pos = h.pos_m + h.kp * (view.s - fix.s_ref) + h.kp * self.antenna_x_m
            out.append(h.kp * offset(self.lines, h, pos, lat, lon))  # + left of body-forward
        return out


def _after(fix: Fix, d: float) -> float | None:
    split = [h.split_d for h in fix.hyps if h.split_d is not None]
    return round(d - max(split), 2) if split else None
