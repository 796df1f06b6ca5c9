"""The network of an onboard DB: tracks, connections, switches and the grid of tracks that
lie along no line (SPEC §8.1; RailTopoModel netElements/netRelations, railML 3, OSRD).

A *track* (netElement, track section) runs between two switches or ends. Where it lies
along a line (main and station tracks) it names its ``line_code`` and local name (U/D/S,
``1``, ``2``…) and the line's km at both ends, and its centreline is the ``gis`` grid of that
line and track between those km. A track along no line's km (crossovers, connecting curves,
sidings and yard tracks without kilometrage) has its centreline in ``track_points``, every
20 m of its own length.

A *connection* joins an end of one track to an end of another, with its navigability; the
connections at a switch name it. A *switch* lists its ports (OSRD's: a point switch has its
toe A1 and its branches B1 left and B2 right; a crossing or slip A1–B1 and A2–B2) and its
geometry: switch number n (frog angle atan(1/n)), diverging radius, the side of the
diverging branch.

Every table here is optional in a source set: a line-only source set (U/D/S grids) is a
network of one track per line and track and no switches (:mod:`dbtools.topology` derives
them), and a DB built from it holds these tables empty.
"""

from __future__ import annotations

from schemas.enums import Navigability, Side, SwitchType, TrackEnd, TrackKind
from schemas.model import Column, ForeignKey, Table

ENDS = tuple(e.value for e in TrackEnd)

TRACK_ID = Column("track_id", "str", "Track (netElement) identifier, kept verbatim from the source (e.g. 88_L_3842)")
#: A line code where a network row may lie along no line.
LINE_CODE_OPTIONAL = Column(
    "line_code", "str", "Line (route) code; empty where the row lies along no line", nullable=True
)


def _port(name: str, what: str, *, required: bool, open_ok: bool = False) -> tuple[Column, Column]:
    """The track and end columns of one switch port; ``open_ok``: a branch may lead out of
    the DB (an extract's edge: left empty, a warning of validation)."""
    nullable = not required or open_ok
    edge = "; empty where the branch leads out of the DB" if open_ok else ""
    return (
        Column(
            f"{name}_track", "str", f"Track at port {name.upper()}: {what}{edge}", required=required, nullable=nullable
        ),
        Column(
            f"{name}_end",
            "str",
            "End of that track at the switch (begin/end)",
            enum=ENDS,
            required=required,
            nullable=nullable,
        ),
    )


NETWORK_TRACKS = Table(
    name="tracks",
    kind="db",
    description=(
        "Tracks (netElements) of the network. A track along a line names its line_code, local "
        "track name and the km at both ends (its centreline: the gis grid of that line and track); "
        "any other track has its centreline in track_points."
    ),
    columns=(
        TRACK_ID,
        LINE_CODE_OPTIONAL,
        Column(
            "track",
            "str",
            "Local track name: U/D/S on a line, 1, 2, 3… in a station, a siding's name",
            required=False,
            nullable=True,
        ),
        Column(
            "kind",
            "str",
            "main, station, siding, crossover, connecting or yard",
            enum=tuple(k.value for k in TrackKind),
        ),
        Column(
            "km_begin_m",
            "float",
            "Line km at the track's begin (where it lies along a line)",
            unit="m",
            required=False,
            nullable=True,
            km_notation=True,
        ),
        Column(
            "km_end_m",
            "float",
            "Line km at the track's end (where it lies along a line)",
            unit="m",
            required=False,
            nullable=True,
            km_notation=True,
        ),
        Column("length_m", "float", "Length along the centreline from begin to end", unit="m", min=0.0),
        Column("name", "str", "Name or description", required=False, nullable=True),
        *(
            Column(
                f"{end}_buffer_stop",
                "bool",
                f"1: the track's {end} is a buffer stop (a dead end by design, not a gap in the data)",
                required=False,
                nullable=True,
            )
            for end in ENDS
        ),
    ),
    primary_key=("track_id",),
    without_rowid=True,
    foreign_keys=(ForeignKey(("line_code",), "lines", ("line_code",)),),
    # no secondary index: every reader reads the whole table (Table.indexes)
    required=False,
)

CONNECTIONS = Table(
    name="connections",
    kind="db",
    description=(
        "Connections (netRelations): an end of track A joined to an end of track B, and whether a "
        "train may pass A→B, B→A, both or neither (the two branches of a switch)."
    ),
    columns=(
        Column("track_a", "str", "Track A"),
        Column("end_a", "str", "End of track A at the connection (begin/end)", enum=ENDS),
        Column("track_b", "str", "Track B"),
        Column("end_b", "str", "End of track B at the connection (begin/end)", enum=ENDS),
        Column(
            "navigability",
            "str",
            "both, AB (A to B only), BA (B to A only) or none",
            enum=tuple(n.value for n in Navigability),
        ),
        Column("switch_id", "str", "The switch this connection passes, if any", required=False, nullable=True),
    ),
    primary_key=("track_a", "end_a", "track_b", "end_b"),
    without_rowid=True,
    foreign_keys=(
        ForeignKey(("track_a",), "tracks", ("track_id",)),
        ForeignKey(("track_b",), "tracks", ("track_id",)),
    ),
    # no secondary index on (track_b, end_b): every reader reads the whole table (Table.indexes)
    required=False,
)

SWITCHES = Table(
    name="switches",
    kind="db",
    description=(
        "Switches and crossings with their ports (point switch: A1 toe, B1 left and B2 right branch "
        "seen from the toe; crossing and slips: routes A1–B1 and A2–B2, slips also A1–B2 / A2–B1) and "
        "turnout geometry."
    ),
    columns=(
        Column("switch_id", "str", "Switch identifier, kept verbatim from the source"),
        Column(
            "type",
            "str",
            "point, crossing, single_slip or double_slip",
            enum=tuple(s.value for s in SwitchType),
        ),
        *_port("a1", "the toe of a point switch; one end of the first route of a crossing", required=True),
        *_port(
            "b1", "the left branch of a point switch; the other end of the first route", required=True, open_ok=True
        ),
        *_port(
            "b2",
            "the right branch of a point switch; one end of the second route of a crossing",
            required=True,
            open_ok=True,
        ),
        *_port("a2", "crossings and slips only: the other end of the second route", required=False),
        Column(
            "diverging_side",
            "str",
            "Point switch: the side of the diverging branch seen from the toe (the other is the through branch)",
            enum=tuple(s.value for s in Side),
            required=False,
            nullable=True,
        ),
        Column(
            "switch_number",
            "float",
            "Switch number n: the frog angle is atan(1/n) (1:9 to 1:18.5 in Europe, 8–16 in Japan)",
            required=False,
            nullable=True,
            min=1.0,
            max=100.0,
        ),
        Column(
            "diverging_radius_m",
            "float",
            "Radius of the diverging branch",
            unit="m",
            required=False,
            nullable=True,
            min=20.0,
        ),
        Column(
            "diverging_speed_kmh",
            "float",
            "Permitted speed on the diverging branch",
            unit="km/h",
            required=False,
            nullable=True,
            min=0.0,
            max=400.0,
        ),
        LINE_CODE_OPTIONAL,
        Column(
            "km_m", "float", "Line km of the switch's toe", unit="m", required=False, nullable=True, km_notation=True
        ),
        Column("lat", "float", "Latitude of the toe", unit="deg", required=False, nullable=True, min=-90.0, max=90.0),
        Column(
            "lon", "float", "Longitude of the toe", unit="deg", required=False, nullable=True, min=-180.0, max=180.0
        ),
        Column("name", "str", "Name or local number", required=False, nullable=True),
    ),
    primary_key=("switch_id",),
    without_rowid=True,
    foreign_keys=(ForeignKey(("line_code",), "lines", ("line_code",)),),
    required=False,
)

TRACK_POINTS = Table(
    name="track_points",
    kind="db",
    description=(
        "Centreline grid of the tracks along no line's km (crossovers, connecting curves, sidings "
        "and yard tracks without kilometrage): one point every 20 m of the track's own length."
    ),
    columns=(
        TRACK_ID,
        Column("pos_m", "float", "Distance along the track from its begin", unit="m", min=0.0),
        Column(
            "km_m",
            "float",
            "Line km at the point where the track has one (interpolated between km posts)",
            unit="m",
            required=False,
            nullable=True,
            km_notation=True,
        ),
        Column("lat", "float", "Latitude (datum of the metric CRS)", unit="deg", min=-90.0, max=90.0),
        Column("lon", "float", "Longitude, same datum", unit="deg", min=-180.0, max=180.0),
        Column(
            "height_m",
            "float",
            "Rail height, as in gis",
            unit="m",
            required=False,
            nullable=True,
            min=-100.0,
            max=4000.0,
        ),
    ),
    primary_key=("track_id", "pos_m"),
    without_rowid=True,
    foreign_keys=(ForeignKey(("track_id",), "tracks", ("track_id",)),),
    required=False,
)

#: The network tables, in dependency order (tracks first).
NETWORK_TABLES: tuple[Table, ...] = (NETWORK_TRACKS, CONNECTIONS, SWITCHES, TRACK_POINTS)

#: Ports of each switch type, and the routes through it (pairs of ports a train may pass).
SWITCH_PORTS: dict[SwitchType, tuple[str, ...]] = {
    SwitchType.POINT: ("a1", "b1", "b2"),
    SwitchType.CROSSING: ("a1", "b1", "a2", "b2"),
    SwitchType.SINGLE_SLIP: ("a1", "b1", "a2", "b2"),
    SwitchType.DOUBLE_SLIP: ("a1", "b1", "a2", "b2"),
}
SWITCH_ROUTES: dict[SwitchType, tuple[tuple[str, str], ...]] = {
    SwitchType.POINT: (("a1", "b1"), ("a1", "b2")),
    SwitchType.CROSSING: (("a1", "b1"), ("a2", "b2")),
    SwitchType.SINGLE_SLIP: (("a1", "b1"), ("a2", "b2"), ("a1", "b2")),
    SwitchType.DOUBLE_SLIP: (("a1", "b1"), ("a2", "b2"), ("a1", "b2"), ("a2", "b1")),
}
