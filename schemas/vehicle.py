"""The vehicle's geometry: run.json ``vehicle`` block, or a ``--vehicle VEHICLE.toml``.

Vehicle frame (SPEC §4.1): x forward (toward the F end) from the reference point, y left,
z up from the rail top (the top of rail plane under the reference point). Every position
below is in metres in that frame.

* ``length_m`` — coupler to coupler; ``front_x_m`` — x of the F end, so the vehicle
  occupies x ∈ [front_x_m − length_m, front_x_m];
* ``antennas`` — one per GNSS receiver (the ``receiver`` of ``gnss_obs`` rows);
* ``balise_reader`` — the antenna that reads balises;
* ``gps_antenna`` — the antenna of the ``gps`` stream (absent: the first of ``antennas``);
* ``balise_reader_r``, ``gps_antenna_r``, ``imu_r`` — on a vehicle with a positioning unit in
  each cab [S003 §2], the R cab's own reader and the sensors of its ``gps_r`` and ``imu_r``
  streams (``schemas.logs.CAB_R_STREAMS``), in this same vehicle frame;
* ``imu`` — lever arm of the IMU and the rotation of the (remapped) sensor axes to the
  body axes, z-y-x Tait–Bryan angles (yaw, then pitch, then roll) in degrees;
* ``axles`` — wheels; the axle named by ``tacho_axle`` carries the tachometer of the
  ``tacho`` stream and must give ``wheel_diameter_m`` and ``teeth`` (they become run.json's
  ``wheel_diameter_m`` / ``teeth``). ``tacho_axle`` is required for a train (a train run
  has a tacho stream) and wherever a tacho stream is imported; elsewhere it may be absent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

VType = Literal["str", "float", "int"]


@dataclass(frozen=True)
class VehicleField:
    name: str
    type: VType
    description: str
    unit: str = ""
    required: bool = True
    min: float | None = None
    max: float | None = None


#: Plausible wheel diameters [m] per vehicle kind (a road-rail vehicle's rail wheels are
#: small), the range any rail wheel lies in, and the teeth of a tachometer per revolution.
WHEEL_DIAMETER_M: dict[str, tuple[float, float]] = {"train": (0.5, 1.3), "road_rail": (0.2, 1.3)}
ANY_WHEEL_DIAMETER_M = (0.2, 1.3)
TEETH_RANGE = (1, 1000)

#: Largest |x| or |y| of a point on a vehicle [m] (a 25 m car plus margins).
MAX_X_M = 100.0
MAX_Y_M = 3.0

_X = VehicleField("x_m", "float", "Forward of the reference point", "m", min=-MAX_X_M, max=MAX_X_M)
_Y = VehicleField("y_m", "float", "Left of the reference point", "m", min=-MAX_Y_M, max=MAX_Y_M)
_Z = VehicleField("z_m", "float", "Above the rail top", "m", min=-1.0, max=8.0)

VEHICLE_TOP: tuple[VehicleField, ...] = (
    VehicleField("vehicle_id", "str", "Vehicle identifier (run.json vehicle_id)"),
    VehicleField("vehicle_kind", "str", "train or road_rail (run.json vehicle_kind)"),
    VehicleField("length_m", "float", "Length, coupler to coupler", "m", min=0.5, max=2 * MAX_X_M),
    VehicleField("reference", "str", "What the reference point is (free text, e.g. 'centre between bogies')"),
    VehicleField("front_x_m", "float", "x of the F end", "m", min=0.0, max=2 * MAX_X_M),
    VehicleField("tacho_axle", "str", "Axle id of the tacho stream's tachometer", required=False),
)
ANTENNA: tuple[VehicleField, ...] = (
    VehicleField("id", "str", "Antenna id, unique"),
    VehicleField("receiver", "str", "Receiver id, unique (gnss_obs.receiver)"),
    _X,
    _Y,
    _Z,
)
BALISE_READER: tuple[VehicleField, ...] = (
    _X,
    _Y,
    VehicleField("z_m", "float", "Above the rail top", "m", required=False, min=-1.0, max=2.0),
)
GPS_ANTENNA: tuple[VehicleField, ...] = (
    _X,
    _Y,
    VehicleField("z_m", "float", "Above the rail top", "m", required=False, min=-1.0, max=8.0),
)
IMU: tuple[VehicleField, ...] = (
    _X,
    _Y,
    _Z,
    VehicleField("roll_deg", "float", "Mounting roll, sensor → body", "deg", required=False, min=-180.0, max=180.0),
    VehicleField("pitch_deg", "float", "Mounting pitch, sensor → body", "deg", required=False, min=-90.0, max=90.0),
    VehicleField("yaw_deg", "float", "Mounting yaw, sensor → body", "deg", required=False, min=-180.0, max=360.0),
)
AXLE: tuple[VehicleField, ...] = (
    VehicleField("id", "str", "Axle id, unique"),
    _X,
    VehicleField(
        "wheel_diameter_m",
        "float",
        "Nominal wheel diameter (required on the tacho axle)",
        "m",
        required=False,
        min=ANY_WHEEL_DIAMETER_M[0],
        max=ANY_WHEEL_DIAMETER_M[1],
    ),
    VehicleField(
        "teeth",
        "int",
        "Tachometer pulses per revolution (an axle with a tacho)",
        required=False,
        min=TEETH_RANGE[0],
        max=TEETH_RANGE[1],
    ),
)
#: Sections of the vehicle block: (name, fields, is a list).
VEHICLE_SECTIONS: tuple[tuple[str, tuple[VehicleField, ...], bool], ...] = (
    ("antennas", ANTENNA, True),
    ("balise_reader", BALISE_READER, False),
    ("balise_reader_r", BALISE_READER, False),  # the R cab's, on a vehicle with a reader per cab [S003 §2]
    ("gps_antenna", GPS_ANTENNA, False),
    ("gps_antenna_r", GPS_ANTENNA, False),  # the R cab's (gps_r stream), a unit per cab [S003 §2]
    ("imu", IMU, False),
    ("imu_r", IMU, False),  # the R cab's (imu_r stream), a unit per cab [S003 §2]
    ("axles", AXLE, True),
)
