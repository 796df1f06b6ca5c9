"""Feature-point rules (SPEC §3, [S000 Table 1], SPEC §5.3).

A feature (curve) is six rows with seq 1–6 in running order: straight, transition,
left|right (radius R > 0), transition, straight, none. Rows 1–2 are the entry straight,
3–4 bound the curve body (where |κ| ≥ (1/R)(1 − 20 %)), 5–6 are the exit straight.
``sign`` is +1 on D and S tracks (running toward increasing km) and −1 on U.

Structure:

* ``feature.rows`` (error) — not exactly six rows with seq 1, 2, …, 6.
* ``feature.pattern`` (error) — a row's attribute breaks the Table-1 pattern.
* ``feature.order`` (error) — km not monotonic in running direction (sign·Δkm < 0 between
  rows, or a curve body of zero length).
* ``feature.straight_length`` (error) — entry or exit straight shorter than
  ``min_straight_m`` (20 m).

Against the GIS grid (curvature κ at grid vertices, positive left of increasing km, see
:mod:`dbtools.rules.gis`):

* ``feature.outside_gis`` (error) — a row's km is outside the GIS range of its line/track.
* ``feature.direction`` (error) — the mean GIS κ over the body (vertices between rows 3 and 4)
  turns the other way: a *left* curve in running direction has κ > 0 on D/S and κ < 0 on U
  (the U attribute is as seen running toward decreasing km).
* ``feature.radius`` (error) — |mean κ| over the body outside (1/R)(1 ± ``feature_tolerance``).
* ``feature.straight`` (error) — max |κ| at the vertices of the entry (exit) straight above
  ``straight_kappa_max`` + :func:`stencil_leak` of the adjacent transition.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.rules.common import Locator, capped, column, fmt_km, py
from dbtools.rules.config import ValidationConfig
from dbtools.rules.gis import Grid
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
    return np.abs(kappa) * y / h**2


def _range_stat(values: F64, lo: npt.NDArray[np.int64], hi: npt.NDArray[np.int64]) -> tuple[F64, F64, F64]:
    """(mean, max |·|, count) of the finite ``values[lo:hi]`` for each pair of bounds."""
    finite = np.isfinite(values)
    v = np.where(finite, values, 0.0)
    cs = np.concatenate([[0.0], np.cumsum(v)])
    cn = np.concatenate([[0], np.cumsum(finite)])
    count = (cn[hi] - cn[lo]).astype(float)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = (cs[hi] - cs[lo]) / count
    mx = np.full(len(lo), np.nan)
    nonempty = np.flatnonzero(hi > lo)
    if len(nonempty):
        absval = np.append(np.where(finite, np.abs(values), np.nan), np.nan)
        idx = np.empty(2 * len(nonempty), dtype=np.int64)
        idx[0::2], idx[1::2] = lo[nonempty], hi[nonempty]
        mx[nonempty] = np.fmax.reduceat(absval, idx)[0::2]
    return mean, mx, count


def check_features(fp: pd.DataFrame, grid: Grid, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """All feature-point rules (see module docstring)."""
    out: list[Finding] = []
    if fp.empty:
        return out
    cap = config.max_findings_per_rule
    file = loc.file(T)
    line, track, fid = column(fp, "line_code"), column(fp, "track"), column(fp, "feature_id")
    seq, km, radius, attr = column(fp, "seq"), column(fp, "km_m"), column(fp, "radius_m"), column(fp, "attribute")

    def row_keys(i: int) -> dict[str, object]:
        return {"line_code": py(line[i]), "track": py(track[i]), "feature_id": py(fid[i]), "seq": py(seq[i])}

    def feat_keys(i: int) -> dict[str, object]:
        return {"line_code": py(line[i]), "track": py(track[i]), "feature_id": py(fid[i])}

    # feature.outside_gis (every row, whatever its feature looks like)
    rows = np.flatnonzero(pd.notna(line) & pd.notna(track) & np.isfinite(km))
    rgid = grid.group_of(line[rows], track[rows])
    kmin, kmax = grid.km_range(rgid)
    with np.errstate(invalid="ignore"):
        outside = (rgid < 0) | (km[rows] < kmin - config.km_epsilon_m) | (km[rows] > kmax + config.km_epsilon_m)
    out += capped(
        "feature.outside_gis",
        Severity.ERROR,
        T,
        np.flatnonzero(outside),
        lambda j: Finding(
            "feature.outside_gis",
            Severity.ERROR,
            T,
            (
                f"no GIS grid for line {line[rows[j]]} track {track[rows[j]]}"
                if rgid[j] < 0
                else f"km {fmt_km(km[rows[j]])} is outside the GIS range {fmt_km(kmin[j])}–{fmt_km(kmax[j])}"
            ),
            keys=row_keys(int(rows[j])),
            value=py(km[rows[j]]),
            limit=None if rgid[j] < 0 else [py(kmin[j]), py(kmax[j])],
            column="km_m",
            **loc.at(T, int(rows[j])),
        ),
        cap,
        file,
    )
    in_gis = np.zeros(len(fp), dtype=bool)
    in_gis[rows[~outside]] = True

    # group rows into features, ordered by seq
    keyed = np.flatnonzero(pd.notna(line) & pd.notna(track) & pd.notna(fid))
    if len(keyed) == 0:
        return out
    fgid = (
        pd.DataFrame({"l": line[keyed], "t": track[keyed], "f": fid[keyed]})
        .groupby(["l", "t", "f"], sort=False)
        .ngroup()
        .to_numpy()
    )
    order = np.lexsort((np.nan_to_num(seq[keyed], nan=np.inf), fgid))
    r = keyed[order]
    g = fgid[order]
    n_feat = int(g.max()) + 1
    counts = np.bincount(g, minlength=n_feat)
    first = np.searchsorted(g, np.arange(n_feat))
    six = np.flatnonzero(counts == 6)
    block = r[first[six][:, None] + np.arange(6)]  # (k, 6) frame rows
    ok_seq = np.all(seq[block] == np.arange(1, 7), axis=1)
    bad_feat = np.concatenate([np.flatnonzero(counts != 6), six[~ok_seq]])
    bad_feat.sort()

    def rows_finding(f: int) -> Finding:
        i = int(r[first[f]])
        seqs = [py(seq[j]) for j in r[first[f] : first[f] + counts[f]]]
        return Finding(
            "feature.rows",
            Severity.ERROR,
            T,
            f"feature has {counts[f]} row(s) with seq {seqs}; it needs exactly six, seq 1 to 6",
            keys=feat_keys(i),
            value=[None if s is None else int(s) for s in seqs],
            limit=[1, 2, 3, 4, 5, 6],
            column="seq",
            **loc.at(T, i),
        )

    out += capped("feature.rows", Severity.ERROR, T, bad_feat, rows_finding, cap, file)
    block = block[ok_seq]
    if len(block) == 0:
        return out

    # feature.pattern
    a6 = attr[block]
    pat_bad = np.zeros(a6.shape, dtype=bool)
    for k, allowed in enumerate(PATTERN):
        pat_bad[:, k] = ~np.isin(a6[:, k], allowed)
    pr, pc = np.nonzero(pat_bad)
    out += capped(
        "feature.pattern",
        Severity.ERROR,
        T,
        np.arange(len(pr)),
        lambda j: Finding(
            "feature.pattern",
            Severity.ERROR,
            T,
            f"row {pc[j] + 1} of the feature is '{a6[pr[j], pc[j]]}', expected {' or '.join(PATTERN[pc[j]])} "
            "(Table 1: straight, transition, left|right, transition, straight, none)",
            keys=row_keys(int(block[pr[j], pc[j]])),
            value=py(a6[pr[j], pc[j]]),
            limit=list(PATTERN[pc[j]]),
            column="attribute",
            **loc.at(T, int(block[pr[j], pc[j]])),
        ),
        cap,
        file,
    )

    # feature.order
    k6 = km[block]
    sign = np.where(track[block[:, 0]] == Track.UP.value, -1.0, 1.0)
    step = sign[:, None] * np.diff(k6, axis=1)
    with np.errstate(invalid="ignore"):
        order_bad = ~np.all(step >= 0, axis=1) | ~(step[:, 2] > 0)
    out += capped(
        "feature.order",
        Severity.ERROR,
        T,
        np.flatnonzero(order_bad),
        lambda j: Finding(
            "feature.order",
            Severity.ERROR,
            T,
            f"km of rows 1–6 ({', '.join(f'{v:g}' for v in k6[j])}) are not "
            f"{'decreasing' if sign[j] < 0 else 'increasing'} in the running direction of track "
            f"{track[block[j, 0]]}",
            keys=feat_keys(int(block[j, 0])),
            value=[py(v) for v in k6[j]],
            limit="decreasing" if sign[j] < 0 else "increasing",
            column="km_m",
            **loc.at(T, int(block[j, 0])),
        ),
        cap,
        file,
    )
    good = ~order_bad
    # feature.straight_length
    for name, a, b in (("entry", 0, 1), ("exit", 4, 5)):
        length = step[:, a]
        bad = np.flatnonzero(good & (length < config.min_straight_m - config.km_epsilon_m))

        def short(j: int, name: str = name, a: int = a, b: int = b) -> Finding:
            return Finding(
                "feature.straight_length",
                Severity.ERROR,
                T,
                f"{name} straight (rows {a + 1}–{b + 1}) is {step[j, a]:.1f} m long; "
                f"at least {config.min_straight_m:g} m is required",
                keys=feat_keys(int(block[j, 0])),
                value=round(float(step[j, a]), 3),
                limit=config.min_straight_m,
                column="km_m",
                **loc.at(T, int(block[j, a])),
            )

        out += capped("feature.straight_length", Severity.ERROR, T, bad, short, cap, file)

    # against the GIS curvature: only well-formed features wholly inside the grid
    fi = np.flatnonzero(good & np.all(in_gis[block], axis=1))
    if len(fi) == 0 or grid.n < 3:
        return out
    blk, k6f, sg = block[fi], k6[fi], sign[fi]
    gid = grid.group_of(line[blk[:, 0]], track[blk[:, 0]])
    R = radius[blk[:, 2]]
    att = attr[blk[:, 2]]

    def span(c0: int, c1: int) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
        lo_km = np.minimum(k6f[:, c0], k6f[:, c1])
        hi_km = np.maximum(k6f[:, c0], k6f[:, c1])
        lo = grid.searchsorted(gid, lo_km - config.km_epsilon_m, "left")
        hi = grid.searchsorted(gid, hi_km + config.km_epsilon_m, "right")
        return lo, hi

    lo, hi = span(2, 3)
    mean, _, count = _range_stat(grid.kappa, lo, hi)
    # body shorter than the grid spacing: the vertex nearest its middle
    empty = np.flatnonzero(count == 0)
    if len(empty):
        mid = 0.5 * (k6f[empty, 2] + k6f[empty, 3])
        j = grid.searchsorted(gid[empty], mid)
        j = np.clip(j, grid.start[gid[empty]], grid.end[gid[empty]] - 1)
        jm = np.maximum(j - 1, grid.start[gid[empty]])
        pick = np.where(np.abs(grid.km[jm] - mid) < np.abs(grid.km[j] - mid), jm, j)
        mean[empty] = grid.kappa[pick]
    tol = config.feature_tolerance
    curve = np.isfinite(mean) & np.isfinite(R) & (R > 0) & np.isin(att, PATTERN[2])
    expected = np.where(att == Attribute.LEFT.value, 1.0, -1.0) * sg
    with np.errstate(invalid="ignore", divide="ignore"):
        kap = np.abs(mean)
        dir_bad = curve & (mean * expected < 0) & (kap >= config.straight_kappa_max)
        rad_bad = curve & ((kap < (1 - tol) / R) | (kap > (1 + tol) / R))
        r_gis = 1.0 / kap

    def gis_side(j: int) -> str:
        left_in_km = mean[j] > 0
        return "left" if (left_in_km if sg[j] > 0 else not left_in_km) else "right"

    out += capped(
        "feature.direction",
        Severity.ERROR,
        T,
        np.flatnonzero(dir_bad),
        lambda j: Finding(
            "feature.direction",
            Severity.ERROR,
            T,
            f"the feature says {att[j]} but the GIS grid curves {gis_side(j)} between rows 3 and 4 "
            f"in the running direction of track {track[blk[j, 2]]}",
            keys=row_keys(int(blk[j, 2])),
            value=gis_side(j),
            limit=py(att[j]),
            column="attribute",
            **loc.at(T, int(blk[j, 2])),
        ),
        cap,
        file,
    )
    out += capped(
        "feature.radius",
        Severity.ERROR,
        T,
        np.flatnonzero(rad_bad),
        lambda j: Finding(
            "feature.radius",
            Severity.ERROR,
            T,
            f"radius {R[j]:g} m but the GIS grid gives {r_gis[j]:.0f} m between rows 3 and 4 "
            f"(allowed ±{tol:.0%} in curvature: {R[j] / (1 + tol):.0f}–{R[j] / (1 - tol):.0f} m)",
            keys=row_keys(int(blk[j, 2])),
            value=round(float(r_gis[j]), 1) if np.isfinite(r_gis[j]) else None,
            limit=[round(float(R[j] / (1 + tol)), 1), round(float(R[j] / (1 - tol)), 1)],
            column="radius_m",
            **loc.at(T, int(blk[j, 2])),
        ),
        cap,
        file,
    )

    # feature.straight: entry (rows 1–2, transition rows 2–3) and exit (rows 5–6, transition 4–5)
    with np.errstate(invalid="ignore"):
        kappa_r = np.where(np.isfinite(R) & (R > 0), 1.0 / np.where(R > 0, R, 1.0), 0.0)
    for name, c0, c1, t0, t1 in (("entry", 0, 1, 1, 2), ("exit", 4, 5, 3, 4)):
        lo, hi = span(c0, c1)
        _, mx, count = _range_stat(grid.kappa, lo, hi)
        lt = np.abs(k6f[:, t1] - k6f[:, t0]) / (1 - tol)
        limit = config.straight_kappa_max + stencil_leak(kappa_r, lt, config.gis_spacing_m)
        bad = np.flatnonzero((count > 0) & (mx > limit))

        def curved(j: int, name: str = name, c0: int = c0, c1: int = c1, limit: F64 = limit, mx: F64 = mx) -> Finding:
            return Finding(
                "feature.straight",
                Severity.ERROR,
                T,
                f"the {name} straight (rows {c0 + 1}–{c1 + 1}) is not straight on the GIS grid: radius "
                f"≈ {1 / mx[j]:.0f} m, a straight here needs ≥ {1 / limit[j]:.0f} m",
                keys=row_keys(int(blk[j, c0])),
                value=round(float(1 / mx[j]), 1),
                limit=round(float(1 / limit[j]), 1),
                **loc.at(T, int(blk[j, c0])),
            )

        out += capped("feature.straight", Severity.ERROR, T, bad, curved, cap, file)
    return out
