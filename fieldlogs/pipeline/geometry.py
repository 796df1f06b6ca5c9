"""Where the sensors sit on the vehicle, and the vehicle's extent along the track.

The positions the pipeline reports are those of the vehicle's **reference point** (x = 0 of
the vehicle frame, SPEC §4.1; ``schemas/vehicle.py``). A sensor at x_s forward of it (toward
the F end) reads the track at

    km_sensor = km_ref + k·x_s,

k = ±1 the sign of km per metre of body-forward travel (``Fix.k``, so a cab reversal is
followed). Hence a balise read by the reader at x_r is at the reference point's km
``km_balise − k·x_r`` [S003 §4: the reader's position is part of the onboard setup], and a
GPS fix taken at an antenna x_a ahead puts the reference point at ``km_fix − k·x_a``. The
vehicle occupies x ∈ [front_x − length, front_x]: its F end is at km_ref + k·front_x and its
R end at km_ref + k·(front_x − length); the head is the end in the running direction.

Without a ``vehicle`` block every offset is 0 (the sensors are at the reference point, as
in the suite's simulator) and the extent is unknown.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fieldlogs.pipeline.types import FloatArray


@dataclass(frozen=True)
class VehicleGeometry:
    """The offsets the pipeline uses (x forward of the reference point, metres)."""

    reader_x_m: float = 0.0
    """The balise reader."""
    gps_antenna_x_m: float = 0.0
    """The antenna of the ``gps`` stream (the vehicle block's ``gps_antenna``, else its first antenna)."""
    front_x_m: float | None = None
    """The F end (None: extent unknown)."""
    length_m: float | None = None

    @classmethod
    def of(cls, vehicle: dict[str, Any] | None) -> VehicleGeometry:
        """From run.json's ``vehicle`` block (already checked by the run reader)."""
        if not vehicle:
            return cls()
        reader = vehicle.get("balise_reader") or {}
        antennas = vehicle.get("antennas") or [{}]
        gps = vehicle.get("gps_antenna") or antennas[0]
        return cls(
            reader_x_m=float(reader.get("x_m", 0.0)),
            gps_antenna_x_m=float(gps.get("x_m", 0.0)),
            front_x_m=_opt(vehicle.get("front_x_m")),
            length_m=_opt(vehicle.get("length_m")),
        )

    def ends(self, km: FloatArray, k: FloatArray, cab: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(head, tail) km of the vehicle for reference-point km ``km``, body-forward km sign
        ``k`` and cab direction ``cab`` (+1: the F end leads); NaN when the extent is unknown."""
        if self.front_x_m is None or self.length_m is None:
            nan = np.full(np.shape(km), np.nan)
            return nan, nan.copy()
        f_end = km + k * self.front_x_m
        r_end = km + k * (self.front_x_m - self.length_m)
        leads = np.asarray(cab) >= 0
        return np.where(leads, f_end, r_end), np.where(leads, r_end, f_end)


def _opt(v: Any) -> float | None:
    return None if v is None else float(v)
