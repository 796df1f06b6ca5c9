"""The audit database (``trainpos audit``): runs, their events and traces, per-route and
per-track views.

One file per audit, written by the coordinating process of a fleet audit only (one
SQLite writer), one transaction per finished run. Tables are created from these
declarations (:mod:`dbtools.database`); the ``route_summary`` and ``track_summary`` views
are declared here with their columns and defined in SQL in :mod:`dbtools.audit_db`.

A track is named by one key, ``track_id`` (the network's netElement; ``LINE:TRACK`` on a
line-only DB), everywhere: routes and per-track figures are grouped by it, and ``line_code``
and ``track`` ride along as display names (null for a track off any line: a crossover, a
connecting curve).
"""

from __future__ import annotations

from schemas.model import Column, DType, ForeignKey, Table
from schemas.outputs import EVENTS

#: ``PRAGMA application_id`` of an audit DB: ASCII "TPAU".
AUDIT_APPLICATION_ID = 0x54504155
#: ``PRAGMA user_version`` of an audit DB. 2: tables declared in ``schemas/`` and renamed
#: ``audit_*``; the run context hashes the DB's actual content (1 used its meta hash).
#: 3: ``audit_track_path`` (a run's route as a path of tracks). 4: runs and routes keyed by
#: ``track_id`` (``audit_runs.track_id``, ``route_summary`` per track_id and direction, the
#: ``track_summary`` view), the positioning unit audited and the units' comparison.
AUDIT_SCHEMA_VERSION = 4
#: What the current schema changed, for the message refusing an older audit DB.
AUDIT_SCHEMA_CHANGE = "runs, routes and tracks keyed by track_id; the unit audited"

#: ``trainpos audit --unit``: the positioning unit replayed [S003 §2: one per cab] — F (the
#: pipeline as it always runs), R (the R cab's) or both (F's figures stored, compared with R's).
UNIT_CHOICES = ("F", "R", "both")

RUN_PATH = Column("run_path", "str", "Run folder (absolute path): the run's identity in the audit")


def _n(name: str, description: str, dtype: DType = "int", unit: str = "") -> Column:
    """A nullable figure of an audited run (missing on a run that failed)."""
    return Column(name, dtype, description, unit=unit, nullable=True)


def _track_names() -> tuple[Column, Column]:
    """The display names beside a ``track_id``."""
    return (
        _n("line_code", "Line of that track (display; null off a line)", "str"),
        _n("track", "Local name of that track (display; null off a line)", "str"),
    )


def _correction_pcts() -> tuple[Column, Column]:
    """Mean and largest position-correction % over balise corrections."""
    return (
        _n("mean_correction_pct", "Mean balise position-correction %", "float", "%"),
        _n("max_correction_pct", "Largest balise position-correction %", "float", "%"),
    )


AUDIT_RUNS = Table(
    name="audit_runs",
    kind="audit",
    description=(
        "One row per audited run folder: status, route, headline figures. Correction counts "
        "and % are balise corrections only (SPEC §5.2)."
    ),
    columns=(
        RUN_PATH,
        _n("run_id", "Run id (run.json)", "str"),
        _n("vehicle_id", "Vehicle id (run.json)", "str"),
        _n("vehicle_kind", "train or road_rail", "str"),
        Column("fingerprint", "str", "SHA-256 of the run's files and the context ('' when unreadable)"),
        _n("quick_key", "SHA-256 of the run's file names, sizes and mtimes (skip without reading)", "str"),
        _n("context", "SHA-256 of the onboard DB's content hash and the pipeline config", "str"),
        Column("status", "str", "ok, or error (message in error)", enum=("ok", "error")),
        _n("error", "Why the run failed", "str"),
        _n("db_version", "Onboard DB version the run was audited with", "str"),
        _n("track_id", "Track of the run: the one claimed on most cycles (the route's key)", "str"),
        *_track_names(),
        _n("direction", "down when the km increased over the run, up otherwise", "str"),
        _n("duration_s", "Run duration", "float", "s"),
        _n("distance_m", "Travelled distance (corrected odometry)", "float", "m"),
        _n("n_corrections", "Balise position corrections"),
        _n("n_feature_corrections", "Accepted feature-point corrections"),
        _n("n_feature_refused", "Refused feature-point corrections"),
        *_correction_pcts(),
        _n("n_slips", "Slip and slide episodes"),
        _n("n_failsafe", "Fail-safe events"),
        _n("n_anomalies", "Balise anomalies"),
        _n("gps_decisions", "Up/down decisions from trusted GPS fixes"),
        _n("gps_trusted_share", "Share of trusted GPS fixes", "float"),
        _n("max_margin_m", "Largest safety margin", "float", "m"),
        _n("first_determined_t", "Time the position was first determined", "float", "s"),
        _n("summary_json", "The pipeline's run summary (JSON)", "str"),
        Column("audited_at", "str", "When the run was audited (UTC, ISO 8601 with Z)"),
        _n("elapsed_s", "Wall time of the run in its worker", "float", "s"),
        _n("cpu_s", "CPU time of the run in its worker", "float", "s"),
        Column(
            "unit",
            "str",
            "Positioning unit whose figures the row holds: F, R (the R cab's), both (unit F's, compared with R's)",
            nullable=True,
            enum=UNIT_CHOICES,
        ),
        _n("unit_cycles_compared", "Unit both: cycles where both units claimed a km"),
        _n("unit_max_difference_m", "Unit both: largest |km F − km R|", "float", "m"),
        _n("unit_cycles_beyond_margins", "Unit both: cycles with |km F − km R| > margin F + margin R"),
        _n("unit_cycles_on_other_tracks", "Unit both: cycles where both are determined on different tracks"),
        _n("unit_disagreements", "Unit both: spans of consecutive disagreeing cycles"),
        _n("unit_disagreement_spans", "Unit both: JSON list of [t_from, t_to] of every disagreement span", "str"),
    ),
    primary_key=("run_path",),
)

AUDIT_EVENTS = Table(
    name="audit_events",
    kind="audit",
    description="The pipeline's events of every audited run (columns of the run's events output).",
    columns=(RUN_PATH, *(Column(c.name, c.dtype, c.description, unit=c.unit, nullable=True) for c in EVENTS.columns)),
    foreign_keys=(ForeignKey(("run_path",), AUDIT_RUNS.name, ("run_path",)),),
    indexes=(("run_path",), ("type",)),
)

AUDIT_TRACES = Table(
    name="audit_traces",
    kind="audit",
    description=(
        "One row per run: its 1 Hz trace (full rate around slip/slide episodes) for the "
        "report's plots, one Parquet blob."
    ),
    columns=(
        RUN_PATH,
        Column("n_rows", "int", "Rows of the trace"),
        Column("format", "str", "Encoding of data", enum=("parquet",)),
        Column("data", "bytes", "The trace (columns t, km_m, margin_m, speed_mps, v_pulse_mps, kappa, lat, lon, …)"),
    ),
    primary_key=("run_path",),
    foreign_keys=(ForeignKey(("run_path",), AUDIT_RUNS.name, ("run_path",)),),
)

AUDIT_TRACK_PATH = Table(
    name="audit_track_path",
    kind="audit",
    description=(
        "A run's route as a path of tracks: one row per maximal stretch of cycles claimed on one "
        "track (state determined) or ambiguous among candidate tracks, in order (seq)."
    ),
    columns=(
        RUN_PATH,
        Column("seq", "int", "Order of the entry in the run's path (0, 1, …)", min=0),
        Column("state", "str", "determined (one track) or ambiguous (candidates)", enum=("determined", "ambiguous")),
        _n("track_id", "Track (netElement) claimed; the implied LINE:TRACK on a line-only DB", "str"),
        _n("line_code", "Line of that track (display; null off a line)", "str"),
        _n("track", "Local name of that track (U/D/S, a station track's 1, 2 …; display)", "str"),
        _n("candidates", "State ambiguous: JSON list of every candidate track id of the stretch", "str"),
        Column("t_from", "float", "First cycle of the stretch", unit="s"),
        Column("t_to", "float", "Last cycle of the stretch", unit="s"),
        Column("distance_m", "float", "Distance travelled over the stretch (Σ |v|·Δt)", unit="m"),
        _n("pos_from_m", "Distance along the track from its begin at the first cycle", "float", "m"),
        _n("pos_to_m", "Distance along the track from its begin at the last cycle", "float", "m"),
        Column("n_cycles", "int", "Cycles of the stretch", min=1),
    ),
    primary_key=("run_path", "seq"),
    foreign_keys=(ForeignKey(("run_path",), AUDIT_RUNS.name, ("run_path",)),),
)

AUDIT_META = Table(
    name="audit_meta",
    kind="audit",
    description="Audit metadata: onboard DB path, version and content hash, config (JSON), last audit.",
    columns=(Column("key", "str", "Key"), Column("value", "str", "Value", nullable=True)),
    primary_key=("key",),
)

ROUTE_SUMMARY = Table(
    name="route_summary",
    kind="audit",
    description="View: per route (the run's track_id, direction) over the runs with status ok.",
    columns=(
        _n("track_id", "Track of the runs (audit_runs.track_id)", "str"),
        *_track_names(),
        _n("direction", "down or up", "str"),
        Column("n_runs", "int", "Runs audited without error"),
        _n("distance_m", "Travelled distance", "float", "m"),
        _n("n_corrections", "Balise corrections"),
        *_correction_pcts(),
        _n("n_feature_corrections", "Accepted feature-point corrections"),
        _n("n_feature_refused", "Refused feature-point corrections"),
        _n("n_slips", "Slip and slide episodes"),
        _n("n_failsafe", "Fail-safe events"),
        _n("n_anomalies", "Balise anomalies"),
    ),
    extra={"view": "yes"},
)

TRACK_SUMMARY = Table(
    name="track_summary",
    kind="audit",
    description=(
        "View: per track_id over the determined stretches of the runs' paths (audit_track_path, "
        "runs with status ok); events counted on a track when their time falls within such a stretch."
    ),
    columns=(
        _n("track_id", "Track", "str"),
        *_track_names(),
        Column("n_runs", "int", "Runs determined on the track at some time"),
        _n("distance_m", "Distance travelled while determined on the track", "float", "m"),
        Column("n_cycles", "int", "Cycles determined on the track"),
        _n("n_corrections", "Balise corrections within its stretches"),
        *_correction_pcts(),
        _n("n_slips", "Slip and slide episodes starting within its stretches"),
        _n("n_failsafe", "Fail-safe events within its stretches"),
        _n("n_anomalies", "Balise anomalies within its stretches"),
    ),
    extra={"view": "yes"},
)

#: Tables of an audit DB in dependency order (runs first: the others reference it).
AUDIT_TABLES: tuple[Table, ...] = (AUDIT_RUNS, AUDIT_EVENTS, AUDIT_TRACES, AUDIT_META, AUDIT_TRACK_PATH)
#: Views of an audit DB.
AUDIT_VIEWS: tuple[Table, ...] = (ROUTE_SUMMARY, TRACK_SUMMARY)
