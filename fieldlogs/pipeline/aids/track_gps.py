"""GPS offsets from each candidate track as an aid: which branch after a facing switch [SPEC §8.3; S001 §4.2].

While the estimate is ambiguous, every trusted GPS fix (:mod:`fieldlogs.pipeline.gps`) is
compared with each candidate: r_j = the signed offset (left of body-forward) of the antenna from
candidate j's centreline at the candidate's dead-reckoned position. The GPS error is a slow
Gauss–Markov bias b (σ_b = ``gps.noise_sigma_m``, correlation time τ = ``gps.noise_tau_s``, the
S001 D-GPS model and the simulator's) plus white noise σ_w (``gps.noise_white_m``), so the n
offsets r of the true candidate at times t_i have covariance

    C_ik = σ_w²·δ_ik + σ_b²·exp(−|t_i − t_k|/τ),     Q_j = r_jᵀC⁻¹r_j

(one Cholesky factorisation for every candidate; τ = ∞ gives the constant bias, C = σ_w²·I +
σ_b²·11ᵀ and Q = (Σr² − σ_b²(Σr)²/(σ_w² + n·σ_b²))/σ_w² by Sherman–Morrison). The
log-likelihood ratio of a against b is ½(Q_b − Q_a); b is dropped once some a reaches Wald's
A = ln((1 − β)/α) (``track_select``), the sequential test S001 runs for up/down. Under the model
the likelihood ratio of a wrong candidate against the true one is a non-negative martingale of
mean 1 as fixes are added, so by Ville's inequality the chance that it *ever* reaches e^A is at
most e^−A = α/(1 − β), whatever the number of fixes: with k candidates the true one is dropped
with probability at most (k − 1)·α/(1 − β). A bias saturates the evidence: two tracks c apart
with a bias b toward the other one separate only while (c² − 2bc)/(2σ_b²) ≥ A (tracks 3.8 m
apart: b ≤ 0.54 m), and the position stays ambiguous until the bias decorrelates (τ) or other
evidence comes.

**Evidence before the set.** The likelihood of a candidate is that of its whole path: the
fixes before a candidate set began count as well, each on the track the candidate was on then.

* After a split (or a candidate dropped), each candidate keeps its lineage's offsets: its own,
  or its parent's — the candidate of the last set on the track it came from — before the
  split. Two branches of one split share their parent's rows (equal offsets: no evidence
  between them, but the slow bias is seen before the toe); two candidates from different
  parents (an ambiguity among parallel tracks carried through a switch) keep the evidence
  already gathered between them. On the one determined track the latest ``MAX_PREFIX`` fixes in
  a row are kept for the next split (no jump, no gap over ``gps.max_gap_s``).
* A set whose candidates have no lineage (the initial position among parallel tracks, a
  line-based placement with its parallel tracks) takes the trusted fixes before it, back to
  ``MAX_PREFIX`` of them while every candidate's dead-reckoned antenna stays on its own track
  and the fixes follow at most ``gps.max_gap_s`` apart, cut after any jump in them: the
  initial position's steady chain is evidence at once, not five fixes later.

Evidence longer than ``MAX_ROWS`` fixes keeps its last ``MAX_PREFIX`` (a new test, as a restart).
On one candidate nothing is decided: its fixes are worked into the evidence when it is next
needed, a stretch at once (:meth:`TrackGpsAid.flush`) — the same evidence as fix by fix.

**Multipath steps.** The model holds a bias that changes slowly; a multipath step
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
test decide between two candidates on fewer than ``track_select.gps_min_fixes`` fixes at which
their offsets differ (the rows before their split do not count): a step of about the branches'
divergence over one second (2 m, 1–2 s past the toe of a 1:9 turnout) passes for noise on the
wrong branch, and only the following fixes show that neither branch has a constant offset. A fix joins
the evidence only after ``MIN_SPACING_M`` of travel
since the last one used: at a standstill the slow error does not decorrelate from fix to fix
(the simulator's and the S001 D-GPS error is Gauss–Markov with τ ≈ 3 min), so a train standing
18 m past a toe, where the branches are 0.8 m apart, would otherwise count the same error a
hundred times as independent noise and decide on it.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from functools import cached_property
from statistics import NormalDist
from typing import TYPE_CHECKING, Any, NamedTuple, Protocol

import numpy as np

from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.track_imu import kept, resolve
from fieldlogs.pipeline.config import GpsConfig, TrackSelectConfig
from fieldlogs.pipeline.hypotheses import TrackLine, TrackLines, after_switch_m
from fieldlogs.pipeline.types import Fix, FloatArray, Hypothesis
from schemas.enums import PositionState

if TYPE_CHECKING:
    from fieldlogs.pipeline.estimate import Travel

#: Travel between two fixes used as evidence [m] (module docstring).
MIN_SPACING_M = 1.0
#: Fixes kept as the start of a new candidate set's evidence: on the determined track before a
#: split, or evaluated back along the candidates' own tracks (module docstring).
MAX_PREFIX = 30
#: Longest evidence: beyond it, only its last ``MAX_PREFIX`` fixes are kept (module docstring).
MAX_ROWS = 200
#: Fixes heard on a single candidate held before they are worked into the evidence at once
#: (:meth:`TrackGpsAid.flush`; any number gives the same evidence).
MAX_PENDING = 4096


def offset(tl: TrackLine, pos: float, px: float, py: float) -> float:
    """Signed offset [m] (+ left of the track's begin→end direction) of the point (px, py) of
    ``tl``'s plane from its centreline at ``pos``."""
    if tl.xy.shape[0] < 2:
        return float("nan")
    x, y, ux, uy = tl.point(pos)
    return float(-(px - x) * uy + (py - y) * ux)


class Moment(Protocol):
    """What the evidence reads of a moment: its time, unsigned travel and the run's travel."""

    @property
    def t(self) -> float: ...
    @property
    def d(self) -> float: ...
    @property
    def travel(self) -> Travel: ...


class At(NamedTuple):
    """A :class:`Moment` remembered (:meth:`TrackGpsAid.flush`)."""

    t: float
    d: float
    travel: Travel


def offsets_at(tl: TrackLine, pos: FloatArray, px: list[float], py: list[float]) -> list[float]:
    """:func:`offset` of each point (px_k, py_k) at each ``pos``_k at once, on the centreline
    points of :meth:`TrackLine.points` (the same numbers as :meth:`TrackLine.point` one at a
    time) by the same operations as :func:`offset`."""
    x, y, ux, uy = tl.points(pos)
    out: list[float] = (-(np.asarray(px) - x) * uy + (np.asarray(py) - y) * ux).tolist()
    return out


def quad(r: FloatArray, sigma_w: float, sigma_b: float, t: FloatArray | None = None, tau_s: float = math.inf) -> float:
    """Q = rᵀC⁻¹r of one candidate's offsets (module docstring); see :func:`quads`."""
    return float(quads(np.atleast_2d(r), sigma_w, sigma_b, t, tau_s)[0])


def quads(
    r: FloatArray, sigma_w: float, sigma_b: float, t: FloatArray | None = None, tau_s: float = math.inf
) -> FloatArray:
    """Q_j = r_jᵀC⁻¹r_j for each row of the (candidates × fixes) offsets, with the fixes' error
    covariance C_ik = σ_w²·δ_ik + σ_b²·exp(−|t_i − t_k|/τ) (a Gauss–Markov bias of correlation
    time τ plus white noise; τ = ∞ or no times: the constant bias C = σ_w²·I + σ_b²·11ᵀ, whose
    Q is (Σr² − σ_b²(Σr)²/(σ_w² + n·σ_b²))/σ_w² by Sherman–Morrison). One Cholesky
    factorisation C = LLᵀ serves every candidate: Q_j = |L⁻¹r_j|²."""
    n = r.shape[1]
    if t is None or not math.isfinite(tau_s):
        corr = np.ones((n, n))
    elif tau_s <= 0.0:
        corr = np.eye(n)
    else:
        tt = np.asarray(t, dtype=float)
        corr = np.exp(-np.abs(tt[:, None] - tt[None, :]) / tau_s)
    c = sigma_b**2 * corr + sigma_w**2 * np.eye(n)
    z = np.linalg.solve(np.linalg.cholesky(c), np.asarray(r, dtype=float).T)
    return np.asarray(np.sum(z * z, axis=0), dtype=float)


def chi2_upper(p: float, n: int) -> float:
    """The χ²(n) quantile p by Wilson and Hilferty (1931): n·(1 − 2/(9n) + z_p·√(2/(9n)))³, z_p
    the standard normal quantile (stdlib; SciPy stays out of ``trainpos run``). Slightly above
    the exact value for small n (n = 1, p = 0.9999: 16.2 against 15.1), so a restart is, if
    anything, later."""
    z = NormalDist().inv_cdf(p)
    a = 2.0 / (9.0 * n)
    return float(n * (1.0 - a + z * math.sqrt(a)) ** 3)


def gps_llr(
    offsets: FloatArray, sigma_w: float, sigma_b: float, t: FloatArray | None = None, tau_s: float = math.inf
) -> FloatArray:
    """LLR[a, b] = ½(Q_b − Q_a) for the (candidates × fixes) offsets (:func:`quads`)."""
    q = quads(np.asarray(offsets, dtype=float), sigma_w, sigma_b, t, tau_s)
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
    planes: dict[tuple[float, float], tuple[list[float], list[float]]] = field(
        default_factory=dict, repr=False, kw_only=True
    )
    """The fixes in each track's local plane, made on first use (shared by the aids made from one)."""
    t_list: list[float] = field(default_factory=list, repr=False, kw_only=True)
    """:meth:`fix_times`, made on first use."""

    def fix_times(self) -> list[float]:
        """``t`` as a list, for ``bisect`` at every scheduling (the index ``np.searchsorted``
        gives: the times are in order)."""
        if not self.t_list and self.t.size:
            self.t_list.extend(self.t.tolist())
        return self.t_list

    def plane(self, tl: TrackLine) -> tuple[list[float], list[float]]:
        """The fixes in ``tl``'s local plane [m] (:meth:`TrackLine.plane`, elementwise: the same
        numbers as one fix at a time)."""
        xy = self.planes.get(tl.origin)
        if xy is None:
            x, y = tl.plane(self.lat, self.lon)
            xy = self.planes[tl.origin] = (x.tolist(), y.tolist())
        return xy

    def plane_of(self, tl: TrackLine, j: int) -> tuple[float, float]:
        """Fix ``j`` in ``tl``'s local plane [m] (:meth:`plane`)."""
        xy = self.plane(tl)
        return xy[0][j], xy[1][j]


@dataclass(eq=False)
class TrackGpsAid(NetworkFixes):
    """The GPS offset test (module docstring)."""

    antenna_x_m: float = 0.0
    name: str = "track_gps"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    lane = True
    """Heard in the engine's lane (:mod:`fieldlogs.pipeline.aid`): it keeps no view past a call."""
    key: tuple[int, ...] = ()
    """Lineage ids of the candidates the evidence is held for."""
    times: list[float] = field(default_factory=list)
    """Times of the fixes of the evidence."""
    cols: dict[int, list[float]] = field(default_factory=dict)
    """Per candidate lineage: its offsets at ``times`` (its ancestors' before a split)."""
    tracks: dict[int, str] = field(default_factory=dict)
    """Per candidate lineage of the current set: its track (a split's parent is found by it)."""
    last_d: float = float("-inf")
    """Unsigned travel at the last fix used."""
    set_t: float = float("-inf")
    """Time the current candidate set began."""
    prev: tuple[float, list[float]] | None = None
    """(t, offsets) of the last fix seen, for the jump test."""
    jump_t: float = float("-inf")
    """Time of the last jump seen."""
    pending: list[tuple[float, float, float, int, Fix]] = field(default_factory=list, init=False, repr=False)
    """(t, d, S, fix index, estimate) of the fixes heard on a single candidate, not yet in the
    evidence (:meth:`flush`)."""
    travel: Travel | None = field(default=None, init=False, repr=False)
    """The run's travel (:meth:`flush` works the pending fixes in with it)."""
    key_fix: Fix | None = field(default=None, init=False, repr=False)
    fix_key: tuple[int, ...] = field(default=(), init=False, repr=False)
    """The estimate :meth:`_key_of` last saw and its candidates' lineage ids."""

    def observations(self) -> list[Observation]:
        return []

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or not fix.hyps:
            return None
        ts = self.fix_times()
        j = bisect.bisect_right(ts, view.t)
        return Observation(ts[j], j) if j < len(ts) else None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        if fix is not None and len(fix.hyps) == 1:
            # one candidate: nothing to decide, its evidence only kept for the next split — worked
            # in when next needed, a stretch of fixes at once (:meth:`flush`)
            self.travel = view.travel
            self.pending.append((view.t, view.d, view.s, obs.payload, fix))
            if len(self.pending) >= MAX_PENDING:
                self.flush()  # the same evidence whenever it is worked in: bounded memory on a long run
            return Outcome()
        self.flush()
        if fix is None or not fix.hyps:
            self.prev, self.key = None, ()
            self._keep([])
            return Outcome()
        off = self._offsets(fix, view.s, obs.payload)
        return self._test(fix, view) if self._hear(fix, view, off) else Outcome()

    def _hear(self, fix: Fix, at: Moment, off: list[float]) -> bool:
        """Work the fix at ``at`` (its candidates' offsets ``off``) into the evidence; whether the
        test may run on it (module docstring)."""
        single = len(fix.hyps) < 2
        if self._jumped(at.t, off):
            self.jump_t = at.t
            self._keep([])  # no evidence across a jump
        elif single and (fix.state != PositionState.DETERMINED or self._gap(at.t)):
            self._keep([])  # the track before a split: determined, fixes in a row
        key = self._key_of(fix)
        if key != self.key:
            self._begin(fix, at)  # a new candidate set: its evidence from the fixes before it
            self.key = key
        if at.d - self.last_d < MIN_SPACING_M:
            return False  # standing: no independent evidence
        self.last_d = at.d
        self._append(at.t, dict(zip(key, off, strict=True)))
        # a jump in or just before this evidence: no GPS decision on it (docstring)
        return not (single or self.jump_t >= self.set_t - self.gps.jump_hold_s)

    def flush(self) -> None:
        """Work the fixes heard on a single candidate since the last call into the evidence, in
        their order, as if each had been when heard (:meth:`_hear`; a single candidate never
        decides anything): their offsets computed at once (:func:`offsets_at`)."""
        pend, self.pending = self.pending, []
        if not pend or self.travel is None:
            return
        travel = self.travel
        pos = [
            h.pos_m + h.kp * (s - fix.s_ref) + h.kp * self.antenna_x_m for _t, _d, s, _j, fix in pend for h in fix.hyps
        ]
        off = [0.0] * len(pend)
        by_track: dict[str, list[int]] = {}
        for k, row in enumerate(pend):
            by_track.setdefault(row[4].hyps[0].track_id, []).append(k)
        for track_id, ks in by_track.items():
            tl = self.lines[track_id]
            if tl.xy.shape[0] >= 2:
                xs, ys = self.plane(tl)
                js = [pend[k][3] for k in ks]
                o = offsets_at(tl, np.asarray([pos[k] for k in ks]), [xs[j] for j in js], [ys[j] for j in js])
            else:
                o = [math.nan] * len(ks)
            for k, v in zip(ks, o, strict=True):
                off[k] = pend[k][4].hyps[0].kp * v  # + left of body-forward
        for (t, d, _s, _j, fix), v in zip(pend, off, strict=True):
            self._hear(fix, At(t, d, travel), [v])

    def _key_of(self, fix: Fix) -> tuple[int, ...]:
        """The candidates' lineage ids (made once per estimate: it is asked at every fix)."""
        if self.key_fix is not fix:
            self.key_fix, self.fix_key = fix, tuple(h.hid for h in fix.hyps)
        return self.fix_key

    def _test(self, fix: Fix, view: EngineView) -> Outcome:
        """The sequential test on the evidence (module docstring)."""
        r = np.asarray([self.cols[h.hid] for h in fix.hyps], dtype=float)
        if not np.isfinite(r).all():
            return Outcome()
        sw, sb = max(self.gps.noise_white_m, 1e-3), self.gps.noise_sigma_m
        q = quads(r, sw, sb, np.asarray(self.times, dtype=float), self.gps.noise_tau_s)
        if float(q.min()) > chi2_upper(1.0 - self.cfg.alpha, r.shape[1]):
            self._keep([-1])  # no candidate explains the fixes: start again from this one
            return Outcome()
        # a pair is decided only on gps_min_fixes fixes at which the two candidates' offsets differ
        # (not the common track before their split): too few for a multipath step to show (docstring)
        apart = (r[:, None, :] != r[None, :, :]).sum(axis=2)
        llr = np.where(apart >= self.cfg.gps_min_fixes, 0.5 * (q[None, :] - q[:, None]), -np.inf)
        detail: dict[str, Any] = {
            "evidence": "gps",
            "fixes": int(apart.max()),
            "llr": round(float(np.max(llr)), 2) if np.isfinite(llr).any() else None,
            "after_switch_m": after_switch_m(fix.hyps, view.d),
        }
        return resolve(fix, kept(llr, self.cfg.threshold), view, self.lines, detail)

    def _gap(self, t: float) -> bool:
        return bool(self.times) and t - self.times[-1] > self.gps.max_gap_s

    def _keep(self, rows: list[int]) -> None:
        """Keep only the evidence rows ``rows`` (indexes into ``times``)."""
        self.times = [self.times[k] for k in rows] if self.times else []
        self.cols = {h: [c[k] for k in rows] for h, c in self.cols.items()} if self.times else {}
        if not self.times:
            self.last_d = float("-inf")

    def _append(self, t: float, offsets: dict[int, float]) -> None:
        if len(self.times) >= MAX_ROWS:
            self._keep(list(range(len(self.times) - MAX_PREFIX, len(self.times))))
        if not self.times:
            self.cols = {}
        self.times.append(t)
        for h, o in offsets.items():
            self.cols.setdefault(h, []).append(o)

    def _begin(self, fix: Fix, view: Moment) -> None:
        """The evidence of a new candidate set (module docstring, *evidence before the set*): each
        candidate's lineage's offsets — its own, or its parent's before a split (the candidate of
        the last set on the track it came from) — when every candidate has one; otherwise the fixes
        before now evaluated on every candidate's own track, dead reckoned back."""
        self.set_t = view.t
        old = dict(self.cols)
        parent = {h.hid: h.hid for h in fix.hyps if h.hid in old}
        on = {t: hid for hid, t in self.tracks.items() if hid in old}
        for h in fix.hyps:
            if h.hid not in parent and h.came_from is not None and h.came_from[0] in on:
                parent[h.hid] = on[h.came_from[0]]
        if self.times and len(parent) == len(fix.hyps):
            self.cols = {h.hid: list(old[parent[h.hid]]) for h in fix.hyps}
        else:
            back = self._backfill(fix, view)
            self.times = [t for t, _ in back]
            self.cols = {h.hid: [o[k] for _, o in back] for k, h in enumerate(fix.hyps)}
            self.last_d = float(np.interp(back[-1][0], view.travel.t, view.travel.d)) if back else float("-inf")
        self.tracks = {h.hid: h.track_id for h in fix.hyps}

    def _backfill(self, fix: Fix, view: Moment) -> list[tuple[float, list[float]]]:
        """Trusted fixes before ``view.t`` (newest first until one lies more than
        ``gps.max_gap_s`` from the next, a candidate's dead-reckoned antenna leaves its own track,
        or ``MAX_PREFIX`` are taken; at least ``MIN_SPACING_M`` of travel apart), each with its
        offset from every candidate's track there, oldest first, cut after the last jump in them."""
        out: list[tuple[float, list[float]]] = []
        j = int(np.searchsorted(self.t, view.t, side="left")) - 1
        t_next, d_next = view.t, view.d
        lo = j + 1
        sd: tuple[list[float], list[float]] = ([], [])
        while j >= 0 and len(out) < MAX_PREFIX:
            tj = float(self.t[j])
            if t_next - tj > self.gps.max_gap_s:
                break
            if j < lo:  # the travel at the next fixes back, vectorised (np.interp is elementwise)
                lo = max(j - 2 * MAX_PREFIX, 0)
                sd = self._travel_at(view.travel, lo, j + 1)
            s_j, d_j = sd[0][j - lo], sd[1][j - lo]
            if not all(self._inside(h, fix, s_j) for h in fix.hyps):
                break
            if d_next - d_j >= MIN_SPACING_M:
                out.append((tj, self._offsets(fix, s_j, j)))
                d_next = d_j
            t_next, j = tj, j - 1
        out.reverse()
        for k in range(len(out) - 1, 0, -1):
            if np.all(np.abs(np.subtract(out[k][1], out[k - 1][1])) > self.jump_limit):
                self.jump_t = max(self.jump_t, out[k][0])
                return out[k:]
        return out

    @cached_property
    def jump_limit(self) -> float:
        """The jump test's limit on a fix-to-fix change of an offset: ``gps_jump_sigma``·σ_w·√2."""
        return self.cfg.gps_jump_sigma * max(self.gps.noise_white_m, 1e-3) * math.sqrt(2.0)

    def _travel_at(self, travel: Travel, j0: int, j1: int) -> tuple[list[float], list[float]]:
        """S and d interpolated at fixes ``j0 ≤ j < j1``."""
        tj = self.t[j0:j1]
        return np.interp(tj, travel.t, travel.s).tolist(), np.interp(tj, travel.t, travel.d).tolist()

    def _inside(self, h: Hypothesis, fix: Fix, s: float) -> bool:
        pos = h.pos_m + h.kp * (s - fix.s_ref) + h.kp * self.antenna_x_m
        return 0.0 <= pos <= self.lines[h.track_id].length_m

    def _jumped(self, t: float, off: list[float]) -> bool:
        """No candidate's offset can have moved by noise since the last fix (every |Δr_j| beyond
        ``gps_jump_sigma``·σ_w·√2, the last fix at most ``gps.max_gap_s`` before; a single
        previous offset — the track the candidates split from — is compared with each)."""
        prev, self.prev = self.prev, (t, off)
        if prev is None or t - prev[0] > self.gps.max_gap_s:
            return False
        before = prev[1] * len(off) if len(prev[1]) == 1 else prev[1]
        if len(before) != len(off):  # (a single offset against a single one: compared as it is)
            return False
        limit = self.jump_limit
        if len(off) == 1:
            return abs(off[0] - before[0]) > limit
        return all(abs(a - b) > limit for a, b in zip(off, before, strict=True))

    def _offsets(self, fix: Fix, s: float, j: int) -> list[float]:
        """Each candidate's offset (+ left of body-forward) from its track at signed travel ``s``
        of fix ``j``."""
        out = []
        for h in fix.hyps:
            pos = h.pos_m + h.kp * (s - fix.s_ref) + h.kp * self.antenna_x_m
            tl = self.lines[h.track_id]
            out.append(h.kp * offset(tl, pos, *self.plane_of(tl, j)))  # + left of body-forward
        return out
