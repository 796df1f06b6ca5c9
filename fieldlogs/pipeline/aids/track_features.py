"""Feature points on the network's tracks: evidence of the track and corrections along it
[S000 §3.2, §4.3.2; SPEC §5.3, §8.3].

Feature tables per track
    ``track_feature_points`` give curves by pos (distance from the track's begin), rows 1…6
    and attributes as seen running begin → end; ``feature_points`` of a line and track are
    mapped onto each network track of that line and track that holds all six rows
    (:meth:`~fieldlogs.pipeline.hypotheses.TrackLine.pos_of_km`), reordered begin → end (rows
    6…1 with left/right swapped where km decreases along the track). Either way a candidate
    (track, kp) meets the rows in travel order u = kp·pos (:meth:`FeatureTable.travel_rows`
    with the normal direction +1).

Evidence (:class:`TrackFeatureAid`, while the position is ambiguous)
    For every candidate the next feature on its track is scheduled; the first one whose
    window is complete is tested. With u_a(i) = kp·pos of the candidate a owning the feature
    at cycle i, m the margin at the evaluation (plus a's ``extra_m``), and r2, r5 the rows
    where the curve's transitions begin and end (travel order), the window runs from the last
    cycle i0 with u_a ≤ r2 − m to the first cycle i1 with u_a ≥ r5 + m: if a is the true
    track the train is before the curve at i0 and beyond it at i1. The yaw rate gives the
    heading profile ψ_i = Σ_{i0 < j ≤ i} ωz,j·Δt_j over the window (net change Δψ = ψ_i1,
    span max ψ − min ψ, greatest rise and fall :func:`~fieldlogs.pipeline.track_heading.rises`).
    Each candidate c (margin m_c = m + its ``extra_m``, positions p0, p1 at i0, i1) allows,
    from the centrelines (:mod:`fieldlogs.pipeline.track_heading`, across joints with one
    exit):

    * a net change in [min ψ_end − max ψ_start, max ψ_end − min ψ_start], ψ_start the travel
      headings its track can have within p0 ± m_c, ψ_end the same at p1;
    * a span no larger than the headings' over [p0 − m_c, p1 + m_c];
    * a rise and a fall at least those of the chords lying wholly within [p0 + m_c, p1 − m_c]
      (:func:`~fieldlogs.pipeline.track_heading.sure_turns`: run over for certain);
    * for each curve of its feature tables wholly within [p0 + m_c, p1 − m_c] (rows 2–5), a
      turn its way of at least (r4 − r3 + (r3 − r2)/2 + (r5 − r4)/2)/R.

    Its violation δ_c is how far the profile lies outside the worst of these (a constraint
    whose geometry is unknown adds none, so unknown geometry never counts against a
    candidate). With σ² = (b_g·T)² + q²·T + σ_geo² as in
    :mod:`fieldlogs.pipeline.aids.track_imu` (T = t_i1 − t_i0), LLR_ab = (δ_b² − δ_a²) / (2σ²)
    and b is dropped when some a reaches Wald's A (``track_select.alpha``, ``beta``): the true
    candidate is dropped only if its own δ, a deviation of the gyro from the true track's
    turns, reaches √(2A)·σ. So a curve seen where one candidate has it and another runs
    straight drops the straight one, a straight run drops the curved one, and a curve of the
    same turn on two candidates decides nothing. No test when the sense of motion changes
    in the window or the yaw rate is missing; ``track_select.feature_headings`` = false
    switches the test off.

Correction (:class:`TrackFeatureFixAid`, while determined on one track)
    The S000 feature unit (:class:`~fieldlogs.pipeline.aids.features.FeatureUnit`: search
    margin, eight diagnostics, the exit crossing as correction point) runs on the candidate's
    pos instead of the line km, with the track form's features of its track: an accepted
    feature is an absolute fix on that track at pos r4 (travel order), a refused one a
    ``feature_refused`` event. Line-form features of a line track are the line aid's
    (:class:`~fieldlogs.pipeline.aids.feature_aid.FeatureAid`), so none is applied twice.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from dbtools.gis.geometry import arc_turn
from dbtools.network import Network
from fieldlogs.pipeline.aid import EngineView, Observation, Outcome, Priority
from fieldlogs.pipeline.aids.feature_table import Candidate, FeatureTable, line_feature_tables, load_tables
from fieldlogs.pipeline.aids.features import FeatureUnit, KmBetween
from fieldlogs.pipeline.aids.topology import with_hyps
from fieldlogs.pipeline.aids.track_imu import kept, resolve
from fieldlogs.pipeline.config import MarginConfig, TrackSelectConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.hypotheses import TrackLine, TrackLines, after_switch_m
from fieldlogs.pipeline.positions import margin_m
from fieldlogs.pipeline.track_heading import (
    headings,
    rises,
    span,
    sure_turns,
    turn_range,
    violation_llr,
)
from fieldlogs.pipeline.types import Event, Fix, FloatArray, Hypothesis
from schemas.enums import EventType, FixSource, PositionState

#: First window of the forward scan [cycles] (doubled until the feature is passed).
_CHUNK = 512


@dataclass(frozen=True)
class TrackFeatureTables:
    """Feature tables by track id, both normal directions begin → end (module docstring)."""

    own: dict[str, FeatureTable]
    """From ``track_feature_points``."""
    line: dict[str, FeatureTable]
    """From ``feature_points``, mapped onto the tracks along their line."""
    skipped: list[dict[str, Any]] = field(default_factory=list)

    def on(self, track_id: str) -> list[FeatureTable]:
        return [t for t in (self.own.get(track_id), self.line.get(track_id)) if t is not None]

    def __bool__(self) -> bool:
        return bool(self.own or self.line)


def _mapped(tab: FeatureTable, tl: TrackLine) -> FeatureTable | None:
    """The line table's features lying on ``tl`` (all six rows within its length), by pos."""
    pos = tl.pos_of_kms(tab.km).reshape(-1, 6)
    inside = np.isfinite(pos).all(axis=1) & (pos.min(axis=1) >= -0.5) & (pos.max(axis=1) <= tl.length_m + 0.5)
    if not inside.any():
        return None
    pos, left = pos[inside], tab.left[inside]
    forward = pos[:, 5] >= pos[:, 0]
    pos = np.where(forward[:, None], pos, pos[:, ::-1])
    left = np.where(forward, left, ~left)
    return FeatureTable("", tl.track_id, tab.feature_id[inside], pos, tab.radius_m[inside], left, 1)


def track_feature_tables(net: Network, lines: TrackLines) -> TrackFeatureTables:
    """Both forms of feature points per network track (module docstring); track-form
    features on a track the network does not have are skipped with that reason."""

    def build() -> TrackFeatureTables:
        own, skipped = load_tables(net.track_feature_points, where=("track_id",), position="pos_m")
        by_id: dict[str, FeatureTable] = {}
        for (_, tid), tab in own.items():
            if tid in lines.lines:
                by_id[tid] = tab
            else:
                skipped += [{"track_id": tid, "feature_id": f, "reason": "unknown track"} for f in tab.feature_id]
        line_tabs, _ = line_feature_tables(net)
        mapped: dict[str, FeatureTable] = {}
        for key, tab in line_tabs.items():
            for tl in lines.by_line.get(key, []):
                m = _mapped(tab, tl)
                if m is not None:
                    mapped[tl.track_id] = m
        return TrackFeatureTables(by_id, mapped, skipped)

    return net.cached(("track_features", "tables"), build)


def _u_at(h: Hypothesis, fix: Fix, s: FloatArray, kd: int) -> FloatArray:
    """u = kd·pos of candidate ``h`` of ``fix`` at signed travels ``s`` (kd = kp × the sense
    of motion: pos per metre of unsigned travel, so u grows as the train runs)."""
    return kd * (h.pos_m + h.kp * (np.asarray(s, dtype=float) - fix.s_ref))


@dataclass(frozen=True)
class _Test:
    """What the evidence test needs back at its observation."""

    hid: int
    track_id: str
    feature_id: str
    kp: int
    u: FloatArray
    """Rows r1…r6 in travel order."""
    radius_m: float


@dataclass(eq=False)
class TrackFeatureAid:
    """The heading test at feature points while the track is ambiguous (module docstring)."""

    tables: TrackFeatureTables
    lines: TrackLines
    wz: FloatArray
    """Yaw rate per cycle [rad/s]."""
    cfg: TrackSelectConfig
    margin: MarginConfig
    name: str = "track_feature"
    priority: Priority = Priority.TRACK
    needs_track: bool = True
    done: set[tuple[int, str, str, int]] = field(default_factory=set)
    """(candidate lineage, track, feature, kd) already tested."""
    _changes: npt.NDArray[np.int_] | None = field(default=None, repr=False)

    def observations(self) -> list[Observation]:
        return []

    def _bounds(self, tr: Travel, i: int) -> list[int]:
        """``i``, the cycles after it where the sense of motion changes, and the run's end."""
        if self._changes is None:
            mot = np.asarray(tr.motion)
            self._changes = np.flatnonzero(mot[1:] != mot[:-1]) + 1
        return [i, *self._changes[self._changes > i].tolist(), tr.n]

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        if fix is None or len(fix.hyps) < 2:
            return None
        tr = view.travel
        for s0, s1 in itertools.pairwise(self._bounds(tr, view.i)):
            mot = int(tr.motion[s0])
            best: tuple[int, _Test] | None = None
            for h in fix.hyps:
                for tab in self.tables.on(h.track_id):
                    nxt = self._next(h, fix, tab, tr, (s0, s1), mot)
                    if nxt is not None and (best is None or nxt[0] < best[0]):
                        best = nxt
            if best is not None:
                return Observation(max(float(tr.t[best[0]]), view.t), best[1])
        return None

    def _next(
        self, h: Hypothesis, fix: Fix, tab: FeatureTable, tr: Travel, seg: tuple[int, int], mot: int
    ) -> tuple[int, _Test] | None:
        """The first cycle of the motion segment ``seg`` at which the next untested feature of
        ``tab`` ahead of ``h`` has its window complete (u ≥ r5 + margin), with the test."""
        kd = h.kp * mot
        u_all, _, _ = tab.travel_rows(kd)
        i = seg[0]
        m_now = float(margin_m(fix, tr.d[i], tr.allowance[i], self.margin)) + h.extra_m
        u_now = float(_u_at(h, fix, tr.s[i : i + 1], kd)[0])
        ahead = np.flatnonzero(u_all[:, 4] + m_now >= u_now)
        for j in ahead[np.argsort(u_all[ahead, 4], kind="stable")]:
            fid = str(tab.feature_id[j])
            if (h.hid, h.track_id, fid, kd) in self.done:
                continue
            i_end = self._passed(h, fix, tr, seg, float(u_all[j, 4]), kd)
            if i_end is None:
                return None
            return i_end, _Test(h.hid, h.track_id, fid, kd, u_all[j].copy(), float(tab.radius_m[j]))
        return None

    def _passed(self, h: Hypothesis, fix: Fix, tr: Travel, seg: tuple[int, int], u5: float, kd: int) -> int | None:
        """First cycle of ``seg`` with u ≥ ``u5`` + margin (chunks of doubling length)."""
        a, step = seg[0], _CHUNK
        while a < seg[1]:
            b = min(a + step, seg[1])
            m = margin_m(fix, tr.d[a:b], tr.allowance[a:b], self.margin) + h.extra_m
            hit = np.flatnonzero(_u_at(h, fix, tr.s[a:b], kd) >= u5 + m)
            if hit.size:
                return a + int(hit[0])
            a, step = b, 2 * step
        return None

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        test: _Test = obs.payload
        self.done.add((test.hid, test.track_id, test.feature_id, test.kp))
        fix = view.estimate
        if fix is None or len(fix.hyps) < 2:
            return Outcome()
        tr, i1 = view.travel, view.i
        mot = int(tr.motion[i1])
        own = [h for h in fix.hyps if (h.hid, h.track_id, h.kp * mot) == (test.hid, test.track_id, test.kp)]
        if not own:
            return Outcome()
        m = float(margin_m(fix, tr.d[i1], tr.allowance[i1], self.margin))
        i0 = self._start(own[0], fix, tr, i1, float(test.u[1]) - m - own[0].extra_m, test.kp)
        if i0 is None:
            return Outcome()
        span = slice(i0 + 1, i1 + 1)
        w = self.wz[span]
        if not np.isfinite(w).all() or (tr.motion[i0 : i1 + 1] != tr.motion[i1]).any():
            return Outcome()
        prof = np.concatenate([[0.0], np.cumsum(w * np.diff(tr.t[i0 : i1 + 1]))])
        viol = [self._violation(h, h.kp * mot, fix, tr, (i0, i1), m + h.extra_m, prof) for h in fix.hyps]
        sigma = self._sigma(float(tr.t[i1] - tr.t[i0]))
        keep = kept(violation_llr(viol, sigma), self.cfg.threshold)
        detail: dict[str, Any] = {
            "evidence": "feature",
            "feature_id": test.feature_id,
            "feature_track_id": test.track_id,
            "R_m": test.radius_m,
            "heading_change_deg": round(math.degrees(float(prof[-1])), 3),
            "heading_span_deg": round(math.degrees(float(np.ptp(prof))), 3),
            "sigma_deg": round(math.degrees(sigma), 3),
            "violation_deg": {h.track_id: round(math.degrees(v), 3) for h, v in zip(fix.hyps, viol, strict=True)},
            "after_switch_m": after_switch_m(fix.hyps, view.d),
            "switch_id": next((h.switch_id for h in fix.hyps if h.switch_id), None),
        }
        return resolve(fix, keep, view, self.lines, detail)

    @staticmethod
    def _start(h: Hypothesis, fix: Fix, tr: Travel, i1: int, u_start: float, kd: int) -> int | None:
        """The last cycle before ``i1`` with u ≤ ``u_start`` (None: not in the data)."""
        u1 = float(_u_at(h, fix, tr.s[i1 : i1 + 1], kd)[0])
        i_lo = int(np.searchsorted(tr.d, tr.d[i1] - (u1 - u_start) - 50.0, side="left"))
        before = np.flatnonzero(_u_at(h, fix, tr.s[i_lo:i1], kd) <= u_start)
        return None if before.size == 0 or i_lo + int(before[-1]) == 0 else i_lo + int(before[-1])

    def _violation(
        self, h: Hypothesis, kd: int, fix: Fix, tr: Travel, ends: tuple[int, int], m: float, prof: FloatArray
    ) -> float:
        """δ_h: how far the heading profile ``prof`` over cycles ``ends`` lies outside what
        candidate ``h`` (running ``kd`` along its track, margin ``m``) allows — the largest of
        the three violations of the module docstring; a constraint whose geometry is unknown
        adds none."""
        p0, p1 = (h.pos_m + h.kp * (float(tr.s[i]) - fix.s_ref) for i in ends)
        out = 0.0
        start = headings(self.lines, h.track_id, kd, p0 - m, p0 + m)
        end = headings(self.lines, h.track_id, kd, p1 - m, p1 + m)
        if start is not None and end is not None:
            lo, hi = turn_range(start, end)
            out = max(out, lo - float(prof[-1]), float(prof[-1]) - hi)
        whole = headings(self.lines, h.track_id, kd, min(p0, p1) - m, max(p0, p1) + m)
        if whole is not None:
            out = max(out, float(np.ptp(prof)) - span(whole))
        left, right = rises(prof)
        sure_left, sure_right = sure_turns(self.lines, h.track_id, kd, min(p0, p1) + m, max(p0, p1) - m)
        out = max(out, sure_left - left, sure_right - right)
        u0, u1 = kd * p0 + m, kd * p1 - m
        for tab in self.tables.on(h.track_id):
            u_all, _, sign = tab.travel_rows(kd)
            for j in np.flatnonzero((u_all[:, 1] >= u0) & (u_all[:, 4] <= u1)):
                need = arc_turn(u_all[j], float(tab.radius_m[j]))
                out = max(out, need - (left if sign[j] > 0 else right))
        return max(out, 0.0)

    def _sigma(self, dur: float) -> float:
        c = self.cfg
        return math.sqrt(
            (math.radians(c.gyro_bias_dps) * dur) ** 2
            + math.radians(c.gyro_noise_dps_rthz) ** 2 * dur
            + math.radians(c.heading_geometry_deg) ** 2
        )


@dataclass(eq=False)
class TrackFeatureFixAid:
    """S000 feature corrections along a determined track (module docstring)."""

    unit: FeatureUnit
    tables: dict[str, FeatureTable]
    """Track-form features by track id."""
    lines: TrackLines
    name: str = "track_feature_fix"
    priority: Priority = Priority.FEATURE
    needs_track: bool = True

    def observations(self) -> list[Observation]:
        return []

    @staticmethod
    def _pos(fix: Fix, h: Hypothesis, tr: Travel) -> KmBetween:
        """pos of ``h`` on cycles [i0, i1) (the feature unit's ``km_between``)."""

        def pos_between(i0: int, i1: int) -> FloatArray:
            s = tr.s[max(i0, 0) : min(i1, tr.n)]
            return np.asarray(h.pos_m + h.kp * (s - fix.s_ref), dtype=float)

        return pos_between

    def _on(self, fix: Fix | None) -> tuple[Hypothesis, FeatureTable] | None:
        if fix is None or fix.state != PositionState.DETERMINED or len(fix.hyps) != 1:
            return None
        tab = self.tables.get(fix.hyps[0].track_id)
        return None if tab is None else (fix.hyps[0], tab)

    def next_observation(self, view: EngineView) -> Observation | None:
        fix = view.estimate
        on = self._on(fix)
        if fix is None or on is None:
            return None
        h, tab = on
        nxt = self.unit.next_evaluation(fix, view.i, self._pos(fix, h, view.travel), tab, h.kp)
        if nxt is None:
            return None
        i_eval, cand = nxt
        return Observation(float(view.travel.t[i_eval]), cand)

    def observe(self, obs: Observation, view: EngineView) -> Outcome:
        fix = view.estimate
        on = self._on(fix)
        cand: Candidate = obs.payload
        if fix is None or on is None or on[0].track_id != cand.track:
            return Outcome()
        h = on[0]
        tr = view.travel
        out = self.unit.evaluate(cand, fix, self._pos(fix, h, tr), view.i)
        detail = {"feature_id": out.feature_id, "track_id": h.track_id, **out.detail}
        if not (out.accepted and out.i_ref is not None and out.km_db is not None):
            if out.detail.get("not_judged"):  # an arc shorter than the κ smoothing (FeatureUnit._arc_unjudged)
                return Outcome()
            return Outcome([Event(view.t, EventType.FEATURE_REFUSED, view.km, detail={**detail, "failed": out.failed})])
        s_ref = float(tr.s[out.i_ref])
        pos_comp = h.pos_m + h.kp * (s_ref - fix.s_ref)
        tl = self.lines[h.track_id]
        km_db = float(tl.km_of_pos(out.km_db))
        # the correction amount in km where the track has km, else along the track
        amount = (float(tl.km_of_pos(pos_comp)) - km_db) if math.isfinite(km_db) else pos_comp - out.km_db
        detail["pos_db_m"] = round(out.km_db, 3)
        km = km_db if math.isfinite(km_db) else None
        ev = Event(view.t, EventType.FEATURE_CORRECTION, km, amount, detail=detail)
        nan = float("nan")
        unc = max(out.uncertainty_m or 0.0, self.unit.cfg.fix_uncertainty_m)
        base = Fix(view.t, s_ref, float(tr.d[out.i_ref]), nan, nan, "", "", 1, FixSource.FEATURE, unc)
        base = replace(base, t_ref=float(tr.t[out.i_ref]))
        new = with_hyps(base, [replace(h, pos_m=out.km_db, extra_m=0.0)], view.t, s_ref, self.lines)
        return Outcome([ev], replace(new, carried=False))
