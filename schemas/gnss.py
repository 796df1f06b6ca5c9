"""Raw GNSS streams (SPEC §4, §5.6): observations (``gnss_obs``) and broadcast ephemerides
(``gnss_nav``), plus the navigation header's ``gnss`` block of ``run.json`` — the inputs of
track-constrained positioning [S002]: pseudoranges per receiver and epoch, the navigation
messages and GNSS time — and the SBAS/MSAS L1 messages (``gnss_sbas``) a receiver logged.

Time convention (every producer and consumer): ``gnss_time_s`` and ``toc_gps_s`` are
continuous GPS time in seconds since 1980-01-06T00:00:00 — no leap seconds; Galileo
(GST) and QZSS time are counted on the same scale (their offsets to GPS time are a few
nanoseconds and are given, where broadcast, in ``gnss.time_corrections``); BeiDou time is
converted (BDT = GPS − 14 s), GLONASS epochs (UTC(SU) + 3 h) are converted with the leap
seconds.

``gnss_nav`` fields are named exactly as georinex names the RINEX 3 navigation variables
and keep RINEX units (s, s/s, s/s², m, rad, rad/s, m^½); ``Toe`` and ``TransTime`` are
seconds of the GNSS week ``week`` (GPS week numbering for every system, as RINEX 3 writes
Galileo weeks). GLONASS rows use their state-vector fields (m, m/s, m/s²; georinex's km
converted to m) and leave the Keplerian ones empty.
"""

from __future__ import annotations

import re

from schemas.model import Column, Table

T = Column("t", "float", "Seconds since the start of the run", unit="s", min=0.0)

#: Seconds per GPS week.
WEEK_S = 604_800.0
#: Satellite ids: system letter (RINEX 3) and two-digit number.
SAT_RE = re.compile(r"^[GRECJSI]\d\d$")
#: RINEX 3 system letters: GPS, GLONASS, Galileo, BeiDou, QZSS, SBAS, NavIC.
SYSTEMS = ("G", "R", "E", "C", "J", "S", "I")
#: Signal names: the RINEX 3 pseudorange observation code (C, band digit, attribute).
SIGNAL_RE = re.compile(r"^C[1-9][A-Z]$")

GNSS_OBS = Table(
    name="gnss_obs",
    kind="log",
    description=(
        "Raw GNSS observations, long format: one row per receiver × epoch × satellite × signal "
        "(signal = the RINEX 3 pseudorange code, e.g. C1C)."
    ),
    columns=(
        T,
        Column(
            "gnss_time_s",
            "float",
            "Receiver epoch, continuous GPS seconds since 1980-01-06 (no leap seconds)",
            unit="s",
            min=0.0,
        ),
        Column("receiver", "str", "Receiver id (vehicle.antennas[].receiver)"),
        Column("sat", "str", "Satellite: system letter + number, e.g. G07, E11, J02, R05"),
        Column("signal", "str", "RINEX 3 pseudorange observation code of the signal, e.g. C1C, C5Q"),
        Column("pseudorange_m", "float", "Pseudorange", unit="m", nullable=True, min=0.0, max=1.0e8),
        Column("carrier_cycles", "float", "Carrier phase", unit="cycles", nullable=True),
        Column("doppler_hz", "float", "Doppler", unit="Hz", nullable=True, min=-1.0e5, max=1.0e5),
        Column("cn0_dbhz", "float", "Carrier-to-noise density", unit="dB-Hz", nullable=True, min=0.0, max=99.0),
        Column(
            "lli",
            "int",
            "RINEX loss-of-lock indicator (bit 0 lock lost, bit 1 half cycle)",
            nullable=True,
            min=0,
            max=7,
        ),
    ),
    primary_key=("receiver", "gnss_time_s", "sat", "signal"),
    required=False,
)


def _nav(name: str, what: str, unit: str = "") -> Column:
    return Column(name, "float", what, unit=unit, required=False, nullable=True)


#: Keplerian / clock fields of GPS, Galileo and QZSS ephemerides (georinex names).
KEPLER_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("SVclockBias", "Clock bias af0", "s"),
    ("SVclockDrift", "Clock drift af1", "s/s"),
    ("SVclockDriftRate", "Clock drift rate af2", "s/s²"),
    ("IODE", "Issue of data, ephemeris (Galileo: IODnav)", ""),
    ("Crs", "Sine harmonic correction to the orbit radius", "m"),
    ("DeltaN", "Mean motion difference", "rad/s"),
    ("M0", "Mean anomaly at Toe", "rad"),
    ("Cuc", "Cosine harmonic correction to the argument of latitude", "rad"),
    ("Eccentricity", "Eccentricity", ""),
    ("Cus", "Sine harmonic correction to the argument of latitude", "rad"),
    ("sqrtA", "Square root of the semi-major axis", "m^½"),
    ("Toe", "Time of ephemeris, seconds of week", "s"),
    ("Cic", "Cosine harmonic correction to the inclination", "rad"),
    ("Omega0", "Longitude of the ascending node at the week start", "rad"),
    ("Cis", "Sine harmonic correction to the inclination", "rad"),
    ("Io", "Inclination at Toe", "rad"),
    ("Crc", "Cosine harmonic correction to the orbit radius", "m"),
    ("omega", "Argument of perigee", "rad"),
    ("OmegaDot", "Rate of right ascension", "rad/s"),
    ("IDOT", "Rate of inclination", "rad/s"),
    ("TGD", "Group delay L1/L2 (GPS, QZSS)", "s"),
    ("health", "SV health (0 healthy)", ""),
    ("SVacc", "SV accuracy (GPS URA, Galileo SISA)", "m"),
    ("TransTime", "Transmission time of the message, seconds of week", "s"),
    ("FitIntvl", "Fit interval (GPS, QZSS)", "h"),
    ("IODC", "Issue of data, clock (GPS, QZSS)", ""),
    ("BGDe5a", "Galileo broadcast group delay E1/E5a", "s"),
    ("BGDe5b", "Galileo broadcast group delay E1/E5b", "s"),
    ("DataSrc", "Galileo data source bits (I/NAV, F/NAV)", ""),
    ("week", "GNSS week of Toe, GPS week numbering", "week"),
)
#: GLONASS state-vector fields (georinex names; positions in m).
GLONASS_FIELDS: tuple[tuple[str, str, str], ...] = (
    ("SVrelFreqBias", "GLONASS relative frequency bias", ""),
    ("MessageFrameTime", "GLONASS message frame time, seconds of the UTC week", "s"),
    ("X", "GLONASS position X (PZ-90)", "m"),
    ("dX", "GLONASS velocity X", "m/s"),
    ("dX2", "GLONASS acceleration X", "m/s²"),
    ("Y", "GLONASS position Y", "m"),
    ("dY", "GLONASS velocity Y", "m/s"),
    ("dY2", "GLONASS acceleration Y", "m/s²"),
    ("Z", "GLONASS position Z", "m"),
    ("dZ", "GLONASS velocity Z", "m/s"),
    ("dZ2", "GLONASS acceleration Z", "m/s²"),
    ("FreqNum", "GLONASS frequency channel number", ""),
    ("AgeOpInfo", "GLONASS age of operational information", "day"),
)
NAV_FIELDS: tuple[str, ...] = tuple(n for n, _, _ in KEPLER_FIELDS + GLONASS_FIELDS)

GNSS_NAV = Table(
    name="gnss_nav",
    kind="log",
    description="Broadcast ephemerides: one row per satellite and time of clock (RINEX 3 field names, georinex).",
    columns=(
        Column("sat", "str", "Satellite, e.g. G07, E11, J02, R05"),
        Column("toc_gps_s", "float", "Time of clock, continuous GPS seconds since 1980-01-06", unit="s", min=0.0),
        *(_nav(n, what, unit) for n, what, unit in KEPLER_FIELDS + GLONASS_FIELDS),
    ),
    required=False,
)

#: SBAS PRNs (RTCA DO-229 Table A-1 / ICAO Annex 10; MSAS broadcasts on 129 and 137).
SBAS_PRN_RANGE = (120, 158)
#: Hex digits of one logged SBAS L1 message: the 250 bits left-aligned in 32 bytes (u-blox
#: RXM-SFRBX's eight 32-bit words) or 63 digits (252 bits); the bits past 250 are ignored.
SBAS_HEX_DIGITS = (63, 64)

GNSS_SBAS = Table(
    name="gnss_sbas",
    kind="log",
    description=(
        "SBAS/MSAS L1 messages (RTCA DO-229): one row per 250-bit message received from a GEO "
        "(8-bit preamble, 6-bit type, 212 data bits, 24-bit CRC-24Q), hex, MSB first."
    ),
    columns=(
        T,
        Column(
            "gnss_time_s",
            "float",
            "Reception of the message's last bit, continuous GPS seconds since 1980-01-06",
            unit="s",
            min=0.0,
        ),
        Column("prn", "int", "SBAS PRN of the GEO (120–158; MSAS 129, 137)", min=120, max=158),
        Column(
            "msg_type",
            "int",
            "Message type (0–63) as the receiver reported it",
            required=False,
            nullable=True,
            min=0,
            max=63,
        ),
        Column("message_hex", "str", "The 250 bits as 63 or 64 hex digits, MSB first (trailing pad bits ignored)"),
        Column(
            "valid",
            "int",
            "1 when the receiver found the CRC good (0: logged but failed); the decoder re-checks the CRC",
            required=False,
            nullable=True,
            min=0,
            max=1,
        ),
    ),
    primary_key=("prn", "gnss_time_s"),
    required=False,
)

#: Keys of run.json's ``gnss`` block (navigation-header parameters).
GNSS_BLOCK: tuple[tuple[str, str], ...] = (
    ("klobuchar_alpha", "GPS Klobuchar α0–α3 [s, s/semicircle, s/semicircle², s/semicircle³]"),
    ("klobuchar_beta", "GPS Klobuchar β0–β3 [s, s/semicircle, s/semicircle², s/semicircle³]"),
    ("qzss_klobuchar_alpha", "QZSS Klobuchar α0–α3"),
    ("qzss_klobuchar_beta", "QZSS Klobuchar β0–β3"),
    ("nequick_ai", "Galileo NeQuick ai0–ai2 [sfu, sfu/deg, sfu/deg²]"),
    ("leap_seconds", "GPS − UTC [s] from the navigation header"),
    (
        "time_corrections",
        "[{type (e.g. GPUT, GAUT, GAGP, QZGP), a0_s, a1_s_per_s, t_ref_s (seconds of week), week}]",
    ),
)
GNSS_BLOCK_LENGTHS = {
    "klobuchar_alpha": 4,
    "klobuchar_beta": 4,
    "qzss_klobuchar_alpha": 4,
    "qzss_klobuchar_beta": 4,
    "nequick_ai": 3,
}
