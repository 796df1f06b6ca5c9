"""One key per track in audits and reports (``track_id``; line and track are display names),
and the unit audited (``trainpos audit --unit F|R|both``).

Hand-checked on the bundled network sample: the sim-net runs audited with the sample network
DB, whose crossover 0420-X1 (60.153 m, on no line) and station tracks 0420-3 / 0420-4
(520.383 m) are read from the DB's tracks table; line-only audits keep the numbers of the
(line, track, direction) grouping they had before.
"""

from __future__ import annotations

import json
import shutil
import sqlite3
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.database import read_network
from fieldlogs.audit.runner import audit
from fieldlogs.audit.store import open_audit, read_table, store_run
from fieldlogs.audit.units import check_unit, comparison_fields
from fieldlogs.pipeline.run import run_pipeline
from fieldlogs.pipeline.summary import main_track, merge_claims, track_claims
from fieldlogs.pipeline.units import compare_units, unit_run
from fieldlogs.reports.page import render_html, unit_spans_text
from fieldlogs.reports.report import build_report, report_json
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.samples_net import network_sample_scenarios
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.audit import AUDIT_APPLICATION_ID, AUDIT_SCHEMA_VERSION
from schemas.errors import InputError
from tests.pages import check_page

SAMPLE_LOGS = Path(__file__).parents[3] / "fieldlogs" / "sample_logs"
NET_RUNS = ("crossover", "junction", "station", "turnback")
LINE_RUNS = ("sim-d-evening", "sim-d-reversal", "sim-d-slips", "sim-u-evening", "sim-u-tunnel")


def _copy(names: tuple[str, ...], dst: Path) -> Path:
    dst.mkdir()
    for n in names:
        shutil.copytree(SAMPLE_LOGS / n, dst / n)
    return dst


@pytest.fixture(scope="module")
def net_logs(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _copy(tuple(f"sim-net-{r}" for r in NET_RUNS), tmp_path_factory.mktemp("keys") / "net")


@pytest.fixture(scope="module")
def net_audit(net_logs: Path, sample_network_db: Path) -> Path:
    out = net_logs.parent / "net-audit.sqlite"
    stats = audit([net_logs], sample_network_db, out, workers=2)
    assert (stats.audited, stats.failed) == (len(NET_RUNS), 0), stats.errors
    return out


def _track(db: Path, track_id: str) -> dict[str, Any]:
    with sqlite3.connect(db) as conn:
        conn.row_factory = sqlite3.Row
        return dict(conn.execute("SELECT * FROM tracks WHERE track_id = ?", (track_id,)).fetchone())


def _run_of(frame: pd.DataFrame, run: str) -> pd.DataFrame:
    return frame[frame["run_path"].str.endswith(f"sim-net-{run}")]


def _truth_m(run: str, track_id: str) -> float:
    """Distance the simulator's truth travels on a track (Σ |v|·Δt)."""
    t = pd.read_parquet(SAMPLE_LOGS / f"sim-net-{run}" / "truth.parquet")
    dt = np.diff(t["t"].to_numpy(), append=t["t"].iloc[-1])
    on = (t["track_id"] == track_id).to_numpy()
    return float(np.sum(np.abs(t["speed_mps"].to_numpy()[on]) * dt[on]))


# -- a run's route key ---------------------------------------------------------------------
def _cycles(*blocks: tuple[int, str, str | None, str | None, str | None]) -> pd.DataFrame:
    """(cycles, state, track_id, line_code, track) blocks as positions."""
    rows = [(s, tid, line, trk) for n, s, tid, line, trk in blocks for _ in range(n)]
    return pd.DataFrame(
        {
            "t": np.arange(len(rows)) * 0.1,
            "state": [r[0] for r in rows],
            "track_id": [r[1] for r in rows],
            "line_code": [r[2] for r in rows],
            "track": [r[3] for r in rows],
        }
    )


def test_route_is_the_track_claimed_on_most_cycles() -> None:
    """3 cycles on 0900-D1, 5 on the crossover X1 (4 determined, 1 uncertain), 6 undetermined
    cycles that still carry D1: X1 is the route, with no line and no local name."""
    pos = _cycles(
        (3, "determined", "0900-D1", "0900", "D"),
        (4, "determined", "X1", None, None),
        (1, "uncertain", "X1", None, None),
        (6, "undetermined", "0900-D1", "0900", "D"),
    )
    claims = track_claims(pos)
    assert claims == {"0900-D1": (3, "0900", "D"), "X1": (5, None, None)}
    assert main_track(claims) == ("X1", None, None)
    # a second window of the same run: 3 more on D1 → 6 against 5
    claims = merge_claims([claims, track_claims(_cycles((3, "determined", "0900-D1", "0900", "D")))])
    assert main_track(claims) == ("0900-D1", "0900", "D")
    # ties: the pipeline summary's order of (line, track), then the id
    tie = track_claims(_cycles((2, "determined", "0900:U", "0900", "U"), (2, "determined", "0900:D", "0900", "D")))
    assert main_track(tie) == ("0900:D", "0900", "D")
    assert main_track({}) == (None, None, None)


# -- the network sample --------------------------------------------------------------------
def test_crossover_and_station_runs_count_on_their_own_tracks(net_audit: Path, sample_network_db: Path) -> None:
    """The crossover run is counted on crossover 0420-X1 (no line: empty display names), the
    station run on station track 0420-3, the turnback on 0420-4, the junction on branch 0421-S1."""
    xo, st = _track(sample_network_db, "0420-X1"), _track(sample_network_db, "0420-3")
    assert (xo["line_code"], xo["track"], xo["length_m"]) == (None, None, pytest.approx(60.153))
    assert (st["line_code"], st["track"], st["kind"]) == ("0420", "3", "station")
    summary = read_table(net_audit, "track_summary").set_index("track_id")
    paths = read_table(net_audit, "audit_track_path")
    for run, track_id, length in (
        ("crossover", "0420-X1", xo["length_m"]),
        ("station", "0420-3", st["length_m"]),
        ("turnback", "0420-4", st["length_m"]),
        ("junction", "0421-S1", 1500.0),
    ):
        row = summary.loc[track_id]
        on = paths[(paths["track_id"] == track_id) & (paths["state"] == "determined")]
        assert set(on["run_path"].map(lambda p: p.rsplit("-", 1)[-1])) == {run}, track_id
        assert row["n_runs"] == 1 and row["distance_m"] == pytest.approx(on["distance_m"].sum())
        # determined on it for part of the way the truth travelled on it (the rest is ambiguous
        # at its switches), never more than its length; the audit measures with the odometry's
        # speed, whose error the margin bounds by margin.distance_pct (2 %) of the travel: the IMU
        # test now resolves the turnback's 0420-4 10 m past the toe: 529 m determined by the
        # odometry's speed against the truth's 520 m, and no cycle determined on another track
        truth = _truth_m(run, track_id)
        assert 0.3 * truth < row["distance_m"] <= min(length, truth) * 1.02 + 2.0, (track_id, row["distance_m"], truth)
    assert bool(summary["line_code"].isna()["0420-X1"]) and summary.loc["0420-3", "track"] == "3"
    rep = build_report(net_audit, by="track")
    tracks = rep.groups.set_index("track_id")
    assert (tracks.loc["0420-X1", "line_code"], tracks.loc["0420-X1", "track"]) == ("", "")
    crossing = next(t for t in report_json(rep)["tracks"] if t["track_id"] == "0420-X1")
    assert crossing["line_code"] is None and crossing["track"] is None
    res = CliRunner().invoke(app, ["report", str(net_audit), "--by", "track", "--format", "csv"])
    assert res.exit_code == 0, res.output
    rows = {line.split(",")[0]: line.split(",")[1:4] for line in res.output.splitlines()[1:]}
    assert rows["0420-X1"] == ["", "", "1"] and rows["0420-3"] == ["0420", "3", "1"]  # line, track, runs
    html = render_html(rep, net_audit)
    assert "Slips, feature points, GPS and alarms per track" in html and "0420-X1" in html


def test_track_summary_view_equals_report_by_track(net_audit: Path) -> None:
    view = read_table(net_audit, "track_summary").set_index("track_id").sort_index()
    rep = build_report(net_audit, by="track").groups.set_index("track_id").sort_index()
    assert list(view.index) == list(rep.index)
    for c in ("n_runs", "n_corrections", "n_slips", "n_failsafe", "n_anomalies"):
        assert view[c].astype(int).tolist() == rep[c].astype(int).tolist(), c
    for c in ("distance_m", "mean_correction_pct", "max_correction_pct"):
        np.testing.assert_allclose(view[c].astype(float), rep[c].astype(float), rtol=1e-12, err_msg=c)


def test_runs_and_routes_are_keyed_by_track_id(net_audit: Path, sample_network_db: Path) -> None:
    """Each run's route is the track it was claimed on most; its names are that track's."""
    runs = read_table(net_audit, "audit_runs")
    paths = read_table(net_audit, "audit_track_path")
    tracks = read_network(sample_network_db).tracks.set_index("track_id")
    for r in runs.itertuples():
        tid = str(r.track_id)
        det = paths[(paths["run_path"] == r.run_path) & (paths["state"] == "determined")]
        # the determined cycles per track (uncertain cycles add a few): the route leads them
        per = det.groupby("track_id")["n_cycles"].sum()
        assert per[tid] >= 0.9 * per.max(), (r.run_id, tid, per.to_dict())
        assert (r.line_code, r.track) == (tracks.loc[tid, "line_code"], tracks.loc[tid, "track"])
    view = read_table(net_audit, "route_summary")
    assert sorted(zip(view["track_id"], view["direction"], strict=True)) == sorted(
        set(zip(runs["track_id"], runs["direction"], strict=True))
    )
    assert view["n_runs"].sum() == len(runs)
    rep = build_report(net_audit)
    assert list(rep.routes.columns[:4]) == ["track_id", "line_code", "track", "direction"]
    merged = rep.routes.merge(view, on=["track_id", "direction"], suffixes=("", "_view"))
    assert len(merged) == len(view)
    assert (merged["n_runs"] == merged["n_runs_view"]).all()
    np.testing.assert_allclose(merged["distance_m"], merged["distance_m_view"])


@pytest.fixture(scope="module")
def line_audit(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    logs = _copy(LINE_RUNS, tmp_path_factory.mktemp("keys-line") / "line")
    out = logs.parent / "line-audit.sqlite"
    stats = audit([logs], sample_db, out, workers=2)
    assert (stats.audited, stats.failed) == (len(LINE_RUNS), 0), stats.errors
    return out


def test_line_only_audit_keeps_its_route_numbers(line_audit: Path) -> None:
    """On a line-only DB a track id is LINE:TRACK: the routes by (track_id, direction) are the
    routes by (line, track, direction) the audit had before, with the same figures."""
    runs = read_table(line_audit, "audit_runs")
    assert (runs["track_id"] == runs["line_code"] + ":" + runs["track"]).all()
    # the pipeline summary's main route is the record's
    summary = [json.loads(s) for s in runs["summary_json"]]
    assert [(s["line_code"], s["track"]) for s in summary] == list(zip(runs["line_code"], runs["track"], strict=True))
    old = (
        runs.groupby(["line_code", "track", "direction"])
        .agg(n_runs=("run_path", "size"), distance_m=("distance_m", "sum"), n_corrections=("n_corrections", "sum"))
        .reset_index()
    )
    view = read_table(line_audit, "route_summary").sort_values(["line_code", "track", "direction"])
    assert (
        view[["line_code", "track", "direction", "n_runs", "n_corrections"]].values.tolist()
        == old[["line_code", "track", "direction", "n_runs", "n_corrections"]].values.tolist()
    )
    np.testing.assert_allclose(view["distance_m"], old["distance_m"])
    events = read_table(line_audit, "audit_events").merge(runs, on="run_path")
    bal = events[events["type"] == "balise_correction"]
    mean = bal.groupby(["line_code", "track", "direction"])["correction_pct"].mean()
    np.testing.assert_allclose(view["mean_correction_pct"], mean.to_numpy())
    routes = build_report(line_audit).routes
    assert (
        routes[["line_code", "track", "direction", "n_runs"]].values.tolist()
        == old[["line_code", "track", "direction", "n_runs"]].values.tolist()
    )
    np.testing.assert_allclose(routes["mean_correction_pct"], mean.to_numpy())
    by_track = build_report(line_audit, by="track")
    assert sorted(by_track.tracks["track_id"]) == ["0420:D", "0420:U"]
    assert "Position correction per track" in render_html(by_track, line_audit)


# -- units ---------------------------------------------------------------------------------
def test_comparison_fields_of_a_hand_computed_comparison() -> None:
    """km F 0, 1, 5, 6, 2, 3 against km R 0, 1, 1, 1, 2, 3 with margins 1 + 1: cycles 2 and 3
    (d = 4, 5 > 2) disagree, one span 0.2-0.3 s."""
    pos_f = pd.DataFrame(
        {"t": np.arange(6) * 0.1, "km_m": [0.0, 1, 5, 6, 2, 3], "margin_m": 1.0, "state": "determined", "track_id": "A"}
    )
    pos_r = pos_f.assign(km_m=[0.0, 1, 1, 1, 2, 3])
    fields = comparison_fields(compare_units(pos_f, pos_r)[1])
    assert fields["unit_cycles_compared"] == 6 and fields["unit_max_difference_m"] == pytest.approx(5.0)
    assert (fields["unit_cycles_beyond_margins"], fields["unit_cycles_on_other_tracks"]) == (2, 0)
    assert fields["unit_disagreements"] == 1
    assert json.loads(fields["unit_disagreement_spans"]) == [[pytest.approx(0.2), pytest.approx(0.3)]]
    assert unit_spans_text(fields["unit_disagreement_spans"]) == "0.2–0.3 s"
    with pytest.raises(ValueError, match="unit must be one of F, R, both"):
        check_unit("Q")


def test_audit_with_both_units_stores_their_comparison(
    net_logs: Path, net_audit: Path, sample_network_db: Path, tmp_path: Path
) -> None:
    """--unit both: unit F's figures as the default audit has them, plus the comparison the two
    units' positions give (replayed here directly); --unit R: unit R's figures; a change of
    unit re-audits every run."""
    out = tmp_path / "both.sqlite"
    stats = audit([net_logs], sample_network_db, out, workers=2, unit="both")
    assert (stats.audited, stats.failed) == (len(NET_RUNS), 0), stats.errors
    both = read_table(out, "audit_runs").set_index("run_path").sort_index()
    f = read_table(net_audit, "audit_runs").set_index("run_path").sort_index()
    assert (both["unit"] == "both").all() and (f["unit"] == "F").all()
    cols = ["track_id", "direction", "distance_m", "n_corrections", "mean_correction_pct", "n_slips"]
    pd.testing.assert_frame_equal(both[cols], f[cols])
    net = read_network(sample_network_db)
    run_path = str(next(p for p in both.index if p.endswith("sim-net-turnback")))
    pos = {u: run_pipeline(unit_run(read_run(Path(run_path)), u, tmp_path / u), net).positions for u in ("F", "R")}
    expected = comparison_fields(compare_units(pos["F"], pos["R"])[1])
    claimed = min(int(pos[u]["km_m"].notna().sum()) for u in pos)  # unit R, on its own sensors, starts later
    assert expected["unit_cycles_compared"] >= 0.95 * claimed > 2000
    assert {k: both.loc[run_path, k] for k in expected} == pytest.approx(expected)
    assert (both["unit_disagreements"] == 0).all()  # the sample's two units agree (pipeline/test_units.py)
    rep = build_report(out)
    assert len(rep.units) == len(NET_RUNS) and set(rep.runs["unit"]) == {"both"}
    data = report_json(rep)
    assert all(u["unit_disagreement_spans"] == [] for u in data["units"])
    assert "Units F and R compared" in render_html(rep, out)

    r_out = tmp_path / "r.sqlite"
    assert audit([net_logs], sample_network_db, r_out, workers=2, unit="R").audited == len(NET_RUNS)
    r = read_table(r_out, "audit_runs").set_index("run_path").sort_index()
    assert (r["unit"] == "R").all() and r["unit_disagreements"].isna().all()
    # the units agree on the sample: exactly on the turned view of one set of sensors; within
    # 1 % on sim-net-turnback, whose R cab has its own axle, wheel and slips
    own = r.index.str.endswith("sim-net-turnback")
    np.testing.assert_allclose(r.loc[~own, "distance_m"], f.loc[~own, "distance_m"], rtol=1e-9)
    np.testing.assert_allclose(r.loc[own, "distance_m"], f.loc[own, "distance_m"], rtol=1e-2)
    # the same audit DB with another unit: nothing skipped
    again = audit([net_logs], sample_network_db, out, workers=2, unit="F")
    assert (again.skipped, again.audited) == (0, len(NET_RUNS))
    assert audit([net_logs], sample_network_db, out, workers=2, unit="F").skipped == len(NET_RUNS)


@pytest.fixture(scope="module")
def misplaced(sample_network_db: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(audit DB with both units, run folder) of the station run with a balise reader in each
    cab at x = ±9.5 m, run.json placing the R cab's reader at +30 m instead of −9.5 m."""
    tmp = tmp_path_factory.mktemp("misplaced")
    net = read_network(sample_network_db)
    over = dict(network_sample_scenarios(net)["sim-net-station"])
    over["balise"] = {"readers_x_m": [9.5, -9.5]}
    streams, meta = simulate_run(net, scenario_from_dict(over, source="test"))
    assert meta.vehicle is not None
    meta = replace(meta, vehicle={**meta.vehicle, "balise_reader_r": {"x_m": 30.0, "y_m": 0.0}})
    folder = write_run(tmp / "logs" / "misplaced-r", meta, streams)
    out = tmp / "both.sqlite"
    assert audit([tmp / "logs"], sample_network_db, out, workers=1, unit="both").audited == 1
    return out, folder


def test_both_units_catch_a_misplaced_reader(
    misplaced: tuple[Path, Path], sample_network_db: Path, tmp_path: Path
) -> None:
    """Unit R corrects its km 30 − (−9.5) = 39.5 m off at every balise, so the units disagree
    by about 39.5 m beyond their margins (a few metres), in spans the audit stores as a direct
    replay of the two units gives them."""
    out, folder = misplaced
    rec = read_table(out, "audit_runs").iloc[0]
    assert rec["unit_max_difference_m"] == pytest.approx(39.5, abs=1.5)
    assert rec["unit_cycles_beyond_margins"] > 1000 and rec["unit_disagreements"] >= 1
    spans = json.loads(rec["unit_disagreement_spans"])
    assert len(spans) == rec["unit_disagreements"] and all(a <= b for a, b in spans)
    net = read_network(sample_network_db)
    pos = {u: run_pipeline(unit_run(read_run(folder), u, tmp_path / u), net).positions for u in ("F", "R")}
    expected = comparison_fields(compare_units(pos["F"], pos["R"])[1])
    assert {k: rec[k] for k in expected} == pytest.approx(expected)
    rep = build_report(out)
    assert rep.units["unit_disagreements"].tolist() == [rec["unit_disagreements"]]
    html = render_html(rep, out)
    assert "1 of 1 run(s) with a disagreement" in html and "units F and R disagree in 1 run(s)" in html


def test_units_report_in_the_browser(misplaced: tuple[Path, Path], browser: Any, tmp_path: Path) -> None:
    """The rendering standard (tests/pages.py) on a page with the units' table, the paths of
    tracks and the per-track tables: verdict first, no sideways scroll, sticky headers."""
    page = tmp_path / "units.html"
    page.write_text(render_html(build_report(misplaced[0], by="track"), misplaced[0]), encoding="utf-8")
    seen = check_page(browser, page, tmp_path / "shots")
    assert seen["verdict"].startswith("Units disagree") or seen["verdict"].startswith("Above target")


def _hand_run(path: str, **kw: Any) -> dict[str, Any]:
    return {
        "run_path": path,
        "run_id": path.upper(),
        "vehicle_id": "V1",
        "fingerprint": f"fp-{path}",
        "status": "ok",
        "track_id": "0900-X1",
        "direction": "down",
        "audited_at": "2026-02-01T00:00:00Z",
        "distance_m": 100.0,
        "n_failsafe": 0,
        "n_anomalies": 0,
        "gps_decisions": 0,
        "unit": "both",
        **kw,
    }


def test_report_shows_the_units_disagreements(tmp_path: Path) -> None:
    """Hand-made audit: run a with two disagreement spans, run b with none, run c audited with F."""
    path = tmp_path / "hand.sqlite"
    spans = [[12.0, 14.5], [30.0, 30.2]]
    with open_audit(path) as conn:
        store_run(
            conn,
            _hand_run(
                "a",
                unit_cycles_compared=900,
                unit_max_difference_m=7.5,
                unit_cycles_beyond_margins=20,
                unit_cycles_on_other_tracks=8,
                unit_disagreements=2,
                unit_disagreement_spans=json.dumps(spans),
            ),
            None,
            None,
        )
        store_run(
            conn,
            _hand_run("b", unit_cycles_compared=500, unit_disagreements=0, unit_disagreement_spans="[]"),
            None,
            None,
        )
        store_run(conn, _hand_run("c", unit="F", track_id=None), None, None)
    rep = build_report(path)
    assert rep.units["run_id"].tolist() == ["A", "B"]
    assert rep.units["unit_disagreements"].tolist() == [2, 0]
    data = report_json(rep)
    assert data["units"][0]["unit_disagreement_spans"] == spans and data["units"][0]["unit_cycles_on_other_tracks"] == 8
    assert data["units"][1]["unit_disagreement_spans"] == []
    # the crossover route has no line: null names; the never-positioned run's route is unknown
    assert [(r["track_id"], r["line_code"], r["track"]) for r in data["routes"]] == [
        ("0900-X1", None, None),
        (None, None, None),
    ]
    html = render_html(rep, path)
    assert "Units F and R compared" in html and "12.0–14.5 s, 30.0–30.2 s" in html and "1 of 2 run(s)" in html
    res = CliRunner().invoke(app, ["report", str(path)], env={"COLUMNS": "200"})
    assert res.exit_code == 0, res.output
    assert "Units F and R compared" in res.output and "12.0–14.5 s" in res.output


def test_audit_cli_unit_option(net_logs: Path, sample_network_db: Path, tmp_path: Path) -> None:
    logs = tmp_path / "one"
    shutil.copytree(net_logs / "sim-net-junction", logs / "sim-net-junction")
    out = tmp_path / "cli.sqlite"
    runner = CliRunner()
    res = runner.invoke(app, ["audit", str(logs), "--db", str(sample_network_db), "--out", str(out), "--unit", "both"])
    assert res.exit_code == 0, res.output
    assert read_table(out, "audit_runs")["unit"].tolist() == ["both"]
    assert read_table(out, "audit_meta").set_index("key").loc["unit", "value"] == "both"
    bad = runner.invoke(app, ["audit", str(logs), "--db", str(sample_network_db), "--out", str(out), "--unit", "Q"])
    assert bad.exit_code == 2 and "Q" in bad.output


def test_audit_db_of_schema_3_is_refused_naming_what_changed(tmp_path: Path) -> None:
    old = tmp_path / "v3.sqlite"
    with sqlite3.connect(old) as conn:
        conn.execute(f"PRAGMA application_id={AUDIT_APPLICATION_ID}")
        conn.execute("PRAGMA user_version=3")
        conn.execute("CREATE TABLE audit_runs (run_path TEXT PRIMARY KEY, line_code TEXT, track TEXT)")
    raw = old.read_bytes()
    with pytest.raises(InputError, match=rf"schema 3 is older than this tool's \({AUDIT_SCHEMA_VERSION}: .*track_id"):
        build_report(old)
    res = CliRunner().invoke(app, ["report", str(old)])
    assert res.exit_code == 2 and "audit the runs again" in res.stderr and "Traceback" not in res.stderr
    assert old.read_bytes() == raw
