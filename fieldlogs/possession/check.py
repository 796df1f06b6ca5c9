"""Possession alarms for road-rail vehicles: checking runs against a plan [S001 §3, §4.2.4,
§6; SPEC §5.5].

A road-rail vehicle's run (``gps``, ``cab.pto``; often no tacho or IMU — a ``tacho`` is used
when present) is checked against a possession plan (:mod:`fieldlogs.possession.plan`). The
package is a small positioning application of its own:

* :mod:`~fieldlogs.possession.config` — the settings (``[possession]`` beside ``[gps]``);
* :mod:`~fieldlogs.possession.periods` — on-rail periods (PTO on) and the GPS analysis of
  each (the pipeline's trust filter and up/down test [S001 §4.2]);
* :mod:`~fieldlogs.possession.tacho` — standstills and speeds from a tacho, if usable;
* :mod:`~fieldlogs.possession.kmfilter` — km and its uncertainty band (a constant-velocity
  Kalman filter with gates, restarts and a trusted-fix anchor);
* :mod:`~fieldlogs.possession.alarms` — the alarm and notice rules over one period;
* :mod:`~fieldlogs.possession.results` — alarms, timelines and the JSON shape;
* this module — the run-level entry points (:func:`check_files` over many runs through the
  one replayer of ``audit`` and ``survey``, :func:`check_run`, :func:`check_streams`,
  :func:`check_periods`); :mod:`~fieldlogs.possession.page` draws the HTML report.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from dbtools.network import Network
from fieldlogs.pipeline.config import GpsConfig
from fieldlogs.possession.alarms import evaluate_period
from fieldlogs.possession.config import PossessionConfig
from fieldlogs.possession.periods import RailPeriod, analyse_periods
from fieldlogs.possession.plan import Plan, Possession, possessions_for
from fieldlogs.possession.results import Alarm, PeriodResult, RunCheck, checks_json
from fieldlogs.possession.tacho import Tacho, tacho_problem, tacho_track, tacho_unused
from fieldlogs.replay.discovery import discover_runs
from fieldlogs.runs.handle import Run
from schemas.errors import InputError

if TYPE_CHECKING:
    from dbtools.csv_locale import CsvLocale
    from fieldlogs.replay.network import DbRef

Progress = Callable[[int, int, str], None]
#: Modules the replay's fork server imports once.
PRELOAD = ("fieldlogs.possession.check",)


def check_periods(
    periods: list[RailPeriod],
    possessions: list[Possession],
    start: datetime,
    gps_cfg: GpsConfig | None = None,
    cfg: PossessionConfig | None = None,
    *,
    run: str = "",
    run_id: str = "",
    tacho_note: dict[str, Any] | None = None,
) -> RunCheck:
    """Alarms and notices of a run given its on-rail periods (pure: no I/O); ``tacho_note``
    is :attr:`RunCheck.tacho` (default: used when a period carries one)."""
    gps_cfg = gps_cfg or GpsConfig()
    cfg = cfg or PossessionConfig()
    results: list[PeriodResult] = []
    alarms: list[Alarm] = []
    notices: list[Alarm] = []
    for p in periods:
        r, a, n = evaluate_period(p, possessions, start, gps_cfg, cfg)
        results.append(r)
        alarms += a
        notices += n
    alarms.sort(key=lambda a: (a.t, a.type))
    notices.sort(key=lambda a: (a.t, a.type))
    works = sorted({s[2] for r in results for s in r.timeline.sections} | {r.work_no for r in results if r.work_no})
    if tacho_note is None:
        used = any(p.tacho is not None for p in periods)
        tacho_note = {"used": used, "note": None if used else "no tacho stream"}
    return RunCheck(run, run_id, start, works, results, alarms, notices, tacho_note)


def parse_start_time(run: Run) -> datetime:
    """run.json ``start_time`` as an aware datetime (InputError otherwise: the run cannot be
    related to the plan)."""
    raw = run.field("start_time")
    path = run.folder / "run.json"
    if not raw:
        raise InputError("start_time is missing: the run cannot be related to the plan", path=path)
    try:
        start = datetime.fromisoformat(str(raw).strip())
    except ValueError as exc:
        raise InputError(f"start_time {raw!r} is not an ISO 8601 time", path=path) from exc
    if start.tzinfo is None:
        raise InputError(f"start_time {raw!r} has no UTC offset: the run cannot be related to the plan", path=path)
    return start


def _stream(run: Run, name: str) -> pd.DataFrame | None:
    frame = run.stream(name)
    if frame is None and run.has(name):
        bad = [f for f in run.stream_findings(name) if f.rule == "log.unreadable_stream"]
        raise InputError(bad[0].message if bad else "stream cannot be read", path=run.stream_file(name))
    return frame


def check_run(
    run: Run,
    network: Network,
    possessions: list[Possession],
    gps_cfg: GpsConfig | None = None,
    cfg: PossessionConfig | None = None,
    *,
    work: str | None = None,
) -> RunCheck:
    """Read a run's GPS, cab and (if any) tacho streams, analyse each on-rail period, apply the
    rules (``work``: the work selected on the device; else the plan rows for this vehicle).

    Raises InputError when run.json, its start_time or a needed stream (gps, cab) cannot be
    read; an unreadable tacho is only a note (the km filter then uses the GPS alone).
    """
    gps_cfg = gps_cfg or GpsConfig()
    cfg = cfg or PossessionConfig()
    if run.meta is None:
        bad = [f for f in run.findings if f.severity == "error"]
        raise InputError(bad[0].message if bad else "run.json is invalid", path=run.folder / "run.json")
    start = parse_start_time(run)
    gps = _stream(run, "gps")
    cab = _stream(run, "cab")
    tacho = run.stream("tacho")
    unreadable = None
    if tacho is None and run.has("tacho"):
        bad = [f for f in run.stream_findings("tacho") if f.rule == "log.unreadable_stream"]
        unreadable = bad[0].message if bad else "the stream cannot be read"
    res = check_streams(
        gps,
        cab,
        start,
        network,
        possessions,
        gps_cfg,
        cfg,
        run=str(run.folder),
        run_id=run.run_id,
        tacho=tacho,
        wheel_diameter_m=run.field("wheel_diameter_m"),
        teeth=run.field("teeth"),
        vehicle_id=run.meta.vehicle_id,
        work=work,
    )
    if unreadable is not None:
        res.tacho = tacho_unused(unreadable)
    own = possessions_for(possessions, vehicle_id=run.meta.vehicle_id, work=work)
    if any(p.track_id is not None for p in own):
        _add_track_alarms(res, run, network, own, start)
    return res


def _add_track_alarms(res: RunCheck, run: Run, network: Network, own: list[Possession], start: datetime) -> None:
    """The rule among n tracks (:mod:`fieldlogs.possession.tracks`) over the run's positions
    from the pipeline (default settings), added to the km rules' alarms and notices."""
    from dbtools.topology import topology
    from fieldlogs.pipeline.run import run_pipeline
    from fieldlogs.possession.tracks import track_alarms

    positions = run_pipeline(run, network, summary=False).positions
    alarms, notices = track_alarms(positions, own, start, topology(network))
    res.alarms = sorted([*res.alarms, *alarms], key=lambda a: (a.t, a.type))
    res.notices = sorted([*res.notices, *notices], key=lambda a: (a.t, a.type))


def _usable_tacho(
    tacho: pd.DataFrame | None, wheel_diameter_m: float | None, teeth: int | None, cfg: PossessionConfig
) -> tuple[Tacho | None, dict[str, Any]]:
    """The tacho the km filter may use and :attr:`RunCheck.tacho` saying so, or why not."""
    if tacho is None:
        return None, {"used": False, "note": "no tacho stream"}
    problem = tacho_problem(tacho, wheel_diameter_m, teeth, cfg)
    if problem is not None:
        return None, tacho_unused(problem)
    assert wheel_diameter_m is not None and teeth is not None
    return tacho_track(tacho, float(wheel_diameter_m), int(teeth), cfg), {"used": True, "note": None}


def check_streams(
    gps: pd.DataFrame | None,
    cab: pd.DataFrame | None,
    start: datetime,
    network: Network,
    possessions: list[Possession],
    gps_cfg: GpsConfig | None = None,
    cfg: PossessionConfig | None = None,
    *,
    run: str = "",
    run_id: str = "",
    tacho: pd.DataFrame | None = None,
    wheel_diameter_m: float | None = None,
    teeth: int | None = None,
    vehicle_id: str | None = None,
    work: str | None = None,
) -> RunCheck:
    """:func:`check_run` on stream frames (``gps``, ``cab``, ``tacho`` as in ``schemas.logs``;
    ``wheel_diameter_m`` and ``teeth`` from run.json). Without a tacho, or with one
    :func:`~fieldlogs.possession.tacho.tacho_problem` rejects, the km comes from the GPS alone
    (said in ``RunCheck.tacho``). Only the possessions that may allow this vehicle on rail
    count (:func:`~fieldlogs.possession.plan.possessions_for`: never a protection possession;
    the selected ``work`` or the ``vehicle_id``'s own)."""
    gps_cfg = gps_cfg or GpsConfig()
    cfg = cfg or PossessionConfig()
    own = possessions_for(possessions, vehicle_id=vehicle_id, work=work)
    track, note = _usable_tacho(tacho, wheel_diameter_m, teeth, cfg)
    periods = analyse_periods(gps, cab, network, gps_cfg, cfg, track)
    return check_periods(periods, own, start, gps_cfg, cfg, run=run, run_id=run_id, tacho_note=note)


@dataclass
class PossessionReport:
    """What ``trainpos possession check`` shows: every run's check, the runs that could not
    be checked (folder, one-line error) and the plan's warnings."""

    checks: list[RunCheck]
    plan: Plan
    db: str
    failed: list[tuple[str, str]] = field(default_factory=list)

    @property
    def n_alarms(self) -> int:
        return sum(len(c.alarms) for c in self.checks)

    def to_json(self) -> dict[str, Any]:
        """``{"runs": [...], "failed_runs": [{"run", "error"}]}``."""
        return {**checks_json(self.checks), "failed_runs": [{"run": r, "error": e} for r, e in self.failed]}


def check_one(
    folder: str, db: DbRef, possessions: list[Possession], gps_cfg: GpsConfig, cfg: PossessionConfig, work: str | None
) -> RunCheck:
    """Replayer worker: :func:`check_run` of one run folder against the DB of ``db`` (loaded
    once per worker process)."""
    from fieldlogs.replay.network import load_network
    from fieldlogs.runs.handle import read_run

    return check_run(read_run(Path(folder)), load_network(db), possessions, gps_cfg, cfg, work=work)


def run_folders(roots: Sequence[Path]) -> list[Path]:
    """The run folders to check, in the order given: a root holding ``run.json`` is a run
    (kept as written), any other root is searched for runs (:func:`discover_runs`); each run
    once. InputError when there is none, or for a root that is not a folder."""
    out: list[Path] = []
    seen: set[Path] = set()
    for root in roots:
        found = [Path(root)] if (Path(root) / "run.json").is_file() else discover_runs([Path(root)])
        for p in found:
            if p.resolve() not in seen:
                seen.add(p.resolve())
                out.append(p)
    if not out:
        raise InputError("no run folders (run.json) found", path=", ".join(str(r) for r in roots))
    return out


def check_files(
    run_dirs: Sequence[Path],
    db_path: Path,
    plan_path: Path,
    config_path: Path | None = None,
    work: str | None = None,
    *,
    workers: int | None = None,
    progress: Progress | None = None,
    locale: CsvLocale | None = None,
) -> PossessionReport:
    """Read the DB and the plan (FindingsError on plan errors; ``locale``: its declared CSV
    convention, :mod:`dbtools.csv_locale`), then check every run through
    the replayer (:func:`fieldlogs.replay.pool.replay`: this process or ``workers`` local
    processes; ``progress(done, total, run)`` after each run). A run that cannot be read or
    checked is listed in :attr:`PossessionReport.failed` with its error and the others go
    on; InputError (exit 2) when the DB, the plan or the config cannot be read, or when no
    run could be checked.
    """
    from fieldlogs.config import load_tree
    from fieldlogs.possession.plan import load_plan
    from fieldlogs.replay.network import open_db
    from fieldlogs.replay.pool import replay_values

    tree = load_tree(config_path)
    ref, network = open_db(Path(db_path))
    plan = load_plan(Path(plan_path), network, locale)
    folders = run_folders(run_dirs)
    tasks = [(str(p), (ref, plan.possessions, tree.gps, tree.possession, work)) for p in folders]
    checks, failed = replay_values(
        check_one, tasks, failure="run cannot be checked", workers=workers, preload=PRELOAD, progress=progress
    )
    if not checks:
        run, err = failed[0]
        raise InputError(err, path=None if run in err else run)
    return PossessionReport(checks, plan, str(db_path), failed)
