"""``track_feature_points`` (curves of network tracks by distance along them): read from a
source set with ``seq`` derived, built into a DB of schema 3, a version-2 DB without the table
still read (and hashed as before), validation rules and ``db diff``."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import pandas as pd

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.diff import diff_paths
from dbtools.network import content_hash
from dbtools.sources import read_source_set
from dbtools.validate import validate_path
from schemas.tables import SCHEMA_VERSION

NETWORKS = Path(__file__).resolve().parents[1] / "data" / "networks"
#: The junction's branch B1: arc R 190 m to atan(1/9) (21.03 m), 40 m straight, arc R 500 m
#: to 30° (pos 61.03–267.49), straight to 600 m. Rows without seq: derived from pos_m.
ROWS = """track_id,feature_id,pos_m,radius_m,attribute,role
B1,F1,61.03,0,transition,entry straight check ends
B1,F1,21.03,0,straight,entry straight check starts
B1,F1,61.03,500,left,curve entry
B1,F1,267.49,0,transition,curve exit
B1,F1,267.49,0,straight,exit straight check starts
B1,F1,307.49,0,none,exit straight check ends
"""


def source(tmp_path: Path, rows: str = ROWS, name: str = "src") -> Path:
    dst = tmp_path / name
    shutil.copytree(NETWORKS / "junction", dst)
    (dst / "track_feature_points.csv").write_text(rows, encoding="utf-8")
    return dst


def rules(tmp_path: Path, rows: str) -> dict[str, list[str]]:
    out: dict[str, list[str]] = {}
    n = len(list(tmp_path.glob("bad*")))
    for f in validate_path(source(tmp_path, rows, f"bad{n}")):
        if f.table == "track_feature_points":
            out.setdefault(f.rule, []).append(f.message)
    return out


def test_read_with_seq_in_running_order(tmp_path: Path) -> None:
    net, findings = read_source_set(source(tmp_path))
    assert not [f for f in findings if f.severity == "error"]
    fp = net.track_feature_points.sort_values("seq")
    assert fp["seq"].tolist() == [1, 2, 3, 4, 5, 6]
    assert fp["pos_m"].tolist() == [21.03, 61.03, 61.03, 267.49, 267.49, 307.49]
    assert fp["attribute"].tolist()[2] == "left"


def test_built_db_holds_the_table_and_validates(tmp_path: Path) -> None:
    db = tmp_path / "j.sqlite"
    build_db(source(tmp_path), db)
    with sqlite3.connect(db) as conn:
        assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 3
    assert len(read_network(db).track_feature_points) == 6
    assert not [f for f in validate_path(db) if f.severity == "error"]


def test_version_2_db_without_the_table_reads_and_hashes_as_before(tmp_path: Path) -> None:
    db = tmp_path / "v2.sqlite"
    build_db(NETWORKS / "junction", db)
    before = read_network(db)
    with sqlite3.connect(db) as conn:
        conn.execute("DROP TABLE track_feature_points")
        conn.execute("PRAGMA user_version=2")
    net = read_network(db)  # the stored hash still matches: an empty table is not hashed
    assert net.track_feature_points.empty
    assert content_hash(net.tables) == content_hash(before.tables) == before.meta["content_hash"]


def test_unknown_track_and_outside_the_track(tmp_path: Path) -> None:
    bad = ROWS.replace("B1,F1,307.49", "B1,F1,607.49").replace("B1,F1,21.03", "B1,F1,21.03")
    bad += "ZZ,F9,10,0,straight,\nZZ,F9,30,0,transition,\nZZ,F9,30,300,right,\n"
    bad += "ZZ,F9,60,0,transition,\nZZ,F9,60,0,straight,\nZZ,F9,90,0,none,\n"
    found = rules(tmp_path, bad)
    assert len(found["feature.unknown_track"]) == 6
    assert "'ZZ'" in found["feature.unknown_track"][0]
    assert found["feature.outside_track"] == ["pos_m 607.49 is beyond the end of track B1 (length 600 m)"]


def test_structure_rules_on_pos(tmp_path: Path) -> None:
    # F1: the exit straight (rows 5–6) only 10 m; F2: rows 3 and 4 (seq given) run backwards
    rows = """track_id,feature_id,seq,pos_m,radius_m,attribute,role
B1,F1,1,21.03,0,straight,
B1,F1,2,61.03,0,transition,
B1,F1,3,61.03,500,left,
B1,F1,4,267.49,0,transition,
B1,F1,5,267.49,0,straight,
B1,F1,6,277.49,0,none,
B1,F2,1,400,0,straight,
B1,F2,2,420,0,transition,
B1,F2,3,450,300,right,
B1,F2,4,440,0,transition,
B1,F2,5,470,0,straight,
B1,F2,6,490,0,none,
"""
    found = rules(tmp_path, rows)
    assert found["feature.straight_length"] == ["exit straight (rows 5–6) is 10.0 m long; at least 20 m is required"]
    order = found["feature.order"]
    assert len(order) == 1 and "increasing from the begin of track B1" in order[0]


def test_diff_names_the_feature_on_its_track(tmp_path: Path) -> None:
    old = source(tmp_path)
    new = source(tmp_path, ROWS.replace("B1,F1,61.03,500,left", "B1,F1,61.03,450,left"), "new")
    d = diff_paths(old, new)
    assert "feature F1 on track B1: radius 500 → 450 m" in d.summary
    d = diff_paths(NETWORKS / "junction", old)
    assert "feature F1 on track B1 added (pos 21.0–307.5 m, left R 500 m)" in d.summary
    assert d.tables["track_feature_points"].counts == {"added": 6, "removed": 0, "changed": 0}
    assert isinstance(d.tables["track_feature_points"].added, pd.DataFrame)


def test_turn_against_the_centreline(tmp_path: Path) -> None:
    # B1's chords at the straights' middles (pos 41, 287.5) head 6.34° and 30°: a turn of
    # +23.66° = the feature's (267.49 − 61.03)/500 rad. Mirrored, or at R 250 m (θ = 47.3°),
    # it is off by more than 20 % + 20 m/(2R).
    assert "feature.track_turn" not in rules(tmp_path, ROWS)
    mirrored = rules(tmp_path, ROWS.replace("500,left", "500,right"))["feature.track_turn"]
    assert mirrored == [
        "the centreline of track B1 turns +23.7° between the straights, the feature -23.7° "
        "(± 5.9°; + left from the track's begin)"
    ]
    assert len(rules(tmp_path, ROWS.replace("500,left", "250,left"))["feature.track_turn"]) == 1
