"""GIS grid rules (SPEC §3): the 20 m kilometrage grid of every line and track.

Everything is computed once, vectorised over the whole network, in :class:`Grid`: points
sorted by (line, track, km), a group id per line/track, plane coordinates (each line in the
JGD2011 zone of its median point), geodesic step lengths, segment headings, turn angles and
the Menger curvature at every vertex whose two neighbouring steps are regular 20 m steps.
The feature-point and balise rules reuse the same :class:`Grid`.

Rules:

* ``gis.km_grid`` (error) — km is not a multiple of the grid spacing (20 m).
* ``gis.km_step`` (error) — consecutive km of a line/track do not differ by 20 m and the
  jump is not listed in ``km_breaks`` (a duplicate km is ``schema.duplicate_key``).
* ``gis.km_break_unused`` (warning) — a ``km_breaks`` row matches no jump of the grid.
* ``gis.step_length`` (error) — the geodesic distance between consecutive points is not
  consistent with their km difference Δ: it must lie in
  [chord(Δ, R_min) − tol, Δ + tol], tol = ``step_tolerance_m`` + ``step_tolerance_rel``·Δ,
  where chord(Δ, R) = 2R·sin(Δ/2R) is the chord of an arc of length Δ and
  R_min = spacing / ``spike_max_turn_rad`` the tightest radius the grid accepts.
* ``gis.spike`` (error) — the angle between consecutive 20 m segments exceeds
  ``spike_max_turn_rad``.
* ``gis.track_spacing`` (warning / error) — on a double-track line the U and D points of
  the same km are closer than ``track_spacing_warning_m`` (``…_error_m``) where the two
  tracks are parallel (heading difference < ``parallel_max_rad``); consecutive offending
  points are reported as one finding per stretch.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import Projector, geodesic_step, signed_curvature
from dbtools.rules.common import Locator, capped, column, fmt_km, py, wrap_angle
from dbtools.rules.config import ValidationConfig
from schemas.enums import Severity, Track
from schemas.findings import Finding
from schemas.tables import GIS, KM_BREAKS, LAT_RANGE, LON_RANGE

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


@dataclass
class Grid:
    """Valid GIS points (all of line, track, km, lat, lon present, finite and inside the
    operating area), sorted by (line, track, km), with derived geometry (see module doc)."""

    pos: I64
    """Row of each point in the ``gis`` frame."""
    gid: I64
    """Group id (one per line/track), non-decreasing."""
    group_line: npt.NDArray[np.object_]
    group_track: npt.NDArray[np.object_]
    start: I64
    """First point of each group."""
    end: I64
    """One past the last point of each group."""
    km: F64
    x: F64
    y: F64
    dkm: F64
    """km step to the next point (length n − 1; NaN across groups)."""
    dist: F64
    """Geodesic distance to the next point [m] (length n − 1)."""
    regular: npt.NDArray[np.bool_]
    """The step to the next point is one grid spacing within the same group (length n − 1)."""
    turn: F64
    """Signed angle between the segments before and after a vertex [rad] (NaN unless both
    steps are regular)."""
    kappa: F64
    """Signed Menger curvature at a vertex [1/m], positive left of increasing km (NaN unless
    both steps are regular)."""
    heading: F64
    """Direction of increasing km at a vertex [rad] (chord of the neighbouring points)."""

    @property
    def n(self) -> int:
        return len(self.km)

    def group_of(self, lines: npt.NDArray[np.object_], tracks: npt.NDArray[np.object_]) -> I64:
        """Group id of each (line, track), −1 where the grid has no such group."""
        if len(lines) == 0:
            return np.zeros(0, dtype=np.int64)
        groups = pd.MultiIndex.from_arrays([self.group_line.astype(str), self.group_track.astype(str)])
        query = pd.MultiIndex.from_arrays([np.asarray(lines).astype(str), np.asarray(tracks).astype(str)])
        return np.asarray(groups.get_indexer(query), dtype=np.int64)

    def km_range(self, gid: I64) -> tuple[F64, F64]:
        """(first km, last km) of each group id (NaN for −1)."""
        ok = gid >= 0
        lo = np.full(len(gid), np.nan)
        hi = np.full(len(gid), np.nan)
        lo[ok] = self.km[self.start[gid[ok]]]
        hi[ok] = self.km[self.end[gid[ok]] - 1]
        return lo, hi

    def searchsorted(self, gid: I64, km: F64, side: str = "left") -> I64:
        """Index of the first point of group ``gid`` with km ≥ ``km`` ('left') or > ('right').

        Queries before (after) a group's range get its first index (one past its last)."""
        gid = np.asarray(gid, dtype=np.int64)
        km = np.asarray(km, dtype=float)
        lo_km, hi_km = self.km[self.start[gid]], self.km[self.end[gid] - 1]
        inside = (km >= lo_km) & (km <= hi_km)
        out = np.where(km < lo_km, self.start[gid], self.end[gid]).astype(np.int64)
        q = np.flatnonzero(inside)
        if len(q):
            out[q] = np.searchsorted(self._key, self._key_of(gid[q], km[q]), side=side)  # type: ignore[call-overload]
        return out

    def _key_of(self, gid: I64, km: F64) -> F64:
        """Order-preserving float key: group id + position of km inside the group's range."""
        lo = self.km[self.start[gid]]
        return gid + (km - lo) / self._span[gid]

    def __post_init__(self) -> None:
        if self.n:
            first, last = self.km[self.start], self.km[self.end - 1]
            self._span = (last - first) * (1 + 1e-9) + 1.0
            self._key = self._key_of(self.gid, self.km)
        else:
            self._span = np.zeros(0)
            self._key = np.zeros(0)


def build_grid(gis: pd.DataFrame, config: ValidationConfig) -> Grid:
    line, track = column(gis, "line_code"), column(gis, "track")
    km, lat, lon = column(gis, "km_m"), column(gis, "lat"), column(gis, "lon")
    with np.errstate(invalid="ignore"):
        ok = (
            pd.notna(line)
            & pd.notna(track)
            & np.isfinite(km)
            & (lat >= LAT_RANGE[0])
            & (lat <= LAT_RANGE[1])
            & (lon >= LON_RANGE[0])
            & (lon <= LON_RANGE[1])
        )
    pos = np.flatnonzero(ok)
    lcode, luniq = pd.factorize(pd.Series(line[pos], dtype=object), sort=True)
    tcode, tuniq = pd.factorize(pd.Series(track[pos], dtype=object), sort=True)
    order = np.lexsort((km[pos], tcode, lcode))
    pos, lcode, tcode = pos[order], lcode[order], tcode[order]
    km, lat, lon = km[pos], lat[pos], lon[pos]
    n = len(pos)
    pair = lcode.astype(np.int64) * max(len(tuniq), 1) + tcode
    new_group = np.ones(n, dtype=bool)
    new_group[1:] = pair[1:] != pair[:-1]
    gid = np.cumsum(new_group) - 1
    start = np.flatnonzero(new_group)
    end = np.append(start[1:], n).astype(np.int64)
    group_line = np.asarray(luniq, dtype=object)[lcode[start]]
    group_track = np.asarray(tuniq, dtype=object)[tcode[start]]

    # plane coordinates: each line in the zone of its median point
    x, y = np.full(n, np.nan), np.full(n, np.nan)
    new_line = np.ones(n, dtype=bool)
    new_line[1:] = lcode[1:] != lcode[:-1]
    lstart = np.flatnonzero(new_line)
    lend = np.append(lstart[1:], n)[: len(lstart)]
    zone_of_point = np.empty(n, dtype=np.int64)
    for s, e in zip(lstart, lend, strict=True):
        zone_of_point[s:e] = Projector.for_points(lat[s:e], lon[s:e]).zone
    for zone in np.unique(zone_of_point):
        idx = np.flatnonzero(zone_of_point == zone)
        x[idx], y[idx] = Projector(int(zone)).to_xy(lon[idx], lat[idx])

    same = gid[1:] == gid[:-1]
    dkm = np.where(same, np.diff(km), np.nan)
    regular = same & (np.abs(dkm - config.gis_spacing_m) <= config.km_epsilon_m)
    dist = geodesic_step(lon, lat) if n > 1 else np.zeros(0)

    both = np.zeros(n, dtype=bool)
    both[1:-1] = regular[:-1] & regular[1:]
    seg_h = np.arctan2(np.diff(y), np.diff(x)) if n > 1 else np.zeros(0)
    turn = np.full(n, np.nan)
    turn[1:-1] = wrap_angle(seg_h[1:] - seg_h[:-1])
    turn[~both] = np.nan
    kappa = signed_curvature(x, y)
    kappa[~both] = np.nan
    # heading at a vertex: chord of its neighbours, else the one regular step it has
    heading = np.full(n, np.nan)
    if n > 1:
        heading[1:-1] = np.arctan2(y[2:] - y[:-2], x[2:] - x[:-2])
        heading[~both] = np.nan
        fwd = np.zeros(n, dtype=bool)
        fwd[:-1] = regular
        back = np.zeros(n, dtype=bool)
        back[1:] = regular
        use_fwd = ~both & fwd
        use_back = ~both & ~fwd & back
        heading[use_fwd] = seg_h[np.flatnonzero(use_fwd)]
        heading[use_back] = seg_h[np.flatnonzero(use_back) - 1]
    return Grid(
        pos=pos,
        gid=gid.astype(np.int64),
        group_line=group_line,
        group_track=group_track,
        start=start.astype(np.int64),
        end=end,
        km=km,
        x=x,
        y=y,
        dkm=dkm,
        dist=dist,
        regular=regular,
        turn=turn,
        kappa=kappa,
        heading=heading,
    )


def _gis_keys(grid: Grid, i: int) -> dict[str, object]:
    g = grid.gid[i]
    return {"line_code": py(grid.group_line[g]), "track": py(grid.group_track[g]), "km_m": py(grid.km[i])}


def _break_steps(grid: Grid, km_breaks: pd.DataFrame, config: ValidationConfig) -> tuple[np.ndarray, np.ndarray]:
    """(steps listed as km breaks, km_breaks rows that match no step)."""
    is_break = np.zeros(max(grid.n - 1, 0), dtype=bool)
    if km_breaks.empty or grid.n < 2:
        return is_break, np.arange(len(km_breaks))
    lines, tracks = column(km_breaks, "line_code"), column(km_breaks, "track")
    k_from, k_to = column(km_breaks, "km_from_m"), column(km_breaks, "km_to_m")
    ok = pd.notna(lines) & pd.notna(tracks) & np.isfinite(k_from) & np.isfinite(k_to)
    gid = np.full(len(km_breaks), -1, dtype=np.int64)
    gid[ok] = grid.group_of(lines[ok], tracks[ok])
    rows = np.flatnonzero(gid >= 0)
    i = np.minimum(grid.searchsorted(gid[rows], k_from[rows] - config.km_epsilon_m), grid.n - 2)
    hit = (
        (grid.gid[i] == gid[rows])
        & (grid.gid[i + 1] == gid[rows])
        & (np.abs(grid.km[i] - k_from[rows]) <= config.km_epsilon_m)
        & (np.abs(grid.km[i + 1] - k_to[rows]) <= config.km_epsilon_m)
    )
    is_break[i[hit]] = True
    used = np.zeros(len(km_breaks), dtype=bool)
    used[rows[hit]] = True
    unused = np.flatnonzero(~used)
    return is_break, np.asarray(unused, dtype=np.int64)


def check_gis(
    grid: Grid, gis: pd.DataFrame, km_breaks: pd.DataFrame, config: ValidationConfig, loc: Locator
) -> list[Finding]:
    """All GIS rules (see module docstring)."""
    del gis  # the grid carries everything; kept in the signature for symmetry with the others
    out: list[Finding] = []
    cap = config.max_findings_per_rule
    T = GIS.name
    file = loc.file(T)
    sp = config.gis_spacing_m

    def at(i: int) -> dict[str, Any]:
        return loc.at(T, int(grid.pos[i]))

    # gis.km_grid
    off = np.abs(grid.km - sp * np.round(grid.km / sp))
    bad = np.flatnonzero(off > config.km_epsilon_m)
    out += capped(
        "gis.km_grid",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "gis.km_grid",
            Severity.ERROR,
            T,
            f"km {fmt_km(grid.km[i])} is not on the {sp:g} m grid",
            keys=_gis_keys(grid, i),
            value=py(grid.km[i]),
            limit=f"multiple of {sp:g} m",
            column="km_m",
            **at(i),
        ),
        cap,
        file,
    )

    # gis.km_step, gis.km_break_unused
    is_break, unused = _break_steps(grid, km_breaks, config)
    with np.errstate(invalid="ignore"):
        irregular = ~grid.regular & ~is_break & (grid.dkm > config.km_epsilon_m)
    bad = np.flatnonzero(irregular)
    out += capped(
        "gis.km_step",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "gis.km_step",
            Severity.ERROR,
            T,
            f"km jumps from {fmt_km(grid.km[i])} to {fmt_km(grid.km[i + 1])} ({grid.dkm[i]:g} m, not {sp:g} m) "
            "and the jump is not listed in km_breaks",
            keys=_gis_keys(grid, i + 1),
            value=py(grid.dkm[i]),
            limit=sp,
            column="km_m",
            **at(i + 1),
        ),
        cap,
        file,
    )
    bfile = loc.file(KM_BREAKS.name)
    out += capped(
        "gis.km_break_unused",
        Severity.WARNING,
        KM_BREAKS.name,
        unused,
        lambda r: Finding(
            "gis.km_break_unused",
            Severity.WARNING,
            KM_BREAKS.name,
            "no consecutive GIS points of this line/track jump from km_from_m to km_to_m",
            keys={k: py(km_breaks[k].iat[r]) for k in KM_BREAKS.primary_key},
            value=py(km_breaks["km_to_m"].iat[r]),
            **loc.at(KM_BREAKS.name, r),
        ),
        cap,
        bfile,
    )

    # gis.step_length
    if grid.n > 1:
        dk = grid.dkm
        tol = config.step_tolerance_m + config.step_tolerance_rel * np.abs(dk)
        r_min = sp / config.spike_max_turn_rad
        chord = 2 * r_min * np.sin(np.minimum(np.abs(dk) / (2 * r_min), np.pi / 2))
        lo, hi = chord - tol, dk + tol
        with np.errstate(invalid="ignore"):
            check = (dk > config.km_epsilon_m) & ~is_break
            bad = np.flatnonzero(check & ((grid.dist < lo) | (grid.dist > hi) | ~np.isfinite(grid.dist)))
        out += capped(
            "gis.step_length",
            Severity.ERROR,
            T,
            bad,
            lambda i: Finding(
                "gis.step_length",
                Severity.ERROR,
                T,
                f"points {grid.dist[i]:.2f} m apart but their km differ by {dk[i]:g} m (from km {fmt_km(grid.km[i])})",
                keys=_gis_keys(grid, i + 1),
                value=round(float(grid.dist[i]), 3),
                limit=[round(float(lo[i]), 3), round(float(hi[i]), 3)],
                **at(i + 1),
            ),
            cap,
            file,
        )

    # gis.spike
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(np.abs(grid.turn) > config.spike_max_turn_rad)
    out += capped(
        "gis.spike",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "gis.spike",
            Severity.ERROR,
            T,
            f"the track turns {abs(grid.turn[i]):.3f} rad between consecutive {sp:g} m segments "
            f"(radius ≈ {sp / max(abs(grid.turn[i]), 1e-12):.0f} m): a spike in the grid",
            keys=_gis_keys(grid, i),
            value=round(float(abs(grid.turn[i])), 4),
            limit=config.spike_max_turn_rad,
            **at(i),
        ),
        cap,
        file,
    )

    out += _track_spacing(grid, config, loc)
    return out


def _track_spacing(grid: Grid, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """``gis.track_spacing``: U vs D points of the same line and km, where parallel."""
    T = GIS.name
    u_groups = np.flatnonzero(grid.group_track == Track.UP.value)
    d_of_u = grid.group_of(grid.group_line[u_groups], np.full(len(u_groups), Track.DOWN.value, dtype=object))
    u_groups, d_of_u = u_groups[d_of_u >= 0], d_of_u[d_of_u >= 0]
    if len(u_groups) == 0:
        return []
    u = np.concatenate([np.arange(grid.start[g], grid.end[g]) for g in u_groups])
    dg = np.repeat(d_of_u, grid.end[u_groups] - grid.start[u_groups])
    j = np.minimum(grid.searchsorted(dg, grid.km[u] - config.km_epsilon_m), grid.n - 1)
    match = (grid.gid[j] == dg) & (np.abs(grid.km[j] - grid.km[u]) <= config.km_epsilon_m)
    ui, di = u[match], j[match]
    if len(ui) == 0:
        return []
    sep = np.hypot(grid.x[ui] - grid.x[di], grid.y[ui] - grid.y[di])
    dh = np.abs(wrap_angle(grid.heading[ui] - grid.heading[di]))
    with np.errstate(invalid="ignore"):
        flag = (dh < config.parallel_max_rad) & (sep < config.track_spacing_warning_m)
    k = np.flatnonzero(flag)
    if len(k) == 0:
        return []
    # stretches: consecutive flagged U points of one group → one finding each, at its minimum
    brk = np.ones(len(k), dtype=bool)
    brk[1:] = (ui[k[1:]] != ui[k[:-1]] + 1) | (grid.gid[ui[k[1:]]] != grid.gid[ui[k[:-1]]])
    starts = np.flatnonzero(brk)
    ends = np.append(starts[1:], len(k))
    run_min = np.minimum.reduceat(sep[k], starts)
    is_error = run_min < config.track_spacing_error_m
    warn = config.track_spacing_warning_m

    def build(r: int) -> Finding:
        idx = k[starts[r] : ends[r]]
        m = idx[int(np.argmin(sep[idx]))]
        i = int(ui[m])
        sev = Severity.ERROR if is_error[r] else Severity.WARNING
        lim = config.track_spacing_error_m if is_error[r] else warn
        km_a, km_b = grid.km[ui[idx[0]]], grid.km[ui[idx[-1]]]
        stretch = f"km {fmt_km(km_a)}" if len(idx) == 1 else f"km {fmt_km(km_a)}–{fmt_km(km_b)} ({len(idx)} points)"
        return Finding(
            "gis.track_spacing",
            sev,
            T,
            f"up and down tracks only {sep[m]:.2f} m apart at km {fmt_km(grid.km[i])} where parallel "
            f"(limit {lim:g} m, nominal {config.track_spacing_m:g} m); closer than {warn:g} m over {stretch}",
            keys={"line_code": py(grid.group_line[grid.gid[i]]), "km_m": py(grid.km[i])},
            value=round(float(sep[m]), 3),
            limit=lim,
            **loc.at(T, int(grid.pos[i])),
        )

    out: list[Finding] = []
    for sev, runs in ((Severity.ERROR, np.flatnonzero(is_error)), (Severity.WARNING, np.flatnonzero(~is_error))):
        out += capped("gis.track_spacing", sev, T, runs, build, config.max_findings_per_rule, loc.file(T))
    return out
