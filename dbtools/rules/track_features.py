"""Rules of ``track_feature_points``: curve feature points of network tracks by distance
along the track [S000 Table 1; SPEC §5.3, §8.1].

The rows of a feature are checked as those of ``feature_points``
(:mod:`dbtools.rules.features`: ``feature.rows``, ``feature.pattern``, ``feature.order``,
``feature.straight_length``), with ``pos_m`` in place of ``km_m`` and the running order from
the track's begin to its end (pos increasing), reported on table ``track_feature_points``.
Against the network:

* ``feature.unknown_track`` (error) — the row's ``track_id`` is no track of the network
  (neither in ``tracks`` nor one derived from a line's grid). Fix: correct the track_id, or
  add the track to ``tracks``.
* ``feature.outside_track`` (error) — ``pos_m`` lies beyond the track's ``length_m`` (more
  than ``km_epsilon_m``): the row is not on its track. Fix: correct ``pos_m`` (the distance
  from the track's begin, as in ``track_points``) or the track's ``length_m``.
* ``feature.track_turn`` (error) — the track's centreline (``track_points``, or the ``gis``
  grid of its line) does not turn as the feature says between its straights: with ψ the
  heading of the centreline chord holding the middle of the entry straight (rows 1–2) and of
  the exit straight (rows 5–6), ψ_exit − ψ_entry differs from the feature's own turn
  θ = ±(r4 − r3 + (r3 − r2)/2 + (r5 − r4)/2)/R (+ left, as seen from the track's begin) by
  more than ``feature_tolerance``·|θ| + s/(2R) (s = ``gis_spacing_m``: a chord may reach into
  the curve). The positioning takes a feature for the track's geometry, so a wrong one could
  drop the true track. Fix: correct the attribute (left/right as seen running from the
  track's begin), ``radius_m`` or the ``pos_m`` of rows 3–4, or the centreline.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import arc_turn
from dbtools.network import Network
from dbtools.rules.common import Locator, column, py
from dbtools.rules.config import ValidationConfig
from dbtools.rules.features import FeatureRows, check_structure
from dbtools.topology import all_tracks, centreline
from schemas.enums import Attribute
from schemas.findings import Finding
from schemas.tables import TRACK_FEATURE_POINTS

T = TRACK_FEATURE_POINTS.name
FloatArray = npt.NDArray[np.float64]


def check_track_features(net: Network, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """All rules of the module docstring (nothing when the table is empty)."""
    fp = net.track_feature_points
    if fp.empty:
        return []
    r = FeatureRows.of(fp, config, loc, table=T, where=("track_id",), pos_col="pos_m")
    out, b, order_bad = check_structure(r, np.ones(len(fp)))
    tracks = all_tracks(net)
    length = dict(zip(tracks["track_id"].astype(str), tracks["length_m"].astype(float), strict=True))
    tid = column(fp, "track_id")
    known = np.array([t is not None and str(t) in length for t in tid])
    lim = np.array([length.get(str(t), np.nan) for t in tid])
    pos = r.km

    def unknown(i: int) -> Finding:
        return r.finding(
            "feature.unknown_track",
            f"track_id '{tid[i]}' is no track of the network (tracks, or a line's grid)",
            i,
            keys=r.row_keys(i),
            value=py(tid[i]),
            column="track_id",
        )

    def outside(i: int) -> Finding:
        return r.finding(
            "feature.outside_track",
            f"pos_m {pos[i]:g} is beyond the end of track {tid[i]} (length {lim[i]:g} m)",
            i,
            keys=r.row_keys(i),
            value=py(pos[i]),
            limit=[0.0, py(lim[i])],
            column="pos_m",
        )

    named = pd.notna(tid)
    out += r.capped("feature.unknown_track", np.flatnonzero(named & ~known), unknown)
    with np.errstate(invalid="ignore"):
        beyond = known & (pos > lim + config.km_epsilon_m)
    out += r.capped("feature.outside_track", np.flatnonzero(beyond), outside)
    if b is not None:
        out += _turns(net, r, b.block[~order_bad], tracks, config)
    return out


def _chord_headings(net: Network, row: pd.Series) -> tuple[FloatArray, FloatArray]:
    """(pos of the points, heading of each chord [rad, anticlockwise from east, unwrapped])
    of a track's centreline, in the local equirectangular plane (east = Δlon·cos lat)."""
    cl = centreline(net, row)
    if cl.lat.size < 2:
        return np.empty(0), np.empty(0)
    east = np.diff(cl.lon) * math.cos(math.radians(float(np.mean(cl.lat))))
    return cl.pos_m.astype(float), np.unwrap(np.arctan2(np.diff(cl.lat), east))


def _turns(
    net: Network, r: FeatureRows, block: npt.NDArray[np.int64], tracks: pd.DataFrame, config: ValidationConfig
) -> list[Finding]:
    """``feature.track_turn`` of the well-formed features ``block`` (k, 6)."""
    rows = {str(row["track_id"]): row for _, row in tracks.iterrows()}
    tid = column(net.track_feature_points, "track_id")
    tol, spacing = config.feature_tolerance, config.gis_spacing_m
    bad: list[tuple[int, float, float, float]] = []
    for blk in block:
        t = str(tid[blk[0]])
        if t not in rows:
            continue
        pos, psi = _chord_headings(net, rows[t])
        if psi.size == 0:
            continue
        u = r.km[blk]
        radius = float(r.radius[blk[2]])
        sign = 1.0 if r.attr[blk[2]] == Attribute.LEFT.value else -1.0
        theta = sign * arc_turn(u, radius)
        j = np.clip(np.searchsorted(pos, [(u[0] + u[1]) / 2, (u[4] + u[5]) / 2], side="right") - 1, 0, psi.size - 1)
        turn = float(psi[j[1]] - psi[j[0]])
        if abs(turn - theta) > tol * abs(theta) + spacing / (2.0 * radius):
            bad.append((int(blk[2]), turn, theta, tol * abs(theta) + spacing / (2.0 * radius)))

    def build(k: int) -> Finding:
        i, turn, theta, allowed = bad[k]
        return r.finding(
            "feature.track_turn",
            f"the centreline of track {tid[i]} turns {math.degrees(turn):+.1f}° between the straights, the "
            f"feature {math.degrees(theta):+.1f}° (± {math.degrees(allowed):.1f}°; + left from the track's begin)",
            i,
            keys=r.row_keys(i),
            value=round(math.degrees(turn), 2),
            limit=round(math.degrees(theta), 2),
            column="attribute",
        )

    return r.capped("feature.track_turn", np.arange(len(bad)), build)
