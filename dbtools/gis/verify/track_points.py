"""GIS verification of the tracks off a line's kilometrage: the ``track_points`` grid of
station tracks, crossovers, connecting curves (SPEC §8.1), verified per ``track_id``.

The line verification (:func:`dbtools.gis.verify.run.verify_fixes`) walks its grid by
(line_code, track) and km. A ``track_points`` track has its own 20 m grid along its length
``pos_m`` (:mod:`dbtools.gis.track_grid`), which is the same structure with ``pos_m`` in the
place of km: so the very same steps (map-matching to the known track, cell statistics, the
between-run test, defects, scans, proposals) run on a *track-point grid*
(:func:`track_point_network`): internally a network whose ``gis`` holds one grid per track id
(walked as line ``track_id``, track ``S``, km = ``pos_m``, and declared as that track, so
every row comes out with its ``track_id``) in the same metric plane (the network's meta,
hence its georeference, is kept). Fixes are those whose position names a ``track_id`` that
has track points; they carry no along-track reference (the pipeline's km is a line km, not a
distance along the track), so only the lateral test applies — ``km_residual`` stays empty.

What a user sees (:func:`verify_track_points`) is keyed by ``track_id`` alone: the internal
walk is undone (:func:`on_tracks`) — ``line_code`` and ``track`` are the track's own names
from ``tracks`` (empty for a track along no line: a crossover), and the distance along the
track is named for what it is: ``pos_from_m``, ``pos_to_m`` (cells, defects, along-track
defects) and ``pos_m`` (proposed points), metres from the track's begin.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from dbtools.gis.verify.config import FIX_COLUMNS, KM_EPOCH_COLUMN, VerifyConfig
from dbtools.gis.verify.result import GisVerification
from dbtools.gis.verify.run import verify_fixes
from dbtools.network import Network, canonical, empty_frame
from schemas.network import NETWORK_TRACKS
from schemas.tables import GIS, KM_BREAKS

#: The local track name of every track-point grid track in the internal walk (one per track id).
POINT_TRACK = "S"
#: Columns renamed from the internal walk's km to the distance along the track.
POS_NAMES = {"km_from_m": "pos_from_m", "km_to_m": "pos_to_m", "km_m": "pos_m"}


def track_point_network(network: Network) -> Network:
    """The network with its ``track_points`` as the grid (module docstring)."""

    def build() -> Network:
        tp = network.track_points
        ids = tp["track_id"].astype(str)
        gis = pd.DataFrame(
            {
                "line_code": ids,
                "track": POINT_TRACK,
                "km_m": tp["pos_m"].astype(float),
                "lat": tp["lat"].astype(float),
                "lon": tp["lon"].astype(float),
                "height_m": tp["height_m"] if "height_m" in tp else np.nan,
            }
        )
        length = tp.groupby(ids)["pos_m"].max()
        tracks = pd.DataFrame(
            {
                "track_id": length.index,
                "line_code": length.index,
                "track": POINT_TRACK,
                "kind": "station",
                "km_begin_m": 0.0,
                "km_end_m": length.to_numpy(dtype=float),
                "length_m": length.to_numpy(dtype=float),
            }
        )
        tables = {
            **network.tables,
            GIS.name: gis,
            KM_BREAKS.name: empty_frame(KM_BREAKS),
            NETWORK_TRACKS.name: canonical(NETWORK_TRACKS, tracks),
        }
        return Network(tables=tables, meta=dict(network.meta), origin=network.origin)

    return network.cached(("gis_verify", "track_point_network"), build)


def on_tracks(network: Network, result: GisVerification) -> GisVerification:
    """``result`` of the internal walk as a user sees it (module docstring): ``line_code`` and
    ``track`` the track's own (empty off a line), km columns renamed to ``pos_*``."""
    t = network.tracks
    names = t.assign(track_id=t["track_id"].astype(str)).drop_duplicates("track_id").set_index("track_id")

    def named(frame: pd.DataFrame) -> pd.DataFrame:
        out = frame.rename(columns=POS_NAMES)
        tid = out["track_id"].astype(str)
        for col in ("line_code", "track"):
            values = names[col].astype(object).reindex(tid).to_numpy(dtype=object, copy=True)
            values[pd.isna(values)] = None  # a track along no line: empty, not NaN
            out[col] = pd.Series(values, index=out.index, dtype=object)
        return out

    return GisVerification(
        result.config,
        named(result.cells),
        named(result.defects),
        named(result.coverage),
        named(result.proposal),
        result.counts,
        result.km_residual,
        named(result.km_defects),
        result.scan,
    )


def verify_track_points(
    network: Network, fixes: pd.DataFrame, cfg: VerifyConfig | None = None
) -> GisVerification | None:
    """The verification of the track-point grid from the fixes on its tracks (``fixes`` with
    a ``track_id`` column), keyed by ``track_id``; None when the network has no track points."""
    if network.track_points.empty:
        return None
    ids = set(network.track_points["track_id"].astype(str))
    tid = fixes["track_id"].astype(object) if "track_id" in fixes else pd.Series(None, index=fixes.index)
    on = fixes[tid.isin(ids).to_numpy(dtype=bool)]
    extra = [KM_EPOCH_COLUMN] if KM_EPOCH_COLUMN in on else []
    fx = on[[*FIX_COLUMNS, *extra]].assign(line_code=on["track_id"].astype(str), track=POINT_TRACK, km_ref_m=np.nan)
    return on_tracks(network, verify_fixes(track_point_network(network), fx.reset_index(drop=True), cfg))
