"""Enumerations shared by tables, logs, the pipeline and reports."""

from __future__ import annotations

from enum import IntEnum, StrEnum


class Track(StrEnum):
    """Track of a line. ``D`` (down) counts km up, ``U`` (up) counts km down, ``S`` single."""

    UP = "U"
    DOWN = "D"
    SINGLE = "S"


class BaliseKind(StrEnum):
    """I1/I2: initial-position pair (5 m apart); C: position-correction balise."""

    I1 = "I1"
    I2 = "I2"
    C = "C"


class Attribute(StrEnum):
    """Feature-point row attribute [S000 Table 1]."""

    STRAIGHT = "straight"
    TRANSITION = "transition"
    LEFT = "left"
    RIGHT = "right"
    NONE = "none"


class Severity(StrEnum):
    ERROR = "error"
    WARNING = "warning"


class CabDirection(StrEnum):
    """F: running forward (4-wire), R: running reversed (5-wire)."""

    FORWARD = "F"
    REVERSE = "R"


class VehicleKind(StrEnum):
    TRAIN = "train"
    ROAD_RAIL = "road_rail"


class GpsFix(IntEnum):
    """GPS fix quality as logged: 0 none, 1 GPS, 2 D-GPS."""

    NONE = 0
    GPS = 1
    DGPS = 2


class PositionState(StrEnum):
    """Fail-safe position states of the pipeline."""

    UNDETERMINED = "undetermined"
    DETERMINED = "determined"
    UNCERTAIN = "uncertain"


class RadarStatus(StrEnum):
    """Status of one radar frame [S004]: only ``ok`` and ``standstill`` carry a speed."""

    OK = "ok"
    STANDSTILL = "standstill"
    """No Doppler line but the ground echo is there: speed 0 (± the lowest measurable speed)."""
    ALIASED = "aliased"
    """Doppler beyond the Nyquist frequency (speed above the radar's range): no speed."""
    NO_REFLECTIONS = "no_reflections"
    """No ground echo at all (no line at a ground range, no static echo): no speed."""
    LOW_QUALITY = "low_quality"
    """Too few lines, missing samples, no clear direction or too large an uncertainty: no speed."""


def direction_sign(track: str) -> int:
    """+1 where km grows in the track's normal running direction (D, S), −1 on U."""
    return -1 if track == Track.UP else 1
