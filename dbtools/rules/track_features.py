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
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from dbtools.network import Network
from dbtools.rules.common import Locator, column, py
from dbtools.rules.config import ValidationConfig
from dbtools.rules.features import FeatureRows, check_structure
from dbtools.topology import all_tracks
from schemas.findings import Finding
from schemas.tables import TRACK_FEATURE_POINTS

T = TRACK_FEATURE_POINTS.name


def check_track_features(net: Network, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """All rules of the module docstring (nothing when the table is empty)."""
    fp = net.track_feature_points
    if fp.empty:
        return []
    r = FeatureRows.of(fp, config, loc, table=T, where=("track_id",), pos_col="pos_m")
    out, _, _ = check_structure(r, np.ones(len(fp)))
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
    return out
