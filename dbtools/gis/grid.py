"""The 20 m GIS grid from surveyed track centrelines and kilometre posts (pure).

Method, per line (all metric work in the survey's one plane projection, chosen by the policy
of :mod:`dbtools.gis.index` from all centreline vertices):

1. Each track centreline is a polyline; ``s`` is the distance along it on the ground
   (geodesic length of each segment, so km is not off by the zone's scale factor of
   0.9999–1.0001); positions are interpolated in the plane.
2. Every kilometre post of the line is projected onto each track (nearest point): the foot
   gives the post's chainage ``s_p`` and its signed lateral offset ``o_p`` (left positive).
   Posts more than ``max_post_offset_m`` from a track, or beyond its ends, are not used on it.
   The posts also orient the track: a polyline drawn from high to low km is reversed.
3. Kilometrage is measured along the line of the posts, not along each track: through a
   curve of deflection Δθ a parallel track at lateral distance d from that line is d·Δθ
   shorter (inside) or longer (outside). The *reference chainage* ``r`` removes this:
   ``dr = ds − o·dθ`` with ``o`` the median post offset of the track and ``dθ`` the turn of
   the polyline (each vertex's turn split over its two segments). ``r = s`` when the posts
   stand on the track; exact for a track parallel to the line of the posts.
4. ``km(r)`` is piecewise linear through the posts, with slope 1 before the first and
   after the last post. A post with ``km_after_m`` is a kilometrage break: km counts to
   ``km_m`` before it and restarts at ``km_after_m`` after it (a new *run*).
5. Grid points are the multiples of 20 m of km inside each run (both ends inclusive, so a
   break post gets a point for each of its kilometrages); km → r → s → (x, y, height) by
   linear interpolation along the polyline, then back to lon/lat. Each break gives one
   ``km_breaks`` row (last grid km before, first grid km after).

Everything is vectorised over the vertices and grid points; transformers are cached.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import Projector, geodesic_step
from dbtools.gis.index import projection_for
from dbtools.gis.posts import PostProjection, Posts, grid_kms, km_runs, project_posts, reference_chainage
from dbtools.network import canonical, empty_frame
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.gisinput import CENTRELINE_VERTICES, KM_POSTS
from schemas.tables import GIS, KM_BREAKS

FloatArray = npt.NDArray[np.float64]

#: A post farther than this from a track is not used on that track [m].
MAX_POST_OFFSET_M = 50.0
#: Consecutive vertices closer than this are duplicates [m].
DUPLICATE_VERTEX_M = 1e-3
#: Posts closer than this along a track are the same place [m].
SAME_PLACE_M = 0.01
#: Warn when the km difference of two posts differs from the measured distance by more than
#: max(SPACING_ABS_M, SPACING_REL · distance).
SPACING_ABS_M = 1.0
SPACING_REL = 0.01

#: Extra frame columns the readers may add: file line of the row, and a label prefix for
#: inputs without lines (GeoJSON: "feature 3, vertex 12").
ROW_COL = "_row"
LABEL_COL = "_label"


@dataclass
class TrackSummary:
    """What was built for one line/track."""

    line_code: str
    track: str
    points: int
    km_first_m: float
    km_last_m: float
    length_m: float
    posts_used: int
    post_offset_m: float
    """Median signed offset of the posts from the track (left of increasing km positive)."""
    reversed: bool
    """The polyline was drawn from high to low km and has been reversed."""
    breaks: int


@dataclass
class GridResult:
    gis: pd.DataFrame
    km_breaks: pd.DataFrame
    findings: list[Finding] = field(default_factory=list)
    tracks: list[TrackSummary] = field(default_factory=list)
    zones: dict[str, int] = field(default_factory=dict)
    """JGD2011 plane rectangular zone used per line (0: another projection, see ``epsg``)."""
    epsg: int = 0
    """EPSG code of the one plane projection of the survey."""


class _Where:
    """Finding locations: file and line of an input row (or a label when there are no lines)."""

    def __init__(self, frame: pd.DataFrame, table: str, file: str | None) -> None:
        self.table, self.file = table, file
        self.rows = frame[ROW_COL] if ROW_COL in frame.columns else None
        self.labels = frame[LABEL_COL] if LABEL_COL in frame.columns else None

    def finding(
        self,
        rule: str,
        severity: Severity,
        message: str,
        idx: Any = None,
        *,
        keys: Mapping[str, object] | None = None,
        value: object = None,
        limit: object = None,
        column: str | None = None,
    ) -> Finding:
        row = None
        if idx is not None and self.rows is not None:
            v = self.rows.loc[idx]
            row = None if pd.isna(v) else int(v)
        if idx is not None and self.labels is not None:
            label = self.labels.loc[idx]
            if isinstance(label, str) and label:
                message = f"{label}: {message}"
        return Finding(
            rule,
            severity,
            self.table,
            message,
            keys=dict(keys or {}),
            value=value,
            limit=limit,
            file=self.file,
            row=row,
            column=column,
        )


def build_grid(
    centrelines: pd.DataFrame,
    posts: pd.DataFrame,
    *,
    centrelines_file: str | None = None,
    posts_file: str | None = None,
    max_post_offset_m: float = MAX_POST_OFFSET_M,
) -> GridResult:
    """The GIS grid (and kilometrage breaks) of every line/track; see the module docstring.

    Inputs are typed frames as declared in :mod:`schemas.gisinput` (already schema-checked).
    Problems come back as findings; tracks with errors produce no grid points.
    """
    cw = _Where(centrelines, CENTRELINE_VERTICES.name, centrelines_file)
    pw = _Where(posts, KM_POSTS.name, posts_file)
    result = GridResult(empty_frame(GIS), empty_frame(KM_BREAKS))
    findings = result.findings
    post_lines = posts["line_code"].astype(object)
    line_codes = centrelines["line_code"].astype(object)
    gis_parts: list[pd.DataFrame] = []
    break_rows: list[dict[str, object]] = []

    # posts: breaks must go forward; lines must exist
    km_after_all = posts["km_after_m"].to_numpy(dtype=float, na_value=np.nan)
    km_all = posts["km_m"].to_numpy(dtype=float, na_value=np.nan)
    for i in np.flatnonzero(~np.isnan(km_after_all) & (km_after_all <= km_all)).tolist():
        idx = posts.index[i]
        findings.append(
            pw.finding(
                "gisinput.break_backwards",
                Severity.ERROR,
                f"km_after_m {km_after_all[i]:g} is not larger than km_m {km_all[i]:g}: a break must "
                "jump forward (a repeated kilometrage cannot be held by the gis table)",
                idx,
                keys={"line_code": post_lines.iat[i], "km_m": km_all[i]},
                value=km_after_all[i],
                limit=km_all[i],
                column="km_after_m",
            )
        )
    known_lines = set(line_codes.dropna())
    for i in np.flatnonzero(~post_lines.isin(known_lines).to_numpy()).tolist():
        findings.append(
            pw.finding(
                "gisinput.unknown_line",
                Severity.ERROR,
                f"no centreline for line_code '{post_lines.iat[i]}'",
                posts.index[i],
                keys={"line_code": post_lines.iat[i], "km_m": km_all[i]},
                value=post_lines.iat[i],
                column="line_code",
            )
        )

    # one plane for the whole survey, by the grid index's policy (dbtools.gis.index)
    projector = projection_for(
        centrelines["lat"].to_numpy(dtype=float, na_value=np.nan),
        centrelines["lon"].to_numpy(dtype=float, na_value=np.nan),
    )
    for line_code in sorted(known_lines):
        assert projector is not None  # a known line has vertices
        on_line = centrelines[line_codes == line_code]
        result.zones[line_code], result.epsg = projector.zone, projector.epsg
        sel = np.flatnonzero((post_lines == line_code).to_numpy())
        px, py = projector.to_xy(posts["lon"].to_numpy(dtype=float)[sel], posts["lat"].to_numpy(dtype=float)[sel])
        line_posts = Posts(
            frame_index=posts.index[sel],
            km=km_all[sel],
            km_after=km_after_all[sel],
            x=px,
            y=py,
            used=np.zeros(sel.size, dtype=bool),
            nearest_m=np.full(sel.size, np.inf),
        )
        tracks = on_line["track"].astype(object)
        for track in sorted(set(tracks.dropna())):
            vertices = on_line[tracks == track].sort_values("seq", kind="stable")
            built = _track_grid(str(line_code), str(track), vertices, line_posts, projector, cw, pw, max_post_offset_m)
            findings.extend(built.findings)
            if built.gis is not None and built.summary is not None:
                gis_parts.append(built.gis)
                break_rows.extend(built.breaks)
                result.tracks.append(built.summary)
        for j in np.flatnonzero(~line_posts.used).tolist():
            i = int(sel[j])
            near = line_posts.nearest_m[j]
            where = (
                f"is {near:.1f} m from the nearest track of line '{line_code}'"
                if math.isfinite(near)
                else f"lies beyond the ends of every track of line '{line_code}'"
            )
            findings.append(
                pw.finding(
                    "gisinput.post_off_track",
                    Severity.ERROR,
                    f"post km {km_all[i]:g} {where}; a post must lie within {max_post_offset_m:g} m of a track",
                    posts.index[i],
                    keys={"line_code": line_code, "km_m": km_all[i]},
                    value=round(float(near), 3) if math.isfinite(near) else None,
                    limit=max_post_offset_m,
                )
            )

    if gis_parts:
        result.gis = canonical(GIS, pd.concat(gis_parts, ignore_index=True))
    if break_rows:
        result.km_breaks = canonical(KM_BREAKS, pd.DataFrame(break_rows))
    return result


@dataclass
class _TrackBuilt:
    findings: list[Finding]
    gis: pd.DataFrame | None = None
    breaks: list[dict[str, object]] = field(default_factory=list)
    summary: TrackSummary | None = None


@dataclass
class _Polyline:
    """One track's cleaned centreline: plane vertices, heights (or None), ground chainage."""

    x: FloatArray
    y: FloatArray
    heights: FloatArray | None
    s: FloatArray


@dataclass(frozen=True)
class _TrackCtx:
    """Who a track is, for findings."""

    line_code: str
    track: str
    first_idx: Any
    cw: _Where
    pw: _Where

    @property
    def keys(self) -> dict[str, object]:
        return {"line_code": self.line_code, "track": self.track}


def _track_grid(
    line_code: str,
    track: str,
    vertices: pd.DataFrame,
    posts: Posts,
    projector: Projector,
    cw: _Where,
    pw: _Where,
    max_post_offset_m: float,
) -> _TrackBuilt:
    """Steps 1–5 of the module docstring for one track."""
    out = _TrackBuilt([])
    ctx = _TrackCtx(line_code, track, vertices.index[0], cw, pw)
    poly = _polyline(vertices, projector, ctx, out.findings)
    if poly is None:
        return out
    proj, usable, reversed_ = _orient(poly, posts, max_post_offset_m)
    posts.used |= usable
    posts.nearest_m = np.minimum(posts.nearest_m, np.where(proj.beyond, np.inf, proj.distance_m))
    if not usable.any():
        out.findings.append(
            cw.finding(
                "gisinput.no_posts",
                Severity.ERROR,
                f"no kilometre post of line '{line_code}' lies within {max_post_offset_m:g} m of track {track}",
                ctx.first_idx,
                keys=ctx.keys,
                limit=max_post_offset_m,
            )
        )
        return out
    offset = float(np.median(proj.offset_m[usable]))
    r = reference_chainage(poly.x, poly.y, poly.s, offset)
    if np.any(np.diff(r) <= 0):
        out.findings.append(
            cw.finding(
                "gisinput.sharp_turn",
                Severity.ERROR,
                f"the track turns too sharply for posts {offset:.1f} m beside it (reference chainage "
                "would run backwards); check for a spike in the centreline",
                ctx.first_idx,
                keys=ctx.keys,
                value=offset,
            )
        )
        return out
    # posts on this track in order of reference chainage
    sel = np.flatnonzero(usable)
    rp = np.interp(proj.km_m[sel], poly.s, r)
    order = np.argsort(rp, kind="stable")
    sel, rp = sel[order], rp[order]
    km_before = posts.km[sel]
    km_after = np.where(np.isnan(posts.km_after[sel]), km_before, posts.km_after[sel])
    if not _check_post_order(ctx, posts.frame_index[sel], rp, km_before, km_after, out.findings):
        return out
    runs = km_runs(r, rp, km_before, km_after)
    return _grid_points(ctx, out, poly, r, runs, projector, (int(sel.size), offset, reversed_))


def _polyline(
    vertices: pd.DataFrame, projector: Projector, ctx: _TrackCtx, findings: list[Finding]
) -> _Polyline | None:
    """Step 1: plane vertices without repeats, heights if given on every vertex, chainage
    on the ground (geodesic, not in the plane: scale factor 0.9999–1.0001); None (and a
    finding) when fewer than two distinct vertices remain."""
    lon = vertices["lon"].to_numpy(dtype=float)
    lat = vertices["lat"].to_numpy(dtype=float)
    x, y = projector.to_xy(lon, lat)
    h = vertices["height_m"].to_numpy(dtype=float, na_value=np.nan)
    step = geodesic_step(lon, lat)
    dup = np.flatnonzero(step < DUPLICATE_VERTEX_M) + 1
    if dup.size:
        findings.append(
            ctx.cw.finding(
                "gisinput.duplicate_vertex",
                Severity.WARNING,
                f"{dup.size} vertex(es) repeat the previous one and were dropped",
                vertices.index[dup[0]],
                keys=ctx.keys,
                value=int(dup.size),
            )
        )
        keep = np.ones(x.size, dtype=bool)
        keep[dup] = False
        x, y, h, step = x[keep], y[keep], h[keep], geodesic_step(lon[keep], lat[keep])
    if x.size < 2:
        findings.append(
            ctx.cw.finding(
                "gisinput.short_track",
                Severity.ERROR,
                f"track {ctx.track} of line '{ctx.line_code}' has fewer than two distinct vertices",
                ctx.first_idx,
                keys=ctx.keys,
                value=int(x.size),
                limit=2,
            )
        )
        return None
    has_h = ~np.isnan(h)
    if has_h.any() and not has_h.all():
        findings.append(
            ctx.cw.finding(
                "gisinput.partial_height",
                Severity.WARNING,
                f"height_m is given on {int(has_h.sum())} of {h.size} vertices of the track; heights ignored",
                ctx.first_idx,
                keys=ctx.keys,
                column="height_m",
            )
        )
    return _Polyline(x, y, h if has_h.all() else None, np.concatenate([[0.0], np.cumsum(step)]))


def _orient(
    poly: _Polyline, posts: Posts, max_post_offset_m: float
) -> tuple[PostProjection, npt.NDArray[np.bool_], bool]:
    """Step 2: the posts projected onto the track; a polyline drawn from high to low km is
    reversed in place. Returns (projection, usable posts, reversed)."""
    proj, usable = project_posts(poly.x, poly.y, poly.s, posts, max_post_offset_m)
    if usable.sum() < 2:
        return proj, usable, False
    order = np.argsort(proj.km_m[usable], kind="stable")
    km_used = posts.km[usable][order]
    if km_used[-1] >= km_used[0]:
        return proj, usable, False
    poly.x, poly.y = poly.x[::-1].copy(), poly.y[::-1].copy()
    poly.heights = poly.heights[::-1].copy() if poly.heights is not None else None
    poly.s = poly.s[-1] - poly.s[::-1]
    proj, usable = project_posts(poly.x, poly.y, poly.s, posts, max_post_offset_m)
    return proj, usable, True


def _check_post_order(
    ctx: _TrackCtx,
    index: pd.Index,
    rp: FloatArray,
    km_before: FloatArray,
    km_after: FloatArray,
    findings: list[Finding],
) -> bool:
    """Consecutive posts along the track (reference chainage ``rp``): distinct places, km
    increasing (errors: False), km difference close to their distance (warning)."""
    ok = True
    for a in range(rp.size - 1):
        b = a + 1
        f = _post_pair(ctx, index[b], (rp[a], rp[b]), (km_after[a], km_before[a], km_before[b]))
        if f is not None:
            findings.append(f)
            ok = ok and f.severity != Severity.ERROR
    return ok


def _post_pair(ctx: _TrackCtx, idx: Any, rp: tuple[float, float], km: tuple[float, float, float]) -> Finding | None:
    """The finding (if any) for post b after post a: ``rp`` their reference chainages,
    ``km`` = (km after a, km before a, km before b)."""
    after_a, before_a, before_b = km
    pkeys = {**ctx.keys, "km_m": before_b}
    t = ctx.track
    if rp[1] - rp[0] < SAME_PLACE_M:
        return ctx.pw.finding(
            "gisinput.posts_same_place",
            Severity.ERROR,
            f"posts km {before_a:g} and km {before_b:g} project to the same place on track {t}",
            idx,
            keys=pkeys,
        )
    if before_b <= after_a:
        return ctx.pw.finding(
            "gisinput.km_order",
            Severity.ERROR,
            f"kilometrage does not increase along track {t}: post km {before_b:g} comes after "
            f"post km {after_a:g} (a post is misplaced or its km is wrong)",
            idx,
            keys=pkeys,
            value=before_b,
            limit=after_a,
            column="km_m",
        )
    dkm, dr = before_b - after_a, rp[1] - rp[0]
    tol = max(SPACING_ABS_M, SPACING_REL * dr)
    if abs(dkm - dr) <= tol:
        return None
    return ctx.pw.finding(
        "gisinput.post_spacing",
        Severity.WARNING,
        f"posts km {after_a:g} → {before_b:g} differ by {dkm:.1f} m of km but lie {dr:.1f} m apart along track {t}",
        idx,
        keys=pkeys,
        value=round(float(dkm - dr), 3),
        limit=round(tol, 3),
    )


def _grid_points(
    ctx: _TrackCtx,
    out: _TrackBuilt,
    poly: _Polyline,
    r: FloatArray,
    runs: list[tuple[list[float], list[float]]],
    projector: Projector,
    posts: tuple[int, float, bool],
) -> _TrackBuilt:
    """Step 5: km → r → s → (x, y, height) by linear interpolation, back to lon/lat;
    ``posts`` = (posts used, their median offset, reversed) for the summary."""
    kms, refs, out.breaks = grid_kms(runs, ctx.keys)
    if not kms:
        out.findings.append(
            ctx.cw.finding(
                "gisinput.no_grid",
                Severity.ERROR,
                f"track {ctx.track} of line '{ctx.line_code}' is shorter than one grid step",
                ctx.first_idx,
                keys=ctx.keys,
            )
        )
        return out
    grid_km = np.concatenate(kms)
    s = poly.s
    sg = np.interp(np.concatenate(refs), r, s)
    glon, glat = projector.to_lonlat(np.interp(sg, s, poly.x), np.interp(sg, s, poly.y))
    out.gis = pd.DataFrame(
        {
            "line_code": ctx.line_code,
            "track": ctx.track,
            "km_m": grid_km,
            "lat": np.round(glat, 9),
            "lon": np.round(glon, 9),
            "height_m": np.round(np.interp(sg, s, poly.heights), 3) if poly.heights is not None else np.nan,
        }
    )
    n_posts, offset, reversed_ = posts
    out.summary = TrackSummary(
        ctx.line_code,
        ctx.track,
        int(grid_km.size),
        float(grid_km[0]),
        float(grid_km[-1]),
        float(s[-1]),
        n_posts,
        round(offset, 3),
        reversed_,
        len(out.breaks),
    )
    return out
