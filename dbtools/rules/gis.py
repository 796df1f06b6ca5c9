"""GIS grid rules (SPEC §3): the 20 m kilometrage grid of every line and track.

Everything is computed once, vectorised over the whole network, in the network's
:class:`~dbtools.gis.index.GridIndex` (points sorted by (line, track, km), a track id per
line/track, plane coordinates in the network's one projection, geodesic step lengths, and
— :meth:`~dbtools.gis.index.GridIndex.shape` — turn angles, headings and the Menger
curvature at every vertex whose two neighbouring steps are regular 20 m steps). The
feature-point and balise rules use the same index.

Rules:

* ``gis.km_grid`` (error) — km is not a multiple of the grid spacing (20 m). Fix: round the km
  of the point to the 20 m grid (re-run ``gis grid`` from the survey).
* ``gis.km_step`` (error) — consecutive km of a line/track do not differ by 20 m and the
  jump is not listed in ``km_breaks`` (a duplicate km is ``schema.duplicate_key``). Fix: add
  the missing points, delete the extra ones, or add a ``km_breaks`` row for a real kilometrage
  jump.
* ``gis.km_break_unused`` (warning) — a ``km_breaks`` row matches no jump of the grid. Fix:
  correct the row's km (from/to) or delete it.
* ``gis.step_length`` (error) — the geodesic distance between consecutive points is not
  consistent with their km difference Δ: it must lie in
  [chord(Δ, R_min) − tol, Δ + tol], tol = ``step_tolerance_m`` + ``step_tolerance_rel``·Δ,
  where chord(Δ, R) = 2R·sin(Δ/2R) is the chord of an arc of length Δ and
  R_min = spacing / ``spike_max_turn_rad`` the tightest radius the grid accepts. Fix: correct
  the coordinates of the point (a typo, a swapped lat/lon) or its km.
* ``gis.spike`` (error) — the angle between consecutive 20 m segments exceeds
  ``spike_max_turn_rad``. Fix: correct the coordinates of the point at the kink.
* ``gis.track_spacing`` (warning / error) — on a double-track line the U and D points of
  the same km are closer than ``track_spacing_warning_m`` (``…_error_m``) where the two
  tracks are parallel (heading difference < ``parallel_max_rad``); consecutive offending
  points are reported as one finding per stretch. Fix: correct the track (U/D) of the points,
  or the coordinates of one track; widen the limits in the validation config where the tracks
  really are that close.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis import index as grid_blocks
from dbtools.gis.geometry import wrap_angle
from dbtools.gis.index import GridIndex, GridShape
from dbtools.rules.common import Locator, capped, fmt_km, py
from dbtools.rules.config import ValidationConfig
from schemas.enums import Severity, Track
from schemas.findings import Finding
from schemas.tables import GIS, KM_BREAKS

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]


def _gis_keys(grid: GridIndex, i: int) -> dict[str, object]:
    t = grid.tid[i]
    return {"line_code": py(grid.lines[t]), "track": py(grid.tracks[t]), "km_m": py(grid.km[i])}


def check_gis(grid: GridIndex, km_breaks: pd.DataFrame, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """All GIS rules (see module docstring); ``km_breaks`` is the frame the index was built with."""
    shape = grid.shape(config.gis_spacing_m, config.km_epsilon_m)
    out: list[Finding] = []
    cap = config.max_findings_per_rule
    T = GIS.name
    file = loc.file(T)
    sp = config.gis_spacing_m

    def at(i: int) -> dict[str, Any]:
        return loc.at(T, grid.row(i))

    # gis.km_grid
    bad = _off_grid(grid.km, sp, config.km_epsilon_m)
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
    is_break, unused = grid.break_steps(config.km_epsilon_m)
    with np.errstate(invalid="ignore"):
        irregular = ~shape.regular & ~is_break & (grid.dkm > config.km_epsilon_m)
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
        r_min = sp / config.spike_max_turn_rad

        def limits(a: int, b: int) -> tuple[F64, F64]:
            d = dk[a:b]
            tol = config.step_tolerance_m + config.step_tolerance_rel * np.abs(d)
            chord = 2 * r_min * np.sin(np.minimum(np.abs(d) / (2 * r_min), np.pi / 2))
            return chord - tol, d + tol

        with np.errstate(invalid="ignore"):
            check = (dk > config.km_epsilon_m) & ~is_break
        bad, dist, lo, hi = grid.steps_outside(check, limits)  # aligned with bad
        out += capped(
            "gis.step_length",
            Severity.ERROR,
            T,
            np.arange(bad.size),
            lambda j: Finding(
                "gis.step_length",
                Severity.ERROR,
                T,
                f"points {dist[j]:.2f} m apart but their km differ by {dk[bad[j]]:g} m "
                f"(from km {fmt_km(grid.km[bad[j]])})",
                keys=_gis_keys(grid, bad[j] + 1),
                value=round(float(dist[j]), 3),
                limit=[round(float(lo[j]), 3), round(float(hi[j]), 3)],
                **at(bad[j] + 1),
            ),
            cap,
            file,
        )

    # gis.spike
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(np.abs(shape.turn) > config.spike_max_turn_rad)
    out += capped(
        "gis.spike",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "gis.spike",
            Severity.ERROR,
            T,
            f"the track turns {abs(shape.turn[i]):.3f} rad between consecutive {sp:g} m segments "
            f"(radius ≈ {sp / max(abs(shape.turn[i]), 1e-12):.0f} m): a spike in the grid",
            keys=_gis_keys(grid, i),
            value=round(float(abs(shape.turn[i])), 4),
            limit=config.spike_max_turn_rad,
            **at(i),
        ),
        cap,
        file,
    )

    out += _track_spacing(grid, shape, config, loc)
    return out


def _off_grid(km: F64, spacing: float, epsilon: float) -> I64:
    """The points whose |km − spacing·round(km / spacing)| > ``epsilon``, ``BLOCK`` points at
    a time in place (one temporary of a block, not of the whole grid)."""
    parts = [np.zeros(0, dtype=np.int64)]
    for a in range(0, km.size, grid_blocks.BLOCK):
        k = km[a : a + grid_blocks.BLOCK]
        off = k / spacing
        np.round(off, out=off)
        off *= spacing
        np.subtract(k, off, out=off)
        parts.append(np.flatnonzero(np.abs(off, out=off) > epsilon) + a)
    return np.concatenate(parts).astype(np.int64)


def _track_spacing(grid: GridIndex, shape: GridShape, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """``gis.track_spacing``: U vs D points of the same line and km, where parallel."""
    T = GIS.name
    ui, sep = _close_up_points(grid, shape, config)
    if len(ui) == 0:
        return []
    # stretches: consecutive flagged U points of one group → one finding each, at its minimum
    brk = np.ones(len(ui), dtype=bool)
    brk[1:] = (ui[1:] != ui[:-1] + 1) | (grid.tid[ui[1:]] != grid.tid[ui[:-1]])
    starts = np.flatnonzero(brk)
    ends = np.append(starts[1:], len(ui))
    run_min = np.minimum.reduceat(sep, starts)
    is_error = run_min < config.track_spacing_error_m
    warn = config.track_spacing_warning_m

    def build(r: int) -> Finding:
        a, b = int(starts[r]), int(ends[r])
        m = a + int(np.argmin(sep[a:b]))
        i = int(ui[m])
        sev = Severity.ERROR if is_error[r] else Severity.WARNING
        lim = config.track_spacing_error_m if is_error[r] else warn
        km_a, km_b = grid.km[ui[a]], grid.km[ui[b - 1]]
        stretch = f"km {fmt_km(km_a)}" if b - a == 1 else f"km {fmt_km(km_a)}–{fmt_km(km_b)} ({b - a} points)"
        return Finding(
            "gis.track_spacing",
            sev,
            T,
            f"up and down tracks only {sep[m]:.2f} m apart at km {fmt_km(grid.km[i])} where parallel "
            f"(limit {lim:g} m, nominal {config.track_spacing_m:g} m); closer than {warn:g} m over {stretch}",
            keys={"line_code": py(grid.lines[grid.tid[i]]), "km_m": py(grid.km[i])},
            value=round(float(sep[m]), 3),
            limit=lim,
            **loc.at(T, grid.row(i)),
        )

    out: list[Finding] = []
    for sev, runs in ((Severity.ERROR, np.flatnonzero(is_error)), (Severity.WARNING, np.flatnonzero(~is_error))):
        out += capped("gis.track_spacing", sev, T, runs, build, config.max_findings_per_rule, loc.file(T))
    return out


def _close_up_points(grid: GridIndex, shape: GridShape, config: ValidationConfig) -> tuple[I64, F64]:
    """The U points closer than ``track_spacing_warning_m`` to the D point of the same line and
    km where the two are parallel, in grid order, and that distance [m]: the U tracks taken
    ``BLOCK`` points at a time (whole tracks; bounded temporaries)."""
    u_groups = np.flatnonzero(grid.tracks == Track.UP.value)
    d_of_u = grid.track_ids(grid.lines[u_groups], np.full(len(u_groups), Track.DOWN.value, dtype=object))
    u_groups, d_of_u = u_groups[d_of_u >= 0], d_of_u[d_of_u >= 0]
    sizes = grid.end[u_groups] - grid.start[u_groups]
    first = np.concatenate([[0], np.cumsum(sizes)])  # points of the U tracks before each
    flagged: list[tuple[I64, F64]] = []
    g = 0
    while g < len(u_groups):  # tracks g:h hold about BLOCK points (at least one track)
        h = max(int(np.searchsorted(first, first[g] + grid_blocks.BLOCK, side="right")) - 1, g + 1)
        part = u_groups[g:h]
        u = np.concatenate([np.arange(grid.start[t], grid.end[t]) for t in part])
        dg = np.repeat(d_of_u[g:h], sizes[g:h])
        j = np.minimum(grid.searchsorted(dg, grid.km[u] - config.km_epsilon_m), grid.n - 1)
        match = (grid.tid[j] == dg) & (np.abs(grid.km[j] - grid.km[u]) <= config.km_epsilon_m)
        ui, di = u[match], j[match]
        sep = np.hypot(grid.x[ui] - grid.x[di], grid.y[ui] - grid.y[di])
        dh = np.abs(wrap_angle(shape.heading[ui] - shape.heading[di]))
        with np.errstate(invalid="ignore"):
            flag = (dh < config.parallel_max_rad) & (sep < config.track_spacing_warning_m)
        flagged.append((ui[flag], sep[flag]))
        g = h
    if not flagged:
        return np.zeros(0, dtype=np.int64), np.zeros(0)
    return np.concatenate([f[0] for f in flagged]).astype(np.int64), np.concatenate([f[1] for f in flagged])
