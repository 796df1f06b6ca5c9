"""``db diff`` of the network tables: tracks, connections, switches and track_points added,
removed and changed, a moved switch with how far it moved."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from dbtools.diff import diff_paths

NETWORKS = Path(__file__).resolve().parents[1] / "data" / "networks"


def edited(tmp_path: Path, name: str, table: str, edit: object) -> Path:
    dst = tmp_path / f"{name}-new"
    shutil.copytree(NETWORKS / name, dst)
    f = pd.read_csv(dst / f"{table}.csv", dtype=str, keep_default_na=False)
    f = edit(f)  # type: ignore[operator]
    f.to_csv(dst / f"{table}.csv", index=False, lineterminator="\n")
    return dst


def test_same_network_has_no_changes() -> None:
    d = diff_paths(NETWORKS / "station4", NETWORKS / "station4")
    assert not d.has_changes
    assert d.summary[-1].startswith("no content differences")


def test_switch_moved_says_by_how_much(tmp_path: Path) -> None:
    """W1 of the junction 10 m further on: km +10 m and 10 m by lat/lon (the line runs east)."""

    def edit(f: pd.DataFrame) -> pd.DataFrame:
        on = f["switch_id"] == "W1"
        f.loc[on, "km_m"] = "410"
        f.loc[on, "lon"] = f"{float(f.loc[on, 'lon'].iloc[0]) + 10.0 / 55_800.0:.9f}"  # ≈ 10 m at 60.2°N
        f.loc[on, "switch_number"] = "12"
        return f

    d = diff_paths(NETWORKS / "junction", edited(tmp_path, "junction", "switches", edit))
    assert d.tables["switches"].counts == {"added": 0, "removed": 0, "changed": 1}
    line = next(s for s in d.summary if s.startswith("switch W1"))
    assert "moved +10.0 m in km (0k400.0 → 0k410.0)" in line
    dist = float(line.split("m in km")[1].split(", ")[1].split(" m by")[0])
    assert dist == pytest.approx(10.0, abs=0.1)
    assert "switch_number 9 → 12" in line
    rows = d.to_dict()["tables"]["switches"]["rows"]
    assert rows[0]["changes"]["km_m"] == [400.0, 410.0]


def test_tracks_and_connections_added_removed_changed(tmp_path: Path) -> None:
    def tracks(f: pd.DataFrame) -> pd.DataFrame:
        f.loc[f["track_id"] == "A2", "length_m"] = "590"
        f = f[f["track_id"] != "B1"]
        extra = pd.DataFrame([dict.fromkeys(f.columns, "") | {"track_id": "Z1", "kind": "siding", "length_m": "50"}])
        return pd.concat([f, extra], ignore_index=True)

    new = edited(tmp_path, "junction", "tracks", tracks)
    c = pd.read_csv(new / "connections.csv", dtype=str, keep_default_na=False)
    c.loc[c["navigability"] == "none", "navigability"] = "both"
    c = c[~((c["track_a"] == "A1") & (c["track_b"] == "B1"))]
    c.to_csv(new / "connections.csv", index=False, lineterminator="\n")
    d = diff_paths(NETWORKS / "junction", new)
    assert d.tables["tracks"].counts == {"added": 1, "removed": 1, "changed": 1}
    s = "\n".join(d.summary)
    assert "track Z1 (50 m, siding) added" in s
    assert "track B1 (9002 S, km 0k000.0–0k600.0, 600 m, main) removed" in s
    assert "track A2: length_m 600 → 590 m" in s
    assert "connection A1 end ↔ B1 begin (both, switch W1) removed" in s
    assert "connection B1 begin ↔ A2 begin: navigability none → both" in s


def test_track_points_moved(tmp_path: Path) -> None:
    def edit(f: pd.DataFrame) -> pd.DataFrame:
        on = (f["track_id"] == "X1") & (f["pos_m"] == "20")
        f.loc[on, "lat"] = f"{float(f.loc[on, 'lat'].iloc[0]) + 0.5 / 111_400.0:.9f}"  # 0.5 m north
        return f[~((f["track_id"] == "X2") & (f["pos_m"] == "40"))]

    d = diff_paths(NETWORKS / "crossover", edited(tmp_path, "crossover", "track_points", edit))
    s = [x for x in d.summary if x.startswith("track_points")]
    assert s[0].startswith("track_points of X1: 1 changed (moved up to 0.5")
    assert s[1] == "track_points of X2: 1 removed"
