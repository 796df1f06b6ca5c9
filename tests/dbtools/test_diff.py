"""``db diff``: row diffs matched on domain keys, and the summaries a maintainer reads."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.diff import DbDiff, diff_networks, diff_paths
from dbtools.gis.geometry import GEOD
from dbtools.network import Network, canonical, content_hash
from schemas.errors import FindingsError, InputError
from schemas.tables import DB_TABLES, FEATURE_POINTS, KM_BREAKS, LINES, SCHEMA_VERSION

BALISES_CSV = (
    "balise_id,kind,line_code,station_code,track,signal_type,km_actual_m,km_equipment_m,dist_from_initial_m\n"
    "B001,I1,0420,01,D,,100,100,\n"
    "B002,I2,0420,01,D,,105,105,\n"
    "B003,I1,0420,01,U,,905,905,\n"
    "B004,I2,0420,01,U,,900,900,\n"
    "B005,C,0420,01,D,H,600,600,500\n"
)


def write_sources(folder: Path, balises: str = BALISES_CSV) -> Path:
    """A straight double-track line 0420, km 0–1000, tracks 3.8 m apart, two initial pairs."""
    folder.mkdir(parents=True)
    km = np.arange(0.0, 1001.0, 20.0)
    n = km.size
    clon, clat, _ = GEOD.fwd(np.full(n, 139.4), np.full(n, 35.9), np.full(n, 90.0), km)
    frames = []
    for track, az in (("D", 0.0), ("U", 180.0)):  # down track left (north) of an eastbound line
        lon, lat, _ = GEOD.fwd(clon, clat, np.full(n, az), np.full(n, 1.9))
        frames.append(pd.DataFrame({"line_code": "0420", "track": track, "km_m": km, "lat": lat, "lon": lon}))
    pd.concat(frames).to_csv(folder / "gis.csv", index=False, float_format="%.10f")
    (folder / "balises.csv").write_text(balises)
    (folder / "feature_points.csv").write_text("line_code,track,feature_id,km_m,radius_m,attribute,role\n")
    return folder


@pytest.fixture(scope="module")
def base(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """(source folder, DB built from it as version 2026.10)."""
    root = tmp_path_factory.mktemp("diff")
    src = write_sources(root / "src")
    db = root / "old.sqlite"
    build_db(src, db, db_version="2026.10")
    return src, db


@pytest.fixture
def net(base: tuple[Path, Path]) -> Network:
    return read_network(base[1])


def _copy(net: Network) -> Network:
    return Network({k: v.copy() for k, v in net.tables.items()}, origin="new.sqlite", meta=dict(net.meta))


def _diff(old: Network, new: Network) -> DbDiff:
    """Diff after re-sealing ``new`` (its stored content hash matches its edited content)."""
    new.meta["content_hash"] = content_hash(new.tables)
    return diff_networks(old, new)


def _move(gis: pd.DataFrame, track: str, km_from: float, km_to: float, metres: np.ndarray | float) -> None:
    """Move grid points north by ``metres`` (in place)."""
    m = (gis["track"] == track) & gis["km_m"].between(km_from, km_to)
    n = int(m.sum())
    lon, lat, _ = GEOD.fwd(
        gis.loc[m, "lon"].to_numpy(), gis.loc[m, "lat"].to_numpy(), np.zeros(n), np.broadcast_to(metres, n)
    )
    gis.loc[m, "lat"] = lat
    gis.loc[m, "lon"] = lon


def test_identical_dbs_have_no_changes(base: tuple[Path, Path], tmp_path: Path) -> None:
    other = tmp_path / "same.sqlite"
    shutil.copyfile(base[1], other)
    d = diff_paths(base[1], other)
    assert not d.has_changes
    assert all(t.counts == {"added": 0, "removed": 0, "changed": 0} for t in d.tables.values())
    assert d.meta == {}
    assert d.summary == ["no content differences (108 rows compared)"]
    assert d.schema_version == (SCHEMA_VERSION, SCHEMA_VERSION)


def test_source_folder_against_its_build_has_no_changes(base: tuple[Path, Path]) -> None:
    d = diff_paths(base[0], base[1])
    assert not d.has_changes
    assert d.old["kind"] == "sources" and d.new["kind"] == "db"
    assert d.old["content_hash"] == d.new["content_hash"]  # what a build would store
    assert "content_hash" not in d.meta
    assert d.schema_version == (None, SCHEMA_VERSION)


def test_moved_gis_points_grouped_into_km_runs(net: Network) -> None:
    new = _copy(net)
    _move(new.gis, "D", 200, 500, 2.0 + 0.2 * np.arange(16))  # 16 points, mean 3.5 m, max 5.0 m
    _move(new.gis, "D", 600, 600, 0.5)  # not contiguous with the run above
    _move(new.gis, "U", 700, 740, 1.0)
    d = _diff(net, new)
    assert d.tables["gis"].counts == {"added": 0, "removed": 0, "changed": 20}
    assert d.summary[1:] == [
        "GIS 0420 D km 0k200–0k500: 16 points moved, mean 3.5 m, max 5.0 m",
        "GIS 0420 D km 0k600: 1 point moved 0.50 m",
        "GIS 0420 U km 0k700–0k740: 3 points moved, mean 1.0 m, max 1.0 m",
    ]
    assert d.summary[0].startswith("content_hash ")
    row = d.tables["gis"].rows()[0]
    assert row["change"] == "changed" and row["keys"] == {"line_code": "0420", "track": "D", "km_m": 200.0}
    assert set(row["changes"]) <= {"lat", "lon"} and "lat" in row["changes"]


def test_added_and_removed_gis_points(net: Network) -> None:
    new = _copy(net)
    gis = new.gis
    extra = gis[(gis["track"] == "D") & (gis["km_m"] >= 940)].copy()
    extra["km_m"] += 100.0
    new.tables["gis"] = canonical_gis(pd.concat([gis[gis["km_m"] > 0], extra]))
    d = _diff(net, new)
    assert d.tables["gis"].counts == {"added": 4, "removed": 2, "changed": 0}
    assert "GIS 0420 D km 1k040–1k100: 4 points added" in d.summary
    assert "GIS 0420 D km 0k000: 1 point removed" in d.summary
    assert "GIS 0420 U km 0k000: 1 point removed" in d.summary


def canonical_gis(frame: pd.DataFrame) -> pd.DataFrame:
    from schemas.tables import GIS

    return canonical(GIS, frame)


def test_balises_moved_added_removed(base: tuple[Path, Path], tmp_path: Path) -> None:
    balises = (
        BALISES_CSV.replace("B005,C,0420,01,D,H,600,600,500", "B005,C,0420,01,D,H,612,600,512")
        .replace("B003,I1,0420,01,U,,905,905,\n", "")
        .replace("B004,I2,0420,01,U,,900,900,\n", "")
        + "B006,C,0420,05,D,H,800,800,700\nB007,C,0420,05,D,R,850,850,750\nB008,C,0420,05,D,H,990,990,890\n"
    )
    src = write_sources(tmp_path / "src", balises)
    new_db = tmp_path / "new.sqlite"
    build_db(src, new_db, db_version="2026.11")
    d = diff_paths(base[1], new_db)
    assert d.tables["balises"].counts == {"added": 3, "removed": 2, "changed": 1}
    assert d.summary == [
        "db_version 2026.10 → 2026.11",
        f"content_hash {d.old['content_hash'][:12]}… → {d.new['content_hash'][:12]}…",
        "balise B005 (C, 0420 01 D) moved +12.0 m (km_actual 0k600.0 → 0k612.0); dist_from_initial 500 → 512 m",
        "3 balises added at station 05 (0420 D): B006, B007, B008",
        "2 balises removed at station 01 (0420 U): B003, B004",
    ]
    assert d.meta["db_version"] == ("2026.10", "2026.11")
    rows = {(r["change"], r["keys"]["balise_id"]): r for r in d.tables["balises"].rows()}
    assert rows[("changed", "B005")]["changes"] == {
        "km_actual_m": [600.0, 612.0],
        "dist_from_initial_m": [500.0, 512.0],
    }
    assert rows[("added", "B006")]["changes"]["signal_type"] == [None, "H"]
    assert rows[("removed", "B003")]["changes"]["kind"] == ["I1", None]


def _features(radius: float, shift: float = 0.0) -> pd.DataFrame:
    km = np.array([827, 847, 881, 953, 987, 1007], dtype=float) + shift
    return canonical(
        FEATURE_POINTS,
        pd.DataFrame(
            {
                "line_code": "0420",
                "track": "D",
                "feature_id": "F12",
                "seq": range(1, 7),
                "km_m": km,
                "radius_m": [0, 0, radius, 0, 0, 0],
                "attribute": ["straight", "transition", "left", "transition", "straight", "none"],
                "role": None,
            }
        ),
    )


def test_feature_point_summaries(net: Network) -> None:
    old = _copy(net)
    old.tables["feature_points"] = _features(400.0)
    new = _copy(net)
    f13 = _features(300.0, shift=2000.0).assign(feature_id="F13")
    new.tables["feature_points"] = canonical(FEATURE_POINTS, pd.concat([_features(450.0, shift=5.0), f13]))
    d = _diff(old, new)
    assert "feature F12 0420 D: radius 400 → 450 m; km +5.0 m (rows 1,2,3,4,5,6)" in d.summary
    assert "feature F13 0420 D added (km 2k827.0–3k007.0, left R 300 m)" in d.summary
    d = _diff(new, old)
    assert "feature F13 0420 D removed (km 2k827.0–3k007.0, left R 300 m)" in d.summary


def test_lines_and_km_breaks(net: Network) -> None:
    new = _copy(net)
    new.tables["lines"] = canonical(LINES, pd.DataFrame({"line_code": ["0420", "0421"], "name": ["Main", None]}))
    new.tables["km_breaks"] = canonical(
        KM_BREAKS, pd.DataFrame({"line_code": ["0420"], "track": ["D"], "km_from_m": [500.0], "km_to_m": [520.0]})
    )
    d = _diff(net, new)
    assert "line 0420: name — → Main" in d.summary
    assert "line 0421 added (—)" in d.summary
    assert "km break 0420 D at 0k500.0 added (→ 0k520.0)" in d.summary


def test_json_shape_is_stable_and_plain(net: Network) -> None:
    new = _copy(net)
    new.meta["db_version"] = "2026.11"
    _move(new.gis, "U", 0, 0, 1.0)
    out = _diff(net, new).to_dict()
    text = json.dumps(out)  # plain Python values only: no numpy scalars, no NaN
    assert "NaN" not in text
    assert set(out) == {"old", "new", "schema_version", "meta", "tables", "summary"}
    assert out["schema_version"] == {"old": SCHEMA_VERSION, "new": SCHEMA_VERSION}
    assert out["meta"]["db_version"] == ["2026.10", "2026.11"]
    assert out["old"]["origin"].endswith("old.sqlite") and out["new"]["db_version"] == "2026.11"
    assert list(out["tables"]) == [t.name for t in DB_TABLES]
    for t in out["tables"].values():
        assert set(t) == {"added", "removed", "changed", "rows"}
        assert len(t["rows"]) == t["added"] + t["removed"] + t["changed"]
    (row,) = out["tables"]["gis"]["rows"]
    assert set(row) == {"change", "keys", "changes"}
    assert all(isinstance(v, list) and len(v) == 2 for v in row["changes"].values())
    assert isinstance(out["summary"], list) and all(isinstance(s, str) for s in out["summary"])


def test_tampered_side_is_flagged(net: Network) -> None:
    new = _copy(net)
    new.balises.loc[0, "km_actual_m"] = 101.0  # content changed, stored hash not updated
    d = diff_networks(net, new)
    assert any(s.startswith("NEW (new.sqlite): content does not match its stored content_hash") for s in d.summary)


def test_km_notation_does_not_count_as_a_change(base: tuple[Path, Path], tmp_path: Path) -> None:
    src = tmp_path / "src"
    shutil.copytree(base[0], src)
    text = (src / "balises.csv").read_text().replace(",600,600,500", ",0k600.0,0k600,500")
    (src / "balises.csv").write_text(text)
    assert not diff_paths(base[1], src).has_changes


def test_source_set_with_errors_is_refused(tmp_path: Path) -> None:
    src = write_sources(tmp_path / "src")
    (src / "gis.csv").unlink()
    with pytest.raises(FindingsError):
        diff_paths(src, src)


def test_unreadable_input(base: tuple[Path, Path], tmp_path: Path) -> None:
    bad = tmp_path / "bad.sqlite"
    bad.write_text("not a database")
    with pytest.raises(InputError, match="not an SQLite database"):
        diff_paths(base[1], bad)
    with pytest.raises(InputError, match="no such file"):
        diff_paths(tmp_path / "missing.sqlite", base[1])
