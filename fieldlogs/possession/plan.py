"""Possession plans (SPEC §5.5, [S001 §4.2.4]): reading, validation and the three states.

A plan file (``possessions.csv`` or an .xlsx sheet with the same columns, declared once in
:data:`schemas.plans.POSSESSIONS`) has one row per possession: ``work_no``, ``line_code``,
``track``, ``km_from_m``, ``km_to_m`` (metres or ``12k345.6``), ``planned_start``,
``planned_end``, ``started_at``, ``released_at``. It is read like every other source:
all cells as text through :func:`schemas.frames.read_and_check` (types, empty required
cells, track enumeration, duplicate work numbers), then the plan's own rules. Every problem
is a finding naming file, line and column:

* times are ISO 8601 **with a UTC offset** (``2026-01-16T01:00:00+09:00``, ``…Z``); a time
  without an offset is an error (the plan and the vehicle's clock must be comparable);
* ``km_from_m < km_to_m``; ``planned_start < planned_end``;
* ``released_at`` only after a ``started_at``, and not before it;
* the line and track exist in the onboard DB (GIS grid); a km range reaching beyond the
  track's grid is a warning;
* a ``track_id`` (optional column: the possessed track of a network — a station track, a
  crossover) is a track of the onboard DB;
* on a network DB, ``track`` may also name a station track of the line (``3`` of line
  ``0420``: the tracks table's ``line_code``/``track``, km within its ``km_begin_m``…``km_end_m``):
  without a ``track_id`` the possession is on that network track — the one of that name whose
  km range overlaps the row's; several (a station track split at a joint) are the error
  ``plan.track_id_needed``: name the possessed one in ``track_id``.

States [S001 §4.2.4]: at wall-clock time T a possession is *not started* (no
``started_at``, or T before it), *started*, or *released* (``released_at`` ≤ T).
"""

from __future__ import annotations

import math
from collections.abc import Collection
from dataclasses import dataclass, field
from datetime import datetime
from enum import StrEnum
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.csv_locale import CsvLocale
from dbtools.network import Network
from dbtools.tabular import read_checked_table
from dbtools.topology import all_tracks, grid_extents
from schemas.enums import Severity
from schemas.errors import FindingsError, UsageError
from schemas.findings import Finding
from schemas.frames import FIRST_DATA_LINE, read_and_check
from schemas.plans import POSSESSIONS

#: Time columns of a plan; the first two are required.
TIME_COLUMNS = ("planned_start", "planned_end", "started_at", "released_at")
TIME_EXAMPLE = "2026-01-16T01:00:00+09:00"
FloatArray = npt.NDArray[np.float64]


class PossessionState(StrEnum):
    """The three states of a possession [S001 §4.2.4]."""

    NOT_STARTED = "not_started"
    STARTED = "started"
    RELEASED = "released"


@dataclass(frozen=True)
class Possession:
    """One row of a plan, times timezone-aware."""

    work_no: str
    line_code: str
    track: str
    km_from_m: float
    km_to_m: float
    planned_start: datetime
    planned_end: datetime
    started_at: datetime | None = None
    released_at: datetime | None = None
    vehicle_id: str | None = None
    """The vehicle the work is for (None: any)."""
    track_id: str | None = None
    """The network track possessed (a station track, a crossover …); None: the line and track."""
    purpose: str = "work"
    """``work`` or ``protection`` (adjacent-line protection: never legitimises running on it)."""
    row: int | None = None
    """File line of the row (header = line 1), for messages."""

    def state_at(self, when: datetime) -> PossessionState:
        if self.released_at is not None and when >= self.released_at:
            return PossessionState.RELEASED
        if self.started_at is not None and when >= self.started_at:
            return PossessionState.STARTED
        return PossessionState.NOT_STARTED

    @property
    def window(self) -> tuple[datetime, datetime]:
        """Earliest to latest of the planned and actual times."""
        times = [t for t in (self.planned_start, self.planned_end, self.started_at, self.released_at) if t]
        return min(times), max(times)

    def covers(self, km: float) -> bool:
        return self.km_from_m <= km <= self.km_to_m


@dataclass
class Plan:
    possessions: list[Possession]
    findings: list[Finding] = field(default_factory=list)
    path: str = ""

    @property
    def errors(self) -> list[Finding]:
        return [f for f in self.findings if f.severity == Severity.ERROR]


def _text(v: object) -> str | None:
    """A cell as text, None when empty."""
    if v is None or v is pd.NA or (isinstance(v, float) and math.isnan(v)):
        return None
    return str(v)


def parse_time(text: str) -> datetime:
    """ISO 8601 with a UTC offset → aware datetime; ValueError otherwise."""
    s = text.strip()
    t = datetime.fromisoformat(s)
    if t.tzinfo is None or t.utcoffset() is None:
        raise ValueError("no UTC offset")
    return t


class _Rows:
    """The plan's findings, and the file lines of rows with an error (left out of the plan)."""

    def __init__(self, frame: pd.DataFrame, file: str, findings: list[Finding]) -> None:
        self.frame, self.file, self.findings = frame, file, findings
        self.bad = {f.row for f in findings if f.severity == Severity.ERROR and f.row is not None}

    def error(self, rule: str, i: int, column: str, message: str, value: object = None, limit: object = None) -> None:
        """An error of row ``i`` (0-based data row)."""
        work = self.frame["work_no"].iat[i]
        self.findings.append(
            Finding(
                rule,
                Severity.ERROR,
                POSSESSIONS.name,
                message,
                keys={"work_no": _text(work)},
                value=value,
                limit=limit,
                file=self.file,
                row=i + FIRST_DATA_LINE,
                column=column,
            )
        )
        self.bad.add(i + FIRST_DATA_LINE)


def _parse_times(rows: _Rows) -> dict[str, list[datetime | None]]:
    """Every time cell parsed (None when empty or wrong; wrong ones are findings)."""
    frame = rows.frame
    times: dict[str, list[datetime | None]] = {c: [None] * len(frame) for c in TIME_COLUMNS}
    for c in TIME_COLUMNS:
        for i, v in enumerate(frame[c].tolist()):
            if _text(v) is None:
                continue
            try:
                times[c][i] = parse_time(str(v))
            except ValueError as exc:
                if "offset" in str(exc):
                    rule, message = "plan.time_offset", f"'{v}' has no UTC offset: write e.g. {TIME_EXAMPLE}"
                else:
                    rule, message = "plan.time_format", f"'{v}' is not an ISO 8601 time (e.g. {TIME_EXAMPLE})"
                rows.error(rule, i, c, message, value=str(v), limit="ISO 8601 with offset")
    return times


def _order_rules(rows: _Rows, i: int, times: dict[str, list[datetime | None]], km_from: float, km_to: float) -> None:
    """km_from < km_to, planned_start < planned_end, released_at only after started_at."""
    if np.isfinite(km_from) and np.isfinite(km_to) and not km_from < km_to:
        message = f"km_to_m {km_to:g} m must be greater than km_from_m {km_from:g} m"
        rows.error("plan.km_order", i, "km_to_m", message, value=float(km_to), limit=float(km_from))
    ps, pe = times["planned_start"][i], times["planned_end"][i]
    if ps is not None and pe is not None and not ps < pe:
        rows.error("plan.time_order", i, "planned_end", "planned_end must be after planned_start", str(pe), str(ps))
    st, rl = times["started_at"][i], times["released_at"][i]
    if rl is not None and _text(rows.frame["started_at"].iat[i]) is None:
        rows.error("plan.release_without_start", i, "released_at", "released_at given but started_at is empty")
    if st is not None and rl is not None and rl < st:
        rows.error("plan.time_order", i, "released_at", "released_at is before started_at", str(rl), str(st))


def _db_rules(
    rows: _Rows, i: int, tracks: dict[tuple[str, str], tuple[float, float]], km_from: float, km_to: float
) -> None:
    """The line and track exist in the onboard DB; a warning when the section leaves its grid."""
    for rule, column, message, value, limit in _track_errors(rows.frame, i, tracks):
        rows.error(rule, i, column, message, value, limit)
    warning = _outside_grid(rows.frame, i, tracks, km_from, km_to, rows.file)
    if warning is not None:
        rows.findings.append(warning)


def _possessions(
    rows: _Rows,
    times: dict[str, list[datetime | None]],
    km_from: FloatArray,
    km_to: FloatArray,
    station: list[str | None],
) -> list[Possession]:
    """The rows without an error, as possessions (``station``: the network track a row naming
    a station track possesses)."""
    frame = rows.frame
    possessions = []
    for i in range(len(frame)):
        ps, pe = times["planned_start"][i], times["planned_end"][i]
        if i + FIRST_DATA_LINE in rows.bad or ps is None or pe is None:
            continue
        possessions.append(
            Possession(
                work_no=str(frame["work_no"].iat[i]),
                line_code=str(frame["line_code"].iat[i]),
                track=str(frame["track"].iat[i]),
                km_from_m=float(km_from[i]),
                km_to_m=float(km_to[i]),
                planned_start=ps,
                planned_end=pe,
                started_at=times["started_at"][i],
                released_at=times["released_at"][i],
                vehicle_id=_text(frame["vehicle_id"].iat[i]) if "vehicle_id" in frame.columns else None,
                track_id=(_text(frame["track_id"].iat[i]) if "track_id" in frame.columns else None) or station[i],
                purpose=_text(frame["purpose"].iat[i]) or "work" if "purpose" in frame.columns else "work",
                row=i + FIRST_DATA_LINE,
            )
        )
    return possessions


def read_plan(path: Path, network: Network | None = None, locale: CsvLocale | None = None) -> Plan:
    """Read and check a plan file; rows with errors are left out of ``possessions``.
    ``locale``: the CSV convention declared (``--delimiter``/``--decimal``); else a plan
    saved from a spreadsheet in a European locale is detected (:mod:`dbtools.csv_locale`:
    one ``source.locale`` warning).

    Raises :class:`~schemas.errors.InputError` when the file cannot be read at all.
    """
    path = Path(path)
    tf = read_checked_table(path, sheet=POSSESSIONS.name, declared=POSSESSIONS, locale=locale or CsvLocale())
    file = str(path)
    co = read_and_check(POSSESSIONS, tf.frame, file=file)
    findings = [*tf.findings, *co.findings]
    if any(f.rule == "schema.missing_column" for f in findings):
        return Plan([], findings, file)
    rows = _Rows(co.frame, file, findings)
    times = _parse_times(rows)
    named = {} if network is None else _station_tracks(network, grid := _grid_extents(network))
    tracks = None if network is None else {**_extents(named), **grid}
    ids = None if network is None else {str(t) for t in all_tracks(network)["track_id"]}
    km_from = co.frame["km_from_m"].to_numpy(dtype=float, na_value=np.nan)
    km_to = co.frame["km_to_m"].to_numpy(dtype=float, na_value=np.nan)
    for i in range(len(co.frame)):
        _order_rules(rows, i, times, float(km_from[i]), float(km_to[i]))
        if tracks is not None:
            _db_rules(rows, i, tracks, float(km_from[i]), float(km_to[i]))
        if ids is not None and "track_id" in co.frame.columns:
            _track_id_rule(rows, i, ids)
    station = _station_track_ids(rows, named, km_from, km_to)
    return Plan(_possessions(rows, times, km_from, km_to, station), findings, file)


def _track_id_rule(rows: _Rows, i: int, ids: set[str]) -> None:
    """A possession's ``track_id`` is a track of the onboard DB (declared or implied)."""
    tid = _text(rows.frame["track_id"].iat[i])
    if tid is not None and tid not in ids:
        near = sorted(t for t in ids if t.split("-")[0] == tid.split("-")[0])[:12] or sorted(ids)[:12]
        msg = f"track_id '{tid}' is not a track of the onboard DB (e.g. {', '.join(near)})"
        rows.error("plan.unknown_track_id", i, "track_id", msg, tid, near)


NamedTracks = dict[tuple[str, str], list[tuple[str, float, float]]]
"""(line, track) → [(track_id, km lo, km hi)] of network tracks named by a line and track."""


def _grid_extents(network: Network) -> dict[tuple[str, str], tuple[float, float]]:
    """(line, track) → (km min, km max) of the GIS grid's line tracks
    (:func:`dbtools.topology.grid_extents`)."""
    ext = grid_extents(network)
    keys = zip(ext["line_code"].astype(str), ext["track"].astype(str), strict=True)
    return dict(zip(keys, zip(ext["km_lo"].astype(float), ext["km_hi"].astype(float), strict=True), strict=True))


def _station_tracks(network: Network, grid: Collection[tuple[str, str]]) -> NamedTracks:
    """The network tracks named by a line and track that the GIS ``grid`` does not hold
    (station tracks with their own points)."""
    t = all_tracks(network)
    out: NamedTracks = {}
    for tid, line, track, k0, k1 in zip(
        t["track_id"], t["line_code"], t["track"], t["km_begin_m"], t["km_end_m"], strict=True
    ):
        key = (_text(line), _text(track))
        if key[0] is None or key[1] is None or (key[0], key[1]) in grid or pd.isna(k0) or pd.isna(k1):
            continue
        out.setdefault((key[0], key[1]), []).append((str(tid), min(float(k0), float(k1)), max(float(k0), float(k1))))
    return out


def _extents(named: NamedTracks) -> dict[tuple[str, str], tuple[float, float]]:
    """(line, track) → (km min, km max) over the named tracks."""
    return {k: (min(lo for _, lo, _ in v), max(hi for _, _, hi in v)) for k, v in named.items()}


def _station_track_ids(rows: _Rows, named: NamedTracks, km_from: FloatArray, km_to: FloatArray) -> list[str | None]:
    """Per row, the network track a station-track row possesses (None: a line track, or a
    ``track_id`` given); ``plan.track_id_needed`` where several tracks of that name overlap."""
    frame = rows.frame
    out: list[str | None] = [None] * len(frame)
    given = frame["track_id"] if "track_id" in frame.columns else pd.Series([None] * len(frame), index=frame.index)
    for i in range(len(frame)):
        key = (_text(frame["line_code"].iat[i]), _text(frame["track"].iat[i]))
        if _text(given.iat[i]) is not None or key[0] is None or key[1] is None or (key[0], key[1]) not in named:
            continue
        lo, hi = min(km_from[i], km_to[i]), max(km_from[i], km_to[i])
        hit = [tid for tid, a, b in named[(key[0], key[1])] if a < hi and lo < b]
        if len(hit) == 1:
            out[i] = hit[0]
        elif len(hit) > 1:
            msg = (
                f"line '{key[0]}' track '{key[1]}' is {len(hit)} network tracks over this km range "
                f"({', '.join(hit)}): name the possessed one in track_id"
            )
            rows.error("plan.track_id_needed", i, "track", msg, key[1], hit)
    return out


def _track_errors(
    frame: pd.DataFrame, i: int, tracks: dict[tuple[str, str], tuple[float, float]]
) -> list[tuple[str, str, str, object, object]]:
    """(rule, column, message, value, limit) when the row's line or track is not in the DB."""
    line, track = _text(frame["line_code"].iat[i]), _text(frame["track"].iat[i])
    if line is None or track is None:
        return []
    lines = sorted({a for a, _ in tracks})
    if line not in lines:
        return [("plan.unknown_line", "line_code", f"line '{line}' is not in the onboard DB", line, lines)]
    if (line, track) not in tracks:
        have = sorted(b for a, b in tracks if a == line)
        msg = f"line '{line}' has no track '{track}' in the onboard DB (tracks: {', '.join(have)})"
        return [("plan.unknown_track", "track", msg, track, have)]
    return []


def _outside_grid(
    frame: pd.DataFrame,
    i: int,
    tracks: dict[tuple[str, str], tuple[float, float]],
    km_from: float,
    km_to: float,
    file: str,
) -> Finding | None:
    """A warning when the section reaches beyond the track's GIS grid."""
    key = (str(frame["line_code"].iat[i]), str(frame["track"].iat[i]))
    if key not in tracks or not (np.isfinite(km_from) and np.isfinite(km_to)):
        return None
    lo, hi = tracks[key]
    if lo <= km_from and km_to <= hi:
        return None
    work = frame["work_no"].iat[i]
    return Finding(
        "plan.km_outside_gis",
        Severity.WARNING,
        POSSESSIONS.name,
        f"section {km_from:g}–{km_to:g} m reaches beyond the GIS grid of {key[0]}/{key[1]} ({lo:g}–{hi:g} m)",
        keys={"work_no": _text(work)},
        value=[km_from, km_to],
        limit=[lo, hi],
        file=file,
        row=i + FIRST_DATA_LINE,
        column="km_from_m" if km_from < lo else "km_to_m",
    )


def load_plan(path: Path, network: Network | None = None, locale: CsvLocale | None = None) -> Plan:
    """:func:`read_plan`, raising :class:`~schemas.errors.FindingsError` (exit 1) on any error."""
    plan = read_plan(path, network, locale)
    if plan.errors:
        raise FindingsError(
            f"the possession plan has {len(plan.errors)} error(s); fix them and check again", plan.errors, path=path
        )
    return plan


def plan_frame(possessions: list[Possession]) -> pd.DataFrame:
    """Possessions as a plan table (text times), e.g. to write a CSV; the optional
    ``track_id`` column only when some possession names its track."""
    rows = []
    for p in possessions:
        rows.append(
            {
                "work_no": p.work_no,
                "line_code": p.line_code,
                "track": p.track,
                "km_from_m": p.km_from_m,
                "km_to_m": p.km_to_m,
                **{c: (getattr(p, c).isoformat() if getattr(p, c) else "") for c in TIME_COLUMNS},
                "track_id": p.track_id,
            }
        )
    with_ids = any(p.track_id is not None for p in possessions)
    return pd.DataFrame(rows, columns=[c for c in POSSESSIONS.column_names if with_ids or c != "track_id"])


def possessions_for(
    possessions: list[Possession], *, vehicle_id: str | None = None, work: str | None = None
) -> list[Possession]:
    """The possessions that may allow this vehicle to be on rail [S001 §6.1(a), §3.1(e)].

    The worker selects the vehicle's own planned work on the device before putting it on
    rail, and an adjacent-line protection possession protects the neighbouring track — it
    never makes running on that track right. So: never a ``protection`` possession; with
    ``work`` (the selected work) only that work's rows; otherwise the rows for this vehicle
    or for any vehicle. UsageError when ``work`` is not a work of the plan."""
    own = [p for p in possessions if p.purpose != "protection"]
    if work is not None:
        chosen = [p for p in own if p.work_no == work]
        if not chosen:
            known = ", ".join(sorted({p.work_no for p in own})) or "none"
            raise UsageError(f"work '{work}' is not a work possession of the plan (works: {known})")
        return chosen
    return [p for p in own if p.vehicle_id is None or vehicle_id is None or p.vehicle_id == vehicle_id]
