"""GIS verification of the tracks off a line's kilometrage: the ``track_points`` grid of
station tracks, crossovers, connecting curves (SPEC §8.1), verified per ``track_id``.

The line verification (:func:`dbtools.gis.verify.run.verify_fixes`) keys its grid by
(line_code, track) and km. A ``track_points`` track has its own 20 m grid along its length
``pos_m`` (:mod:`dbtools.gis.track_grid`), which is the same structure with ``pos_m`` in the
place of km: so the very same steps (map-matching to the known track, cell statistics, the
between-run test, defects, scans, proposals) run on a *track-point grid*, a network whose
``gis`` holds one "line" per track id (line_code = ``track_id``, track ``S``, km = ``pos_m``)
in the same metric plane (the network's meta, hence its georeference, is kept). Fixes are
those whose position names a ``track_id`` that has track points; they carry no along-track
reference (the pipeline's km is a line km, not a distance along the track), so only the
lateral test applies — ``km_residual`` stays empty. In the result, ``line_code`` is the
track id and ``km_m`` the distance along the track from its begin.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from dbtools.gis.verify.config import FIX_COLUMNS, KM_EPOCH_COLUMN, VerifyConfig
from dbtools.gis.verify.result import GisVerification
from dbtools.gis.verify.run import verify_fixes
from dbtools.network import Network, empty_frame
from schemas.tables import GIS, KM_BREAKS

#: The local track name every track-point grid track gets (one track per track id).
POINT_TRACK = "S"


def track_point_network(network: Network) -> Network:
    """The network with its ``track_points`` as the grid (module docstring)."""

    def build() -> Network:
        tp = network.track_points
        gis = pd.DataFrame(
            {
                "line_code": tp["track_id"].astype(str),
                "track": POINT_TRACK,
                "km_m": tp["pos_m"].astype(float),
                "lat": tp["lat"].astype(float),
                "lon": tp["lon"].astype(float),
                "height_m": tp["height_m"] if "height_m" in tp else np.nan,
            }
        )
        tables = {**network.tables, GIS.name: gis, KM_BREAKS.name: empty_frame(KM_BREAKS)}
        return Network(tables=tables, meta=dict(network.meta), origin=network.origin)

    return network.cached(("gis_verify", "track_point_network"), build)


def verify_track_points(
    network: Network, fixes: pd.DataFrame, cfg: VerifyConfig | None = None
) -> GisVerification | None:
    """The verification of the track-point grid from the fixes on its tracks (``fixes`` with
    a ``track_id`` column); None when the network has no track points."""
    if network.track_points.empty:
        return None
    ids = set(network.track_points["track_id"].astype(str))
    tid = fixes["track_id"].astype(object) if "track_id" in fixes else pd.Series(None, index=fixes.index)
    on = fixes[tid.isin(ids).to_numpy(dtype=bool)]
    extra = [KM_EPOCH_COLUMN] if KM_EPOCH_COLUMN in on else []
    fx = on[[*FIX_COLUMNS, *extra]].assign(line_code=on["track_id"].astype(str), track=POINT_TRACK, km_ref_m=np.nan)
    return verify_fixes(track_point_network(network), fx.reset_index(drop=True), cfg)
