"""Feature-point rules (SPEC §3, [S000 Table 1], SPEC §5.3).

A feature (curve) is six rows with seq 1–6 in running order: straight, transition,
left|right (radius R > 0), transition, straight, none. Rows 1–2 are the entry straight,
3–4 bound the curve body (where |κ| ≥ (1/R)(1 − 20 %)), 5–6 are the exit straight.
``sign`` is +1 on D and S tracks (running toward increasing km) and −1 on U.

Structure:

* ``feature.rows`` (error) — not exactly six rows with seq 1, 2, …, 6. Fix: give the feature
  exactly six rows, numbered 1–6 in running order.
* ``feature.pattern`` (error) — a row's attribute breaks the Table-1 pattern. Fix: the
  attributes in running order are straight, transition, left or right, transition, straight,
  none.
* ``feature.order`` (error) — km not monotonic in running direction (sign·Δkm < 0 between
  rows, or a curve body of zero length). Fix: correct the km of the rows (in running
  direction; on U toward decreasing km).
* ``feature.straight_length`` (error) — entry or exit straight shorter than
  ``min_straight_m`` (20 m). Fix: correct the km of rows 1–2 or 5–6, or drop the feature if
  the straight is really that short.

Against the GIS grid (curvature κ at grid vertices, positive left of increasing km, see
:mod:`dbtools.rules.gis`):

* ``feature.outside_gis`` (error) — a row's km is outside the GIS range of its line/track. Fix:
  correct the row's km, line_code or track, or extend the GIS grid.
* ``feature.direction`` (error) — the mean GIS κ over the body (vertices between rows 3 and 4)
  turns the other way: a *left* curve in running direction has κ > 0 on D/S and κ < 0 on U
  (the U attribute is as seen running toward decreasing km). Fix: swap left and right (on U as
  seen running toward decreasing km), or check the track.
* ``feature.radius`` (error) — |mean κ| over the body outside (1/R)(1 ± ``feature_tolerance``).
  Fix: correct ``radius_m`` (or the km of rows 3–4) from the curve list; if the GIS is wrong,
  fix the grid.
* ``feature.straight`` (error) — max |κ| at the vertices of the entry (exit) straight above
  ``straight_kappa_max`` + :func:`stencil_leak` of the adjacent transition. Fix: move rows 2
  and 5 (the transitions' ends) to where the GIS is straight, or fix a kink in the grid.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.index import GridIndex
from dbtools.rules.common import Locator, capped, column, fmt_km, group_ids, py
from dbtools.rules.config import ValidationConfig
from schemas.enums import Attribute, Severity, Track
from schemas.findings import Finding
from schemas.tables import FEATURE_POINTS

T = FEATURE_POINTS.name
F64 = npt.NDArray[np.float64]
#: Allowed attributes of rows 1–6 [S000 Table 1].
PATTERN: tuple[tuple[str, ...], ...] = (
    (Attribute.STRAIGHT.value,),
    (Attribute.TRANSITION.value,),
    (Attribute.LEFT.value, Attribute.RIGHT.value),
    (Attribute.TRANSITION.value,),
    (Attribute.STRAIGHT.value,),
    (Attribute.NONE.value,),
)


def stencil_leak(kappa: F64, transition_m: F64, spacing_m: float) -> F64:
    """Curvature a straight's grid vertex shows because its forward neighbour lies in the
    curve: Menger curvature of (−h, 0), (0, 0), (h, y) is y/h², with y the offset of the
    track h metres past the tangent point, y(h) = κh³/(6L) for a clothoid of length L ≥ h,
    κ(L²/6 + L(h − L)/2 + (h − L)²/2) when the arc starts within h (κ/2 with no transition).

    E.g. R = 300 m, L = 36 m, h = 20 m → 3.1e-4 1/m (the grid cannot tell the last metre of a
    straight from a 3 200 m curve), so this is added to ``straight_kappa_max``.
    """
    h = spacing_m
    lt = np.maximum(np.asarray(transition_m, dtype=float), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        y_clothoid = h**3 / (6.0 * lt)
    y_arc = lt**2 / 6.0 + lt * (h - lt) / 2.0 + (h - lt) ** 2 / 2.0
    y = np.where(lt >= h, y_clothoid, y_arc)
    return np.asarray(np.abs(kappa) * y / h**2, dtype=np.float64)


class _RangeStats:
    """(mean, max |·|, count) of the finite values of an array over ranges ``lo:hi``: the means
    from prefix sums built once for every range asked (the body and both straights), the
    counts and maxima from the values of the ranges alone (no other array of the grid's size)."""

    def __init__(self, values: F64) -> None:
        self.values = values
        self.sums = np.zeros(values.size + 1)  # [0, cumsum of the finite values], in place
        finite = self.sums[1:]
        np.copyto(finite, values, where=np.isfinite(values))
        np.cumsum(finite, out=finite)

    def value(self, i: npt.NDArray[np.int64]) -> F64:
        """The values at ``i``."""
        return np.asarray(self.values[i], dtype=np.float64)

    def of(self, lo: npt.NDArray[np.int64], hi: npt.NDArray[np.int64]) -> tuple[F64, F64, F64]:
        """(mean, max |·|, count) of the finite ``values[lo:hi]`` for each pair of bounds."""
        mx = np.full(len(lo), np.nan)
        count = np.zeros(len(lo))
        nonempty = np.flatnonzero(hi > lo)
        if len(nonempty):
            size = hi[nonempty] - lo[nonempty]
            first = np.concatenate([[0], np.cumsum(size)[:-1]])  # each range's start in ``idx``
            idx = np.repeat(lo[nonempty] - first, size) + np.arange(int(size.sum()))
            v = self.values[idx]
            finite = np.isfinite(v)
            count[nonempty] = np.add.reduceat(finite.astype(np.int64), first)
            mx[nonempty] = np.fmax.reduceat(np.where(finite, np.abs(v), np.nan), first)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (self.sums[hi] - self.sums[lo]) / count
        return mean, mx, count


@dataclass(frozen=True)
class FeatureRows:
    """The feature-point columns as arrays, and how findings name a row. ``where`` holds the
    columns that name the feature's track (``line_code``, ``track`` in ``feature_points``;
    ``track_id`` in ``track_feature_points``) and ``km`` the row positions (``km_m`` or
    ``pos_m``, the column named ``pos_col``)."""

    table: str
    where: dict[str, npt.NDArray[Any]]
    fid: npt.NDArray[Any]
    seq: F64
    km: F64
    radius: F64
    attr: npt.NDArray[Any]
    config: ValidationConfig
    loc: Locator
    groups: npt.NDArray[np.int64]
    """The feature of each row (:func:`~dbtools.rules.common.group_ids` of the ``where``
    columns and ``feature_id``; −1 where one is missing)."""
    pos_col: str = "km_m"

    @classmethod
    def of(
        cls,
        fp: pd.DataFrame,
        config: ValidationConfig,
        loc: Locator,
        table: str = T,
        where: tuple[str, ...] = ("line_code", "track"),
        pos_col: str = "km_m",
    ) -> FeatureRows:
        fid, seq, km = column(fp, "feature_id"), column(fp, "seq"), column(fp, pos_col)
        radius, attr = column(fp, "radius_m"), column(fp, "attribute")
        cols = {c: column(fp, c) for c in where}
        groups = group_ids(fp, (*where, "feature_id"))
        return cls(table, cols, fid, seq, km, radius, attr, config, loc, groups, pos_col)

    @property
    def line(self) -> npt.NDArray[Any]:
        return self.where["line_code"]

    @property
    def track(self) -> npt.NDArray[Any]:
        return self.where["track"]

    def row_keys(self, i: int) -> dict[str, object]:
        return {**self.feat_keys(i), "seq": py(self.seq[i])}

    def feat_keys(self, i: int) -> dict[str, object]:
        return {**{c: py(v[i]) for c, v in self.where.items()}, "feature_id": py(self.fid[i])}

    def running(self, i: int) -> str:
        """The running direction of row ``i``'s track, for messages."""
        if self.pos_col == "km_m":
            return f"in the running direction of track {self.track[i]}"
        return f"from the begin of track {self.where['track_id'][i]}"

    def capped(self, rule: str, items: npt.NDArray[np.int64], build: Callable[[int], Finding]) -> list[Finding]:
        return capped(
            rule, Severity.ERROR, self.table, items, build, self.config.max_findings_per_rule, self.loc.file(self.table)
        )

    def finding(self, rule: str, message: str, at: int, **kw: Any) -> Finding:
        return Finding(rule, Severity.ERROR, self.table, message, **kw, **self.loc.at(self.table, at))


@dataclass(frozen=True)
class _Blocks:
    """Well-formed features: (k, 6) frame rows in seq order, with their km and running sign."""

    block: npt.NDArray[np.int64]
    k6: F64
    sign: F64
    step: F64
    """sign · Δkm between consecutive rows (k, 5)."""


def check_features(fp: pd.DataFrame, grid: GridIndex, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """All feature-point rules (see module docstring)."""
    if fp.empty:
        return []
    r = FeatureRows.of(fp, config, loc)
    out, in_gis = _outside_gis(r, grid)
    sign = np.where(r.track == Track.UP.value, -1.0, 1.0)
    found, b, order_bad = check_structure(r, sign)
    out += found
    if b is None:
        return out
    # against the GIS curvature: only well-formed features wholly inside the grid
    fi = np.flatnonzero(~order_bad & np.all(in_gis[b.block], axis=1))
    if len(fi) == 0 or grid.n < 3:
        return out
    g = _Blocks(b.block[fi], b.k6[fi], b.sign[fi], b.step[fi])
    kappa = _RangeStats(grid.shape(config.gis_spacing_m, config.km_epsilon_m).kappa)
    gid = grid.track_ids(r.line[g.block[:, 0]], r.track[g.block[:, 0]])
    out += _body(r, g, grid, gid, kappa)
    out += _straights(r, g, grid, gid, kappa)
    return out


def check_structure(r: FeatureRows, sign: F64) -> tuple[list[Finding], _Blocks | None, npt.NDArray[np.bool_]]:
    """``feature.rows``, ``feature.pattern``, ``feature.order`` and ``feature.straight_length``
    of the rows ``r`` (``sign`` per row: +1 where the running order is increasing position);
    the well-formed six-row blocks (None: none) and which of them break the order."""
    out, block = _six_rows(r)
    if len(block) == 0:
        return out, None, np.zeros(0, dtype=bool)
    out += _pattern(r, block)
    k6 = r.km[block]
    sg = sign[block[:, 0]]
    b = _Blocks(block, k6, sg, sg[:, None] * np.diff(k6, axis=1))
    with np.errstate(invalid="ignore"):
        order_bad = ~np.all(b.step >= 0, axis=1) | ~(b.step[:, 2] > 0)
    out += _order(r, b, order_bad)
    out += _straight_length(r, b, ~order_bad)
    return out, b, order_bad


def _outside_gis(r: FeatureRows, grid: GridIndex) -> tuple[list[Finding], npt.NDArray[np.bool_]]:
    """``feature.outside_gis`` (every row, whatever its feature looks like); rows in the grid."""
    line, track, km, eps = r.line, r.track, r.km, r.config.km_epsilon_m
    rows = np.flatnonzero(pd.notna(line) & pd.notna(track) & np.isfinite(km))
    rgid = grid.track_ids(line[rows], track[rows])
    kmin, kmax = grid.km_range(rgid)
    with np.errstate(invalid="ignore"):
        outside = (rgid < 0) | (km[rows] < kmin - eps) | (km[rows] > kmax + eps)

    def build(j: int) -> Finding:
        i = int(rows[j])
        known = rgid[j] >= 0
        return r.finding(
            "feature.outside_gis",
            f"km {fmt_km(km[i])} is outside the GIS range {fmt_km(kmin[j])}–{fmt_km(kmax[j])}"
            if known
            else f"no GIS grid for line {line[i]} track {track[i]}",
            i,
            keys=r.row_keys(i),
            value=py(km[i]),
            limit=[py(kmin[j]), py(kmax[j])] if known else None,
            column="km_m",
        )

    in_gis = np.zeros(len(km), dtype=bool)
    in_gis[rows[~outside]] = True
    return r.capped("feature.outside_gis", np.flatnonzero(outside), build), in_gis


def _six_rows(r: FeatureRows) -> tuple[list[Finding], npt.NDArray[np.int64]]:
    """``feature.rows``; the (k, 6) frame rows of the features with seq 1…6."""
    groups = r.groups
    keyed = np.flatnonzero(groups >= 0)
    if len(keyed) == 0:
        return [], np.zeros((0, 6), dtype=np.int64)
    fgid = groups[keyed]
    order = np.lexsort((np.nan_to_num(r.seq[keyed], nan=np.inf), fgid))
    rows, g = keyed[order], fgid[order]
    n_feat = int(g.max()) + 1
    counts = np.bincount(g, minlength=n_feat)
    first = np.searchsorted(g, np.arange(n_feat))
    six = np.flatnonzero(counts == 6)
    block = rows[first[six][:, None] + np.arange(6)]
    ok_seq = np.all(r.seq[block] == np.arange(1, 7), axis=1)
    bad_feat = np.sort(np.concatenate([np.flatnonzero(counts != 6), six[~ok_seq]]))

    def build(f: int) -> Finding:
        i = int(rows[first[f]])
        seqs = [py(r.seq[j]) for j in rows[first[f] : first[f] + counts[f]]]
        return r.finding(
            "feature.rows",
            f"feature has {counts[f]} row(s) with seq {seqs}; it needs exactly six, seq 1 to 6",
            i,
            keys=r.feat_keys(i),
            value=[None if s is None else int(s) for s in seqs],
            limit=[1, 2, 3, 4, 5, 6],
            column="seq",
        )

    return r.capped("feature.rows", bad_feat, build), np.asarray(block[ok_seq], dtype=np.int64)


def _pattern(r: FeatureRows, block: npt.NDArray[np.int64]) -> list[Finding]:
    """``feature.pattern``: each row's attribute against [S000 Table 1]."""
    a6 = r.attr[block]
    pat_bad = np.zeros(a6.shape, dtype=bool)
    for k, allowed in enumerate(PATTERN):
        pat_bad[:, k] = ~np.isin(a6[:, k], allowed)
    pr, pc = np.nonzero(pat_bad)

    def build(j: int) -> Finding:
        i = int(block[pr[j], pc[j]])
        return r.finding(
            "feature.pattern",
            f"row {pc[j] + 1} of the feature is '{a6[pr[j], pc[j]]}', expected {' or '.join(PATTERN[pc[j]])} "
            "(Table 1: straight, transition, left|right, transition, straight, none)",
            i,
            keys=r.row_keys(i),
            value=py(a6[pr[j], pc[j]]),
            limit=list(PATTERN[pc[j]]),
            column="attribute",
        )

    return r.capped("feature.pattern", np.arange(len(pr)), build)


def _order(r: FeatureRows, b: _Blocks, order_bad: npt.NDArray[np.bool_]) -> list[Finding]:
    """``feature.order``: km monotonic in running direction, a curve body of non-zero length."""

    def build(j: int) -> Finding:
        i = int(b.block[j, 0])
        word = "decreasing" if b.sign[j] < 0 else "increasing"
        return r.finding(
            "feature.order",
            f"{r.pos_col} of rows 1–6 ({', '.join(f'{v:g}' for v in b.k6[j])}) are not {word} {r.running(i)}",
            i,
            keys=r.feat_keys(i),
            value=[py(v) for v in b.k6[j]],
            limit=word,
            column=r.pos_col,
        )

    return r.capped("feature.order", np.flatnonzero(order_bad), build)


def _straight_length(r: FeatureRows, b: _Blocks, good: npt.NDArray[np.bool_]) -> list[Finding]:
    """``feature.straight_length``: entry (rows 1–2) and exit (rows 5–6) long enough."""
    out: list[Finding] = []
    min_m = r.config.min_straight_m
    for name, a, c in (("entry", 0, 1), ("exit", 4, 5)):
        bad = np.flatnonzero(good & (b.step[:, a] < min_m - r.config.km_epsilon_m))

        def short(j: int, name: str = name, a: int = a, c: int = c) -> Finding:
            return r.finding(
                "feature.straight_length",
                f"{name} straight (rows {a + 1}–{c + 1}) is {b.step[j, a]:.1f} m long; "
                f"at least {min_m:g} m is required",
                int(b.block[j, a]),
                keys=r.feat_keys(int(b.block[j, 0])),
                value=round(float(b.step[j, a]), 3),
                limit=min_m,
                column=r.pos_col,
            )

        out += r.capped("feature.straight_length", bad, short)
    return out


def _span(
    r: FeatureRows, b: _Blocks, grid: GridIndex, gid: npt.NDArray[np.int64], c0: int, c1: int
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """Grid points between rows c0 and c1 of each feature (ε-inclusive)."""
    eps = r.config.km_epsilon_m
    lo_km = np.minimum(b.k6[:, c0], b.k6[:, c1])
    hi_km = np.maximum(b.k6[:, c0], b.k6[:, c1])
    return grid.searchsorted(gid, lo_km - eps, "left"), grid.searchsorted(gid, hi_km + eps, "right")


def _body_curvature(r: FeatureRows, b: _Blocks, grid: GridIndex, gid: npt.NDArray[np.int64], kappa: _RangeStats) -> F64:
    """Mean GIS κ over the body (rows 3–4); a body shorter than the grid spacing takes the
    vertex nearest its middle."""
    lo, hi = _span(r, b, grid, gid, 2, 3)
    mean, _, count = kappa.of(lo, hi)
    empty = np.flatnonzero(count == 0)
    if len(empty):
        mid = 0.5 * (b.k6[empty, 2] + b.k6[empty, 3])
        j = grid.searchsorted(gid[empty], mid)
        j = np.clip(j, grid.start[gid[empty]], grid.end[gid[empty]] - 1)
        jm = np.maximum(j - 1, grid.start[gid[empty]])
        pick = np.where(np.abs(grid.km[jm] - mid) < np.abs(grid.km[j] - mid), jm, j)
        mean[empty] = kappa.value(pick)
    return mean


def _body(r: FeatureRows, b: _Blocks, grid: GridIndex, gid: npt.NDArray[np.int64], kappa: _RangeStats) -> list[Finding]:
    """``feature.direction`` and ``feature.radius`` from the mean κ over the body."""
    blk, sg, tol = b.block, b.sign, r.config.feature_tolerance
    R = r.radius[blk[:, 2]]
    att = r.attr[blk[:, 2]]
    mean = _body_curvature(r, b, grid, gid, kappa)
    curve = np.isfinite(mean) & np.isfinite(R) & (R > 0) & np.isin(att, PATTERN[2])
    expected = np.where(att == Attribute.LEFT.value, 1.0, -1.0) * sg
    with np.errstate(invalid="ignore", divide="ignore"):
        kap = np.abs(mean)
        dir_bad = curve & (mean * expected < 0) & (kap >= r.config.straight_kappa_max)
        rad_bad = curve & ((kap < (1 - tol) / R) | (kap > (1 + tol) / R))
        r_gis = 1.0 / kap

    def gis_side(j: int) -> str:
        left_in_km = mean[j] > 0
        return "left" if (left_in_km if sg[j] > 0 else not left_in_km) else "right"

    def direction(j: int) -> Finding:
        i = int(blk[j, 2])
        return r.finding(
            "feature.direction",
            f"the feature says {att[j]} but the GIS grid curves {gis_side(j)} between rows 3 and 4 "
            f"in the running direction of track {r.track[i]}",
            i,
            keys=r.row_keys(i),
            value=gis_side(j),
            limit=py(att[j]),
            column="attribute",
        )

    def radius(j: int) -> Finding:
        i = int(blk[j, 2])
        return r.finding(
            "feature.radius",
            f"radius {R[j]:g} m but the GIS grid gives {r_gis[j]:.0f} m between rows 3 and 4 "
            f"(allowed ±{tol:.0%} in curvature: {R[j] / (1 + tol):.0f}–{R[j] / (1 - tol):.0f} m)",
            i,
            keys=r.row_keys(i),
            value=round(float(r_gis[j]), 1) if np.isfinite(r_gis[j]) else None,
            limit=[round(float(R[j] / (1 + tol)), 1), round(float(R[j] / (1 - tol)), 1)],
            column="radius_m",
        )

    return r.capped("feature.direction", np.flatnonzero(dir_bad), direction) + r.capped(
        "feature.radius", np.flatnonzero(rad_bad), radius
    )


def _straights(
    r: FeatureRows, b: _Blocks, grid: GridIndex, gid: npt.NDArray[np.int64], kappa: _RangeStats
) -> list[Finding]:
    """``feature.straight``: entry (rows 1–2, transition rows 2–3) and exit (rows 5–6,
    transition 4–5) straight on the grid, allowing the stencil leak of the transition."""
    out: list[Finding] = []
    R = r.radius[b.block[:, 2]]
    tol = r.config.feature_tolerance
    with np.errstate(invalid="ignore"):
        kappa_r = np.where(np.isfinite(R) & (R > 0), 1.0 / np.where(R > 0, R, 1.0), 0.0)
    for name, c0, c1, t0, t1 in (("entry", 0, 1, 1, 2), ("exit", 4, 5, 3, 4)):
        lo, hi = _span(r, b, grid, gid, c0, c1)
        _, mx, count = kappa.of(lo, hi)
        lt = np.abs(b.k6[:, t1] - b.k6[:, t0]) / (1 - tol)
        limit = r.config.straight_kappa_max + stencil_leak(kappa_r, lt, r.config.gis_spacing_m)
        bad = np.flatnonzero((count > 0) & (mx > limit))

        def curved(j: int, name: str = name, c0: int = c0, c1: int = c1, limit: F64 = limit, mx: F64 = mx) -> Finding:
            i = int(b.block[j, c0])
            return r.finding(
                "feature.straight",
                f"the {name} straight (rows {c0 + 1}–{c1 + 1}) is not straight on the GIS grid: radius "
                f"≈ {1 / mx[j]:.0f} m, a straight here needs ≥ {1 / limit[j]:.0f} m",
                i,
                keys=r.row_keys(i),
                value=round(float(1 / mx[j]), 1),
                limit=round(float(1 / limit[j]), 1),
            )

        out += r.capped("feature.straight", bad, curved)
    return out
