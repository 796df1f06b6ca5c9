"""Field-log streams (SPEC §4): one folder per run, ``run.json`` plus one table per stream,
CSV or Parquet with the same columns. ``t`` is seconds since the start of the run.

Frame (SPEC §4.1): x forward, y left, z up; specific force with gravity (az ≈ +G at rest);
rates positive counter-clockwise seen from the axis' positive end (wz > 0 turning left,
wy < 0 nose pitching up).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from schemas.enums import BaliseKind, CabDirection, Track, VehicleKind
from schemas.model import Column, Table
from schemas.tables import LAT_RANGE, LON_RANGE
from schemas.units import SPEED_OF_LIGHT_MPS

T = Column("t", "float", "Seconds since the start of the run", unit="s", min=0.0)

#: Plausibility limits used by ``logs check`` (SPEC / issue 3).
MAX_ABS_ACCEL_MPS2 = 30.0
MAX_ABS_RATE_RADPS = 3.0

TACHO = Table(
    name="tacho",
    kind="log",
    description="Tachometer: cumulative pulse count every 100 ms cycle.",
    columns=(T, Column("pulses", "int", "Cumulative pulse count, never decreasing", min=0)),
    rate_hz=10.0,
    required=False,
)


def _acc(name: str, what: str) -> Column:
    return Column(name, "float", what, unit="m/s²", min=-MAX_ABS_ACCEL_MPS2, max=MAX_ABS_ACCEL_MPS2)


def _rate(name: str, what: str) -> Column:
    return Column(name, "float", what, unit="rad/s", min=-MAX_ABS_RATE_RADPS, max=MAX_ABS_RATE_RADPS)


IMU = Table(
    name="imu",
    kind="log",
    description="6-axis IMU, body frame x forward, y left, z up, specific force with gravity.",
    columns=(
        T,
        _acc("ax", "Forward specific force"),
        _acc("ay", "Leftward specific force"),
        _acc("az", "Upward specific force (≈ +G at rest)"),
        _rate("wx", "Roll rate (positive: left side up... right-handed about x)"),
        _rate("wy", "Pitch rate (negative when the nose pitches up)"),
        _rate("wz", "Yaw rate (positive turning left)"),
    ),
    rate_hz=100.0,
    required=False,
)

BALISE = Table(
    name="balise",
    kind="log",
    description="Balise telegrams received, one row per balise passed.",
    columns=(
        T,
        Column("kind", "str", "I1, I2 or C", enum=tuple(k.value for k in BaliseKind)),
        Column("line_code", "str", "Line code (I1)", nullable=True),
        Column("station_code", "str", "Station code (I2)", nullable=True),
        Column("track", "str", "Up/down (I2)", nullable=True, enum=tuple(t.value for t in Track)),
        Column("signal_type", "str", "Signal type (C)", nullable=True),
    ),
    required=False,
)

GPS = Table(
    name="gps",
    kind="log",
    description="GPS receiver output, 1 Hz.",
    columns=(
        T,
        Column("lat", "float", "Latitude", unit="deg", nullable=True, min=LAT_RANGE[0], max=LAT_RANGE[1]),
        Column("lon", "float", "Longitude", unit="deg", nullable=True, min=LON_RANGE[0], max=LON_RANGE[1]),
        Column("fix", "int", "0 none, 1 GPS, 2 D-GPS", min=0, max=2),
        Column("nsat", "int", "Satellites used", min=0, max=64),
        Column("hdop", "float", "Horizontal dilution of precision", nullable=True, min=0.0, max=99.9),
    ),
    rate_hz=1.0,
    required=False,
)

CAB = Table(
    name="cab",
    kind="log",
    description="Cab events: running direction and road-rail PTO (on rail).",
    columns=(
        T,
        Column("direction", "str", "F forward (4-wire), R reverse (5-wire)", enum=tuple(d.value for d in CabDirection)),
        Column("pto", "int", "Road-rail PTO: 1 on rail, 0 off", required=False, nullable=True, min=0, max=1),
    ),
    required=False,
)

TRUTH = Table(
    name="truth",
    kind="log",
    description="Ground truth (simulated or surveyed runs only).",
    columns=(
        T,
        Column("line_code", "str", "Line code", nullable=True),
        Column("track", "str", "Track", nullable=True, enum=tuple(t.value for t in Track)),
        Column("km_m", "float", "True actual kilometrage", unit="m", nullable=True),
        Column("speed_mps", "float", "True speed over ground (signed: + in cab forward)", unit="m/s"),
        Column("slipping", "int", "1 while the wheel slips or slides", min=0, max=1),
    ),
    required=False,
)

RADAR = Table(
    name="radar",
    kind="log",
    description="2-frequency CW radar ground speed [S004], about 3 Hz.",
    columns=(T, Column("speed_mps", "float", "Ground speed", unit="m/s", min=0.0, max=150.0)),
    rate_hz=3.0,
    required=False,
)


def _if(name: str, what: str) -> Column:
    return Column(name, "float", what, unit="FS", min=-1.0, max=1.0, float32=True)


#: S004 Table 1: f1 and f2 alternate every T_pri = 50 µs, one (f1, f2) pair per 100 µs.
RADAR_IF_NOMINAL_RATE_HZ = 1.0 / (2 * 50e-6)

RADAR_IF = Table(
    name="radar_if",
    kind="log",
    description=(
        "Raw IF samples of the 2-frequency CW radar [S004], one row per (f1, f2) pair: f1 sampled "
        "at t, f2 T_pri later; I + jQ normalised to the ADC full scale (FS); rate 1/(2·T_pri) "
        "of the run.json 'radar' block."
    ),
    columns=(
        T,
        _if("i1", "In-phase sample of f1"),
        _if("q1", "Quadrature sample of f1"),
        _if("i2", "In-phase sample of f2 (T_pri after f1)"),
        _if("q2", "Quadrature sample of f2"),
    ),
    rate_hz=RADAR_IF_NOMINAL_RATE_HZ,
    required=False,
)

#: Every stream, in the order they are listed and checked.
LOG_STREAMS: dict[str, Table] = {t.name: t for t in (TACHO, IMU, BALISE, GPS, CAB, TRUTH, RADAR, RADAR_IF)}


@dataclass(frozen=True)
class RunField:
    name: str
    type: type
    description: str
    required: bool = True


RUN_JSON: tuple[RunField, ...] = (
    RunField("run_id", str, "Run identifier"),
    RunField("vehicle_id", str, "Vehicle identifier"),
    RunField("vehicle_kind", str, f"{' or '.join(v.value for v in VehicleKind)}"),
    RunField("wheel_diameter_m", float, "Nominal wheel diameter [m] used for pulse distance"),
    RunField("teeth", int, "Tachometer pulses per wheel revolution"),
    RunField("start_time", str, "ISO 8601 wall-clock time of t = 0, with offset"),
    RunField("db_version", str, "DB version the run was recorded with", required=False),
    RunField("notes", str, "Free notes", required=False),
)


@dataclass(frozen=True)
class RadarField:
    """One number of the optional ``run.json`` block ``radar`` and its plausible range."""

    name: str
    unit: str
    description: str
    min: float
    max: float


#: The ``radar`` block of ``run.json`` (needed to process ``radar_if``); S004 Table 1 values
#: in the descriptions. ``looks_toward`` (optional, ``F`` default) is the vehicle end the beam
#: points to.
RUN_JSON_RADAR: tuple[RadarField, ...] = (
    RadarField("f0_hz", "Hz", "Carrier frequency f0 (Table 1: 24.06 GHz)", 1e9, 300e9),
    RadarField("delta_f_hz", "Hz", "Frequency difference Δf = f2 − f1 (Table 1: 12.75 MHz)", 1e5, 1e9),
    RadarField("t_pri_s", "s", "Switching interval f1 → f2, T_pri (Table 1: 50 µs)", 1e-7, 1e-2),
    RadarField("t_epi_s", "s", "Observation time of one FFT frame, T_epi (Table 1: 307 ms)", 1e-3, 10.0),
    RadarField("height_m", "m", "Antenna height h above the ground (track bed) surface", 0.05, 5.0),
    RadarField("depression_deg", "deg", "Beam axis below the horizontal, toward looks_toward", 5.0, 85.0),
    RadarField("beam_elev_deg", "deg", "Half-power half-width in elevation (Table 1: ±7.5°)", 0.5, 30.0),
    RadarField("beam_az_deg", "deg", "Half-power half-width in azimuth (Table 1: ±3.0°)", 0.5, 30.0),
)
RADAR_LOOKS_TOWARD = (CabDirection.FORWARD.value, CabDirection.REVERSE.value)


@dataclass(frozen=True)
class RadarParams:
    """The run's radar [S004 Table 1] and the figures that follow from it."""

    f0_hz: float
    delta_f_hz: float
    t_pri_s: float
    t_epi_s: float
    height_m: float
    depression_deg: float
    beam_elev_deg: float
    beam_az_deg: float
    looks_toward: str = "F"

    @property
    def wavelength_m(self) -> float:
        """λ = c / f0 (24.06 GHz: 12.46 mm)."""
        return SPEED_OF_LIGHT_MPS / self.f0_hz

    @property
    def sample_rate_hz(self) -> float:
        """Samples per second of each frequency: 1 / (2·T_pri) (10 kHz)."""
        return 1.0 / (2.0 * self.t_pri_s)

    @property
    def samples_per_frame(self) -> int:
        """N = round(T_epi · rate) samples of each frequency per FFT frame (3070)."""
        return max(round(self.t_epi_s * self.sample_rate_hz), 1)

    @property
    def speed_resolution_mps(self) -> float:
        """ΔV = λ / (2·T_epi): one Doppler bin as radial speed (0.073 km/h)."""
        return self.wavelength_m / (2.0 * self.t_epi_s)

    @property
    def v_max_mps(self) -> float:
        """Radial speed at the Doppler Nyquist frequency rate/2: λ·rate/4 (112.14 km/h)."""
        return self.wavelength_m * self.sample_rate_hz / 4.0

    @property
    def r_max_m(self) -> float:
        """Unambiguous range c / (2·Δf) of the phase difference (11.76 m)."""
        return SPEED_OF_LIGHT_MPS / (2.0 * self.delta_f_hz)

    @property
    def look_sign(self) -> int:
        """+1 when the beam looks toward the F end (body +x), −1 toward the R end."""
        return 1 if self.looks_toward == CabDirection.FORWARD.value else -1

    def depression_range_rad(self, beamwidths: float) -> tuple[float, float]:
        """Depression angles of the beam axis ± ``beamwidths`` half-widths, kept in (0.5°, 89.5°)."""
        lo = self.depression_deg - beamwidths * self.beam_elev_deg
        hi = self.depression_deg + beamwidths * self.beam_elev_deg
        return math.radians(max(lo, 0.5)), math.radians(min(hi, 89.5))

    def to_json(self) -> dict[str, float | str]:
        return {f.name: getattr(self, f.name) for f in RUN_JSON_RADAR} | {"looks_toward": self.looks_toward}
