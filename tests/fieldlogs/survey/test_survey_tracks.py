"""The survey per network track (``track_id``): segments on a track off every line (its
``pos_m`` in the place of km), the G balises of groups identified by content and passed per
track, and the bundled sample network's station run surveyed with rows keyed by the station
track's id; on a line-only DB every row's track_id is the implied ``LINE:TRACK``."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.interchange.geojson import survey_geojson
from dbtools.network import Network
from dbtools.sample_network import sample_source_dir
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.dbindex import balise_index
from fieldlogs.survey.extract import find_segments
from fieldlogs.survey.groups import group_passes
from fieldlogs.survey.inspection import group_status
from fieldlogs.survey.runner import survey

SAMPLE_LOGS = Path(__file__).parents[3] / "fieldlogs" / "sample_logs"
CFG = SurveyConfig()


def test_a_crossover_is_a_segment_of_its_own_along_its_pos() -> None:
    """10 cycles on line 0420 D (km 100…190), 10 on crossover X1 (no line, pos 0…90), 10 on U
    (km 300…210, decreasing): three segments; the crossover's by track_id, in pos."""
    km = np.r_[np.arange(100.0, 200.0, 10.0), np.full(10, np.nan), np.arange(300.0, 200.0, -10.0)]
    pos = pd.DataFrame(
        {
            "state": "determined",
            "line_code": ["0420"] * 10 + [None] * 10 + ["0420"] * 10,
            "track": ["D"] * 10 + [None] * 10 + ["U"] * 10,
            "track_id": ["0420-D1"] * 10 + ["X1"] * 10 + ["0420-U5"] * 10,
            "km_m": km,
            "pos_m": np.r_[np.arange(0.0, 100.0, 10.0), np.arange(0.0, 100.0, 10.0), np.arange(90.0, -10.0, -10.0)],
        }
    )
    segs = find_segments(pos, np.arange(30.0) * 10.0, np.ones(30, dtype=int), extrapolate_m=0.0)
    got = [(s.line_code, s.track, s.track_id, s.motion, s.ia, s.ib) for s in segs]
    assert got == [("0420", "D", "0420-D1", 1, 0, 10), ("", "", "X1", 1, 10, 20), ("0420", "U", "0420-U5", -1, 20, 30)]


NET = Network(
    {
        "balises": pd.DataFrame(
            {
                "balise_id": ["C1", "G1", "G2"],
                "kind": ["C", "G", "G"],
                "line_code": ["0420", "0420", None],
                "station_code": ["01", None, None],
                "track": ["D", None, None],
                "signal_type": ["home", None, None],
                "km_actual_m": [500.0, 545.0, 30.0],
                "km_equipment_m": [500.0, 545.0, 30.0],
                "track_id": [None, "T3", "X9"],
                "nid_c": [None, 800, 800],
                "nid_bg": [None, 7, 8],
                "n_pig": [None, 0, 0],
            }
        )
    }
)


def test_a_group_telegram_is_identified_by_its_identity_and_every_balise_has_its_track() -> None:
    index = balise_index(NET)
    assert index.identify_group({"nid_c": 800.0, "nid_bg": 7.0, "n_pig": 0.0}) == ("G1", "0420", "")
    assert index.identify_group({"nid_c": 800, "nid_bg": 7, "n_pig": 1}) is None  # no such balise
    assert index.identify_group({"nid_c": None, "nid_bg": 7, "n_pig": 0}) is None
    # own track_id where given, else the implied LINE:TRACK of a DB without declared tracks
    assert index.track_ids == {"C1": "0420:D", "G1": "T3", "G2": "X9"}


def test_group_passes_by_hand() -> None:
    """A run on track T3 from u = 0 to 90 m (1 m margin + pass_margin 5 m): G1 at 45 is
    passed at the cycle nearest it (t = 4, u = 40; 50 is as near, the first wins) and not
    read; G3 at 95 is beyond the stretch less its margin; G2 (on X9, never driven) read at
    t = 20 is a pass of its own."""
    places = pd.DataFrame({"balise_id": ["G1", "G3", "G2"], "track_id": ["T3", "T3", "X9"], "place": [45.0, 95.0, 30]})
    t = np.arange(10.0)
    reads = pd.DataFrame({"balise_id": ["G2"], "t": [20.0]})
    out = group_passes(
        places, t, t * 10.0, np.ones(10), np.full(10, "T3", dtype=object), np.ones(10, dtype=bool), reads, CFG
    )
    assert out.to_dict("list") == {
        "balise_id": ["G1", "G2"],
        "seg": [-1, -1],
        "t_pass": [4.0, 20.0],
        "km_pass_m": [45.0, 30.0],
        "read": [False, True],
    }


def test_a_group_balise_never_read_on_two_passes_is_missed() -> None:
    passes = pd.DataFrame({"balise_id": ["G1", "G1", "G2"], "read": [False, False, True]})
    reads = pd.Series({"G2": 1})
    rows = group_status(NET, balise_index(NET).track_ids, passes, reads, CFG).set_index("balise_id")
    got = [rows.loc["G1", c] for c in ("track_id", "status", "passes", "reads", "missed_passes")]
    assert got == ["T3", "missed", 2, 0, 2]
    assert rows.loc["G2", "status"] == "unverified" and rows.loc["G2", "track_id"] == "X9"
    assert str(rows.loc["G2", "reason"]).startswith("balise of a group")


@pytest.fixture(scope="module")
def station(sample_network_db: Path, tmp_path_factory: pytest.TempPathFactory):  # type: ignore[no-untyped-def]
    root = tmp_path_factory.mktemp("station")
    shutil.copytree(SAMPLE_LOGS / "sim-net-station", root / "sim-net-station")
    return survey([root], sample_network_db, workers=1)


def test_the_station_run_is_surveyed_per_track(station) -> None:  # type: ignore[no-untyped-def]
    b = station.balises.set_index("balise_id")
    # the station run reads group BG3 on station track 3 (0420-3) — its rows carry that track
    assert b.loc[["BG3.0", "BG3.1"], "track_id"].tolist() == ["0420-3", "0420-3"]
    assert b.loc["BG3.0", "reads"] == 1 and b.loc["BG3.0", "passes"] == 1
    # I1/I2/C balises carry the declared track holding their km (0420 D 18485 → D1)
    assert b.loc["0420-02-D-I1", "track_id"] == "0420-D1"
    assert station.candidates.empty  # no group telegram taken for a balise the DB lacks
    assert int(station.runs["unknown"].sum()) == 0
    tp = station.gis_tracks.coverage.set_index("track_id")
    assert tp.loc["0420-3", "runs"] == 1 and tp.loc["0420-3", "track"] == "3"
    out = station.to_dict()
    assert out["gis"]["track_points"]["coverage"][0]["track_id"] == "0420-3"
    line_tracks = {"0420-D1", "0420-D2", "0420-D6", "0420-U1", "0420-U5"}
    assert {f["track_id"] for f in out["features"] if f["db_table"] == "feature_points"} <= line_tracks
    # the loops' and the branch's own curves (track_feature_points) on the line's km: one pass of 3
    own = {(f["track_id"], f["feature_id"], f["status"]) for f in out["features"] if f["db_table"] != "feature_points"}
    assert {(t, f) for t, f, _ in own} == {(t, f) for t in ("0420-3", "0420-4") for f in ("F1", "F2")} | {
        ("0421-S1", "F1")
    }
    assert {s for *_, s in own} == {"unverified"}
    feats = survey_geojson(station.network, station)["features"]
    cells = [f for f in feats if f["properties"]["layer"] == "cells" and f["properties"]["track_id"] == "0420-3"]
    assert cells and all(f["geometry"] is not None and "pos_from_m" in f["properties"] for f in cells)


def test_on_a_line_only_db_every_track_id_is_line_colon_track(tmp_path: Path) -> None:
    db = tmp_path / "line.sqlite"
    build_db(sample_source_dir(), db, db_version="line-only")
    shutil.copytree(SAMPLE_LOGS / "sim-d-evening", tmp_path / "logs" / "sim-d-evening")
    rep = survey([tmp_path / "logs"], db, workers=1)
    for frame in (rep.balises, rep.features):
        implied = frame["line_code"].astype(str) + ":" + frame["track"].astype(str)
        assert (frame["track_id"] == implied).all()
    assert rep.gis_tracks is None and "track_points" not in (rep.to_dict()["gis"] or {})


def test_an_unread_group_balise_on_a_driven_track_is_missed(tmp_path: Path) -> None:
    """A G balise added to the DB on 0420-D1 at km 19k000 (group 99: no run reads it): the
    station and junction runs drive D1 past it with a determined position — two passes
    without a read, so it is missed, with its passes in the inspection list."""
    from dbtools.sample_network import sample_network_source_dir

    src = tmp_path / "src"
    shutil.copytree(sample_network_source_dir(), src)
    balises = src / "balises.csv"
    header = balises.read_text(encoding="utf-8").splitlines()[0].split(",")
    row = dict.fromkeys(header, "") | {
        "balise_id": "BG99.0",
        "kind": "G",
        "line_code": "0420",
        "track": "D",
        "km_actual_m": "19000.0",
        "km_equipment_m": "19000.0",
        "track_id": "0420-D1",
        "nid_c": "800",
        "nid_bg": "99",
        "n_pig": "0",
        "n_total": "1",
    }
    with balises.open("a", encoding="utf-8") as f:
        f.write(",".join(row[c] for c in header) + "\n")
    db = tmp_path / "net.sqlite"
    build_db(src, db, db_version="with-bg99")
    for r in ("station", "junction"):
        shutil.copytree(SAMPLE_LOGS / f"sim-net-{r}", tmp_path / "logs" / f"sim-net-{r}")
    rep = survey([tmp_path / "logs"], db, workers=1)
    b = rep.balises.set_index("balise_id")
    assert [b.loc["BG99.0", c] for c in ("track_id", "status", "passes", "reads")] == ["0420-D1", "missed", 2, 0]
    m = rep.missed[rep.missed["balise_id"] == "BG99.0"]
    assert len(m) == 2 and set(m["track_id"]) == {"0420-D1"}
    assert rep.flagged  # a missed balise is something to act on


def test_a_group_balise_along_a_line_is_placed_between_its_neighbours(tmp_path: Path) -> None:
    """Group BG1 (0420-D1, km 20k700/20k703) moved +3 m in the DB: the runs that read it
    place it by dead reckoning from the C balise before it (20k611) — residual DB km −
    runs' km ≈ +3.0 m on both balises of the group, keyed by 0420-D1."""
    from dbtools.sample_network import sample_network_source_dir

    src = tmp_path / "src"
    shutil.copytree(sample_network_source_dir(), src)
    balises = src / "balises.csv"
    lines = balises.read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):
        for old, new in (
            ("BG1.0,G,0420,,D,,20700.0,20700.0,", "BG1.0,G,0420,,D,,20703.0,20703.0,"),
            ("BG1.1,G,0420,,D,,20703.0,20703.0,", "BG1.1,G,0420,,D,,20706.0,20706.0,"),
        ):
            if line.startswith(old):
                lines[i] = new + line[len(old) :]
    balises.write_text("\n".join(lines) + "\n", encoding="utf-8")
    db = tmp_path / "net.sqlite"
    build_db(src, db, db_version="bg1-moved")
    for r in ("station", "junction", "crossover"):
        shutil.copytree(SAMPLE_LOGS / f"sim-net-{r}", tmp_path / "logs" / f"sim-net-{r}")
    b = survey([tmp_path / "logs"], db, workers=1).balises
    for rec in b[b["balise_id"].isin(["BG1.0", "BG1.1"])].to_dict("records"):
        assert rec["track_id"] == "0420-D1" and rec["n_estimates"] >= 1
        assert abs(rec["residual_m"] - 3.0) < 0.5
    assert len(b[b["balise_id"].isin(["BG1.0", "BG1.1"])]) == 2
