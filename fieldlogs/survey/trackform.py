"""Curves a network track along a line holds per track (``track_feature_points``), on the
line's km.

The survey places the runs' curvature on a track along a line — a main track, a station
track (``0420-3`` is line 0420 track ``3``), a branch — by the line km of its balise chains
(:mod:`fieldlogs.survey.curvature`), so the curves the DB gives that track by ``pos_m`` are
compared and proposed through the track's own km ↔ pos mapping, the pipeline's
(:class:`fieldlogs.pipeline.hypotheses.TrackLine`: the line grid's rolled length where the
track lies on its line's grid, a branch such as ``0421-S1``; else its ``track_points`` that
carry a km, linear between them).

* **DB → km** (:func:`km_features`): the six rows' pos → km, keyed by the track's line and
  local track (its ``tracks`` row), in that line track's normal running order (km
  increasing on D, S and station tracks, decreasing on U: :func:`schemas.enums.direction_sign`).
  ``track_feature_points`` are written from the track's begin to its end; where that runs
  against the normal order the rows are met 6…1: the positions are reversed and left/right
  swapped (the same lower-limit crossings, seen the other way). Every row keeps its
  ``track_id``; a feature with a row the mapping cannot place is left out.
* **km → pos** (:func:`pos_rows`): a proposal's six km rows (normal order) back to
  ``track_feature_points`` rows of the track, by the inverse mapping and the same reversal.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.hypotheses import track_lines
from schemas.enums import direction_sign

FloatArray = npt.NDArray[np.float64]
SWAP = {"left": "right", "right": "left"}


def along_line(network: Network) -> dict[str, tuple[str, str]]:
    """track_id → (line_code, local track) of every track along a line that holds
    ``track_feature_points`` rows."""
    tfp, t = network.track_feature_points, network.tracks
    if not len(tfp) or not len(t):
        return {}
    named = t[t["line_code"].notna() & t["track"].notna() & (t["line_code"].astype(str) != "")]
    held = set(tfp["track_id"].astype(str))
    return {
        str(r.track_id): (str(r.line_code), str(r.track))
        for r in named.itertuples(index=False)
        if str(r.track_id) in held
    }


def _remap(x: FloatArray, attrs: list[str], sign: int) -> tuple[FloatArray, list[str]]:
    """Six positions (seq order) and attributes in the order where sign·x increases:
    reversed with left/right swapped where they run the other way."""
    if sign * (x[-1] - x[0]) >= 0:
        return x, attrs
    return x[::-1].copy(), [SWAP.get(a, a) for a in attrs]


def km_features(network: Network) -> pd.DataFrame:
    """The ``track_feature_points`` of the tracks along a line as ``feature_points`` rows
    (line_code, track, feature_id, seq, km_m, radius_m, attribute, role) with their
    ``track_id`` (module docstring)."""

    def build() -> pd.DataFrame:
        tracks = along_line(network)
        tfp = network.track_feature_points
        out = []
        lines = track_lines(network).lines
        for (tid, fid), g in tfp[tfp["track_id"].astype(str).isin(tracks)].groupby(["track_id", "feature_id"]):
            g = g.sort_values("seq")
            tl = lines.get(str(tid))
            km = tl.km_of_pos(g["pos_m"].to_numpy(dtype=float)) if tl is not None else np.full(len(g), np.nan)
            if len(g) != 6 or not np.isfinite(km).all():
                continue
            line, track = tracks[str(tid)]
            km, attrs = _remap(km, g["attribute"].astype(str).tolist(), direction_sign(track))
            out.append(
                pd.DataFrame(
                    {
                        "line_code": line,
                        "track": track,
                        "feature_id": str(fid),
                        "seq": np.arange(1, 7),
                        "km_m": km,
                        "radius_m": g["radius_m"].to_numpy(dtype=float),
                        "attribute": attrs,
                        "role": g["role"].to_numpy(dtype=object) if "role" in g else None,
                        "track_id": str(tid),
                    }
                )
            )
        return pd.concat(out, ignore_index=True) if out else pd.DataFrame()

    return network.cached("survey_track_form_km_features", build)


def pos_rows(rows: list[dict[str, Any]], track_id: str, network: Network) -> list[dict[str, Any]]:
    """Six ``feature_points`` rows (km, the line track's normal order) as the
    ``track_feature_points`` rows of ``track_id`` (module docstring)."""
    km = np.array([float(r["km_m"]) for r in rows])
    pos, attrs = _remap(track_lines(network)[track_id].pos_of_kms(km), [str(r["attribute"]) for r in rows], 1)
    return [
        {"track_id": track_id, "feature_id": r["feature_id"], "seq": i + 1, "pos_m": round(float(x), 1)}
        | {"radius_m": r["radius_m"], "attribute": a, "role": r["role"]}
        for i, (r, x, a) in enumerate(zip(rows, pos, attrs, strict=True))
    ]
