"""Enumerations shared by tables, logs, the pipeline and reports."""

from __future__ import annotations

from enum import IntEnum, StrEnum


class Track(StrEnum):
    """Track of a line. ``D`` (down) counts km up, ``U`` (up) counts km down, ``S`` single."""

    UP = "U"
    DOWN = "D"
    SINGLE = "S"


class BaliseKind(StrEnum):
    """I1/I2: initial-position pair (5 m apart); C: position-correction balise [S003];
    G: a balise of a European (ETCS) balise group, identified by NID_C/NID_BG and its
    position N_PIG in the group (SUBSET-026 §3.4, §7.5)."""

    I1 = "I1"
    I2 = "I2"
    C = "C"
    G = "G"


#: The kinds of the papers' Japanese balise system [S003]: keyed by line, station and track.
S003_KINDS = (BaliseKind.I1, BaliseKind.I2, BaliseKind.C)


class TrackKind(StrEnum):
    """What a track (netElement, track section) of the network is used for."""

    MAIN = "main"
    """a running track of a line (U/D/S of the papers)"""
    STATION = "station"
    """a platform or loop track of a station (``1``, ``2``, ``3``…)"""
    SIDING = "siding"
    CROSSOVER = "crossover"
    """joins two parallel tracks of one line through two switches"""
    CONNECTING = "connecting"
    """a connecting curve between lines (its own length, no line km)"""
    YARD = "yard"


class TrackEnd(StrEnum):
    """An end of a track: where its distance from the begin is 0, or its length
    (RailTopoModel ``positionOn`` 0 and 1; railML 2 ``trackBegin``/``trackEnd``)."""

    BEGIN = "begin"
    END = "end"


class Navigability(StrEnum):
    """May a train pass a connection from track A to track B, the other way, both or neither
    (RailTopoModel ``navigability``; ``none`` joins the two branches of a switch)."""

    BOTH = "both"
    A_TO_B = "AB"
    B_TO_A = "BA"
    NONE = "none"


class SwitchType(StrEnum):
    """Kinds of track node with moving or crossing parts (OSRD's switch types, railML 3
    ``switchIS/@type``, OSM ``railway:switch``)."""

    POINT = "point"
    """a turnout: toe (port A) and two branches (B1 left, B2 right seen from the toe)"""
    CROSSING = "crossing"
    """a diamond crossing: A1–B1 and A2–B2 cross, no change of track"""
    SINGLE_SLIP = "single_slip"
    """a diamond crossing with one slip route (A1–B2)"""
    DOUBLE_SLIP = "double_slip"
    """a diamond crossing with both slip routes (A1–B2, A2–B1)"""


class Side(StrEnum):
    """The side of the diverging branch of a turnout, seen from its toe."""

    LEFT = "left"
    RIGHT = "right"


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
    AMBIGUOUS = "ambiguous"
    """On a network after a facing switch: several candidate tracks remain (``candidates``);
    no track is claimed until evidence leaves one."""


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


class IqConvention(StrEnum):
    """How a radar's recorded I and Q samples form the complex IF signal [S004 §2].

    ``i+jq``: z = I + jQ (the default; a target approaching where the radar looks gives a
    positive Doppler frequency and the f1–f2 phase difference gives its range). ``i-jq``:
    z = I − jQ — the quadrature channel recorded with the other sign (a common wiring):
    the recorded spectrum is the mirror image, Doppler and range phase both change sign.
    """

    I_PLUS_JQ = "i+jq"
    I_MINUS_JQ = "i-jq"


def direction_sign(track: str) -> int:
    """+1 where km grows in the track's normal running direction (D, S), −1 on U."""
    return -1 if track == Track.UP else 1


class FixSource(StrEnum):
    """What set the position in force (``positions.last_fix_source``)."""

    NONE = "none"
    BALISE = "balise"
    FEATURE = "feature"
    GPS = "gps"
    GNSS = "gnss"
    """A track-constrained GNSS epoch from raw pseudoranges [S002]: corrects the km, but is no
    absolute fix for the position-correction % (that measures the wheel between balises)."""

    @property
    def absolute(self) -> bool:
        """A source good enough to compute a position-correction % from [S003 §5.2]."""
        return self in (FixSource.BALISE, FixSource.FEATURE)


class EventType(StrEnum):
    """Types of the pipeline's ``events`` output; :data:`EVENT_MEANING` says what each is."""

    INPUT_REPAIRED = "input_repaired"
    ON_RAIL = "on_rail"
    OFF_RAIL = "off_rail"
    INITIAL_POSITION = "initial_position"
    INITIAL_POSITION_GPS = "initial_position_gps"
    BALISE_CORRECTION = "balise_correction"
    PAIR_IGNORED = "pair_ignored"
    C_BALISE_IGNORED = "c_balise_ignored"
    BALISE_ANOMALY = "balise_anomaly"
    FEATURE_CORRECTION = "feature_correction"
    FEATURE_REFUSED = "feature_refused"
    SLIP = "slip"
    SLIDE = "slide"
    FAILSAFE = "failsafe"
    IMU_LOST = "imu_lost"
    IMU_BACK = "imu_back"
    TRACK_DECISION = "track_decision"
    CROSSOVER = "crossover"
    TRACK_CHANGE = "track_change"
    GPS_TRACK_DISAGREES = "gps_track_disagrees"
    INITIAL_POSITION_GNSS = "initial_position_gnss"
    GNSS_CORRECTION = "gnss_correction"
    GNSS_REFUSED = "gnss_refused"
    GNSS_TRACK_DISAGREES = "gnss_track_disagrees"
    CLOCK_OFFSET = "clock_offset"
    WHEEL_SCALE = "wheel_scale"
    BALISE_CLOCK = "balise_clock"
    SWITCH_SPLIT = "switch_split"
    TRACK_RESOLVED = "track_resolved"
    HYPOTHESIS_DROPPED = "hypothesis_dropped"
    TRACK_CHANGE_REFUSED = "track_change_refused"
    GPS_CORRECTION = "gps_correction"
    ROLLBACK_SUSPECTED = "rollback_suspected"
    UNITS_DISAGREE = "units_disagree"


EVENT_MEANING: dict[EventType, str] = {
    EventType.INPUT_REPAIRED: "a stream was sorted or had rows without t or with a repeated t dropped",
    EventType.ON_RAIL: "PTO on: a road-rail vehicle was put on rail (position starts undetermined)",
    EventType.OFF_RAIL: "PTO off: the vehicle left the rail; its position is forgotten",
    EventType.INITIAL_POSITION: "an I1→I2 initial pair set line, track and km [S003 §4.3]",
    EventType.INITIAL_POSITION_GPS: "a GPS up/down decision set the initial position (10 m uncertainty) [S001 §4.2]",
    EventType.BALISE_CORRECTION: "an initial pair or a C balise corrected the km; correction_pct is the position-"
    "correction % [S003 §4.5]",
    EventType.PAIR_IGNORED: "an I2 without its I1 within 10 m of travel (reverse order or missed I1)",
    EventType.C_BALISE_IGNORED: "a C telegram before any initial pair, or running against the pair's direction",
    EventType.BALISE_ANOMALY: "a telegram the DB does not know, or an ambiguous C balise; the state is kept",
    EventType.FEATURE_CORRECTION: "a curve feature point corrected the km at its exit crossing [S000 §3.2]",
    EventType.FEATURE_REFUSED: "a curve feature point failed a diagnostic (named in detail.failed); no correction",
    EventType.SLIP: "wheel slip (traction) corrected inertially [S000 §3.1]",
    EventType.SLIDE: "wheel slide (braking) corrected inertially [S000 §3.1]",
    EventType.FAILSAFE: "a slip/slide correction exceeded the maximum correction time: position uncertain",
    EventType.ROLLBACK_SUSPECTED: "a start moved against the cab by the IMU (rolling back; the tacho gives no "
    "sense): travel taken as backward, position uncertain [S003 §5.3(2)]",
    EventType.IMU_LOST: "the IMU fell silent while moving: slips cannot be detected; position uncertain, margin grows",
    EventType.IMU_BACK: "the IMU samples are back (the position stays uncertain until the next absolute fix)",
    EventType.TRACK_DECISION: "trusted GPS fixes decided line and track (up/down) [S001 §4.2]",
    EventType.CROSSOVER: "the offset from the decided track moved across to the other track [S001 §7]",
    EventType.TRACK_CHANGE: "after a crossover GPS decided the other track (uncertain until a pair confirms it)",
    EventType.GPS_TRACK_DISAGREES: "a GPS decision contradicts the balise-given track without a crossover",
    EventType.INITIAL_POSITION_GNSS: "a track-constrained GNSS epoch set the initial position on the GPS-decided "
    "track (its own uncertainty) [S002]",
    EventType.GNSS_CORRECTION: "a track-constrained GNSS epoch whose uncertainty is below the margin corrected "
    "the km [S002]",
    EventType.GNSS_REFUSED: "notice: the GNSS aid cannot run on this track (no heights, …) or an epoch "
    "contradicts the estimate; no correction",
    EventType.GNSS_TRACK_DISAGREES: "constrained fits on another track of the line are far better: evidence "
    "against the track in force (kept) [S002]",
    EventType.CLOCK_OFFSET: "warning: the IMU's or GPS' clock is offset from the tacho's beyond the tolerance "
    "(cross-correlation); the stream's t was moved back by the offset",
    EventType.WHEEL_SCALE: "warning: the balise intervals show a wheel scale error beyond the margin's share; the "
    "margin's distance share was widened to cover it",
    EventType.BALISE_CLOCK: "warning: the balise corrections follow the speed at the telegrams (a late or early "
    "balise clock); the telegrams' t was moved back by the offset, or the balises refused",
    EventType.SWITCH_SPLIT: "dead reckoning reached a facing switch: one candidate per branch, position ambiguous",
    EventType.TRACK_RESOLVED: "evidence (detail.evidence: balise_group, gps, imu, or the aid that set a track) "
    "left one candidate track; detail.after_switch_m is the travel since the split",
    EventType.HYPOTHESIS_DROPPED: "a candidate ran past a buffer stop or a non-navigable end, or evidence ruled it "
    "out; with none left the position is forgotten",
    EventType.TRACK_CHANGE_REFUSED: "a line-based aid (GPS decision, balise, feature point) put the position on a "
    "track no navigable path reaches from the candidates within the travel and the margin: refused, the "
    "candidates kept",
    EventType.GPS_CORRECTION: "on a network, a trusted D-GPS fix on the determined track, agreeing with the "
    "estimate and with an along-track uncertainty well below the margin, corrected the distance along the track",
    EventType.UNITS_DISAGREE: "the other cab's positioning unit disagrees (run --unit both) [S003 §2]: both claim a "
    "km and |km_F − km_R| exceeds the sum of their margins, or both are determined on different tracks; one "
    "event per span (t to detail.t_to), detail gives the largest difference, its bound and the tracks",
}

#: Events that correct the km, and the one the position-correction % is defined on [S003 §5.2].
CORRECTION_EVENTS = (EventType.BALISE_CORRECTION, EventType.FEATURE_CORRECTION)
SLIP_EVENTS = (EventType.SLIP, EventType.SLIDE)


class AlarmType(StrEnum):
    """Possession alarms for road-rail vehicles [S001 §3, §6]."""

    WRONG_TRACK = "wrong_track"
    WRONG_TRACK_SUSPECTED = "wrong_track_suspected"
    OVERRUN = "overrun"
    RELEASED_ON_RAIL = "released_on_rail"
    NOT_STARTED = "not_started"


class NoticeType(StrEnum):
    """Possession notices: the worker is told, no alarm [S001 §3, §7]."""

    APPROACHING_END = "approaching_end"
    OVERRUN_POSSIBLE = "overrun_possible"
    TRACK_UNDECIDED = "track_undecided"
    CROSSOVER = "crossover"
    POSITION_UNCERTAIN = "position_uncertain"
    POSITION_UNDETERMINED = "position_undetermined"
    TRACK_UNCONFIRMED = "track_unconfirmed"


ALARM_MEANING: dict[AlarmType | NoticeType, str] = {
    AlarmType.WRONG_TRACK: "on rail on a different track than the selected work's possession",
    AlarmType.WRONG_TRACK_SUSPECTED: "still undecided 120 s after PTO on while the fixes lean to another track",
    AlarmType.OVERRUN: "outside the possession's km range",
    AlarmType.RELEASED_ON_RAIL: "the possession was released while the vehicle is on rail",
    AlarmType.NOT_STARTED: "on rail before the possession was started",
    NoticeType.APPROACHING_END: "30 m before the end of the possession section",
    NoticeType.OVERRUN_POSSIBLE: "the km band is too wide to judge an overrun; judgement held",
    NoticeType.TRACK_UNDECIDED: "no up/down decision 120 s after PTO on",
    NoticeType.CROSSOVER: "a crossover to the other track was detected",
    NoticeType.POSITION_UNCERTAIN: "the km is uncertain (poor GPS); alarms held",
    NoticeType.POSITION_UNDETERMINED: "no km yet on this on-rail period",
    NoticeType.TRACK_UNCONFIRMED: "ambiguous among tracks that include the possessed one: not yet confirmed on it",
}
