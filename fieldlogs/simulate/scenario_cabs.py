"""The ``[cab_r]`` scenario table: the R cab's own sensors, for a vehicle with a positioning
unit in each cab working independently ([the position-detection field test §2]: 車載装置は各運転台に
設置し，独立して動作する).

With ``sensors = true`` the run also has the streams ``imu_r``, ``tacho_r`` and ``gps_r``
(``schemas.logs.CAB_R_STREAMS``): the R cab's IMU at ``imu_x_m``, its GPS antenna at
``gps_x_m`` (x forward of the reference point, toward the vehicle's F end, so the R cab's are
negative) and the tachometer of its own axle, whose true diameter has its own wear draw
(``tacho.wear_pct``) times ``1 + wheel_error_pct/100`` and its own slip/slide episodes
(``[slip]``); every noise is drawn independently of the F cab's sensors. The knobs are
documented with their units in ``fieldlogs/simulate/scenarios/default.toml``;
:func:`check_cab_r` holds the range checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: |x| of the R cab's sensors at most [m]: inside the simulated 20 m car (reference point at
#: its centre, ``fieldlogs.simulate.gnss.trainsim``), which run.json's vehicle block declares.
MAX_SENSOR_X_M = 10.0
#: |wheel_error_pct| at most [%].
MAX_WHEEL_ERROR_PCT = 20.0


@dataclass(frozen=True)
class CabRCfg:
    sensors: bool = False
    imu_x_m: float = -9.5
    gps_x_m: float = -9.5
    wheel_error_pct: float = 0.0


def check_cab_r(c: CabRCfg) -> tuple[str, str] | None:
    """(dotted key, message) of the first bad ``[cab_r]`` knob, or None."""
    for key, x in (("cab_r.imu_x_m", c.imu_x_m), ("cab_r.gps_x_m", c.gps_x_m)):
        if not (math.isfinite(x) and abs(x) <= MAX_SENSOR_X_M):
            return key, f"must lie within ±{MAX_SENSOR_X_M:g} m of the reference point (the car), got {x}"
    if not (math.isfinite(c.wheel_error_pct) and abs(c.wheel_error_pct) <= MAX_WHEEL_ERROR_PCT):
        return "cab_r.wheel_error_pct", f"must be within ±{MAX_WHEEL_ERROR_PCT:g} %, got {c.wheel_error_pct}"
    return None
