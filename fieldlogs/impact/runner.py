"""``trainpos db impact``: :func:`impact_runs` replays the runs against both DB versions and builds
the report (the method: :mod:`fieldlogs.impact`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from contextlib import closing
from pathlib import Path
from typing import Any

from dbtools.network import Network
from fieldlogs.impact.replay import RunFigures, impact_one, open_pair
from fieldlogs.impact.report import ImpactReport, RunImpact
from fieldlogs.replay.discovery import discover_runs
from fieldlogs.replay.network import DbRef
from fieldlogs.replay.pool import replay
from schemas.errors import InputError

#: Modules the replay's fork server imports once, besides the worker's.
PRELOAD = ("fieldlogs.pipeline.run", "fieldlogs.runs.handle", "fieldlogs.pipeline.warm")

Progress = Callable[[int, int, str], None]


def impact_runs(
    old: Path,
    new: Path,
    roots: Sequence[Path],
    *,
    plan: Path | None = None,
    tree: Any = None,
    workers: int | None = None,
    progress: Progress | None = None,
) -> ImpactReport:
    """Replay every run below ``roots`` against ``old`` and ``new`` (``tree``: the
    configuration tree, :class:`fieldlogs.config.SuiteConfig`; its pipeline sections and
    ``[gps]``/``[possession]`` for the plan). InputError when a DB or the plan cannot be
    read, or no run is found."""
    from fieldlogs.config import SuiteConfig

    tree = tree or SuiteConfig()
    ref_old, ref_new, net_old, net_new = open_pair(Path(old), Path(new))
    plan_path = None
    if plan is not None:
        from fieldlogs.possession.plan import load_plan

        for net in (net_old, net_new):  # a plan that does not fit a version is refused up front
            load_plan(Path(plan), net)
        plan_path = str(Path(plan).resolve())
    runs = discover_runs(roots)
    if not runs:
        raise InputError("no run folders (run.json) found", path=", ".join(str(r) for r in roots))
    tasks = [(str(p), (ref_old, ref_new, plan_path, tree)) for p in runs]
    report = ImpactReport(_side(ref_old, net_old), _side(ref_new, net_new), plan_path)
    outcomes = replay(impact_one, tasks, workers=workers, ordered=True, preload=PRELOAD, progress=progress)
    with closing(outcomes):
        for out in outcomes:
            if out.value is None:  # the run could not even be read
                failed = RunFigures(False, error=out.error)
                report.runs.append(RunImpact(out.run, failed, failed))
                continue
            report.runs.append(RunImpact(out.run, out.value["old"], out.value["new"]))
    return report


def _side(ref: DbRef, net: Network) -> dict[str, Any]:
    return {"path": ref.path, "db_version": net.meta.get("db_version"), "content_hash": ref.content_hash}
