"""Kilometrage ↔ distance along a track.

Both tracks of a double-track line share one kilometrage, but the wheels roll each
track's own length: in a curve of radius R and deflection Δθ the inner track is 1.9·Δθ m
shorter than its km difference (3.8 m track spacing) and the outer one longer — e.g.
0.16 % over a 600 m balise interval. Dead reckoning therefore advances along the track's
own length — the 3-D rail's, measured on the GIS grid (geodesic, so no map-projection scale
error; with the gradient, the curves' arc over their chords and the rail height:
:attr:`dbtools.gis.index.GridIndex.c`) — and converts back to km. Beyond the grid's ends
1 m of travel is 1 m of km.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from dbtools.gis.index import grid_index
from dbtools.network import Network

FloatArray = npt.NDArray[np.float64]


def _interp_extrapolated(x: FloatArray | float, xp: FloatArray, fp: FloatArray) -> FloatArray:
    """np.interp with slope-1 extension beyond both ends (one point: on Python floats, the same
    IEEE operations; the estimate is read one cycle at a time by the aids)."""
    xa = np.asarray(x, dtype=float)
    if xa.size == 1:
        v, lo, hi = xa.item(), float(xp[0]), float(xp[-1])
        if v > hi:
            r = float(fp[-1]) + (v - hi)
        elif v < lo:
            r = float(fp[0]) + (v - lo)
        else:
            r = float(np.interp(v, xp, fp))
        return np.full(xa.shape, r)
    out = np.interp(xa, xp, fp)
    out = np.where(xa < xp[0], fp[0] + (xa - xp[0]), out)
    return np.asarray(np.where(xa > xp[-1], fp[-1] + (xa - xp[-1]), out), dtype=np.float64)


@dataclass(frozen=True)
class TrackMetric:
    """Cumulative track length ``c`` at each grid km of one line/track."""

    km: FloatArray
    c: FloatArray
    max_slope: float = field(init=False, repr=False, compare=False)
    """The largest |Δkm / Δc| of :meth:`km_of_c` (at least 1, the slope beyond the ends; ∞ where two
    grid points share a c): a Lipschitz constant of the dead-reckoned km in the travel,
    |km(S₁) − km(S₀)| ≤ max_slope·|S₁ − S₀|, which the feature aid's scheduling bounds its
    next evaluation with (:meth:`~fieldlogs.pipeline.aids.features.FeatureUnit.evaluation_not_before`)."""

    def __post_init__(self) -> None:
        dk, dc = np.abs(np.diff(self.km)), np.diff(self.c)
        with np.errstate(divide="ignore", invalid="ignore"):
            slopes = np.where(dc > 0, dk / np.where(dc > 0, dc, 1.0), np.where(dk > 0, np.inf, 0.0))
        top = float(slopes.max(initial=1.0))
        object.__setattr__(self, "max_slope", float("inf") if top != top else max(1.0, top))  # NaN: no bound

    def c_of_km(self, km: FloatArray | float) -> FloatArray:
        return _interp_extrapolated(km, self.km, self.c)

    def km_of_c(self, c: FloatArray | float) -> FloatArray:
        return _interp_extrapolated(c, self.c, self.km)


IDENTITY = TrackMetric(np.array([0.0, 1.0]), np.array([0.0, 1.0]))


def track_metric(network: Network, line_code: str, track: str) -> TrackMetric:
    """The metric of a line/track: km and cumulative rail length ``c`` of its
    points in the network's grid index (:attr:`~dbtools.gis.index.GridIndex.c`); the
    identity when the track has fewer than two grid points.

    Kilometrage breaks (km jumps larger than the distance between the points) count the
    distance actually travelled, so km jumps across them as the grid does.
    """

    def build() -> TrackMetric:
        grid = grid_index(network)
        t = grid.track_id(line_code, track)
        if t is None or grid.end[t] - grid.start[t] < 2:
            return IDENTITY
        sl = slice(int(grid.start[t]), int(grid.end[t]))
        return TrackMetric(grid.km[sl], grid.c[sl])

    return network.cached(("track_metric", line_code, track), build)
