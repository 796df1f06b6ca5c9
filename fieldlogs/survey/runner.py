"""``trainpos survey``: discover the runs, replay them, aggregate the survey.

Every run is replayed once (:func:`fieldlogs.survey.extract.survey_one`, through the one
replayer of ``audit`` and ``gis verify``: this process, a local pool or a Dask cluster);
its result feeds the balise, curve and wheel surveys and, unchanged, the GIS verification
(:func:`fieldlogs.gisverify.evidence.fixes_from_result` → :func:`dbtools.gis.verify.run.verify_fixes`,
whose statistics are reused as they are). A run that cannot be replayed is listed with its
error and the others go on.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.database import read_network
from dbtools.gis.verify.config import VerifyConfig
from dbtools.gis.verify.run import verify_fixes
from dbtools.gis.verify.track_points import verify_track_points
from dbtools.network import Network
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.replay.discovery import discover_runs
from fieldlogs.replay.network import open_db
from fieldlogs.replay.pool import replay_values
from fieldlogs.survey.balises import adjust
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.curvature import place_samples
from fieldlogs.survey.dbindex import balise_index
from fieldlogs.survey.extract import IDENTIFIED, RunSurvey, survey_one
from fieldlogs.survey.featurecompare import compare
from fieldlogs.survey.features import Rule, survey_track
from fieldlogs.survey.groupfix import group_fixes
from fieldlogs.survey.groups import group_places
from fieldlogs.survey.inspection import balise_status, candidates, group_status, missed_passes, pass_table
from fieldlogs.survey.propose import build_proposal
from fieldlogs.survey.result import SurveyReport
from fieldlogs.survey.trajectory import balise_table, chained_reads, trajectories
from fieldlogs.survey.wheels import run_wheels, vehicle_wheels
from schemas.errors import InputError

Progress = Callable[[int, int, str], None]
#: Modules the replay's fork server imports once.
PRELOAD = ("fieldlogs.pipeline.run", "fieldlogs.survey.extract", "fieldlogs.pipeline.warm")


def _unique_ids(runs: list[RunSurvey]) -> None:
    """Two folders with the same run_id are two runs: suffix the folder name."""
    seen: dict[str, int] = {}
    for r in runs:
        seen[r.run_id] = seen.get(r.run_id, 0) + 1
    for r in runs:
        if seen[r.run_id] > 1:
            r.run_id = f"{r.run_id}@{Path(r.folder).name}"
            if r.gis is not None:
                r.gis.run_id = r.run_id


def replay_runs(
    folders: Sequence[Path],
    db: Path,
    network: Network,
    pipeline: PipelineConfig,
    cfg: SurveyConfig,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Progress | None = None,
) -> tuple[list[RunSurvey], list[tuple[str, str]]]:
    """Every run's :class:`RunSurvey` (task order) and the runs that failed (folder, error).

    The runs are replayed with the odometry's ``wheel_calibration`` scale and the balise
    check's ``margin.wheel_rescale`` off: the survey measures the wheel against the configured
    diameter from every source (its radar calibration is still computed and used,
    :mod:`fieldlogs.survey.wheelaids`)."""
    if pipeline.odometry.wheel_calibration:
        pipeline = replace(pipeline, odometry=replace(pipeline.odometry, wheel_calibration=False))
    if pipeline.margin.wheel_rescale:
        pipeline = replace(pipeline, margin=replace(pipeline.margin, wheel_rescale=False))
    ref, _ = open_db(db, network)  # this process replays runs too: it keeps the network
    tasks = [(str(p), (ref, pipeline, cfg)) for p in folders]
    done, failed = replay_values(
        survey_one,
        tasks,
        failure="run cannot be used",
        workers=workers,
        scheduler=scheduler,
        preload=PRELOAD,
        progress=progress,
    )
    _unique_ids(done)
    return done, failed


def _gis(network: Network, runs: Sequence[RunSurvey]) -> tuple[object | None, object | None, str]:
    """The ``gis verify`` results on the runs' evidence — of the line grid, and of the tracks
    off a line (``track_points``, per track_id; None without them) — or why there is none."""
    frames = [r.gis.fixes.assign(run_id=r.run_id) for r in runs if r.gis is not None and len(r.gis.fixes)]
    if not frames:
        return None, None, "no trusted GPS fix on a known track"
    if not len(network.gis):
        return None, None, "the DB has no GIS grid"
    fixes = pd.concat(frames, ignore_index=True)
    try:
        return verify_fixes(network, fixes, VerifyConfig()), verify_track_points(network, fixes, VerifyConfig()), ""
    except InputError as exc:
        return None, None, exc.message


def _run_frame(runs: Sequence[RunSurvey]) -> pd.DataFrame:
    return pd.DataFrame(
        [
            {
                "run_id": r.run_id,
                "folder": r.folder,
                "vehicle_id": r.vehicle_id,
                "start_time": r.start_time,
                "duration_s": r.duration_s,
                "distance_m": r.distance_m,
                **r.counts,
            }
            for r in runs
        ],
        columns=[
            "run_id",
            "folder",
            "vehicle_id",
            "start_time",
            "duration_s",
            "distance_m",
            "telegrams",
            "identified",
            "unknown",
            "unlocated",
            "wrong_direction",
        ],
    )


def aggregate(
    network: Network,
    runs: list[RunSurvey],
    failed: list[tuple[str, str]],
    pipeline: PipelineConfig,
    cfg: SurveyConfig,
    db: str = "",
) -> SurveyReport:
    """The survey of ``runs`` against ``network`` (every module of the package)."""
    table = balise_table(network, cfg.cluster_m)
    reads = chained_reads(runs, table)
    adj = adjust(reads, table, len(runs), cfg)
    traj = trajectories(reads, adj.c_anchor, adj.scale, cfg.extrapolate_m)
    passes = pass_table(runs)
    all_reads = [r.reads.loc[r.reads["status"] == IDENTIFIED, "balise_id"] for r in runs if len(r.reads)]
    per_balise = pd.concat(all_reads).value_counts() if all_reads else pd.Series(dtype=np.int64)
    balises = balise_status(table, adj, passes, per_balise, cfg)
    index = network.cached("survey_balise_index", lambda: balise_index(network))
    places = network.cached("survey_group_places", lambda: group_places(network))
    fixes = group_fixes([r.group_placements for r in runs], adj.scale, network, places)
    groups = group_status(network, index.track_ids, passes, per_balise, cfg, skip=set(table.row), fixes=fixes)
    if len(groups):  # a network's balise groups (fieldlogs.survey.groups)
        balises = pd.concat([balises, groups], ignore_index=True)
    samples, coverage = place_samples(runs, traj, adj.scale, network)
    rule = Rule.of(pipeline.feature, cfg)
    curves = {k: survey_track(k, s, rule) for k, s in sorted(samples.items())}
    wheel_runs = run_wheels(runs, adj.scale, adj.scale_se, adj.scale_distance_m, cfg)
    gis, gis_tracks, note = _gis(network, runs)
    report = SurveyReport(
        db=db,
        db_version=network.meta.get("db_version"),
        network=network,
        config=cfg,
        runs=_run_frame(runs),
        failed_runs=pd.DataFrame(failed, columns=["run", "error"]),
        balises=balises,
        missed=missed_passes(balises, passes),
        candidates=candidates(runs, traj, network, table, cfg),
        features=compare(network.feature_points, curves, coverage, cfg, network, network.track_feature_points),
        curves=curves,
        wheel_runs=wheel_runs,
        wheels=vehicle_wheels(wheel_runs, cfg),
        gis=gis,  # type: ignore[arg-type]
        gis_tracks=gis_tracks,  # type: ignore[arg-type]
        gis_note=note,
        iterations=adj.iterations,
    )
    proposal = build_proposal(report)
    report.changes, report.proposed = proposal.changes, proposal.network
    return report


def survey(
    roots: Sequence[Path],
    db: Path,
    *,
    pipeline: PipelineConfig | None = None,
    config: SurveyConfig | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    progress: Progress | None = None,
) -> SurveyReport:
    """``trainpos survey``: discover, replay, aggregate (module docstring)."""
    pipeline = pipeline or PipelineConfig()
    cfg = config or SurveyConfig()
    network = read_network(Path(db))
    folders = discover_runs(roots)
    if not folders:
        raise InputError("no run folders (run.json) found", path=", ".join(str(r) for r in roots))
    runs, failed = replay_runs(
        folders, Path(db), network, pipeline, cfg, workers=workers, scheduler=scheduler, progress=progress
    )
    if not runs:
        raise InputError(
            f"no run could be used ({failed[0][1] if failed else 'none'})", path=failed[0][0] if failed else None
        )
    return aggregate(network, runs, failed, pipeline, cfg, str(db))
