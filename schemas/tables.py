"""Onboard DB tables and the source files they are built from (SPEC §3).

A source set is a folder with ``gis``, ``balises``, ``feature_points`` and optionally
``lines`` and ``km_breaks``, each as ``NAME.csv`` or ``NAME.xlsx``. The DB tables have the
same names and columns (plus derived ones such as ``feature_points.seq``) and a ``meta``
key/value table.
"""

from __future__ import annotations

from schemas.enums import Attribute, BaliseKind, Track
from schemas.model import KM_PLAUSIBLE_M, Column, ForeignKey, Table
from schemas.network import NETWORK_TABLES, TRACK_ID

#: Bumped whenever a DB table changes shape; stored as ``PRAGMA user_version``.
#: 2: the network tables (tracks, connections, switches, track_points) and the balise-group
#: columns of ``balises``. A version-1 DB is still read: it is a network without them.
#: 3: ``track_feature_points`` (curve feature points of network tracks by distance along the
#: track). A version-2 DB is read as one without them.
SCHEMA_VERSION = 3
#: The versions this tool reads.
READABLE_SCHEMA_VERSIONS = (1, 2, 3)
#: ``PRAGMA application_id`` of every onboard DB: ASCII "TPOS".
APPLICATION_ID = 0x54504F53

#: Latitude and longitude on the globe [deg]; where a network operates is its own
#: declaration or derivation (``dbtools.gis.georef``, DB meta ``area``).
LAT_RANGE = (-90.0, 90.0)
LON_RANGE = (-180.0, 180.0)
#: The JGD2011 box (lat_min, lat_max, lon_min, lon_max) [deg]: the area of the 19 plane
#: rectangular zones, and the operating area derived for a network whose median point is
#: inside it (the only area accepted before areas could be declared).
JAPAN_AREA = (20.0, 46.0, 122.0, 154.0)

TRACKS = tuple(t.value for t in Track)

LINE_CODE = Column("line_code", "str", "Line (route) code; a string, leading zeros kept")
TRACK = Column("track", "str", "U up (km decreasing), D down (km increasing), S single", enum=TRACKS)

LINES = Table(
    name="lines",
    kind="db",
    description="Lines (routes). Optional source; built from the codes used elsewhere if absent.",
    columns=(
        LINE_CODE,
        Column("name", "str", "Line name", required=False, nullable=True),
        Column(
            "attributes_json",
            "str",
            "Any further descriptive columns of lines.csv, as JSON",
            required=False,
            nullable=True,
        ),
    ),
    primary_key=("line_code",),
    required=False,
)

GIS = Table(
    name="gis",
    kind="db",
    description="20 m GIS kilometrage grid: one point every 20 m of km per line and track.",
    columns=(
        LINE_CODE,
        TRACK,
        Column("km_m", "float", "Kilometrage (multiple of 20 m)", unit="m", km_notation=True),
        Column(
            "lat",
            "float",
            "Latitude in the geodetic datum of the metric CRS (JGD2011, WGS 84, …)",
            unit="deg",
            min=LAT_RANGE[0],
            max=LAT_RANGE[1],
        ),
        Column("lon", "float", "Longitude, same datum", unit="deg", min=LON_RANGE[0], max=LON_RANGE[1]),
        Column(
            "height_m",
            "float",
            "Rail height: above the ellipsoid, or above the geoid named in meta (height_datum)",
            unit="m",
            required=False,
            nullable=True,
            min=-100.0,
            max=4000.0,
        ),
    ),
    primary_key=("line_code", "track", "km_m"),
    foreign_keys=(ForeignKey(("line_code",), "lines", ("line_code",)),),
)

#: Columns a table gained after schema version 1: they enter the content hash only when they
#: hold a value, so a DB of version 1 and the same content built today hash alike.
BALISE_GROUP_COLUMNS = (
    Column(
        "track_id",
        "str",
        "Track (netElement) of the balise, where the DB has a network (tracks)",
        required=False,
        nullable=True,
    ),
    Column(
        "nid_c", "int", "G only: country/region code NID_C of the group", required=False, nullable=True, min=0, max=1023
    ),
    Column("nid_bg", "int", "G only: identity NID_BG of the group", required=False, nullable=True, min=0, max=16383),
    Column(
        "n_pig",
        "int",
        "G only: position of the balise in its group N_PIG (0 = first in the nominal direction)",
        required=False,
        nullable=True,
        min=0,
        max=7,
    ),
    Column(
        "n_total",
        "int",
        "G only: number of balises in the group N_TOTAL + 1",
        required=False,
        nullable=True,
        min=1,
        max=8,
    ),
    Column(
        "link_group",
        "str",
        "G only: the next group announced by linking in the nominal direction, as NID_C:NID_BG",
        required=False,
        nullable=True,
    ),
    Column(
        "link_distance_m",
        "float",
        "G only: distance to that next group",
        unit="m",
        required=False,
        nullable=True,
        min=0.0,
        max=KM_PLAUSIBLE_M,
    ),
)

BALISES = Table(
    name="balises",
    kind="db",
    description=(
        "Balises. I1/I2: initial-position pair keyed by (line_code, station_code, track); "
        "C: position-correction balise governed by the pair named on its row; "
        "G: a balise of a European balise group (NID_C, NID_BG, N_PIG of N_TOTAL)."
    ),
    columns=(
        Column("balise_id", "str", "Unique balise identifier"),
        Column(
            "kind",
            "str",
            "I1, I2 (initial pair), C (correction) or G (balise group)",
            enum=tuple(k.value for k in BaliseKind),
        ),
        Column(
            "line_code", "str", "Line (route) code; I1/I2/C always, G where its track lies along a line", nullable=True
        ),
        Column(
            "station_code",
            "str",
            "I1/I2/C: station code of the (governing) initial pair",
            required=False,
            nullable=True,
        ),
        Column("track", "str", "Local track name: U, D or S for I1/I2/C", nullable=True),
        Column("signal_type", "str", "Signal type carried by a C balise telegram", required=False, nullable=True),
        Column("km_actual_m", "float", "Actual kilometrage", unit="m", km_notation=True),
        Column("km_equipment_m", "float", "Equipment kilometrage", unit="m", km_notation=True),
        Column(
            "dist_from_initial_m",
            "float",
            "C only: travel distance from the governing pair's I1",
            unit="m",
            required=False,
            nullable=True,
            min=0.0,
            max=KM_PLAUSIBLE_M,
        ),
        *BALISE_GROUP_COLUMNS,
    ),
    primary_key=("balise_id",),
    foreign_keys=(ForeignKey(("line_code",), "lines", ("line_code",)),),
    indexes=(("line_code", "station_code", "track"), ("kind",)),
)

#: Columns of a feature row that do not depend on how its position is given.
FEATURE_ID = Column("feature_id", "str", "Feature (curve) identifier within the line/track")
FEATURE_SEQ = Column("seq", "int", "Row number 1–6 in running order (derived at build)", required=False, min=1, max=6)
FEATURE_RADIUS = Column("radius_m", "float", "Curve radius; 0 on straight/transition/none rows", unit="m", min=0.0)
FEATURE_ATTRIBUTE = Column(
    "attribute", "str", "straight, transition, left, right or none", enum=tuple(a.value for a in Attribute)
)
FEATURE_ROLE = Column("role", "str", "Free text: what the row marks", required=False, nullable=True)

FEATURE_POINTS = Table(
    name="feature_points",
    kind="db",
    description=(
        "Curve feature points, six rows per feature in running order [S000 Table 1]. "
        "Attributes are as seen by a train in the track's normal direction "
        "(km increasing on D and S, decreasing on U)."
    ),
    columns=(
        LINE_CODE,
        TRACK,
        FEATURE_ID,
        FEATURE_SEQ,
        Column("km_m", "float", "Kilometrage of the row", unit="m", km_notation=True),
        FEATURE_RADIUS,
        FEATURE_ATTRIBUTE,
        FEATURE_ROLE,
    ),
    primary_key=("line_code", "track", "feature_id", "seq"),
    foreign_keys=(ForeignKey(("line_code",), "lines", ("line_code",)),),
    indexes=(("line_code", "track", "km_m"),),
)

TRACK_FEATURE_POINTS = Table(
    name="track_feature_points",
    kind="db",
    description=(
        "Curve feature points of network tracks, placed by distance along the track: curves on "
        "tracks without line km (crossovers, connecting curves, sidings, station tracks) or on any "
        "other track. Six rows per feature in running order [S000 Table 1], as in feature_points, "
        "with running order and attributes as seen by a train running from the track's begin to "
        "its end (pos_m increasing)."
    ),
    columns=(
        TRACK_ID,
        Column("feature_id", "str", "Feature (curve) identifier within the track"),
        FEATURE_SEQ,
        Column(
            "pos_m",
            "float",
            "Distance of the row along the track from its begin (as track_points.pos_m)",
            unit="m",
            min=0.0,
        ),
        FEATURE_RADIUS,
        FEATURE_ATTRIBUTE,
        FEATURE_ROLE,
    ),
    primary_key=("track_id", "feature_id", "seq"),
    foreign_keys=(ForeignKey(("track_id",), "tracks", ("track_id",)),),
    required=False,
)

KM_BREAKS = Table(
    name="km_breaks",
    kind="db",
    description=(
        "Kilometrage breaks: where the GIS grid of a line/track jumps from km_from_m to "
        "km_to_m instead of continuing in 20 m steps."
    ),
    columns=(
        LINE_CODE,
        TRACK,
        Column("km_from_m", "float", "Last grid km before the break", unit="m", km_notation=True),
        Column("km_to_m", "float", "First grid km after the break", unit="m", km_notation=True),
    ),
    primary_key=("line_code", "track", "km_from_m"),
    foreign_keys=(ForeignKey(("line_code",), "lines", ("line_code",)),),
    required=False,
)

META = Table(
    name="meta",
    kind="db",
    description="DB version metadata: key/value pairs.",
    columns=(
        Column(
            "key",
            "str",
            "db_version, created_at, tool_version, schema_version, content_hash, note, source_sha256:<file>, "
            "area, area_source, metric_crs, metric_crs_source, height_datum, geoid_model",
        ),
        Column("value", "str", "Value", nullable=True),
    ),
    primary_key=("key",),
)

#: Meta key prefix of the SHA-256 of each source file a DB was built from (``source_sha256:gis.csv``).
SOURCE_HASH_PREFIX = "source_sha256:"
#: Meta keys of the operating area, metric CRS and heights (``dbtools.gis.georef``).
GEOREF_META_KEYS = ("area", "area_source", "metric_crs", "metric_crs_source", "height_datum", "geoid_model")

#: Content tables in dependency order (lines first: the others reference it).
DB_TABLES: tuple[Table, ...] = (LINES, GIS, BALISES, FEATURE_POINTS, KM_BREAKS, *NETWORK_TABLES, TRACK_FEATURE_POINTS)
#: Tables a DB of schema version 1 does not have; read as empty, hashed only when not empty.
TABLES_SINCE_V2: tuple[Table, ...] = NETWORK_TABLES
#: Tables a DB of schema version 2 does not have; read as empty, hashed only when not empty.
TABLES_SINCE_V3: tuple[Table, ...] = (TRACK_FEATURE_POINTS,)
#: Tables added after version 1: read as empty where a DB lacks them, hashed only when not empty.
TABLES_ADDED: tuple[Table, ...] = (*TABLES_SINCE_V2, *TABLES_SINCE_V3)


def tables_absent_in(version: int) -> tuple[Table, ...]:
    """The content tables a DB of schema ``version`` does not have (read as empty)."""
    return (*(TABLES_SINCE_V2 if version < 2 else ()), *(TABLES_SINCE_V3 if version < 3 else ()))


ALL_DB_TABLES: tuple[Table, ...] = (*DB_TABLES, META)
#: Tables read from a source set, by file stem.
SOURCE_TABLES: dict[str, Table] = {t.name: t for t in DB_TABLES}

#: Feature-point curvature tolerance (SPEC §5.3): upper limit (1/R)(1 + 20 %), lower limit
#: (1/R)(1 − 20 %). The table's curve-entry and curve-exit rows sit at the lower-limit crossings.
FEATURE_TOLERANCE = 0.20
#: Nominal spacing of the GIS grid [m].
GIS_SPACING_M = 20.0
#: Distance between I1 and I2 of an initial pair [m].
PAIR_SPACING_M = 5.0
#: Distance between the track centres of a double-track line [m] (Japanese narrow gauge).
TRACK_SPACING_M = 3.8
