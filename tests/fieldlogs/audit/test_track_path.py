"""A run's route as a path of tracks (``audit_track_path``) and ``report --by track``.

Hand-computed paths from hand-made positions; the four sim-net sample runs audited with the
sample network DB, their paths compared with the simulator's truth; per-track statistics
on a hand-made audit DB.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from cli.main import app
from fieldlogs.audit.runner import audit
from fieldlogs.audit.store import open_audit, read_table, store_run
from fieldlogs.audit.track_path import append_path, path_ids, track_path
from fieldlogs.reports.page import network_paths, path_text, render_html
from fieldlogs.reports.report import build_report, report_json

SAMPLE_LOGS = Path(__file__).parents[3] / "fieldlogs" / "sample_logs"
NET_RUNS = ("crossover", "junction", "station", "turnback")


def _cands(*ids: str) -> str:
    return json.dumps([{"track_id": i, "pos_m": 1.0, "km_m": None, "margin_m": 2.0} for i in ids])


def _positions() -> pd.DataFrame:
    """0.1 s cycles at 10 m/s (1 m per cycle): A ×3, uncertain ×1, A ×2, ambiguous ×2, B ×2,
    undetermined ×1."""
    rows: list[tuple[str, str | None, float | None, str | None]] = [
        ("determined", "A", 0.0, None),
        ("determined", "A", 1.0, None),
        ("determined", "A", 2.0, None),
        ("uncertain", "A", 3.0, None),
        ("determined", "A", 4.0, None),
        ("determined", "A", 5.0, None),
        ("ambiguous", None, None, _cands("A", "B")),
        ("ambiguous", None, None, _cands("B", "C")),
        ("determined", "B", 2.0, None),
        ("determined", "B", 3.0, None),
        ("undetermined", None, None, None),
    ]
    return pd.DataFrame(
        {
            "t": np.arange(len(rows)) * 0.1,
            "state": [r[0] for r in rows],
            "line_code": ["0900" if r[1] else None for r in rows],
            "track": [r[1] and r[1].lower() for r in rows],
            "track_id": [r[1] for r in rows],
            "pos_m": [r[2] for r in rows],
            "speed_mps": 10.0,
            "candidates": [r[3] for r in rows],
        }
    )


def test_path_of_hand_made_positions() -> None:
    p = track_path(_positions())
    assert list(p["state"]) == ["determined", "ambiguous", "determined"]
    assert list(p["track_id"]) == ["A", None, "B"]
    assert list(p["seq"]) == [0, 1, 2]
    # A: cycles 0-2 and 4-5 (the uncertain cycle 3 is skipped, not a change of track): 5 m
    assert list(p["n_cycles"]) == [5, 2, 2]
    assert p["distance_m"].tolist() == pytest.approx([5.0, 2.0, 2.0])
    assert (p.loc[0, "t_from"], p.loc[0, "t_to"]) == pytest.approx((0.0, 0.5))
    assert (p.loc[0, "pos_from_m"], p.loc[0, "pos_to_m"]) == (0.0, 5.0)
    assert json.loads(p.loc[1, "candidates"]) == ["A", "B", "C"]
    assert p.loc[0, "candidates"] is None and p.loc[1, "track_id"] is None
    assert path_ids(p) == ["A", "B"]
    assert path_text(p) == "A (5 m) → {A|B|C} (2 m) → B (2 m)"


def test_path_of_nothing_positioned_is_empty() -> None:
    pos = _positions().assign(state="undetermined")
    assert track_path(pos).empty and track_path(pos.iloc[:0]).empty


@settings(max_examples=40, deadline=None)
@given(st.integers(min_value=1, max_value=10))
def test_windows_appended_equal_the_whole_run(k: int) -> None:
    """A long run replayed by windows has the path of the whole run, wherever it is cut."""
    pos = _positions()
    whole = track_path(pos)
    joined = append_path(track_path(pos.iloc[:k]), track_path(pos.iloc[k:].reset_index(drop=True)))
    pd.testing.assert_frame_equal(joined.reset_index(drop=True), whole, check_dtype=False)


@pytest.fixture(scope="module")
def net_audit(sample_network_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    logs = tmp_path_factory.mktemp("net-logs")
    for r in NET_RUNS:
        shutil.copytree(SAMPLE_LOGS / f"sim-net-{r}", logs / f"sim-net-{r}")
    out = logs.parent / "net-audit.sqlite"
    stats = audit([logs], sample_network_db, out, workers=2)
    assert (stats.audited, stats.failed) == (len(NET_RUNS), 0), stats.errors
    return out


def _truth_rle(run: str) -> list[str]:
    ids = pd.read_parquet(SAMPLE_LOGS / f"sim-net-{run}" / "truth.parquet")["track_id"].tolist()
    return [x for i, x in enumerate(ids) if i == 0 or ids[i - 1] != x]


def _stretches_on_truth(path: pd.DataFrame, run: str) -> list[tuple[str, float]]:
    """(claimed track, share of its cycles on which the truth has that track) per determined stretch."""
    truth = pd.read_parquet(SAMPLE_LOGS / f"sim-net-{run}" / "truth.parquet")
    tt = truth["t"].to_numpy()
    out = []
    for r in path[path["state"] == "determined"].itertuples():
        sel = truth["track_id"].to_numpy()[(tt >= r.t_from - 1e-6) & (tt <= r.t_to + 1e-6)]
        out.append((str(r.track_id), float(np.mean(sel == r.track_id))))
    return out


@pytest.mark.parametrize(
    "run",
    [
        "crossover",
        "junction",
        "turnback",
        "station",
    ],
)
def test_sim_net_path_is_the_truth_track_sequence(net_audit: Path, run: str) -> None:
    paths = read_table(net_audit, "audit_track_path", order_by=("run_path", "seq"))
    path = paths[paths["run_path"].str.endswith(f"sim-net-{run}")]
    ids = path_ids(path)
    truth = _truth_rle(run)
    # the determined tracks in the truth's order (a track left before the first claim may be missing)
    assert ids == [x for x in truth if x in set(ids)] and len(ids) >= len(truth) - 1
    for track_id, share in _stretches_on_truth(path, run):
        assert share >= 0.95, (track_id, share)  # the truth lags a claim by at most a few cycles at a switch
    # ambiguous stretches list the true track among their candidates (the truth may lag by a cycle)
    truth = pd.read_parquet(SAMPLE_LOGS / f"sim-net-{run}" / "truth.parquet")
    for r in path[path["state"] == "ambiguous"].itertuples():
        on = truth.loc[(truth["t"] >= r.t_from + 0.15) & (truth["t"] <= r.t_to - 0.15), "track_id"]
        assert set(on) <= set(json.loads(r.candidates)), (r.t_from, set(on), r.candidates)


def test_sim_net_path_distance_is_the_run_distance(net_audit: Path) -> None:
    runs = read_table(net_audit, "audit_runs").set_index("run_path")
    paths = read_table(net_audit, "audit_track_path")
    for run_path, g in paths.groupby("run_path"):
        # positioned distance ≤ the run's; the run starts undetermined for ~25 s (a few hundred m)
        total = float(runs.loc[run_path, "distance_m"])
        assert 0.8 * total <= g["distance_m"].sum() <= total + 1.0
        assert list(g.sort_values("seq")["seq"]) == list(range(len(g)))


def test_report_by_track_on_the_sim_net_audit(net_audit: Path, tmp_path: Path) -> None:
    rep = build_report(net_audit, by="track")
    tracks = rep.groups.set_index("track_id")
    det = rep.paths[rep.paths["state"] == "determined"]
    assert tracks.loc["0420-3", "n_runs"] == 1 and tracks.loc["0420-4", "n_runs"] == 1  # station, turnback
    assert tracks.loc["0420-X1", "n_runs"] == 1 and tracks.loc["0421-S1", "n_runs"] == 1  # crossover, junction
    for track_id, g in det.groupby("track_id"):
        assert tracks.loc[track_id, "distance_m"] == pytest.approx(g["distance_m"].sum())
    assert tracks["n_corrections"].sum() <= rep.routes["n_corrections"].sum()
    data = report_json(rep)
    assert {t["track_id"] for t in data["tracks"]} == set(tracks.index)
    assert len(data["paths"]) == len(NET_RUNS) and all(p["path"] for p in data["paths"])
    assert set(network_paths(rep)["run_id"]) == set(rep.runs["run_id"])
    html = render_html(rep, net_audit)
    assert "Routes as paths of tracks" in html and "0420-X1" in html
    res = CliRunner().invoke(app, ["report", str(net_audit), "--by", "track", "--format", "csv"])
    assert res.exit_code == 0, res.output
    assert res.output.splitlines()[0].startswith("track_id,line_code,track,n_runs")


def _ev(t: float, type_: str, pct: float | None = None, **detail: Any) -> dict[str, Any]:
    return {"t": t, "type": type_, "km_m": t, "correction_m": None, "correction_pct": pct, "detail": json.dumps(detail)}


def _stretch(seq: int, state: str, track_id: str | None, t0: float, t1: float, d: float) -> dict[str, Any]:
    return {
        "seq": seq,
        "state": state,
        "track_id": track_id,
        "line_code": "0900" if track_id else None,
        "track": track_id,
        "candidates": None if track_id else '["A", "B"]',
        "t_from": t0,
        "t_to": t1,
        "distance_m": d,
        "pos_from_m": None,
        "pos_to_m": None,
        "n_cycles": 10,
    }


def test_report_by_track_counts_events_within_the_stretches(tmp_path: Path) -> None:
    """Run a: A over 0-22 s (1000 m), ambiguous 22-24 s, B over 24-80 s (3000 m); run b: B only.
    Corrections at 10 s (no %) and 20 s (0.2 %) on A, 23 s (ambiguous: no track), 30 s (0.6 %)
    on B; a's slip at 40 s and fail-safe at 55 s on B; b's correction 0.4 % on B."""
    path = tmp_path / "hand.sqlite"
    run = {"fingerprint": "f", "status": "ok", "line_code": "0900", "track": "D", "audited_at": "x"}
    with open_audit(path) as conn:
        store_run(
            conn,
            {**run, "run_path": "a", "run_id": "A1", "vehicle_id": "V1", "distance_m": 4100.0, "n_failsafe": 1},
            pd.DataFrame(
                [
                    _ev(10, "balise_correction"),
                    _ev(20, "balise_correction", 0.2),
                    _ev(23, "balise_correction", 0.9),
                    _ev(30, "balise_correction", 0.6),
                    _ev(40, "slip", readhered=True, max_error_m=2.0),
                    _ev(55, "failsafe"),
                ]
            ),
            None,
            pd.DataFrame(
                [
                    _stretch(0, "determined", "A", 0, 22, 1000.0),
                    _stretch(1, "ambiguous", None, 22.1, 23.9, 40.0),
                    _stretch(2, "determined", "B", 24, 80, 3000.0),
                ]
            ),
        )
        store_run(
            conn,
            {**run, "run_path": "b", "run_id": "B1", "vehicle_id": "V2", "distance_m": 500.0},
            pd.DataFrame([_ev(5, "balise_correction", 0.4)]),
            None,
            pd.DataFrame([_stretch(0, "determined", "B", 0, 10, 500.0)]),
        )
    g = build_report(path, by="track").groups.set_index("track_id")
    assert list(g.index) == ["A", "B"]
    assert (g.loc["A", "n_runs"], g.loc["A", "distance_m"], g.loc["A", "n_corrections"]) == (1, 1000.0, 2)
    assert g.loc["A", "mean_correction_pct"] == pytest.approx(0.2)
    assert (g.loc["B", "n_runs"], g.loc["B", "distance_m"], g.loc["B", "n_corrections"]) == (2, 3500.0, 2)
    assert g.loc["B", "mean_correction_pct"] == pytest.approx(0.5)
    assert (g.loc["B", "n_slips"], g.loc["B", "n_failsafe"], g.loc["A", "n_failsafe"]) == (1, 1, 0)
    assert np.isnan(g.loc["B", "gps_trusted_share"])
