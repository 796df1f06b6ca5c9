"""Turnout geometry for drawn networks: the diverging way of a point switch.

A turnout of switch number n has the frog angle α = atan(1/n); its diverging branch leaves
the through track tangentially on a circular arc of the diverging radius R until it reaches α.
A loop track or a crossover that ends up ``d`` to the side uses the reverse curve
arc R (0 → α), straight s, arc R (α → 0) with d = 2·R·(1 − cos α) + s·sin α; measured along
the main track its extent is e = 2·R·sin α + s·cos α = 2·R·tan(α/2) + d·cot α, so the radius
that fits a given extent between switch toes is R = (e − d·cot α) / (2·tan(α/2)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt


def radius_for_extent(extent: float, offset: float, n: float) -> float:
    """R of the reverse curve reaching ``offset`` over ``extent`` along the main track (module doc)."""
    alpha = math.atan(1.0 / n)
    r = (extent - offset / math.tan(alpha)) / (2 * math.tan(alpha / 2))
    if r <= 0:
        raise ValueError(f"a 1:{n:g} turnout cannot reach {offset} m to the side within {extent} m")
    if 2 * r * (1 - math.cos(alpha)) > offset:  # the two arcs alone go further: no straight
        raise ValueError(f"{extent} m is too long for a 1:{n:g} reverse curve {offset} m wide (e ≤ d·cot α + d/sin α)")
    return r


def reverse_curve_offset(along: npt.ArrayLike, extent: float, offset: float, n: float) -> npt.NDArray[np.float64]:
    """Lateral offset of the reverse curve at distances ``along`` the straight main track from
    the toe (0 … extent; clipped outside): arc, straight of slope tan α, mirrored arc."""
    r = radius_for_extent(extent, offset, n)
    alpha = math.atan(1.0 / n)
    a = np.clip(np.asarray(along, dtype=float), 0.0, extent)
    a1 = r * math.sin(alpha)
    first = r - np.sqrt(np.maximum(r * r - np.minimum(a, a1) ** 2, 0.0))
    mid = r * (1 - math.cos(alpha)) + (a - a1) * math.tan(alpha)
    last = offset - (r - np.sqrt(np.maximum(r * r - np.minimum(extent - a, a1) ** 2, 0.0)))
    return np.asarray(np.where(a <= a1, first, np.where(a >= extent - a1, last, mid)), dtype=float)


@dataclass
class Path2D:
    """A polyline of straights and circular arcs from (x0, y0) at heading h0 (rad from +x toward
    +y); ``arc(R, turn)`` turns to the left for turn > 0 (exact, no sampling)."""

    x0: float
    y0: float
    h0: float = 0.0
    pieces: list[tuple[float, float]] = field(default_factory=list)  # (length, curvature)

    def straight(self, length: float) -> Path2D:
        self.pieces.append((length, 0.0))
        return self

    def arc(self, radius: float, turn: float) -> Path2D:
        self.pieces.append((radius * abs(turn), math.copysign(1.0 / radius, turn)))
        return self

    @property
    def length(self) -> float:
        return sum(p[0] for p in self.pieces)

    def at(self, s: float) -> tuple[float, float, float]:
        """(x, y, heading) at arc length s."""
        x, y, h = self.x0, self.y0, self.h0
        for length, k in self.pieces:
            d = min(s, length)
            if k == 0.0:
                x, y = x + d * math.cos(h), y + d * math.sin(h)
            else:
                x += (math.sin(h + k * d) - math.sin(h)) / k
                y -= (math.cos(h + k * d) - math.cos(h)) / k
                h += k * d
            s -= d
            if s <= 0:
                break
        return x, y, h


def reverse_curves(x0: float, y0: float, offset: float, n: float, radius: float, sign: float) -> Path2D:
    """Arc R (0 → α), straight, arc R (α → 0) from (x0, y0) heading +x: a turnout's diverging
    curve and its way to a parallel track ``offset`` to the side (sign +1: left, +y)."""
    alpha = math.atan(1.0 / n)
    s = (offset - 2 * radius * (1 - math.cos(alpha))) / math.sin(alpha)
    return Path2D(x0, y0).arc(radius, sign * alpha).straight(s).arc(radius, -sign * alpha)
