"""Fleet audits (``fieldlogs.audit.runner``), the audit DB and its reports (SPEC §7).

Runs: four short simulated runs over a synthetic 8 km line (``audit_data``). Report
numbers are checked on a hand-made audit DB whose statistics are computed by hand.
"""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import sqlite3
from collections.abc import Iterator
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import fieldlogs.audit.runner as audit_mod
import fieldlogs.audit.store as store_mod
from dbtools.audit_db import AuditDB
from dbtools.database import read_network
from fieldlogs.audit.runner import audit, pack, unpack
from fieldlogs.audit.store import open_audit, read_table, read_trace, store_run
from fieldlogs.pipeline.config import PipelineConfig
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.replay.discovery import discover_runs
from fieldlogs.reports.page import render_html
from fieldlogs.reports.report import RUN_JSON_KEYS, build_report, report_json
from fieldlogs.runs.handle import read_run
from schemas.errors import InputError
from tests.fieldlogs.audit.audit_data import RUNS, AuditData, audit_data
from tests.pages import check_page

N = len(RUNS)


@pytest.fixture(scope="session")
def data(tmp_path_factory: pytest.TempPathFactory) -> AuditData:
    return audit_data(tmp_path_factory)


@pytest.fixture(scope="module")
def audited(data: AuditData, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """An audit DB of the four runs (process pool, 2 workers)."""
    out = tmp_path_factory.mktemp("audited") / "audit.sqlite"
    stats = audit([data.logs], data.db, out, workers=2)
    assert (stats.total, stats.audited, stats.failed) == (N, N, 0), stats.errors
    return out


def dump(path: Path) -> dict[str, list[tuple[Any, ...]]]:
    with sqlite3.connect(path) as conn:
        return {
            t: conn.execute(f"SELECT * FROM {t} ORDER BY 1, 2").fetchall()
            for t in ("audit_runs", "audit_events", "audit_traces", "audit_meta")
        }


class Counter:
    """Wraps ``audit_one`` (in-process audits, workers=1) and counts the runs it pipelines."""

    def __init__(self, monkeypatch: pytest.MonkeyPatch) -> None:
        self.calls: list[str] = []
        self.piped: list[str] = []
        real = audit_mod.audit_one

        def wrapped(run_path: str, *args: Any) -> dict[str, Any]:
            self.calls.append(run_path)
            res = real(run_path, *args)
            if not res.get("unchanged"):
                self.piped.append(run_path)
            return res

        monkeypatch.setattr(audit_mod, "audit_one", wrapped)


# -- audit: storage, skip, resume, errors ---------------------------------------------------
def test_audit_stores_runs_events_traces_and_route_view(audited: Path, data: AuditData) -> None:
    runs = read_table(audited, "audit_runs").set_index("run_id")
    assert set(runs.index) == {f"RUN-{name}" for name, *_ in RUNS}
    assert (runs["status"] == "ok").all()
    assert set(runs["direction"]) == {"down", "up"}
    assert runs.loc["RUN-d-west", ["track_id", "line_code", "track", "direction"]].tolist() == [
        "0900:D",
        "0900",
        "D",
        "down",
    ]
    assert (runs["unit"] == "F").all() and runs["unit_disagreements"].isna().all()
    assert runs.loc["RUN-u-east", ["track", "direction"]].tolist() == ["U", "up"]
    assert (runs["distance_m"].between(2800, 3300)).all()
    assert (runs["n_slips"] >= 1).all()
    events = read_table(audited, "audit_events")
    # n_corrections of a run = its balise corrections (the population of the % statistics)
    n_bal = events[events["type"] == "balise_correction"].groupby("run_path").size()
    assert runs.set_index("run_path")["n_corrections"].sort_index().tolist() == n_bal.sort_index().tolist()
    assert (n_bal >= 1).all()
    trace = read_trace(audited, str(data.runs[0].resolve()))
    assert 200 < len(trace) < 1000  # 1 Hz plus full rate around the slip/slide episodes
    assert trace["kappa"].notna().any() and trace["lat"].notna().any()
    view = read_table(audited, "route_summary")
    assert len(view) == 2 and view["n_runs"].sum() == N
    assert view["n_corrections"].sum() == n_bal.sum()


def test_run_audit_and_report_give_the_same_correction_statistics(audited: Path, data: AuditData) -> None:
    """One statistic (balise corrections, S003 §5.2) whether a user runs `trainpos run`,
    reads the audit record or the report by run: the figures agree exactly."""
    runs = read_table(audited, "audit_runs").set_index("run_path")
    by_run = build_report(audited, by="run").groups.set_index("run_path")
    for path in data.runs:
        key = str(path.resolve())
        summary = run_pipeline(read_run(path), read_network(data.db)).summary
        assert summary["n_corrections"] == runs.loc[key, "n_corrections"] == by_run.loc[key, "n_corrections"]
        assert summary["mean_correction_pct"] == pytest.approx(runs.loc[key, "mean_correction_pct"])
        assert summary["mean_correction_pct"] == pytest.approx(by_run.loc[key, "mean_correction_pct"])
        assert summary["max_correction_pct"] == pytest.approx(by_run.loc[key, "max_correction_pct"])
        assert (
            summary["all_corrections"]["n_corrections"] == summary["n_corrections"] + summary["n_feature_corrections"]
        )


def test_reaudit_skips_unchanged_touch_is_still_skipped_config_change_reaudits(
    data: AuditData, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    logs = data.copy_logs(tmp_path / "logs")
    out = tmp_path / "audit.sqlite"
    first = audit([logs], data.db, out, workers=1)
    assert first.audited == N
    before = dump(out)
    count = Counter(monkeypatch)
    again = audit([logs], data.db, out, workers=1)
    assert (again.audited, again.skipped, count.calls) == (0, N, [])  # not even read
    after = dump(out)
    assert {k: v for k, v in after.items() if k != "audit_meta"} == {
        k: v for k, v in before.items() if k != "audit_meta"
    }

    # a new mtime, same content: the worker hashes it, finds it unchanged and records the new key
    tacho = logs / RUNS[0][0] / "tacho.parquet"
    st = tacho.stat()
    os.utime(tacho, ns=(st.st_atime_ns, st.st_mtime_ns + 5_000_000_000))
    touched = audit([logs], data.db, out, workers=1)
    assert (touched.audited, touched.skipped) == (0, N)
    assert count.calls == [str((logs / RUNS[0][0]).resolve())] and count.piped == []
    assert dump(out)["audit_events"] == before["audit_events"]
    count.calls.clear()
    audit([logs], data.db, out, workers=1)
    assert count.calls == []  # the new quick key was stored

    # a changed file content re-audits that run only
    shutil.copy(logs / RUNS[1][0] / "run.json", logs / RUNS[0][0] / "notes.txt")
    changed = audit([logs], data.db, out, workers=1)
    assert (changed.audited, changed.skipped) == (1, N - 1)

    # a changed config re-audits every run
    cfg = PipelineConfig.from_dict({"margin": {"distance_pct": 2.5}})
    count.piped.clear()
    reconf = audit([logs], data.db, out, workers=1, config=cfg)
    assert (reconf.audited, reconf.skipped) == (N, 0) and len(count.piped) == N
    assert audit([logs], data.db, out, workers=1, config=cfg).skipped == N


def test_interrupted_audit_resumes_without_losing_finished_runs(
    data: AuditData, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    out = tmp_path / "audit.sqlite"
    real_store = audit_mod.store_run
    stored: list[str] = []

    def interrupting_store(conn: AuditDB, record: dict[str, Any], *rest: Any) -> None:
        if len(stored) == 2:
            raise KeyboardInterrupt  # Ctrl-C in the coordinating loop, at the 3rd finished run
        real_store(conn, record, *rest)
        stored.append(record["run_path"])

    monkeypatch.setattr(audit_mod, "store_run", interrupting_store)
    with pytest.raises(KeyboardInterrupt):
        audit([data.logs], data.db, out, workers=2)  # the pool is shut down, the queue dropped
    monkeypatch.setattr(audit_mod, "store_run", real_store)
    kept = read_table(out, "audit_runs")
    assert sorted(kept["run_path"]) == sorted(stored) and len(stored) == 2
    assert (kept["status"] == "ok").all()
    assert len(read_table(out, "audit_traces")["run_path"].unique()) == 2

    count = Counter(monkeypatch)
    resumed = audit([data.logs], data.db, out, workers=1)
    assert (resumed.skipped, resumed.audited) == (2, N - 2)
    assert not set(count.calls) & set(stored)  # the finished runs are not audited again
    after = read_table(out, "audit_runs").set_index("run_path")
    assert after.loc[stored, "audited_at"].tolist() == kept.set_index("run_path").loc[stored, "audited_at"].tolist()
    assert len(after) == N


def test_failing_runs_are_recorded_and_the_others_go_on(data: AuditData, tmp_path: Path) -> None:
    logs = data.copy_logs(tmp_path / "logs")
    bad_json = logs / "bad-json"
    shutil.copytree(logs / RUNS[0][0], bad_json)
    (bad_json / "run.json").write_text('{"run_id": "X", ', encoding="utf-8")
    garbage = logs / "garbage-streams"
    shutil.copytree(logs / RUNS[1][0], garbage)
    for p in garbage.glob("*.parquet"):
        p.write_bytes(os.urandom(2000))
    out = tmp_path / "audit.sqlite"
    stats = audit([logs], data.db, out, workers=2)
    assert (stats.total, stats.audited, stats.failed) == (N + 2, N, 2)
    runs = read_table(out, "audit_runs").set_index("run_path")
    err = runs.loc[str(bad_json.resolve())]
    assert err["status"] == "error" and "run.json" in err["error"] and "JSON" in err["error"]
    err = runs.loc[str(garbage.resolve())]
    assert err["status"] == "error"
    assert "tacho: no usable rows" in err["error"] and "imu: no usable rows" in err["error"]
    assert sorted(p for p, _ in stats.errors) == sorted([str(bad_json.resolve()), str(garbage.resolve())])
    assert (runs["status"] == "ok").sum() == N
    # failed runs are retried; fixed, they are audited
    shutil.rmtree(garbage)
    (bad_json / "run.json").write_text((logs / RUNS[0][0] / "run.json").read_text(encoding="utf-8"))
    retry = audit([logs], data.db, out, workers=1)
    assert (retry.audited, retry.failed, retry.skipped) == (1, 0, N)
    rep = build_report(out)
    assert list(rep.failed_runs["run_path"]) == [str(garbage.resolve())]  # records of vanished runs stay


def test_discovery_skips_hidden_folders_and_reports_missing_roots(data: AuditData, tmp_path: Path) -> None:
    logs = data.copy_logs(tmp_path / "logs")
    shutil.copytree(logs / RUNS[0][0], logs / ".d-west.tmp123")  # an atomic write in progress
    assert [p.name for p in discover_runs([logs])] == sorted(name for name, *_ in RUNS)
    assert discover_runs([logs / RUNS[0][0], logs]) == discover_runs([logs])
    with pytest.raises(InputError, match="no such folder"):
        discover_runs([tmp_path / "nope"])


def test_audit_db_refuses_other_sqlite_files_without_touching_them(data: AuditData, tmp_path: Path) -> None:
    db = tmp_path / "net.sqlite"
    shutil.copy(data.db, db)
    raw = db.read_bytes()
    with pytest.raises(InputError, match="not a trainpos audit database"), open_audit(db):
        pass
    with pytest.raises(InputError, match="not a trainpos audit database"):
        build_report(db)
    assert db.read_bytes() == raw
    with pytest.raises(InputError, match="no such audit database"):
        build_report(tmp_path / "missing.sqlite")
    (tmp_path / "text.sqlite").write_text("hello", encoding="utf-8")
    with pytest.raises(InputError, match="not an SQLite database"):
        build_report(tmp_path / "text.sqlite")


def test_pack_round_trip() -> None:
    frame = pd.DataFrame(
        {"t": [0.0, 1.5, float("nan")], "type": ["slip", None, "slip"], "n": [1, 2, 3], "s": ["a", "b", "a"]}
    )
    back = unpack(pack(frame))
    assert back is not None
    assert back["t"].tolist()[:2] == [0.0, 1.5] and pd.isna(back["t"].iloc[2])
    assert back["type"].iloc[0] == back["type"].iloc[2] == "slip" and pd.isna(back["type"].iloc[1])
    assert back["s"].tolist() == ["a", "b", "a"]
    assert back["n"].tolist() == [1.0, 2.0, 3.0]


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.one_of(st.floats(allow_nan=True, allow_infinity=True), st.integers(-(2**40), 2**40)),
            st.one_of(st.none(), st.sampled_from(["slip", "balise", "", "x y"])),
            st.booleans(),
        ),
        max_size=30,
    )
)
def test_rows_from_packed_events_equal_rows_of_the_unpacked_frame(rows: list[tuple[Any, Any, bool]]) -> None:
    """The coordinator stores a worker's packed events without building a frame: the same
    values (NaN and missing text as NULL, absent columns as NULL) as the frame path."""
    frame = pd.DataFrame(
        {
            "t": pd.Series([r[0] for r in rows], dtype=float),
            "type": pd.Series([r[1] for r in rows], dtype=object),
            "detail": pd.Series([r[2] for r in rows], dtype=bool),
        }
    )
    packed = pack(frame)
    via_frame = list(store_mod._rows(unpack(packed), store_mod.EVENT_COLUMNS))  # type: ignore[arg-type]
    direct = list(store_mod._rows(packed, store_mod.EVENT_COLUMNS))
    assert len(direct) == len(rows)
    assert repr(direct) == repr(via_frame)  # None vs nan and float vs str kept apart


# -- Dask ----------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def cluster() -> Iterator[Any]:
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0", silence_logs=50
    ) as c:
        yield c


def test_dask_cluster_audit_equals_local_pool(cluster: Any, data: AuditData, audited: Path, tmp_path: Path) -> None:
    out = tmp_path / "dask.sqlite"
    stats = audit([data.logs], data.db, out, scheduler=cluster.scheduler_address)
    assert (stats.total, stats.audited, stats.failed) == (N, N, 0), stats.errors
    cols = [
        "run_path",
        "track_id",
        "line_code",
        "track",
        "direction",
        "n_corrections",
        "mean_correction_pct",
        "n_slips",
    ]
    local = read_table(audited, "audit_runs")[cols].sort_values("run_path").reset_index(drop=True)
    remote = read_table(out, "audit_runs")[cols].sort_values("run_path").reset_index(drop=True)
    pd.testing.assert_frame_equal(local, remote)
    assert len(read_table(out, "audit_events")) == len(read_table(audited, "audit_events"))
    assert audit([data.logs], data.db, out, scheduler=cluster.scheduler_address).skipped == N


# -- report on a hand-made audit DB --------------------------------------------------------
def _ev(t: float, type_: str, pct: float | None = None, **detail: Any) -> dict[str, Any]:
    return {
        "t": t,
        "type": type_,
        "km_m": 1000.0 + t,
        "correction_m": None,
        "correction_pct": pct,
        "detail": json.dumps(detail),
    }


def _run(path: str, **kw: Any) -> dict[str, Any]:
    base = {
        "run_path": path,
        "run_id": path.upper(),
        "vehicle_id": "V1",
        "fingerprint": f"fp-{path}",
        "status": "ok",
        "track_id": "0900:D",
        "line_code": "0900",
        "track": "D",
        "direction": "down",
        "audited_at": "2026-02-01T00:00:00Z",
        "unit": "F",
        "n_failsafe": 0,
        "n_anomalies": 0,
        "gps_decisions": 0,
    }
    return {**base, **kw}


@pytest.fixture
def hand_made(tmp_path: Path) -> Path:
    """Route 0900 D down: runs a (V1) and b (V2); route 0900 U up: run c (V1, no events);
    run d failed."""
    path = tmp_path / "hand.sqlite"
    with open_audit(path) as conn:
        store_run(
            conn,
            _run("a", distance_m=10_000.0, n_failsafe=1, gps_decisions=1, gps_trusted_share=0.9),
            pd.DataFrame(
                [
                    _ev(10, "balise_correction", None),  # first correction: no % (counted, not in the stats)
                    _ev(20, "balise_correction", 0.2, distance_since_correction_m=2000.0),
                    _ev(25, "feature_correction", 3.0, distance_since_correction_m=200.0),  # not in the stats
                    _ev(30, "balise_correction", 0.6, distance_since_correction_m=1500.0),
                    _ev(40, "slip", readhered=True, max_error_m=5.0),
                    _ev(50, "slide", readhered=False, max_error_m=22.8),
                    _ev(55, "failsafe"),
                    _ev(60, "feature_refused", failed=["sign", "length"]),
                    _ev(70, "feature_refused", failed=["length"]),
                ]
            ),
            None,
        )
        store_run(
            conn,
            _run("b", vehicle_id="V2", distance_m=8000.0),
            pd.DataFrame(
                [
                    _ev(10, "balise_correction", 0.4, distance_since_correction_m=3000.0),
                    _ev(15, "feature_correction", 0.1, distance_since_correction_m=300.0),
                    _ev(20, "balise_correction", 1.0, distance_since_correction_m=1000.0),
                ]
            ),
            None,
        )
        store_run(conn, _run("c", track_id="0900:U", track="U", direction="up", distance_m=5000.0), None, None)
        store_run(
            conn,
            {"run_path": "d", "fingerprint": "", "status": "error", "error": "boom", "audited_at": "x"},
            None,
            None,
        )
    return path


def test_report_statistics_are_over_balise_corrections(hand_made: Path) -> None:
    rep = build_report(hand_made)
    d = rep.routes.set_index("track").loc["D"]
    assert d["n_runs"] == 2 and d["distance_m"] == 18_000.0
    assert d["n_corrections"] == 5  # balise corrections, one without a %
    assert d["mean_correction_pct"] == pytest.approx((0.2 + 0.6 + 0.4 + 1.0) / 4)
    assert d["median_correction_pct"] == pytest.approx((0.4 + 0.6) / 2)
    assert d["max_correction_pct"] == pytest.approx(1.0)
    assert d["share_above_target"] == pytest.approx(2 / 4)  # 0.6 and 1.0 above 0.5
    assert d["n_feature_corrections"] == 2 and d["n_feature_refused"] == 2
    assert d["refusal_reasons"] == "length 2, sign 1"
    assert (d["n_slips"], d["n_slips_readhered"], d["max_slip_error_m"]) == (2, 1, pytest.approx(22.8))
    assert (d["n_failsafe"], d["gps_decisions"], d["gps_trusted_share"]) == (1, 1, pytest.approx(0.9))
    u = rep.routes.set_index("track").loc["U"]
    assert u["n_runs"] == 1 and u["n_corrections"] == 0 and pd.isna(u["mean_correction_pct"])
    assert rep.failed_runs.to_dict("records") == [{"run_path": "d", "error": "boom"}]
    assert build_report(hand_made, target_pct=0.3).routes.set_index("track").loc["D", "share_above_target"] == 0.75

    runs = rep.runs.set_index("run_path")
    assert runs.loc["a", "n_corrections"] == 3 and runs.loc["a", "mean_correction_pct"] == pytest.approx(0.4)
    assert runs.loc["a", "max_correction_pct"] == pytest.approx(0.6) and runs.loc["a", "n_feature_corrections"] == 1
    assert runs.loc["b", "mean_correction_pct"] == pytest.approx(0.7)
    by_vehicle = build_report(hand_made, by="vehicle").groups.set_index("vehicle_id")
    assert by_vehicle.loc["V1", "n_runs"] == 2 and by_vehicle.loc["V1", "n_corrections"] == 3
    assert by_vehicle.loc["V2", "median_correction_pct"] == pytest.approx(0.7)
    by_run = build_report(hand_made, by="run").groups
    assert list(by_run["run_path"]) == ["a", "b", "c"] and list(by_run["n_slips"]) == [2, 0, 0]


def test_report_json_has_the_documented_shape(hand_made: Path) -> None:
    data = json.loads(json.dumps(report_json(build_report(hand_made))))
    assert set(data) == {"target_pct", "routes", "runs", "vehicles", "failed_runs", "tracks", "paths", "units"}
    assert data["target_pct"] == 0.5 and data["units"] == []
    route_keys = [
        "track_id",
        "line_code",
        "track",
        "direction",
        "n_runs",
        "n_corrections",
        "distance_m",
        "mean_correction_pct",
        "median_correction_pct",
        "max_correction_pct",
        "share_above_target",
    ]
    assert all(list(r) == route_keys for r in data["routes"])
    run_keys = [
        "run_id",
        "vehicle_id",
        "unit",
        "track_id",
        "line_code",
        "track",
        "n_corrections",
        "mean_correction_pct",
        "n_slips",
        "n_failsafe",
    ]
    assert list(RUN_JSON_KEYS) == run_keys and all(list(r) == run_keys for r in data["runs"])
    assert data["routes"][0] == {
        "track_id": "0900:D",
        "line_code": "0900",
        "track": "D",
        "direction": "down",
        "n_runs": 2,
        "n_corrections": 5,
        "distance_m": 18000.0,
        "mean_correction_pct": pytest.approx(0.55),
        "median_correction_pct": pytest.approx(0.5),
        "max_correction_pct": 1.0,
        "share_above_target": 0.5,
    }
    assert data["routes"][1]["mean_correction_pct"] is None and data["routes"][1]["share_above_target"] is None
    assert data["runs"][0] == {
        "run_id": "A",
        "vehicle_id": "V1",
        "unit": "F",
        "track_id": "0900:D",
        "line_code": "0900",
        "track": "D",
        "n_corrections": 3,
        "mean_correction_pct": pytest.approx(0.4),
        "n_slips": 2,
        "n_failsafe": 1,
    }
    assert isinstance(data["runs"][0]["n_corrections"], int)
    assert data["failed_runs"] == [{"run_path": "d", "error": "boom"}]


# -- HTML ----------------------------------------------------------------------------------
class Page(HTMLParser):
    def __init__(self) -> None:
        super().__init__()
        self.refs: list[tuple[str, str, str]] = []
        self.imgs: list[str] = []
        self.tables = 0
        self.cells: list[str] = []
        self.scripts = 0
        self._in_td = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        for k, v in attrs:
            if k in ("src", "href") and v is not None:
                self.refs.append((tag, k, v))
        if tag == "img":
            self.imgs.append(dict(attrs).get("src") or "")
        self.tables += tag == "table"
        self.scripts += tag in ("script", "link", "iframe", "object")
        self._in_td = tag == "td"

    def handle_data(self, data: str) -> None:
        if self._in_td:
            self.cells.append(data)


def test_html_report_is_self_contained_with_plots_and_tables(audited: Path, tmp_path: Path) -> None:
    rep = build_report(audited)
    text = render_html(rep, audited)
    page = Page()
    page.feed(text)
    assert page.scripts == 0
    assert all(v.startswith("data:") for _, _, v in page.refs), [v[:60] for _, _, v in page.refs]
    assert len(page.imgs) >= 5
    for src in page.imgs:
        head, b64 = src.split(",", 1)
        assert head == "data:image/png;base64"
        png = base64.b64decode(b64)
        assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000
    assert page.tables >= 3
    for r in rep.routes.itertuples():
        assert r.direction in page.cells and f"{r.mean_correction_pct:.3f}" in page.cells
    assert {f"RUN-{name}" for name, *_ in RUNS} <= set(page.cells)


def test_html_report_in_the_browser(audited: Path, browser: Any, tmp_path: Path) -> None:
    """The rendering standard (tests/pages.py) on the audit report: verdict first, no sideways
    scroll, sticky headers, every plot's axes named with units."""
    page = tmp_path / "report.html"
    page.write_text(render_html(build_report(audited), audited), encoding="utf-8")
    seen = check_page(browser, page, tmp_path / "shots")
    assert seen["plots"] >= 5 and seen["verdict"].split(":")[0] in ("Passed", "Above target", "Incomplete")


def test_html_report_without_the_onboard_db_says_so(hand_made: Path) -> None:
    text = render_html(build_report(hand_made), hand_made)
    assert "not readable" in text and text.count("<img") == 3


def test_report_does_not_depend_on_the_order_the_workers_finished_in(audited: Path, tmp_path: Path) -> None:
    """The same audit with its runs' events stored in the opposite order (as another worker
    schedule stores them) gives the same report, plots included."""
    from fieldlogs.reports.page import render_html

    other = tmp_path / "reordered.sqlite"
    with sqlite3.connect(audited) as src, sqlite3.connect(other) as dst:
        src.backup(dst)
    first = "SELECT run_path FROM audit_events ORDER BY rowid LIMIT 1"
    with sqlite3.connect(other) as conn:
        (was,) = conn.execute(first).fetchone()
        conn.execute(  # the run stored first now stored last, the others in reverse
            "CREATE TEMP TABLE ev AS SELECT * FROM audit_events ORDER BY run_path = ?, run_path DESC, rowid", (was,)
        )
        conn.execute("DELETE FROM audit_events")
        conn.execute("INSERT INTO audit_events SELECT * FROM ev")
        assert conn.execute(first).fetchone() != (was,)
    assert report_json(build_report(other)) == report_json(build_report(audited))
    images = [
        re.findall(r"data:image/png;base64,[A-Za-z0-9+/=]+", render_html(build_report(p), p)) for p in (other, audited)
    ]
    assert images[0] and images[0] == images[1]
