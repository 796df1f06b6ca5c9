"""Per-cycle positions and margins from the sequence of fixes (vectorised).

Between fixes the position is dead reckoning (:mod:`fieldlogs.pipeline.estimate`), so the
engine only records the fixes; every cycle's state, km and margin follow from the fix in
force — the same numbers a per-cycle loop would give, without a Python step per 100 ms.

Margin [S000 §4.3.2] (|position error| ≤ margin must hold on every claimed cycle):

    margin = u_fix + p·|d − d_ref| + (A(d) − A_ref)  [+ q·|d − d_uncertain| while uncertain]

u_fix the fix's own uncertainty (balise 1 m, feature ≥ 10 m, GPS 10 m), p =
``margin.distance_pct`` (2 %) of the travel since the fix's reference point, A the
odometry's cumulative slip-correction budget ½·Δa·T² per episode (eq. 13) with A_ref its
value at the reference point, and q = ``margin.uncertain_growth_pct`` (5 %) of the travel
since a fail-safe made the position uncertain. The paper's margin adds a fixed 20 m per
slip; here each slip adds its own eq. 13 budget instead (22.8 m for a 10 s correction,
less for shorter ones), which the accuracy bench shows to hold.
"""

from __future__ import annotations

from typing import Any, overload

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.topology import all_tracks, implied_track_id
from fieldlogs.pipeline.claims import claims, entries, max_margin
from fieldlogs.pipeline.config import MarginConfig
from fieldlogs.pipeline.estimate import Travel
from fieldlogs.pipeline.geometry import VehicleGeometry
from fieldlogs.pipeline.hypotheses import TrackLine, track_lines
from fieldlogs.pipeline.metric import IDENTITY
from fieldlogs.pipeline.types import Fix, FloatArray
from schemas.enums import FixSource, PositionState


@overload
def margin_m(fix: Fix, d: float, allowance: float, cfg: MarginConfig) -> float: ...
@overload
def margin_m(fix: Fix, d: FloatArray, allowance: FloatArray, cfg: MarginConfig) -> FloatArray: ...
def margin_m(fix: Fix, d: FloatArray | float, allowance: FloatArray | float, cfg: MarginConfig) -> FloatArray | float:
    """The margin of the module docstring for ``fix`` at travel ``d`` and slip budget ``allowance``
    (one travel as floats: the same operations on floats, as the aids ask at every observation)."""
    if isinstance(d, float) and isinstance(allowance, float):
        return margin_at(fix, d, allowance, cfg)
    d_a = np.asarray(d, dtype=float)
    slip = np.maximum(np.asarray(allowance, dtype=float) - fix.allowance_ref_m, 0.0)
    return np.asarray(_grown(fix, d_a, slip, cfg), dtype=float)


def margin_at(fix: Fix, d: float, allowance: float, cfg: MarginConfig) -> float:
    """:func:`margin_m` of one travel ``d`` and slip budget ``allowance`` as floats (what the
    aids ask at every observation)."""
    return float(_grown(fix, d, max(allowance - fix.allowance_ref_m, 0.0), cfg))


def margins(
    fixes: list[Fix], sizes: npt.NDArray[np.int64], d: FloatArray, allowance: FloatArray, cfg: MarginConfig
) -> FloatArray:
    """:func:`margin_m` of many fixes at once: ``d`` and ``allowance`` hold ``sizes[j]`` cycles of
    fix j after those of fix j − 1; the same elementwise operations with each fix's numbers
    repeated over its cycles (the growth while uncertain only on the cycles of fixes that are)."""

    def rep(values: list[float]) -> FloatArray:
        return np.repeat(np.array(values, dtype=float), sizes)

    m = rep([f.uncertainty_m for f in fixes]) + cfg.distance_pct / 100.0 * np.abs(d - rep([f.d_ref for f in fixes]))
    m = m + np.maximum(allowance - rep([f.allowance_ref_m for f in fixes]), 0.0)
    since = rep([np.nan if f.uncertain_since_d is None else f.uncertain_since_d for f in fixes])
    u = ~np.isnan(since)
    m[u] = m[u] + cfg.uncertain_growth_pct / 100.0 * np.abs(d[u] - since[u])
    return m


def _grown(fix: Fix, d: Any, slip: Any, cfg: MarginConfig) -> Any:
    """U + distance_pct·|d − d_ref| + slip (+ uncertain_growth_pct·|d − d_uncertain|), of floats or arrays."""
    m = fix.uncertainty_m + cfg.distance_pct / 100.0 * abs(d - fix.d_ref)
    m = m + slip
    if fix.uncertain_since_d is not None:
        m = m + cfg.uncertain_growth_pct / 100.0 * abs(d - fix.uncertain_since_d)
    return m


def text_column(codes: npt.NDArray[np.uint8], values: dict[str, int]) -> npt.NDArray[np.object_]:
    """The object column whose cell i is the str of code ``codes[i]`` in ``values`` (str → code):
    every cell a reference to one of those few str objects. ``np.full(n, "text", dtype=object)``
    makes a new str per cell instead (the fill goes through a fixed-width unicode array), ≈ 60 B
    a cycle per column — 50 MB each for a day at 10 Hz, only to be read once into Arrow."""
    pool = np.empty(len(values), dtype=object)
    for text, code in values.items():
        pool[code] = text
    return np.take(pool, codes)


def positions_frame(
    travel: Travel, fixes: list[Fix], cfg: MarginConfig, geometry: VehicleGeometry | None = None
) -> pd.DataFrame:
    """Per-cycle state, track, km, equipment km, margin and source from the fixes in force, and
    the vehicle's head and tail km (:mod:`fieldlogs.pipeline.geometry`; NaN without its
    extent). A fix with network candidates (:mod:`fieldlogs.pipeline.hypotheses`) is dead-reckoned
    per candidate along its track: one gives track, pos and km; several give state
    ``ambiguous``, no track or km, and the ``candidates`` column
    (:func:`~fieldlogs.pipeline.claims.claims`)."""
    geometry = geometry or VehicleGeometry()
    t = travel.t
    n = t.size
    # state and source as codes of their few distinct texts (the enums' values), made text once
    cols = _Columns(n)
    if fixes:
        t_eff = np.array([f.t_effective for f in fixes])
        idx = np.searchsorted(t_eff, t, side="right") - 1
        cyc = np.flatnonzero(idx >= 0)
        j = idx[cyc]
        order = np.argsort(j, kind="stable")  # cycles grouped by fix in force, ascending
        groups, first = np.unique(j[order], return_index=True)
        single: list[tuple[Fix, npt.NDArray[np.int64]]] = []  # one candidate each: at once
        for jj, sel in zip(groups.tolist(), np.split(cyc[order], first[1:]), strict=True):
            f = fixes[jj]  # the fix in force on cycles ``sel``: dead reckoning and margin
            if f.state == PositionState.UNDETERMINED:
                continue
            if len(f.hyps) == 1:
                single.append((f, sel))
            else:
                cols.fill(travel, f, sel, cfg)
        cols.fill_single(travel, single, cfg)
    head, tail = geometry.ends(cols.km, cols.k_sign, np.asarray(travel.cab, dtype=float))
    return pd.DataFrame(
        {
            "t": t,
            "state": text_column(cols.state, cols.states),
            "line_code": pd.array(cols.line, dtype="string"),
            "track": pd.array(cols.track, dtype="string"),
            "track_id": pd.array(cols.track_id, dtype="string"),
            "pos_m": cols.pos,
            "km_m": cols.km,
            "km_equipment_m": cols.km_eq,
            "speed_mps": travel.v,
            "margin_m": cols.margin,
            "last_fix_source": pd.array(text_column(cols.source, cols.sources), dtype="string"),
            "km_head_m": head,
            "km_tail_m": tail,
            "candidates": pd.array(cols.candidates, dtype="string"),
        }
    )


class _Columns:
    """The per-cycle columns of :func:`positions_frame`, filled one fix at a time."""

    def __init__(self, n: int) -> None:
        self.states, self.sources = {PositionState.UNDETERMINED.value: 0}, {FixSource.NONE.value: 0}
        self.state = np.zeros(n, dtype=np.uint8)
        self.source = np.zeros(n, dtype=np.uint8)
        self.line = np.full(n, None, dtype=object)  # None: one object, every cell shares it
        self.track = np.full(n, None, dtype=object)
        self.track_id = np.full(n, None, dtype=object)
        self.candidates = np.full(n, None, dtype=object)
        self.km, self.km_eq, self.pos = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
        self.margin, self.k_sign = np.full(n, np.nan), np.full(n, np.nan)
        self._ids: dict[str | None, str | None] = {None: None}
        self._run_motion: FloatArray | None = None

    def interned(self, text: str | None) -> str | None:
        """One str object per track id (the cells share it, as the other text columns do)."""
        return self._ids.setdefault(text, text)

    def fill(self, travel: Travel, f: Fix, sel: npt.NDArray[np.int64], cfg: MarginConfig) -> None:
        base = margin_m(f, travel.d[sel], travel.allowance[sel], cfg)
        state = np.full(sel.size, self.code(str(f.state)), dtype=np.uint8)
        if f.hyps:
            self._network(travel, f, sel, base, state)
        else:
            est = travel.km(f, travel.s[sel])
            self._claim(sel, est, est + (f.km_equipment_m - f.km_m), legacy_pos(travel, f, est), base, f.k)
            self.line[sel], self.track[sel] = f.line_code, f.track
            self.track_id[sel] = self.interned(legacy_track_id(travel, f))
        self.state[sel] = state
        self.source[sel] = self.sources.setdefault(str(f.source), len(self.sources))

    def fill_single(self, travel: Travel, items: list[tuple[Fix, npt.NDArray[np.int64]]], cfg: MarginConfig) -> None:
        """:meth:`fill` of many fixes with one candidate each, at once: the same elementwise
        operations on the fixes' cycles laid end to end, each fix's numbers repeated over its
        own (the margin of :func:`margin_m`, pos = pos_h + kp·(S − s_ref), km per track). A fix
        whose interval reaches over an end of its track on some cycle has neighbours there
        (:func:`~fieldlogs.pipeline.claims.entries`): :meth:`fill` on its own."""
        if not items:
            return
        if travel.network is None:
            raise ValueError("a fix with network candidates needs the travel's network")
        lines = track_lines(travel.network)
        fs = [f for f, _ in items]
        hs = [f.hyps[0] for f in fs]
        tls = [lines[h.track_id] for h in hs]
        sizes = np.array([sel.size for _, sel in items])
        sel = np.concatenate([sel for _, sel in items])

        def rep(values: list[float]) -> FloatArray:
            return np.repeat(np.array(values, dtype=float), sizes)

        m = margins(fs, sizes, travel.d[sel], travel.allowance[sel], cfg)
        pos = rep([h.pos_m for h in hs]) + rep([h.kp for h in hs]) * (travel.s[sel] - rep([f.s_ref for f in fs]))
        mh = m + rep([h.extra_m for h in hs])
        over = (pos - mh < 0) | (pos + mh > rep([tl.length_m for tl in tls]))
        alone = ~np.logical_or.reduceat(over, np.cumsum(sizes) - sizes)
        for (f, own), ok in zip(items, alone.tolist(), strict=True):
            if not ok:
                self.fill(travel, f, own, cfg)
        keep = np.repeat(alone, sizes)
        which = np.repeat(np.arange(len(fs)), sizes)[keep]  # each cycle's fix
        sel, pos, mh = sel[keep], pos[keep], mh[keep]
        km = np.full(sel.size, np.nan)
        first: dict[str, int] = {}
        on_track = np.array([first.setdefault(h.track_id, j) for j, h in enumerate(hs)])[which]
        for j in np.unique(on_track).tolist():  # km per track, over all its fixes' cycles
            on = on_track == j
            km[on] = tls[j].km_of_pos(pos[on])
        eq = km + np.array([_eq_offset(f) for f in fs])[which]
        k_sign = np.array([h.kp * tl.km_sign for h, tl in zip(hs, tls, strict=True)], dtype=float)[which]
        self._claim(sel, km, eq, pos, mh, k_sign)
        self._texts(sel, which, fs, tls)

    def _texts(
        self, sel: npt.NDArray[np.int64], which: npt.NDArray[np.int64], fs: list[Fix], tls: list[TrackLine]
    ) -> None:
        """State, source, line, track and track id of single-candidate fixes ``fs`` on cycles
        ``sel`` (``which``: each cycle's fix)."""
        code = np.array([self.code(str(f.state)) for f in fs], dtype=np.uint8)
        src = np.array([self.sources.setdefault(str(f.source), len(self.sources)) for f in fs], dtype=np.uint8)
        cell = np.empty((len(fs), 3), dtype=object)
        cell[:] = [
            (tl.line_code or None, tl.track or None, self.interned(f.hyps[0].track_id))
            for f, tl in zip(fs, tls, strict=True)
        ]
        self.line[sel], self.track[sel], self.track_id[sel] = cell[which, 0], cell[which, 1], cell[which, 2]
        self.state[sel], self.source[sel] = code[which], src[which]

    def code(self, state: str) -> int:
        return self.states.setdefault(state, len(self.states))

    def _network(
        self, travel: Travel, f: Fix, sel: npt.NDArray[np.int64], base: FloatArray, state: npt.NDArray[np.uint8]
    ) -> None:
        """A fix with candidates (:mod:`fieldlogs.pipeline.claims`): determined cycles claim the
        one track; ambiguous ones list the candidates (and keep km where they agree on it)."""
        if travel.network is None:
            raise ValueError("a fix with network candidates needs the travel's network")
        lines = track_lines(travel.network)
        if self._run_motion is None:
            self._run_motion = _motion(travel)  # the run's, once: every fix reads its cycles of it
        ents = entries(f, travel.s[sel], self._run_motion[sel], base, lines)
        cl = claims(ents)
        own = ents[0]
        tl = lines[own.track_id]
        self._claim(sel, own.km, own.km + _eq_offset(f), own.pos, own.margin, own.kp * tl.km_sign)
        det = sel[~cl.ambiguous]
        self.line[det], self.track[det], self.track_id[det] = (
            tl.line_code or None,
            tl.track or None,
            self.interned(own.track_id),
        )
        amb = sel[cl.ambiguous]
        if amb.size:
            state[cl.ambiguous] = self.code(PositionState.AMBIGUOUS.value)
            self.candidates[amb] = np.array(cl.text, dtype=object)[cl.ambiguous]
            self.margin[amb] = max_margin(ents)[cl.ambiguous]
            self.pos[amb] = np.nan
            keep = sel[cl.same_line]
            self.line[keep], self.track[keep] = tl.line_code or None, tl.track or None
            lost = sel[cl.ambiguous & ~cl.same_line]
            self.km[lost], self.km_eq[lost], self.k_sign[lost] = np.nan, np.nan, np.nan

    def _claim(
        self,
        sel: npt.NDArray[np.int64],
        km: FloatArray,
        km_eq: FloatArray,
        pos: FloatArray,
        margin: FloatArray,
        k: int | FloatArray,
    ) -> None:
        self.km[sel], self.km_eq[sel], self.pos[sel], self.margin[sel], self.k_sign[sel] = km, km_eq, pos, margin, k


def _motion(travel: Travel) -> FloatArray:
    """The sign of the signed travel's step into each cycle (0 standing; the first cycle: its next step)."""
    ds = np.diff(travel.s, prepend=travel.s[0])
    if ds.size > 1:
        ds[0] = ds[1]
    return np.sign(ds)


def _eq_offset(f: Fix) -> float:
    off = f.km_equipment_m - f.km_m
    return off if np.isfinite(off) else 0.0


def legacy_track_id(travel: Travel, f: Fix) -> str | None:
    """The implied track id of a line-based fix (None on a network that has no such track)."""
    if not f.line_code:
        return None
    tid = implied_track_id(f.line_code, f.track)
    net = travel.network
    if net is None or tid in net.cached(("positions", "track_ids"), lambda: set(all_tracks(net)["track_id"])):
        return tid
    return None


def legacy_pos(travel: Travel, f: Fix, km: FloatArray) -> FloatArray:
    """Distance along the implied line track from its lowest km (NaN without a line grid)."""
    m = travel.metric(f)
    if m is IDENTITY:
        return np.full(km.shape, np.nan)
    return np.asarray(m.c_of_km(km) - m.c[0], dtype=float)
