"""A plan row may name a station track by its line and track name (``0420``, ``3``): the
possession is then on that network track, without a ``track_id`` column."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from dbtools.database import read_network
from dbtools.network import Network
from dbtools.sources import read_source_set
from fieldlogs.possession.plan import read_plan

HEADER = "work_no,line_code,track,km_from_m,km_to_m,planned_start,planned_end,started_at,released_at\n"
WHEN = "2026-01-16T01:00:00+09:00,2026-01-16T05:00:00+09:00,2026-01-16T01:05:00+09:00,"
STATION4 = Path(__file__).parents[2] / "data" / "networks" / "station4"


def _plan(tmp_path: Path, *rows: str) -> Path:
    path = tmp_path / "possessions.csv"
    path.write_text(HEADER + "".join(f"{r},{WHEN}\n" for r in rows), encoding="utf-8")
    return path


def test_station_track_name_possesses_that_network_track(sample_network_db: Path, tmp_path: Path) -> None:
    net = read_network(sample_network_db)
    plan = read_plan(_plan(tmp_path, "W1,0420,3,20900,21100", "W2,0420,U,20900,21100", "W3,0420,4,20k950,21k000"), net)
    assert plan.findings == []
    assert {p.work_no: p.track_id for p in plan.possessions} == {"W1": "0420-3", "W2": None, "W3": "0420-4"}


def test_an_unknown_track_name_lists_the_station_tracks_too(sample_network_db: Path, tmp_path: Path) -> None:
    plan = read_plan(_plan(tmp_path, "W1,0420,7,20900,21100"), read_network(sample_network_db))
    assert [(f.rule, f.row, f.column) for f in plan.errors] == [("plan.unknown_track", 2, "track")]
    assert "(tracks: 3, 4, D, U)" in plan.errors[0].message and not plan.possessions


def _split_station(net: Network) -> Network:
    """station4 with its track 3 (km 200–800) cut in two at km 500 (3a, 3b)."""
    t = net.tracks
    three = t[t["track_id"] == "3"].iloc[0]
    a = {**three.to_dict(), "track_id": "3a", "km_end_m": 500.0, "length_m": 300.0}
    b = {**three.to_dict(), "track_id": "3b", "km_begin_m": 500.0, "length_m": 300.0}
    tracks = pd.concat([t[t["track_id"] != "3"], pd.DataFrame([a, b])], ignore_index=True)
    return Network(tables={**net.tables, "tracks": tracks}, meta=dict(net.meta), origin=net.origin)


def test_a_split_station_track_needs_its_track_id(tmp_path: Path) -> None:
    net = _split_station(read_source_set(STATION4)[0])
    plan = read_plan(_plan(tmp_path, "W1,9004,3,300,400", "W2,9004,3,450,650", "W3,9004,3,550,700"), net)
    assert {p.work_no: p.track_id for p in plan.possessions} == {"W1": "3a", "W3": "3b"}
    assert [(f.rule, f.row, f.column) for f in plan.errors] == [("plan.track_id_needed", 3, "track")]
    assert "3a, 3b" in plan.errors[0].message
