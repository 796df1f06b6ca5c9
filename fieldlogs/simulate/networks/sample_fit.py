"""Fit a railway alignment (straights, clothoid–arc–clothoid curves) to a coarse polyline.

The polylines of public map data (here mini-tokyo-3d, vertices ~50–100 m apart, denser in
curves) follow the real line but their curvature is useless for a feature-point table:
a polyline is straight between vertices and turns only at them. This module replaces it
by an :class:`~fieldlogs.simulate.networks.alignment.Alignment` whose curvature is railway-like:

1. **Plane.** Vertices to the JGD2011 plane rectangular zone of the area (zone IX here).
2. **Smoothed heading.** The polyline's heading is piecewise constant in chainage; sampled
   every ``sample_m`` and smoothed with a Gaussian (σ = ``sigma_m``, ≈ 100 m full width).
   Smoothing preserves the total turn, so κ = dθ/ds integrates to the true deflections.
3. **Curves.** Runs where |κ| > ``curvature_threshold`` (1/4000 1/m) of one sign are curve
   candidates; same-sign runs less than ``merge_gap_m`` apart are merged; candidates whose
   deflection Δθ (smoothed heading difference across the run, widened by 2σ) is below
   ``min_deflection_deg`` are wiggles of the data (station throats, digitising) and dropped.
4. **Railway curves.** Each candidate becomes clothoid + arc + clothoid with the *same
   deflection* (so the straights keep their headings): Δθ = (La + Lt)/R, i.e.
   κ = Δθ / (Lc − Lt) with Lc = La + 2·Lt the curve length. The transition length follows a
   simple rule, Lt = clip(0.1·R, 30, 80) m (not the line's actual design), with at least
   ``min_arc_m`` of circular arc. First guesses of R and the curve's position come from the
   centroid and spread (second moment, smoothing variance removed) of κ over the run.
5. **Reconcile.** Least squares (scipy ``least_squares``, TRF with bounds) adjusts the start
   point and heading, every straight's length and every curve's R and Δθ so that the
   raw vertices lie on the alignment (residual: perpendicular distance of each vertex; the
   first and last vertex also pin the ends). The result is exactly an ``Alignment``.
6. **Report.** Signed deviation of every raw vertex from the fitted centreline: max, RMS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from scipy.ndimage import gaussian_filter1d
from scipy.optimize import least_squares

from dbtools.gis.geometry import Projector
from dbtools.gis.georef import projector_for_points
from fieldlogs.simulate.networks.alignment import Alignment, Curve

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class FitSettings:
    sample_m: float = 5.0
    """Heading sampling step [m]."""
    sigma_m: float = 40.0
    """Gaussian smoothing of the heading, standard deviation [m] (FWHM ≈ 94 m)."""
    curvature_threshold: float = 1.0 / 4000.0
    """|κ| above this is curve [1/m]."""
    merge_gap_m: float = 60.0
    """Same-sign curve runs closer than this are one curve [m]."""
    min_deflection_deg: float = 3.0
    """Curves deflecting less than this are dropped as wiggles of the data [deg]."""
    kink_spread_m: float = 15.0
    kink_deflection_deg: float = 6.0
    """A turn concentrated at one vertex (κ spread below kink_spread_m once the smoothing is
    removed) and deflecting less than kink_deflection_deg is a kink of the data, dropped."""
    min_arc_m: float = 20.0
    """Shortest circular arc of a fitted curve [m]."""
    radius_bounds_m: tuple[float, float] = (250.0, 6000.0)
    min_straight_m: float = 50.0
    """Shortest straight between two curves [m] (room for the feature points' straight checks)."""
    eval_step_m: float = 4.0
    """Integration step of the alignment while fitting [m]."""


def transition_length(radius_m: float) -> float:
    """Transition length rule of the sample: 0.1·R clipped to 30–80 m."""
    return float(np.clip(0.1 * radius_m, 30.0, 80.0))


@dataclass
class CurveCandidate:
    """A curve found in the smoothed heading (before the least-squares fit)."""

    centre_m: float
    deflection_rad: float
    spread_m: float
    """Standard deviation of κ about the centre, smoothing removed [m]."""
    kept: bool


@dataclass
class FitResult:
    alignment: Alignment
    """Fitted centreline: plane coordinates, chainage 0 at the first raw vertex, km0 = 0."""
    projector: Projector
    x: FloatArray
    y: FloatArray
    """Raw vertices in the plane."""
    chainage_m: FloatArray
    """Chainage of each raw vertex's foot on the fitted centreline."""
    deviation_m: FloatArray
    """Signed distance of each raw vertex from the fitted centreline (left positive)."""
    candidates: list[CurveCandidate] = field(default_factory=list)
    smoothed_s: FloatArray = field(default_factory=lambda: np.empty(0))
    smoothed_curvature: FloatArray = field(default_factory=lambda: np.empty(0))
    evaluations: int = 0

    @property
    def max_m(self) -> float:
        return float(np.max(np.abs(self.deviation_m)))

    @property
    def rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.deviation_m**2)))


def smoothed_heading(x: FloatArray, y: FloatArray, settings: FitSettings) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(s, smoothed heading, curvature) of a polyline sampled every ``settings.sample_m``."""
    seg = np.hypot(np.diff(x), np.diff(y))
    sv = np.concatenate([[0.0], np.cumsum(seg)])
    heading = np.unwrap(np.arctan2(np.diff(y), np.diff(x)))
    step = settings.sample_m
    s = np.arange(step / 2, sv[-1], step)
    h = heading[np.clip(np.searchsorted(sv, s, side="right") - 1, 0, heading.size - 1)]
    hs = gaussian_filter1d(h, settings.sigma_m / step, mode="nearest")
    return s, hs, np.gradient(hs, step)


def find_curves(s: FloatArray, hs: FloatArray, kappa: FloatArray, settings: FitSettings) -> list[CurveCandidate]:
    """Curve candidates: runs of |κ| above the threshold, merged, with deflection and spread."""
    sign = np.where(np.abs(kappa) > settings.curvature_threshold, np.sign(kappa), 0.0)
    runs: list[list[int]] = []  # [first, last, sign]
    i = 0
    while i < s.size:
        if sign[i] == 0:
            i += 1
            continue
        j = i
        while j + 1 < s.size and sign[j + 1] == sign[i]:
            j += 1
        if runs and runs[-1][2] == sign[i] and s[i] - s[runs[-1][1]] < settings.merge_gap_m:
            runs[-1][1] = j
        else:
            runs.append([i, j, int(sign[i])])
        i = j + 1
    widen = round(2 * settings.sigma_m / settings.sample_m)
    out = []
    for k, (a, b, _) in enumerate(runs):
        lo = max(a - widen, 0 if k == 0 else (runs[k - 1][1] + a) // 2)
        hi = min(b + widen, s.size - 1 if k == len(runs) - 1 else (b + runs[k + 1][0]) // 2)
        dtheta = float(hs[hi] - hs[lo])
        kk, ss = kappa[lo : hi + 1], s[lo : hi + 1]
        total = float(np.sum(kk))
        centre = float(np.sum(ss * kk) / total) if total else float(np.mean(ss))
        var = float(np.sum((ss - centre) ** 2 * kk) / total) if total else 0.0
        spread = math.sqrt(max(var - settings.sigma_m**2, 25.0))
        kink = spread < settings.kink_spread_m and abs(dtheta) < math.radians(settings.kink_deflection_deg)
        kept = abs(dtheta) >= math.radians(settings.min_deflection_deg) and not kink
        out.append(CurveCandidate(centre, dtheta, spread, kept))
    return out


def _curve_lengths(radius: float, dtheta: float, settings: FitSettings) -> tuple[float, float]:
    """(transition, arc) of a curve of radius R deflecting |Δθ|: (La + Lt)/R = |Δθ|."""
    total = abs(dtheta) * radius  # La + Lt
    lt = min(transition_length(radius), max(total - settings.min_arc_m, 0.0))
    return lt, total - lt


class _Model:
    """Parameter vector ↔ alignment: [x0, y0, h0, (gap, R, Δθ) per curve, final straight]."""

    def __init__(self, n_curves: int, settings: FitSettings) -> None:
        self.n = n_curves
        self.settings = settings

    def curves(self, p: FloatArray) -> tuple[list[Curve], float]:
        out, pos = [], 0.0
        for k in range(self.n):
            gap, radius, dtheta = p[3 + 3 * k : 6 + 3 * k]
            lt, la = _curve_lengths(float(radius), float(dtheta), self.settings)
            start = pos + float(gap)
            out.append(Curve(start, lt, la, float(radius), bool(dtheta > 0)))
            pos = start + 2 * lt + la
        return out, pos + float(p[-1])

    def alignment(self, p: FloatArray, step_m: float = 0.5) -> Alignment:
        curves, length = self.curves(p)
        return Alignment(length, curves, x0=float(p[0]), y0=float(p[1]), heading0=float(p[2]), step_m=step_m)

    def polyline(self, p: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Centreline points every ``eval_step_m`` (coarse integration: fast residuals)."""
        a = self.alignment(p, step_m=self.settings.eval_step_m)
        n = max(int(np.ceil(a.length_m / self.settings.eval_step_m)), 2) + 1
        s = np.linspace(0.0, a.length_m, n)
        x, y = a.xy(s)
        return s, x, y


def project_brute(
    px: FloatArray, py: FloatArray, s: FloatArray, x: FloatArray, y: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """(chainage of the foot, signed offset, left positive) of points on a polyline, by brute
    force over all segments (a few hundred points × a few thousand segments)."""
    ax, ay = x[:-1][None, :], y[:-1][None, :]
    dx, dy = np.diff(x)[None, :], np.diff(y)[None, :]
    len2 = dx * dx + dy * dy
    qx, qy = px[:, None] - ax, py[:, None] - ay
    u = np.clip((qx * dx + qy * dy) / np.where(len2 > 0, len2, 1.0), 0.0, 1.0)
    d2 = (qx - u * dx) ** 2 + (qy - u * dy) ** 2
    j = np.argmin(d2, axis=1)
    rows = np.arange(px.size)
    uj = u[rows, j]
    cross = dx[0, j] * qy[rows, j] - dy[0, j] * qx[rows, j]
    dist = np.sqrt(d2[rows, j])
    return s[j] + uj * (s[j + 1] - s[j]), np.where(cross >= 0, 1.0, -1.0) * dist


def fit_alignment(lon: npt.ArrayLike, lat: npt.ArrayLike, settings: FitSettings | None = None) -> FitResult:
    """Fit an alignment to a polyline given as lon/lat vertices (see the module docstring)."""
    settings = settings or FitSettings()
    lon_a, lat_a = np.asarray(lon, dtype=float), np.asarray(lat, dtype=float)
    projector = projector_for_points(lat_a, lon_a)
    x, y = projector.to_xy(lon_a, lat_a)
    s, hs, kappa = smoothed_heading(x, y, settings)
    candidates = find_curves(s, hs, kappa, settings)
    kept = [c for c in candidates if c.kept]

    # first guess: straights at the median polyline heading between curves, curves from the
    # centroid and spread of κ (uniform-equivalent length √12·spread ≈ La + Lt)
    p0: list[float] = [float(x[0]), float(y[0])]
    bounds_lo: list[float] = [-np.inf, -np.inf, -np.inf]
    bounds_hi: list[float] = [np.inf, np.inf, np.inf]
    first_end = kept[0].centre_m - 2 * kept[0].spread_m if kept else s[-1]
    p0.append(float(np.median(hs[s < max(first_end, s[0] + settings.sample_m)])))
    r_lo, r_hi = settings.radius_bounds_m
    pos = 0.0
    for k, c in enumerate(kept):
        length = math.sqrt(12.0) * c.spread_m
        radius = float(np.clip(length / abs(c.deflection_rad), r_lo * 1.01, r_hi * 0.99))
        lt, la = _curve_lengths(radius, c.deflection_rad, settings)
        start = c.centre_m - la / 2 - lt
        gap_min = 0.0 if k == 0 else settings.min_straight_m
        p0 += [max(start - pos, gap_min + 1.0), radius, c.deflection_rad]
        pos = max(start, pos) + 2 * lt + la
        sign = 1.0 if c.deflection_rad > 0 else -1.0
        smallest = math.radians(settings.min_deflection_deg) / 2
        bounds_lo += [gap_min, r_lo, min(sign * smallest, sign * math.pi)]
        bounds_hi += [np.inf, r_hi, max(sign * smallest, sign * math.pi)]
    total = float(np.sum(np.hypot(np.diff(x), np.diff(y))))
    p0.append(max(total - pos, 1.0))
    bounds_lo.append(0.0)
    bounds_hi.append(np.inf)
    model = _Model(len(kept), settings)

    def residuals(p: FloatArray) -> FloatArray:
        sa, xa, ya = model.polyline(p)
        _, off = project_brute(x, y, sa, xa, ya)
        ends = [xa[0] - x[0], ya[0] - y[0], xa[-1] - x[-1], ya[-1] - y[-1]]
        return np.concatenate([off, ends])

    sol = least_squares(
        residuals,
        np.asarray(p0),
        bounds=(np.asarray(bounds_lo), np.asarray(bounds_hi)),
        x_scale="jac",
        method="trf",
        max_nfev=4000,
    )
    alignment = model.alignment(sol.x)
    sa = np.arange(0.0, alignment.length_m, 1.0)
    sa = np.append(sa, alignment.length_m)
    xa, ya = alignment.xy(sa)
    chainage, deviation = project_brute(x, y, sa, xa, ya)
    return FitResult(
        alignment,
        projector,
        x,
        y,
        chainage,
        deviation,
        candidates,
        s,
        kappa,
        int(sol.nfev),
    )
