"""Survey inputs of ``trainpos gis grid``: track centrelines and kilometre posts (SPEC §3,
"GIS grid … built from surveyed centrelines plus kilometre posts").

Centrelines come as CSV/XLSX (one row per vertex, declared below) or as a GeoJSON
FeatureCollection of LineStrings with properties ``line_code`` and ``track`` (an optional
third coordinate is the height); GeoJSON is flattened into the same rows before checking.

A centreline is either a line's track (``line_code`` + ``track``: the 20 m km grid of ``gis``)
or, with ``track_id``, a track along no line km — a crossover, a connecting curve, a turnout's
diverging curve (SPEC §8.1) — whose grid is every 20 m of its own length (``track_points``);
its ``line_code``, when given, names the line whose kilometre posts give it km.
"""

from __future__ import annotations

from schemas.model import Column, Table
from schemas.tables import LAT_RANGE, LINE_CODE, LON_RANGE, TRACKS

LON = Column("lon", "float", "Longitude, JGD2011/WGS84", unit="deg", min=LON_RANGE[0], max=LON_RANGE[1])
CL_LINE_CODE = Column(
    "line_code",
    "str",
    "Line (route) code; on a track_id row optional: the line whose km posts give the track km",
    required=False,
    nullable=True,
)
CL_TRACK = Column(
    "track",
    "str",
    "U up, D down, S single (a line's track); empty on a track_id row",
    enum=TRACKS,
    required=False,
    nullable=True,
)
CL_TRACK_ID = Column(
    "track_id",
    "str",
    "Track along no line km (crossover, connecting or turnout curve): its grid goes to track_points.csv",
    required=False,
    nullable=True,
)
LAT = Column("lat", "float", "Latitude, JGD2011/WGS84", unit="deg", min=LAT_RANGE[0], max=LAT_RANGE[1])

CENTRELINE_VERTICES = Table(
    name="centrelines",
    kind="source",
    description=(
        "Surveyed track centrelines for `gis grid`: one row per vertex, in `seq` order along the "
        "track. A line's track (line_code, track) may run either way: the kilometre posts decide "
        "which end is the low km. A track_id track begins at its lowest seq."
    ),
    columns=(
        CL_LINE_CODE,
        CL_TRACK,
        CL_TRACK_ID,
        Column("seq", "int", "Vertex order along the track (increasing numbers, gaps allowed)"),
        LON,
        LAT,
        Column(
            "height_m",
            "float",
            "Rail height above the ellipsoid (interpolated onto the grid)",
            unit="m",
            required=False,
            nullable=True,
            min=-100.0,
            max=4000.0,
        ),
    ),
    primary_key=("line_code", "track", "track_id", "seq"),
)

KM_POSTS = Table(
    name="km_posts",
    kind="source",
    description=(
        "Kilometre posts for `gis grid`: surveyed position and kilometrage, projected onto every "
        "track of the line. km_after_m marks a kilometrage break at the post: km counts to km_m "
        "before it and restarts at km_after_m after it."
    ),
    columns=(
        LINE_CODE,
        Column("km_m", "float", "Kilometrage of the post (before the break, if any)", unit="m", km_notation=True),
        LON,
        LAT,
        Column(
            "km_after_m",
            "float",
            "Kilometrage just after the post where a break occurs (must be larger than km_m)",
            unit="m",
            required=False,
            nullable=True,
            km_notation=True,
        ),
    ),
    primary_key=("line_code", "km_m"),
)

#: Both inputs by name.
GIS_INPUT_TABLES: dict[str, Table] = {t.name: t for t in (CENTRELINE_VERTICES, KM_POSTS)}
