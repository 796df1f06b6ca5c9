"""The 20 m grid of a track along no line km (pure): crossovers, connecting curves, turnout
curves — the ``track_points`` table (SPEC §8.1; ``schemas.network.TRACK_POINTS``).

Per track (centreline vertices with its ``track_id``, in ``seq`` order; the track begins at
the first vertex):

1. The polyline as for a line's track (:func:`dbtools.gis.centreline.polyline`): plane
   vertices in the survey's one projection, ground chainage ``s`` (geodesic segment lengths).
   Its length is ``L = s[-1]``; for a circular curve surveyed densely this is R·θ (a chord c
   of the arc is shorter than its arc by c³/(24R²): 35 µm over 30 m at R = 190 m with 1 m
   chords).
2. Grid positions ``pos`` = 0, 20, 40, … < L and L itself (the end point; no second point
   when L is within :data:`END_MERGE_M` of the last multiple). Each is placed by linear
   interpolation of the plane vertices at ``s = pos``, then back to lat/lon (and height when
   every vertex has one).
3. km where the track's rows name a ``line_code`` whose kilometre posts lie within the post
   offset limit: each such post projects onto the track (foot chainage ``s_p``); with two or
   more, km is piecewise linear in ``s`` through (s_p, km_p), slope ±1 beyond the first and
   last (the sign of the km direction along the track), as on a line's track but without the
   parallel-offset correction (a crossover is not parallel to the line of the posts). Posts
   whose km does not run one way along the track give a warning and no km. Otherwise km_m is
   empty.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.centreline import Polyline, TrackCtx, Where, polyline
from dbtools.gis.geometry import Projector
from dbtools.gis.posts import Posts, project_posts
from schemas.enums import Severity
from schemas.findings import Finding
from schemas.tables import GIS_SPACING_M

FloatArray = npt.NDArray[np.float64]

#: The end point is not repeated when it lies this close to the last 20 m multiple [m].
END_MERGE_M = 1e-3


@dataclass
class OwnTrackSummary:
    """What was built for one track along no line km."""

    track_id: str
    points: int
    length_m: float
    line_code: str | None
    posts_used: int
    """Posts that gave the track km (0: km_m empty)."""


def grid_positions(length_m: float, spacing_m: float = GIS_SPACING_M) -> FloatArray:
    """0, spacing, 2·spacing, … below ``length_m``, and ``length_m`` (step 2)."""
    pos = np.arange(0.0, length_m, spacing_m)
    if length_m - pos[-1] > END_MERGE_M:
        pos = np.append(pos, length_m)
    else:
        pos[-1] = length_m
    return pos


def _km_along(
    ctx: TrackCtx, poly: Polyline, posts: Posts | None, max_offset_m: float, findings: list[Finding]
) -> tuple[FloatArray | None, int]:
    """Step 3: the (s_p, km_p) knots of the posts that give the track km (a 2×n array), or
    None; and how many posts were used."""
    if posts is None or posts.x.size < 2:
        return None, 0
    proj, usable = project_posts(poly.x, poly.y, poly.s, posts, max_offset_m)
    if usable.sum() < 2:
        return None, int(usable.sum())
    sp, kp = proj.km_m[usable], posts.km[usable]
    order = np.argsort(sp, kind="stable")
    sp, kp = sp[order], kp[order]
    dk = np.diff(kp)
    if not (np.all(dk > 0) or np.all(dk < 0)) or np.any(np.diff(sp) <= 0):
        findings.append(
            ctx.cw.finding(
                "gisinput.track_km_order",
                Severity.WARNING,
                f"the km posts of line '{ctx.line_code}' near {ctx.name} do not run one way along it "
                f"(km {', '.join(f'{k:g}' for k in kp)} in the order of the track); its km_m is left empty",
                ctx.first_idx,
                keys={**ctx.keys, "line_code": ctx.line_code},
            )
        )
        return None, 0
    return np.vstack([sp, kp]), int(sp.size)


def _km_at(knots: FloatArray, pos: FloatArray) -> FloatArray:
    """Piecewise linear through the knots, slope ±1 beyond them."""
    sp, kp = knots
    sign = 1.0 if kp[-1] > kp[0] else -1.0
    km = np.interp(pos, sp, kp)
    km = np.where(pos < sp[0], kp[0] - sign * (sp[0] - pos), km)
    out: FloatArray = np.where(pos > sp[-1], kp[-1] + sign * (pos - sp[-1]), km)
    return out


def own_track_grid(
    track_id: str,
    vertices: pd.DataFrame,
    posts: Posts | None,
    projector: Projector,
    where: tuple[Where, Where],
    max_offset_m: float,
) -> tuple[pd.DataFrame | None, OwnTrackSummary | None, list[Finding]]:
    """Steps 1–3 for one track: its ``track_points`` rows, summary and findings (no rows on
    an error). ``posts``: those of the line its rows name (None: no km)."""
    findings: list[Finding] = []
    lines = vertices["line_code"].dropna().astype(str).unique().tolist()
    line_code = lines[0] if len(lines) == 1 else None
    ctx = TrackCtx(line_code or "", "", vertices.index[0], where[0], where[1], track_id=track_id)
    if len(lines) > 1:
        findings.append(
            where[0].finding(
                "gisinput.track_lines",
                Severity.ERROR,
                f"track {track_id} names more than one line_code ({', '.join(sorted(lines))}); give one or none",
                vertices.index[0],
                keys=ctx.keys,
                column="line_code",
            )
        )
        return None, None, findings
    poly = polyline(vertices, projector, ctx, findings)
    if poly is None:
        return None, None, findings
    knots, used = _km_along(ctx, poly, posts if line_code else None, max_offset_m, findings)
    pos = grid_positions(float(poly.s[-1]))
    lon, lat = projector.to_lonlat(np.interp(pos, poly.s, poly.x), np.interp(pos, poly.s, poly.y))
    rows = pd.DataFrame(
        {
            "track_id": track_id,
            "pos_m": np.round(pos, 3),
            "km_m": np.round(_km_at(knots, pos), 3) if knots is not None else np.nan,
            "lat": np.round(lat, 9),
            "lon": np.round(lon, 9),
            "height_m": np.round(np.interp(pos, poly.s, poly.heights), 3) if poly.heights is not None else np.nan,
        }
    )
    summary = OwnTrackSummary(track_id, len(rows), float(poly.s[-1]), line_code, used if knots is not None else 0)
    return rows, summary, findings
