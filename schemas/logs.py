"""Field-log streams (SPEC §4): one folder per run, ``run.json`` plus one table per stream,
CSV or Parquet with the same columns. ``t`` is seconds since the start of the run.

Frame (SPEC §4.1): x forward, y left, z up; specific force with gravity (az ≈ +G at rest);
rates positive counter-clockwise seen from the axis' positive end (wz > 0 turning left,
wy < 0 nose pitching up).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

from schemas.enums import BaliseKind, CabDirection, Track, VehicleKind
from schemas.gnss import GNSS_BLOCK, GNSS_NAV, GNSS_OBS, GNSS_SBAS
from schemas.model import Column, Table
from schemas.tables import LAT_RANGE, LON_RANGE

T = Column("t", "float", "Seconds since the start of the run", unit="s", min=0.0)

#: Plausibility limits used by ``logs check`` (SPEC / issue 3).
MAX_ABS_ACCEL_MPS2 = 30.0
MAX_ABS_RATE_RADPS = 3.0

TACHO = Table(
    name="tacho",
    kind="log",
    description="Tachometer: cumulative pulse count every 100 ms cycle.",
    columns=(
        T,
        Column("pulses", "int", "Cumulative pulse count, never decreasing (teeth passed in either sense)", min=0),
        Column(
            "direction",
            "int",
            "Sense of motion from a two-phase tachometer over the cycle: +1 toward the vehicle's F end, "
            "−1 toward its R end (rolling back), 0 standstill or not known; absent: the driving cab's",
            nullable=True,
            required=False,
            min=-1,
            max=1,
        ),
    ),
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
        Column("kind", "str", "I1, I2, C or G (ETCS group)", enum=tuple(k.value for k in BaliseKind)),
        Column("line_code", "str", "Line code (I1)", nullable=True),
        Column("station_code", "str", "Station code (I2)", nullable=True),
        Column("track", "str", "Up/down (I2)", nullable=True, enum=tuple(t.value for t in Track)),
        Column("signal_type", "str", "Signal type (C)", nullable=True),
        *(
            Column(name, "int", f"G (ETCS balise group) only: {what}", required=False, nullable=True, min=lo, max=hi)
            for name, what, lo, hi in (
                ("nid_c", "country or region NID_C of the group", 0, 1023),
                ("nid_bg", "identity NID_BG of the group", 0, 16383),
                ("n_pig", "position N_PIG of the balise in its group", 0, 7),
                ("n_total", "balises in the group (N_TOTAL + 1), as in the balises table", 1, 8),
            )
        ),
        Column(
            "reader",
            "str",
            "Which cab's balise reader read the telegram on a vehicle with one per cab (F, R; run.json vehicle "
            "balise_reader and balise_reader_r); absent: the one reader",
            required=False,
            nullable=True,
            enum=tuple(d.value for d in CabDirection),
        ),
    ),
    required=False,
)

#: Optional gps columns that receivers log (``logs import``); absent in older runs.
GPS_RECORDER_COLUMNS = (
    Column(
        "gnss_time_s",
        "float",
        "Fix epoch, continuous GPS seconds since 1980-01-06",
        unit="s",
        required=False,
        nullable=True,
        min=0.0,
    ),
    Column(
        "height_m", "float", "Ellipsoidal height", unit="m", required=False, nullable=True, min=-1000.0, max=10000.0
    ),
    Column("speed_mps", "float", "Speed over ground", unit="m/s", required=False, nullable=True, min=0.0, max=150.0),
    Column(
        "course_deg",
        "float",
        "Course over ground, clockwise from true north",
        unit="deg",
        required=False,
        nullable=True,
        min=0.0,
        max=360.0,
    ),
    Column(
        "sigma_lat_m",
        "float",
        "1-σ latitude error (NMEA GST, UBX hAcc)",
        unit="m",
        required=False,
        nullable=True,
        min=0.0,
    ),
    Column(
        "sigma_lon_m",
        "float",
        "1-σ longitude error (NMEA GST, UBX hAcc)",
        unit="m",
        required=False,
        nullable=True,
        min=0.0,
    ),
    Column(
        "sigma_height_m",
        "float",
        "1-σ height error (NMEA GST, UBX vAcc)",
        unit="m",
        required=False,
        nullable=True,
        min=0.0,
    ),
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
        Column("nsat", "int", "Satellites used; empty where the source does not log it", nullable=True, min=0, max=64),
        Column("hdop", "float", "Horizontal dilution of precision", nullable=True, min=0.0, max=99.9),
        *GPS_RECORDER_COLUMNS,
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
    held=True,
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
        Column(
            "slipping_r",
            "int",
            "1 while the R cab's tacho axle slips or slides (a run with the R cab's own sensors, tacho_r)",
            required=False,
            nullable=True,
            min=0,
            max=1,
        ),
        Column(
            "track_id",
            "str",
            "True track (netElement) of a run routed over a network; empty on a one-line run",
            required=False,
            nullable=True,
        ),
        Column(
            "pos_m",
            "float",
            "True distance along that track from its begin",
            unit="m",
            required=False,
            nullable=True,
            min=0.0,
        ),
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

#: The R cab's own sensors on a vehicle with a positioning unit in each cab [S003 §2]: the
#: stream of the F cab's sensor (or the vehicle's one) → the R cab's, same columns. Each is
#: recorded in the R cab's own frame, x toward the vehicle's R end, y left of it, z up (the
#: vehicle's frame turned half round about z); its sensor's place is run.json vehicle
#: ``imu_r``, ``gps_antenna_r`` (the tacho: run.json's nominal wheel, its own axle).
CAB_R_STREAMS: dict[str, str] = {"imu": "imu_r", "tacho": "tacho_r", "gps": "gps_r"}


def _in_r_cab(table: Table) -> Table:
    """``table`` as the R cab's own sensor records it (:data:`CAB_R_STREAMS`)."""
    columns = tuple(
        replace(
            c,
            description="Sense of motion from the R cab's two-phase tachometer over the cycle: +1 toward the "
            "vehicle's R end (the R cab's forward), −1 toward its F end, 0 standstill or not known",
        )
        if c.name == "direction"
        else c
        for c in table.columns
    )
    what = f"The R cab's own {table.name} (a unit per cab), in the R cab's frame (x toward the vehicle's R end)"
    return replace(table, name=CAB_R_STREAMS[table.name], description=f"{what}: {table.description}", columns=columns)


#: Every stream, in the order they are listed and checked.
LOG_STREAMS: dict[str, Table] = {
    t.name: t
    for t in (
        TACHO,
        IMU,
        BALISE,
        GPS,
        CAB,
        TRUTH,
        RADAR,
        RADAR_IF,
        GNSS_OBS,
        GNSS_NAV,
        GNSS_SBAS,
        *(_in_r_cab(t) for t in (IMU, TACHO, GPS)),
    )
}


@dataclass(frozen=True)
class RunField:
    name: str
    type: type[Any]
    description: str
    required: bool = True


#: run.json's ``gnss`` block (the navigation header's ionosphere and time-system parameters),
#: declared beside the raw GNSS streams in ``schemas.gnss``; the ``vehicle`` block is
#: ``schemas.vehicle``.
RUN_JSON_GNSS_BLOCK = GNSS_BLOCK

RUN_JSON: tuple[RunField, ...] = (
    RunField("run_id", str, "Run identifier"),
    RunField("vehicle_id", str, "Vehicle identifier"),
    RunField("vehicle_kind", str, f"{' or '.join(v.value for v in VehicleKind)}"),
    RunField(
        "wheel_diameter_m",
        float,
        "Nominal wheel diameter [m] used for pulse distance (needed for a train, and wherever a tacho stream is)",
        required=False,
    ),
    RunField("teeth", int, "Tachometer pulses per wheel revolution (needed as wheel_diameter_m is)", required=False),
    RunField("start_time", str, "ISO 8601 wall-clock time of t = 0, with offset"),
    RunField("db_version", str, "DB version the run was recorded with", required=False),
    RunField("notes", str, "Free notes", required=False),
    RunField(
        "vehicle", dict, "Vehicle geometry (antennas, balise reader, IMU, axles): see VEHICLE_FIELDS", required=False
    ),
    RunField(
        "gnss",
        dict,
        "Navigation-header parameters (ionosphere, leap seconds, time corrections): GNSS_BLOCK",
        required=False,
    ),
    RunField(
        "sources", list, "Provenance of an imported run: [{file, sha256, format, counts, skipped}]", required=False
    ),
)
