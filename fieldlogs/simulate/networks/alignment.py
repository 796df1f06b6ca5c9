"""Railway alignment model: horizontal curvature piecewise linear in chainage (straights,
clothoid transitions, circular arcs) and a piecewise-linear gradient profile.

Chainage ``s`` is measured along the line centreline from its start; kilometrage is
``km0 + s``. Each track lies at a signed lateral offset from the centreline (positive
left of increasing km), so both tracks share one kilometrage as SPEC §3 requires.
Curvature is positive turning left in increasing km.

This is the "true" geometry of synthetic networks and of the bundled sample network; the
20 m GIS grid, the feature-point table and the simulator's motion are all derived from it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Curve:
    """One curve: entry clothoid, circular arc, exit clothoid (lengths in metres)."""

    start_m: float
    """Chainage of TS, where the entry transition starts."""
    transition_m: float
    arc_m: float
    radius_m: float
    left: bool
    """Turning left when running in increasing km."""

    @property
    def sc_m(self) -> float:
        return self.start_m + self.transition_m

    @property
    def cs_m(self) -> float:
        return self.sc_m + self.arc_m

    @property
    def end_m(self) -> float:
        """Chainage of ST, where the exit transition ends."""
        return self.cs_m + self.transition_m

    @property
    def curvature(self) -> float:
        return (1.0 if self.left else -1.0) / self.radius_m


def _interp_integral(knots_s: FloatArray, knots_v: FloatArray, s: FloatArray) -> FloatArray:
    """∫ from knots_s[0] to s of the piecewise-linear function through the knots (exact)."""
    seg = np.diff(knots_s)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (knots_v[:-1] + knots_v[1:]) * seg)])
    i = np.clip(np.searchsorted(knots_s, s, side="right") - 1, 0, len(knots_s) - 2)
    ds = s - knots_s[i]
    with np.errstate(invalid="ignore", divide="ignore"):
        slope = np.where(seg[i] > 0, (knots_v[i + 1] - knots_v[i]) / seg[i], 0.0)
    return cum[i] + knots_v[i] * ds + 0.5 * slope * ds * ds


@dataclass
class Alignment:
    """Horizontal and vertical alignment of one line (see module docstring)."""

    length_m: float
    curves: list[Curve] = field(default_factory=list)
    x0: float = 0.0
    y0: float = 0.0
    heading0: float = 0.0
    """Heading at s = 0, radians counter-clockwise from east (plane x)."""
    km0: float = 0.0
    grade_knots: list[tuple[float, float]] = field(default_factory=list)
    """(chainage, gradient as a fraction, + rising in increasing km); linear in between."""
    height0: float = 30.0
    step_m: float = 0.5

    def __post_init__(self) -> None:
        self.curves = sorted(self.curves, key=lambda c: c.start_m)
        prev_end = 0.0
        for c in self.curves:
            if c.start_m < prev_end - 1e-9 or c.end_m > self.length_m + 1e-9:
                raise ValueError(f"curve at {c.start_m:.1f} m overlaps another or the line end")
            if c.radius_m <= 0 or c.transition_m < 0 or c.arc_m < 0:
                raise ValueError("curve radius must be > 0 and lengths ≥ 0")
            prev_end = c.end_m
        ks, kv = [0.0], [0.0]
        for c in self.curves:
            ks += [c.start_m, c.sc_m, c.cs_m, c.end_m]
            kv += [0.0, c.curvature, c.curvature, 0.0]
        ks.append(self.length_m)
        kv.append(0.0)
        self._ks = np.asarray(ks, dtype=float)
        self._kv = np.asarray(kv, dtype=float)
        g = self.grade_knots or [(0.0, 0.0)]
        gs = [s for s, _ in g]
        gv = [v for _, v in g]
        if gs[0] > 0:
            gs, gv = [0.0, *gs], [gv[0], *gv]
        if gs[-1] < self.length_m:
            gs, gv = [*gs, self.length_m], [*gv, gv[-1]]
        self._gs = np.asarray(gs, dtype=float)
        self._gv = np.asarray(gv, dtype=float)
        # positions: cumulative trapezoid of the exact heading on a fine grid
        n = int(np.ceil(self.length_m / self.step_m)) + 1
        self._s = np.linspace(0.0, self.length_m, n)
        h = self.heading(self._s)
        ds = np.diff(self._s)
        self._x = self.x0 + np.concatenate([[0.0], np.cumsum(0.5 * (np.cos(h[:-1]) + np.cos(h[1:])) * ds)])
        self._y = self.y0 + np.concatenate([[0.0], np.cumsum(0.5 * (np.sin(h[:-1]) + np.sin(h[1:])) * ds)])

    # -- horizontal ---------------------------------------------------------------------
    def curvature(self, s: npt.ArrayLike) -> FloatArray:
        """Centreline curvature [1/m], positive left in increasing km."""
        return np.asarray(np.interp(np.asarray(s, dtype=float), self._ks, self._kv), dtype=np.float64)

    def heading(self, s: npt.ArrayLike) -> FloatArray:
        """Heading [rad] in increasing km, counter-clockwise from plane east."""
        return self.heading0 + _interp_integral(self._ks, self._kv, np.asarray(s, dtype=float))

    def xy(self, s: npt.ArrayLike, offset_m: float = 0.0) -> tuple[FloatArray, FloatArray]:
        """Plane coordinates of chainage ``s`` on a track ``offset_m`` left of the centreline."""
        sa = np.asarray(s, dtype=float)
        x = np.interp(sa, self._s, self._x)
        y = np.interp(sa, self._s, self._y)
        if offset_m:
            h = self.heading(sa)
            x = x - offset_m * np.sin(h)
            y = y + offset_m * np.cos(h)
        return x, y

    def track_curvature(self, s: npt.ArrayLike, offset_m: float = 0.0) -> FloatArray:
        """Curvature of the parallel track at ``offset_m`` (left positive): κ / (1 − d·κ)."""
        k = self.curvature(s)
        return k / (1.0 - offset_m * k)

    # -- vertical -----------------------------------------------------------------------
    def grade(self, s: npt.ArrayLike) -> FloatArray:
        """Gradient (rise per metre) in increasing km."""
        return np.asarray(np.interp(np.asarray(s, dtype=float), self._gs, self._gv), dtype=np.float64)

    def height(self, s: npt.ArrayLike) -> FloatArray:
        return self.height0 + _interp_integral(self._gs, self._gv, np.asarray(s, dtype=float))

    # -- kilometrage --------------------------------------------------------------------
    def km(self, s: npt.ArrayLike) -> FloatArray:
        return self.km0 + np.asarray(s, dtype=float)

    def chainage(self, km: npt.ArrayLike) -> FloatArray:
        return np.asarray(km, dtype=float) - self.km0

    @property
    def km_end(self) -> float:
        return self.km0 + self.length_m
