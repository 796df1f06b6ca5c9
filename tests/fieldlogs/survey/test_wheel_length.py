"""The track length the wheel scales are measured against, hand-computed on a known curve
and gradient: the simulator's wheels roll it and the pipeline's metric measures it, each
its own way (splines in the plane with the projection's scale taken out, geodesic chords
with the arc, gradient and height added), and both equal the design's 3-D ground length."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.geometry import Projector
from dbtools.network import Network
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.simulate.track import TrackGeometry

#: JGD2011 zone IX: scale k0 = 0.9999 on its central meridian (plane x = 0).
ZONE = Projector(9)
K0 = 0.9999
R_E = 6_371_000.0


def _helix(radius: float, grade: float, h0: float, n: int = 31) -> tuple[pd.DataFrame, float]:
    """A curve of plane radius ``radius`` leaving the zone's origin northwards, a grid point
    per 20 m of plane arc, rising ``grade`` per metre of ground; and its 3-D ground length
    by hand: L_g = L_plane/k0, √((L_g·(1 + h̄/R_E))² + (g·L_g)²), h̄ the mean height."""
    arc = 20.0 * np.arange(n)
    phi = arc / radius
    x, y = -radius + radius * np.cos(phi), radius * np.sin(phi)
    lon, lat = ZONE.to_lonlat(x, y)
    ground = arc / K0
    h = h0 + grade * ground
    frame = pd.DataFrame({"line_code": "0001", "track": "D", "km_m": arc, "lat": lat, "lon": lon, "height_m": h})
    lg = float(ground[-1])
    hbar = h0 + grade * lg / 2.0
    return frame, float(np.hypot(lg * (1.0 + hbar / R_E), grade * lg))


@pytest.mark.parametrize(
    ("radius", "grade", "h0"), [(400.0, 0.02, 100.0), (400.0, 0.0, 0.0), (1200.0, -0.025, 500.0), (1e7, 0.0, 0.0)]
)
def test_simulator_and_metric_agree_with_the_hand_computed_length(radius: float, grade: float, h0: float) -> None:
    frame, expected = _helix(radius, grade, h0)
    net = Network({"gis": frame})
    m = track_metric(net, "0001", "D")
    measured = float(m.c[-1] - m.c[0])
    km = frame["km_m"].to_numpy()
    geom = TrackGeometry(
        "0001", "D", km, frame["lat"].to_numpy(), frame["lon"].to_numpy(), frame["height_m"].to_numpy()
    )
    rolled = float(geom.sigma(km[-1]) - geom.sigma(km[0]))
    # the effects tested, 600 m at R = 400 m, 20 ‰, 100 m up: projection 1/k0 +60 mm,
    # arc over 20 m chords s²/(24R²) +62 mm, gradient g²/2 +120 mm, height h/R_E +9 mm
    assert measured == pytest.approx(expected, rel=2e-7)
    assert rolled == pytest.approx(expected, rel=2e-7)


def test_the_length_does_not_depend_on_the_plane() -> None:
    frame, _ = _helix(400.0, 0.02, 100.0)
    a = track_metric(Network({"gis": frame}), "0001", "D").c
    b = track_metric(
        Network({"gis": frame}, meta={"metric_crs": "EPSG:6675", "metric_crs_source": "declared"}), "0001", "D"
    ).c
    assert np.array_equal(a, b)
