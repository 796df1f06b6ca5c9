"""The track's 3-D coordinate series [S002 fig. 1] and the antennas on the vehicle.

The track is a polyline of rail-top centreline points P_0..P_{N−1} (ECEF, or GIS latitude,
longitude and *ellipsoidal* height) with cumulative 3-D length s_j = Σ|P_{i+1} − P_i|. On
segment j, P(s) = P_j + (s − s_j)·t_j with the unit tangent t_j, so dP/ds = t_j exactly
(piecewise linear: the Gauss–Newton Jacobian is exact inside a segment).

An antenna mounted ``along_m`` ahead of the vehicle's reference point (+ towards the
vehicle's front), ``lateral_m`` to its left and ``height_m`` above the rail top sits at
A(s) = P(s + d·along) + d·lateral·(û × t) + height·û, with d = +1 when the vehicle faces
increasing s and −1 otherwise, and û the ellipsoid normal (unit up) of the segment. Cant
and the chord of a long body on a curve are below 0.2 m for usual offsets and are ignored.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fieldlogs.gnss.constants import FloatArray, IntArray
from fieldlogs.gnss.geodesy import ecef_to_geodetic, enu_basis, geodetic_to_ecef
from schemas.errors import InputError


class TrackGeometryError(InputError):
    """A track polyline that cannot carry a solution (fewer than 2 distinct points)."""


@dataclass(frozen=True)
class Antenna:
    """Antenna position on the vehicle (module docstring) [m]."""

    along_m: float = 0.0
    lateral_m: float = 0.0
    height_m: float = 0.0


@dataclass(frozen=True)
class TrackLine:
    """Piecewise-linear 3-D track (module docstring)."""

    xyz: FloatArray
    s: FloatArray
    tangent: FloatArray
    up: FloatArray
    left: FloatArray

    @classmethod
    def from_ecef(cls, xyz: FloatArray) -> TrackLine:
        p = np.asarray(xyz, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3:
            raise TrackGeometryError("track polyline: expected an (N, 3) array of ECEF points")
        seg = np.diff(p, axis=0)
        ln = np.linalg.norm(seg, axis=1)
        keep = np.concatenate([[True], ln > 1e-6])
        p = p[keep]
        if p.shape[0] < 2:
            raise TrackGeometryError("track polyline: fewer than 2 distinct points")
        seg = np.diff(p, axis=0)
        ln = np.linalg.norm(seg, axis=1)
        tangent = seg / ln[:, None]
        mid = 0.5 * (p[:-1] + p[1:])
        lat, lon, _ = ecef_to_geodetic(mid)
        up = enu_basis(lat, lon)[:, 2, :]
        left = np.cross(up, tangent)
        left /= np.linalg.norm(left, axis=1, keepdims=True)
        return cls(p, np.concatenate([[0.0], np.cumsum(ln)]), tangent, up, left)

    @classmethod
    def from_geodetic(cls, lat_deg: FloatArray, lon_deg: FloatArray, h_m: FloatArray) -> TrackLine:
        return cls.from_ecef(geodetic_to_ecef(np.radians(lat_deg), np.radians(lon_deg), np.asarray(h_m, dtype=float)))

    @property
    def length_m(self) -> float:
        return float(self.s[-1])

    def segment(self, s: FloatArray) -> IntArray:
        """Segment index of each s (clamped to the ends: outside, P(s) extrapolates the end segment)."""
        return np.clip(np.searchsorted(self.s, np.asarray(s, dtype=float), side="right") - 1, 0, self.s.size - 2)

    def point(self, s: FloatArray) -> FloatArray:
        """P(s) (…, 3)."""
        s = np.asarray(s, dtype=float)
        j = self.segment(s)
        return self.xyz[j] + (s - self.s[j])[..., None] * self.tangent[j]

    def antenna(
        self, s: FloatArray, antenna: Antenna, direction: FloatArray | float = 1.0
    ) -> tuple[FloatArray, FloatArray]:
        """Antenna position A(s) and dA/ds (the tangent at the antenna) for reference-point s."""
        s = np.asarray(s, dtype=float)
        d = np.broadcast_to(np.asarray(direction, dtype=float), s.shape)
        sa = s + d * antenna.along_m
        j = self.segment(sa)
        pos = (
            self.xyz[j]
            + (sa - self.s[j])[..., None] * self.tangent[j]
            + (d * antenna.lateral_m)[..., None] * self.left[j]
            + antenna.height_m * self.up[j]
        )
        return pos, self.tangent[j]

    def project(self, xyz: FloatArray) -> FloatArray:
        """s of the nearest polyline point of each ECEF point (for truth and tests; O(N) per point)."""
        q = np.atleast_2d(np.asarray(xyz, dtype=float))
        out = np.empty(q.shape[0])
        a = self.xyz[:-1]
        seg = self.xyz[1:] - a
        ln = np.diff(self.s)
        for start in range(0, q.shape[0], 256):
            qq = q[start : start + 256]
            rel = qq[:, None, :] - a[None]
            u = np.clip(np.einsum("qnk,nk->qn", rel, seg) / ln**2, 0.0, 1.0)
            d2 = np.sum((rel - u[..., None] * seg[None]) ** 2, axis=-1)
            k = np.argmin(d2, axis=1)
            out[start : start + 256] = self.s[k] + u[np.arange(k.size), k] * ln[k]
        return out
