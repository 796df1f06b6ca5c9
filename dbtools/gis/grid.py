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
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.centreline import Polyline, TrackCtx, Where, polyline
from dbtools.gis.geometry import Projector
from dbtools.gis.index import projection_for
from dbtools.gis.posts import PostProjection, Posts, grid_kms, km_runs, project_posts, reference_chainage
from dbtools.gis.track_grid import OwnTrackSummary, own_track_grid
from dbtools.network import canonical, empty_frame
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.gisinput import CENTRELINE_VERTICES, KM_POSTS
from schemas.network import TRACK_POINTS
from schemas.tables import GIS, KM_BREAKS

FloatArray = npt.NDArray[np.float64]

#: A post farther than this from a track is not used on that track [m].
MAX_POST_OFFSET_M = 50.0
#: Posts closer than this along a track are the same place [m].
SAME_PLACE_M = 0.01
#: Warn when the km difference of two posts differs from the measured distance by more than
#: max(SPACING_ABS_M, SPACING_REL · distance).
SPACING_ABS_M = 1.0
SPACING_REL = 0.01


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
    track_points: pd.DataFrame = field(default_factory=lambda: empty_frame(TRACK_POINTS))
    """The grid of the tracks along no line km (centreline rows with track_id)."""
    own_tracks: list[OwnTrackSummary] = field(default_factory=list)


def build_grid(
    centrelines: pd.DataFrame,
    posts: pd.DataFrame,
    *,
    centrelines_file: str | None = None,
    posts_file: str | None = None,
    max_post_offset_m: float = MAX_POST_OFFSET_M,
) -> GridResult:
    """The GIS grid (and kilometrage breaks) of every line/track, and the ``track_points`` of
    every track along no line km (rows with ``track_id``: :mod:`dbtools.gis.track_grid`);
    see the module docstring.

    Inputs are typed frames as declared in :mod:`schemas.gisinput` (already schema-checked).
    Problems come back as findings; tracks with errors produce no grid points.
    """
    cw = Where(centrelines, CENTRELINE_VERTICES.name, centrelines_file)
    pw = Where(posts, KM_POSTS.name, posts_file)
    result = GridResult(empty_frame(GIS), empty_frame(KM_BREAKS))
    findings = result.findings
    centrelines = centrelines.assign(
        **{c: None for c in ("line_code", "track", "track_id", "height_m") if c not in centrelines.columns}
    )
    own = centrelines["track_id"].notna().to_numpy()
    findings.extend(_key_findings(centrelines, own, cw))
    keyed = centrelines["line_code"].notna().to_numpy() & centrelines["track"].notna().to_numpy()
    line_rows = centrelines[~own & keyed]
    line_codes = line_rows["line_code"].astype(object)
    all_lines = set(centrelines["line_code"].dropna().astype(object))
    findings.extend(_post_findings(posts, all_lines, pw))

    # one plane for the whole survey, by the grid index's policy (dbtools.gis.index)
    projector = projection_for(
        centrelines["lat"].to_numpy(dtype=float, na_value=np.nan),
        centrelines["lon"].to_numpy(dtype=float, na_value=np.nan),
    )
    if projector is None:
        return result
    result.epsg = projector.epsg
    line_posts = {lc: _line_posts(posts, lc, projector) for lc in sorted(all_lines)}
    gis_parts: list[pd.DataFrame] = []
    break_rows: list[dict[str, object]] = []
    for line_code in sorted(set(line_codes.dropna())):
        on_line = line_rows[line_codes == line_code]
        result.zones[line_code] = projector.zone
        lp = line_posts[line_code]
        tracks = on_line["track"].astype(object)
        for track in sorted(set(tracks.dropna())):
            vertices = on_line[tracks == track].sort_values("seq", kind="stable")
            built = _track_grid(str(line_code), str(track), vertices, lp, projector, cw, pw, max_post_offset_m)
            findings.extend(built.findings)
            if built.gis is not None and built.summary is not None:
                gis_parts.append(built.gis)
                break_rows.extend(built.breaks)
                result.tracks.append(built.summary)
        findings.extend(_unused_post_findings(posts, lp, str(line_code), max_post_offset_m, pw))
    if own.any():
        _own_tracks(result, centrelines[own], line_posts, projector, (cw, pw), max_post_offset_m)

    if gis_parts:
        result.gis = canonical(GIS, pd.concat(gis_parts, ignore_index=True))
    if break_rows:
        result.km_breaks = canonical(KM_BREAKS, pd.DataFrame(break_rows))
    return result


def _key_findings(centrelines: pd.DataFrame, own: npt.NDArray[np.bool_], cw: Where) -> list[Finding]:
    """An error for each row that is neither a line's track (line_code and track) nor a
    track of its own (track_id)."""
    lc, tr = centrelines["line_code"].notna().to_numpy(), centrelines["track"].notna().to_numpy()
    out = []
    for i in np.flatnonzero(~own & ~(lc & tr)).tolist():
        missing = "line_code and track" if not lc[i] and not tr[i] else ("track" if lc[i] else "line_code")
        out.append(
            cw.finding(
                "gisinput.centreline_key",
                Severity.ERROR,
                f"the vertex has no {missing}: give line_code and track (a line's track) or track_id "
                "(a track along no line km)",
                centrelines.index[i],
                column="track" if missing == "track" else "line_code",
            )
        )
    return out


def _post_findings(posts: pd.DataFrame, known_lines: set[object], pw: Where) -> list[Finding]:
    """Posts alone: breaks must go forward; their line must have a centreline."""
    out = []
    post_lines = posts["line_code"].astype(object)
    km_after_all = posts["km_after_m"].to_numpy(dtype=float, na_value=np.nan)
    km_all = posts["km_m"].to_numpy(dtype=float, na_value=np.nan)
    for i in np.flatnonzero(~np.isnan(km_after_all) & (km_after_all <= km_all)).tolist():
        out.append(
            pw.finding(
                "gisinput.break_backwards",
                Severity.ERROR,
                f"km_after_m {km_after_all[i]:g} is not larger than km_m {km_all[i]:g}: a break must "
                "jump forward (a repeated kilometrage cannot be held by the gis table)",
                posts.index[i],
                keys={"line_code": post_lines.iat[i], "km_m": km_all[i]},
                value=km_after_all[i],
                limit=km_all[i],
                column="km_after_m",
            )
        )
    for i in np.flatnonzero(~post_lines.isin(known_lines).to_numpy()).tolist():
        out.append(
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
    return out


def _line_posts(posts: pd.DataFrame, line_code: object, projector: Projector) -> Posts:
    """The posts of one line in the plane."""
    sel = np.flatnonzero((posts["line_code"].astype(object) == line_code).to_numpy())
    px, py = projector.to_xy(posts["lon"].to_numpy(dtype=float)[sel], posts["lat"].to_numpy(dtype=float)[sel])
    return Posts(
        frame_index=posts.index[sel],
        km=posts["km_m"].to_numpy(dtype=float, na_value=np.nan)[sel],
        km_after=posts["km_after_m"].to_numpy(dtype=float, na_value=np.nan)[sel],
        x=px,
        y=py,
        used=np.zeros(sel.size, dtype=bool),
        nearest_m=np.full(sel.size, np.inf),
    )


def _unused_post_findings(
    posts: pd.DataFrame, lp: Posts, line_code: str, max_post_offset_m: float, pw: Where
) -> list[Finding]:
    """An error for each post of the line that no track of it could use."""
    out = []
    for j in np.flatnonzero(~lp.used).tolist():
        near = lp.nearest_m[j]
        where = (
            f"is {near:.1f} m from the nearest track of line '{line_code}'"
            if math.isfinite(near)
            else f"lies beyond the ends of every track of line '{line_code}'"
        )
        out.append(
            pw.finding(
                "gisinput.post_off_track",
                Severity.ERROR,
                f"post km {lp.km[j]:g} {where}; a post must lie within {max_post_offset_m:g} m of a track",
                lp.frame_index[j],
                keys={"line_code": line_code, "km_m": lp.km[j]},
                value=round(float(near), 3) if math.isfinite(near) else None,
                limit=max_post_offset_m,
            )
        )
    return out


def _own_tracks(
    result: GridResult,
    rows: pd.DataFrame,
    line_posts: dict[object, Posts],
    projector: Projector,
    where: tuple[Where, Where],
    max_post_offset_m: float,
) -> None:
    """The ``track_points`` of every track_id (:func:`dbtools.gis.track_grid.own_track_grid`)."""
    parts = []
    ids = rows["track_id"].astype(object)
    for tid in sorted(set(ids)):
        vertices = rows[ids == tid].sort_values("seq", kind="stable")
        lines = vertices["line_code"].dropna().astype(object).unique().tolist()
        lp = line_posts.get(lines[0]) if len(lines) == 1 else None
        frame, summary, found = own_track_grid(str(tid), vertices, lp, projector, where, max_post_offset_m)
        result.findings.extend(found)
        if frame is not None and summary is not None:
            parts.append(frame)
            result.own_tracks.append(summary)
    if parts:
        result.track_points = canonical(TRACK_POINTS, pd.concat(parts, ignore_index=True))


@dataclass
class _TrackBuilt:
    findings: list[Finding]
    gis: pd.DataFrame | None = None
    breaks: list[dict[str, object]] = field(default_factory=list)
    summary: TrackSummary | None = None


def _track_grid(
    line_code: str,
    track: str,
    vertices: pd.DataFrame,
    posts: Posts,
    projector: Projector,
    cw: Where,
    pw: Where,
    max_post_offset_m: float,
) -> _TrackBuilt:
    """Steps 1–5 of the module docstring for one track."""
    out = _TrackBuilt([])
    ctx = TrackCtx(line_code, track, vertices.index[0], cw, pw)
    poly = polyline(vertices, projector, ctx, out.findings)
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


def _orient(
    poly: Polyline, posts: Posts, max_post_offset_m: float
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
    ctx: TrackCtx,
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


def _post_pair(ctx: TrackCtx, idx: Any, rp: tuple[float, float], km: tuple[float, float, float]) -> Finding | None:
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
    ctx: TrackCtx,
    out: _TrackBuilt,
    poly: Polyline,
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
