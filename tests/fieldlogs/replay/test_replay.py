"""The replayer (``fieldlogs.replay``): one worker call path in this process, a local pool
and Dask; ordered or as-completed outcomes; errors as records; the per-process network
cache; cancellation that leaves no process behind.

Runs here are folders with a ``run.json`` only: the workers (``workers.py``) are small, as
a possession check's or any other application's per-run function would be.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterator
from contextlib import closing
from pathlib import Path
from typing import Any

import psutil
import pytest

from fieldlogs.replay import pool
from fieldlogs.replay.discovery import discover_runs
from fieldlogs.replay.network import DbRef, open_db
from fieldlogs.replay.pool import pool_size, replay
from fieldlogs.replay.tasks import Outcome
from tests.fieldlogs.audit.audit_data import AuditData, audit_data
from tests.fieldlogs.replay.workers import balise_count, crash, run_info

N = 8


@pytest.fixture
def runs(tmp_path: Path) -> list[Path]:
    """Eight run folders; ``run-3`` has an unreadable run.json."""
    for i in range(N):
        folder = tmp_path / "logs" / f"run-{i}"
        folder.mkdir(parents=True)
        (folder / "run.json").write_text(json.dumps({"run_id": f"R{i}"}), encoding="utf-8")
    (tmp_path / "logs" / "run-3" / "run.json").write_text('{"run_id": ', encoding="utf-8")
    return discover_runs([tmp_path / "logs"])


@pytest.fixture(params=["fork", "forkserver"])
def start(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Both ways pool workers start (``pool.START_METHOD``): forked from this process, or
    from a fork server while this process replays runs itself."""
    monkeypatch.setattr(pool, "START_METHOD", request.param)
    return str(request.param)


def tasks(runs: list[Path], *args: Any) -> list[tuple[str, tuple[Any, ...]]]:
    return [(str(r), args) for r in runs]


def descendants() -> set[int]:
    return {p.pid for p in psutil.Process().children(recursive=True)}


def assert_gone(pids: set[int], timeout_s: float = 20.0) -> None:
    """Every process of ``pids`` has exited (allowing for a process tearing its memory down)."""
    procs = []
    for pid in pids:
        try:
            procs.append(psutil.Process(pid))
        except psutil.NoSuchProcess:
            continue
    _, alive = psutil.wait_procs(procs, timeout=timeout_s)
    assert not alive, [(p.pid, p.cmdline()[:4]) for p in alive]


def check(outcomes: list[Outcome[Any]], runs: list[Path]) -> None:
    assert sorted(o.index for o in outcomes) == list(range(N))
    by_index = {o.index: o for o in outcomes}
    for i, run in enumerate(runs):
        o = by_index[i]
        assert o.run == str(run)
        if i == 3:
            assert not o.ok and o.value is None
            assert o.error is not None and "run.json is not JSON" in o.error and str(run) in o.error
        else:
            assert o.ok and o.value is not None and o.value["run_id"] == f"R{i}"


@pytest.mark.parametrize("workers", [1, 2])
def test_errors_are_records_ordered_or_as_completed_with_progress(runs: list[Path], workers: int, start: str) -> None:
    calls: list[tuple[int, int, str]] = []
    ordered = list(replay(run_info, tasks(runs), workers=workers, ordered=True, progress=lambda *a: calls.append(a)))
    assert [o.index for o in ordered] == list(range(N))
    check(ordered, runs)
    assert [(d, t) for d, t, _ in calls] == [(i + 1, N) for i in range(N)]
    assert [r for _, _, r in calls] == [o.run for o in ordered]
    completed = list(replay(run_info, tasks(runs, 0.05), workers=workers))
    check(completed, runs)
    if workers == 2:  # the pool did work (and, with a fork server, this process while it started)
        pids = {o.value["pid"] for o in completed if o.value}
        assert len(pids) >= 2
        if start == "fork":
            assert os.getpid() not in pids  # this process only stored results


def test_the_pool_starts_no_more_workers_than_the_fleet_pays_for(
    runs: list[Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    """At least two runs per worker, never more workers than cores; one = in this process."""
    monkeypatch.setattr(os, "sched_getaffinity", lambda _pid: {0, 1})
    assert [pool_size(2, n) for n in (0, 1, 2, 3, 4, 5, 100)] == [1, 1, 1, 1, 2, 2, 2]
    assert pool_size(8, 100) == 2 and pool_size(1, 100) == 1
    before = descendants()
    three = list(replay(run_info, tasks(runs[:3]), workers=2))  # too few runs for two workers
    assert {o.value["pid"] for o in three if o.value} == {os.getpid()}
    assert not descendants() - before


def test_a_worker_process_that_dies_fails_its_run_only(runs: list[Path], start: str) -> None:
    """Workers exit abruptly on run-1 (40 tasks, five of them run-1): each time the pool is
    restarted and the runs that were in it are retried one at a time, so only run-1 tasks
    are errors (those this process replayed itself during the pool's start-up succeed)."""
    before = descendants()
    todo = tasks(runs, os.getpid()) * 5
    outcomes = list(replay(crash, todo, workers=2, ordered=True))
    assert [o.index for o in outcomes] == list(range(len(todo)))
    errors = [o for o in outcomes if not o.ok]
    assert errors and {Path(o.run).name for o in errors} == {"run-1"}
    assert all("worker failed" in (o.error or "") for o in errors)
    assert_gone(descendants() - before)


def test_network_is_loaded_once_per_worker_process(tmp_path_factory: pytest.TempPathFactory, runs: list[Path]) -> None:
    data: AuditData = audit_data(tmp_path_factory)
    ref, net = open_db(data.db)
    assert ref.path == str(data.db.resolve()) and len(ref.content_hash) == 64
    outcomes = list(replay(balise_count, tasks(runs, ref), workers=2))
    assert all(o.ok for o in outcomes) and {o.value[1] for o in outcomes if o.value} == {len(net.balises)}
    # in-process runs use the coordinator's own copy; each pool process one loaded copy
    local = [o.value for o in replay(balise_count, tasks(runs[:2], ref), workers=1) if o.value]
    assert {v[2] for v in local} == {id(net)}
    stale = DbRef(ref.path, "0" * 64)  # the file no longer has the content the replay started with
    bad = list(replay(balise_count, tasks(runs[:3], stale), workers=2))
    assert all(not o.ok and "the DB changed" in (o.error or "") for o in bad)


def slow_tasks(runs: list[Path]) -> list[tuple[str, tuple[Any, ...]]]:
    return [(str(r), (1.0,)) for r in runs if not r.name.endswith("3")] * 4


def test_cancelling_a_replay_leaves_no_process_behind(runs: list[Path], start: str) -> None:
    """Ctrl-C while a local replay runs: the workers (and the fork server and the resource
    tracker it started) are all gone."""
    before = descendants()
    seen: set[int] = set()
    results = replay(run_info, slow_tasks(runs), workers=2)
    with pytest.raises(KeyboardInterrupt), closing(results):
        for i, out in enumerate(results):
            assert out.ok
            seen |= descendants() - before
            if i == 3:
                raise KeyboardInterrupt
    assert len(seen) >= (2 if start == "fork" else 3), seen  # workers (+ fork server, resource tracker)
    assert_gone(seen)
    assert not descendants() - before


def test_replay_closed_by_garbage_collection_stops_its_pool(runs: list[Path], start: str) -> None:
    before = descendants()
    results: Iterator[Outcome[Any]] | None = replay(run_info, slow_tasks(runs), workers=2)
    assert results is not None
    next(results)
    time.sleep(1.5)
    seen = descendants() - before
    results = None  # dropped without being closed: the generator's finally stops the pool
    assert seen
    assert_gone(seen)


# -- Dask ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=50
    ) as c:
        yield c


def test_dask_replay_is_the_local_replay(cluster: Any, runs: list[Path]) -> None:
    calls: list[int] = []
    outcomes = list(
        replay(run_info, tasks(runs), scheduler=cluster.scheduler_address, progress=lambda d, t, r: calls.append(d))
    )
    check(outcomes, runs)
    assert calls == list(range(1, N + 1))
    ordered = list(replay(run_info, tasks(runs), scheduler=cluster.scheduler_address, ordered=True))
    assert [o.index for o in ordered] == list(range(N))
    local = list(replay(run_info, tasks(runs), workers=1, ordered=True))
    assert [(o.run, o.error, o.value and o.value["run_id"]) for o in ordered] == [
        (o.run, o.error, o.value and o.value["run_id"]) for o in local
    ]


def test_dask_worker_that_dies_is_a_record(cluster: Any, runs: list[Path]) -> None:
    outcomes = list(replay(crash, tasks(runs[:3], os.getpid()), scheduler=cluster.scheduler_address, ordered=True))
    assert [o.ok for o in outcomes] == [True, False, True]
    assert "worker failed" in (outcomes[1].error or "")
