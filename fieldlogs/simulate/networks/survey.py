"""Synthetic surveys of a known line: the inputs of ``gis grid`` (track centreline vertices
and kilometre posts) generated from a :class:`~fieldlogs.simulate.networks.synthetic.LineSpec`.

Used by the bundled sample network and by the grid round-trip tests: gridding the survey
must give back :func:`fieldlogs.simulate.networks.synthetic.gis_grid` of the same line.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.geometry import Projector
from fieldlogs.simulate.networks.synthetic import LineSpec


def centreline_vertices(spec: LineSpec, projector: Projector, spacing_m: float = 10.0) -> pd.DataFrame:
    """Every track of the line as a polyline: a vertex every ``spacing_m`` of chainage (and at
    both ends), in increasing km, with the rail height (rows of ``schemas.gisinput.CENTRELINE_VERTICES``)."""
    a = spec.alignment
    s = np.arange(0.0, a.length_m, spacing_m)
    if a.length_m - s[-1] > 1e-6:
        s = np.append(s, a.length_m)
    frames = []
    for track in spec.tracks:
        x, y = a.xy(s, spec.offset(track))
        lon, lat = projector.to_lonlat(x, y)
        frames.append(
            pd.DataFrame(
                {
                    "line_code": spec.line_code,
                    "track": str(track),
                    "seq": np.arange(1, s.size + 1),
                    "lon": np.round(lon, 9),
                    "lat": np.round(lat, 9),
                    "height_m": np.round(a.height(s), 3),
                }
            )
        )
    return pd.concat(frames, ignore_index=True)


def km_posts(spec: LineSpec, projector: Projector, km: npt.ArrayLike, offset_m: float = 0.0) -> pd.DataFrame:
    """Kilometre posts at the given kms, standing ``offset_m`` left of the line centreline
    (rows of ``schemas.gisinput.KM_POSTS``, no breaks)."""
    a = spec.alignment
    km_a = np.asarray(km, dtype=float)
    x, y = a.xy(a.chainage(km_a), offset_m)
    lon, lat = projector.to_lonlat(x, y)
    return pd.DataFrame(
        {
            "line_code": spec.line_code,
            "km_m": km_a,
            "lon": np.round(lon, 9),
            "lat": np.round(lat, 9),
            "km_after_m": np.nan,
        }
    )
