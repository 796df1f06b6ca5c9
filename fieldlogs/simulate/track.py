"""Route geometry of one line/track from the onboard DB's 20 m GIS grid.

The grid (lat, lon, height per 20 m of km) is projected to the JGD2011 plane zone and
interpolated by C2 cubic splines x(km), y(km), h(km) (grid heights carry mm rounding:
that shows as track irregularity of ~1e-5 /m in the vertical curvature). With ``'`` = d/dkm and
J_h = √(x'² + y'²), everything the motion needs follows analytically:

* heading Ψ (counter-clockwise from plane east): cos Ψ = x'/J_h, sin Ψ = y'/J_h;
  dΨ/dkm = (x'y'' − y'x'')/J_h²; horizontal curvature κ = (x'y'' − y'x'')/J_h³ (> 0 left
  in increasing km) and dκ/dkm;
* nose-up pitch of a body facing increasing km θ = atan(h'/J_h) and dθ/dkm;
* arc length along the 3-D rail on the ground σ(km) = ∫ √((G·J_h)² + h'²) dkm — the
  distance the wheels roll. G = (1 + h/R_E)/k turns plane length into ground length: k the
  projection's point scale (0.9999–1.0001 in a JGD2011 zone; G·J_h dkm is the geodesic
  length of the plane step, taken numerically per 1 m) and h/R_E the rail's height above
  the ellipsoid (R_E = 6 371 km). It differs from the km difference on the offset tracks
  of a double-track line in curves (radius R ∓ 1.9 m) and on gradients, as on a real line;
* cant from the curvature, so it ramps along the transitions by itself:
  cant = min(cant_max, c·V²·|κ|) [mm] (|κ| < 1/50 km counts as straight), roll of a body facing increasing km
  ψ = −sign(κ)·asin(cant/gauge) (left curve: outer right rail higher, left side down, ψ < 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
from scipy.interpolate import CubicSpline

from dbtools.gis.geometry import geodesic_step
from dbtools.gis.georef import projector_for_points
from dbtools.network import Network
from schemas.enums import Track
from schemas.tables import GIS_SPACING_M

FloatArray = npt.NDArray[np.float64]
#: Mean Earth radius for the rail height's length factor 1 + h/R_E [m].
EARTH_RADIUS_M = 6_371_000.0


class TrackLookupError(LookupError):
    """The line/track is not in the DB or its grid cannot carry a run."""


@dataclass
class TrackState:
    """Geometry at an array of km (see module docstring)."""

    cos_psi: FloatArray
    sin_psi: FloatArray
    dpsi_dkm: FloatArray
    theta: FloatArray
    dtheta_dkm: FloatArray
    kappa: FloatArray
    dkappa_dkm: FloatArray
    j: FloatArray
    """dσ/dkm (3-D ground arc length per metre of km)."""


@dataclass
class Cant:
    """cant = min(max_m, coef·(|κ| − κ0)⁺) [m], sin ψ = cant / gauge.

    κ0 = 1/50 km: curvature below it is straight track; the dead band keeps the sub-mm
    rounding noise of the GIS coordinates (curvature ~1e-6 /m) out of the cant and the roll
    rate, and shifts real cants by coef·κ0 ≈ 0.002 mm only.
    """

    coef_m2: float
    """c·V² in m·m: 11.8 mm·m/(km/h)² × V² / 1000."""
    max_m: float
    gauge_m: float
    kappa0: float = 2e-5

    def cant_m(self, kappa: FloatArray) -> FloatArray:
        return np.minimum(self.max_m, self.coef_m2 * np.clip(np.abs(kappa) - self.kappa0, 0.0, None))

    def roll(self, kappa: FloatArray, dkappa: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(ψ, dψ/dkm) of a body facing increasing km."""
        s = self.cant_m(kappa) / self.gauge_m
        psi = -np.sign(kappa) * np.arcsin(s)
        ramping = (np.abs(kappa) > self.kappa0) & (s * self.gauge_m < self.max_m)
        dpsi = np.where(ramping, -(self.coef_m2 / self.gauge_m) * dkappa / np.sqrt(1.0 - s * s), 0.0)
        return psi, dpsi


class TrackGeometry:
    """Splines through one line/track's GIS grid; σ ↔ km; lat/lon of track positions."""

    def __init__(
        self, line_code: str, track: str, km: FloatArray, lat: FloatArray, lon: FloatArray, h: FloatArray
    ) -> None:
        self.line_code, self.track = line_code, track
        self.km = km
        self.projector = projector_for_points(lat, lon)
        x, y = self.projector.to_xy(lon, lat)
        self._x0, self._y0 = float(x[0]), float(y[0])  # local origin keeps the splines well scaled
        self._sx = CubicSpline(km, x - self._x0)
        self._sy = CubicSpline(km, y - self._y0)
        ok = np.isfinite(h)
        h = np.interp(km, km[ok], h[ok]) if ok.any() else np.zeros_like(km)  # no height: level
        self._sh = CubicSpline(km, h)
        # σ(km) on a fine grid (≤ 1 m), trapezoid of J
        n = max(int(np.ceil((km[-1] - km[0]) / 1.0)) + 1, 2)
        self._kf = np.linspace(km[0], km[-1], n)
        self._ground = self._ground_factor(self._kf)
        j = self.state(self._kf).j
        self._sf = np.concatenate([[0.0], np.cumsum(0.5 * (j[1:] + j[:-1]) * np.diff(self._kf))])

    def _ground_factor(self, kf: FloatArray) -> FloatArray:
        """G at ``kf`` (module docstring): geodesic over plane length of each fine step,
        times 1 + h/R_E, at the steps' midpoints (held at both ends)."""
        x, y = self._sx(kf) + self._x0, self._sy(kf) + self._y0
        lon, lat = self.projector.to_lonlat(x, y)
        plane = np.hypot(np.diff(x), np.diff(y))
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = np.where(plane > 0, geodesic_step(lon, lat) / plane, np.nan)
        ok = np.isfinite(ratio)
        mid = 0.5 * (kf[1:] + kf[:-1])
        inv_k = np.interp(kf, mid[ok], ratio[ok]) if ok.any() else np.ones_like(kf)
        return np.asarray(inv_k * (1.0 + self._sh(kf) / EARTH_RADIUS_M), dtype=float)

    @classmethod
    def from_network(
        cls, network: Network, line_code: str, track: str, km_needed: tuple[float, float] | None = None
    ) -> TrackGeometry:
        """The track's geometry; ``km_needed`` picks the continuous grid piece (km breaks) that holds it."""
        gis = network.gis
        lines = sorted(set(gis["line_code"].dropna().astype(str)))
        if line_code not in lines:
            raise TrackLookupError(f"line '{line_code}' is not in the DB (lines: {', '.join(lines) or 'none'})")
        g = gis[(gis["line_code"] == line_code) & (gis["track"] == track)]
        if g.empty:
            tracks = sorted(set(gis.loc[gis["line_code"] == line_code, "track"].astype(str)))
            raise TrackLookupError(f"line '{line_code}' has no track '{track}' in the DB (tracks: {', '.join(tracks)})")
        g = g.sort_values("km_m")
        km = g["km_m"].to_numpy(dtype=float)
        lat = g["lat"].to_numpy(dtype=float)
        lon = g["lon"].to_numpy(dtype=float)
        h = g["height_m"].to_numpy(dtype=float, na_value=np.nan) if "height_m" in g else np.full(len(g), np.nan)
        # a kilometrage break splits the grid: keep the continuous piece that holds the run
        breaks = np.flatnonzero(np.abs(np.diff(km) - GIS_SPACING_M) > 1e-3) + 1
        pieces = np.split(np.arange(len(km)), breaks)
        lo, hi = km_needed if km_needed is not None else (km[0], km[-1])
        if lo < km[0] - 1e-6 or hi > km[-1] + 1e-6:
            bad = lo if lo < km[0] - 1e-6 else hi
            raise TrackLookupError(
                f"km {bad:.1f} is outside the GIS range {km[0]:.0f}–{km[-1]:.0f} of {line_code}/{track}"
            )
        chosen = [p for p in pieces if km[p[0]] <= lo + 1e-6 and hi <= km[p[-1]] + 1e-6]
        if not chosen:
            spans = ", ".join(f"{km[p[0]]:.0f}–{km[p[-1]]:.0f}" for p in pieces)
            raise TrackLookupError(
                f"km {lo:.1f}–{hi:.1f} is not inside one continuous GIS range of {line_code}/{track} (ranges: {spans})"
            )
        p = chosen[0] if km_needed is not None else max(pieces, key=len)
        if len(p) < 4:
            raise TrackLookupError(f"{line_code}/{track}: fewer than 4 GIS points, cannot build a route")
        return cls(line_code, track, km[p], lat[p], lon[p], h[p])

    @property
    def km_min(self) -> float:
        return float(self.km[0])

    @property
    def km_max(self) -> float:
        return float(self.km[-1])

    @property
    def normal_sign(self) -> int:
        """+1 where the track's normal running direction is increasing km (D, S), −1 on U."""
        return -1 if self.track == Track.UP else 1

    def state(self, km: npt.ArrayLike) -> TrackState:
        k = np.asarray(km, dtype=float)
        x1, x2, x3 = (self._sx(k, n) for n in (1, 2, 3))
        y1, y2, y3 = (self._sy(k, n) for n in (1, 2, 3))
        h1, h2 = self._sh(k, 1), self._sh(k, 2)
        jh2 = x1 * x1 + y1 * y1
        jh = np.sqrt(jh2)
        ground = np.interp(k, self._kf, self._ground)
        cross = x1 * y2 - y1 * x2
        djh = (x1 * x2 + y1 * y2) / jh
        kappa = cross / (jh2 * jh)
        dkappa = (x1 * y3 - y1 * x3) / (jh2 * jh) - 3.0 * cross * djh / (jh2 * jh2)
        return TrackState(
            cos_psi=x1 / jh,
            sin_psi=y1 / jh,
            dpsi_dkm=cross / jh2,
            theta=np.arctan2(h1, jh),
            dtheta_dkm=(h2 * jh - h1 * djh) / (jh2 + h1 * h1),
            kappa=kappa,
            dkappa_dkm=dkappa,
            j=np.sqrt(jh2 * ground * ground + h1 * h1),
        )

    def grade(self, km: npt.ArrayLike) -> FloatArray:
        """Gradient dh/dkm (rise per metre, + rising in increasing km)."""
        return np.asarray(self._sh(np.asarray(km, dtype=float), 1))

    def curvature(self, km: npt.ArrayLike) -> FloatArray:
        return self.state(km).kappa

    def sigma(self, km: npt.ArrayLike) -> FloatArray:
        return np.asarray(np.interp(np.asarray(km, dtype=float), self._kf, self._sf), dtype=float)

    def km_at(self, sigma: npt.ArrayLike) -> FloatArray:
        return np.asarray(np.interp(np.asarray(sigma, dtype=float), self._sf, self._kf), dtype=float)

    def xy(self, km: npt.ArrayLike, lateral_m: float | FloatArray = 0.0) -> tuple[FloatArray, FloatArray]:
        """Plane coordinates of track positions, ``lateral_m`` to the left of increasing km."""
        k = np.asarray(km, dtype=float)
        x, y = self._sx(k) + self._x0, self._sy(k) + self._y0
        if np.any(lateral_m):
            x1, y1 = self._sx(k, 1), self._sy(k, 1)
            jh = np.hypot(x1, y1)
            x, y = x - lateral_m * y1 / jh, y + lateral_m * x1 / jh
        return np.asarray(x), np.asarray(y)

    def lonlat(self, x: FloatArray, y: FloatArray) -> tuple[FloatArray, FloatArray]:
        return self.projector.to_lonlat(x, y)

    def cant_scale(self, km: npt.ArrayLike) -> tuple[FloatArray, FloatArray] | None:
        """Share of the curvature's cant laid at ``km`` and its derivative d/dkm; None: all of it
        everywhere (a line track; a network route has none on turnouts, :mod:`.netgeom`)."""
        return None

    def speed_cap(self, km: npt.ArrayLike) -> FloatArray | None:
        """A speed limit [m/s] at ``km`` besides line speed and curves (turnouts); None: none."""
        return None

    def height(self, km: npt.ArrayLike) -> FloatArray:
        """Rail height h(km) of the grid's spline (the grid's datum: ellipsoidal) [m]."""
        return np.asarray(self._sh(np.asarray(km, dtype=float)), dtype=float)
