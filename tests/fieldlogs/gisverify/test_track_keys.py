"""``gis verify`` keyed by ``track_id``: the track of each line-grid point (declared or
implied), and a hand-displaced station track found, proposed and moved per track_id.

The displaced case: 8 runs of fixes every 4 m along station track 0420-4 of the sample
network (520 m of track points), each run with its own constant GPS bias (σ 0.2 m) and
σ 0.1 m noise per fix; between 200 m and 320 m from the track's begin the fixes lie 2.0 m
to the left of the track points (the track really lies there). Expected by hand: one defect
on 0420-4 from pos 200 to 320 m, shift +2.0 m (the run biases are removed by the
background either side), the interior points 220–300 m proposed 2.0 m to the left, and no
other track touched.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.verify.config import VerifyConfig
from dbtools.gis.verify.proposal import proposed_network
from dbtools.gis.verify.track_points import verify_track_points
from dbtools.network import Network
from dbtools.sources import write_source_set
from dbtools.topology import grid_track_ids
from fieldlogs.gisverify.evidence import VerifyReport
from fieldlogs.gisverify.page import render_html
from tests.pages import check_page

R = 6_378_137.0
TRACK = "0420-4"
SHIFT_M, FROM_M, TO_M = 2.0, 200.0, 320.0


def test_grid_points_take_the_declared_track_holding_their_km(sample_network_db: Path) -> None:
    net = read_network(sample_network_db)
    # 0420 D is declared as D1 16000–20800, D2 20800–21320, … D6 21700–30980; 0421 S as S1
    ids = grid_track_ids(net, ["0420"] * 5 + ["0421"], ["D"] * 5 + ["S"], [20799.9, 20800.0, 15000.0, 21350.0, 4e4, 10])
    assert ids.tolist() == ["0420-D1", "0420-D2", "0420-D1", "0420-D3", "0420-D6", "0421-S1"]
    # a line/track no declared track covers: the implied LINE:TRACK
    assert grid_track_ids(net, ["0999"], ["U"], [5.0]).tolist() == ["0999:U"]


def _plane(lat: np.ndarray, lon: np.ndarray, lat0: float) -> tuple[np.ndarray, np.ndarray]:
    return np.radians(lon) * R * np.cos(lat0), np.radians(lat) * R


def displaced_fixes(net: Network) -> pd.DataFrame:
    """The fixes of the module docstring (equirectangular plane: exact enough over 500 m)."""
    tp = net.track_points[net.track_points["track_id"] == TRACK].sort_values("pos_m")
    pos, lat, lon = (tp[c].to_numpy(float) for c in ("pos_m", "lat", "lon"))
    lat0 = float(np.radians(lat.mean()))
    x, y = _plane(lat, lon, lat0)
    rng = np.random.default_rng(7)
    rows = []
    for r in range(8):
        s = np.arange(rng.uniform(0.0, 4.0), pos[-1], 4.0)
        xs, ys = np.interp(s, pos, x), np.interp(s, pos, y)
        tx, ty = np.gradient(xs), np.gradient(ys)
        n = np.hypot(tx, ty)
        off = np.where((s >= FROM_M) & (s <= TO_M), SHIFT_M, 0.0) + rng.normal(0, 0.2) + rng.normal(0, 0.1, s.size)
        xs, ys = xs - off * ty / n, ys + off * tx / n  # left of begin → end
        rows.append(
            pd.DataFrame(
                {
                    "run_id": f"r{r}",
                    "t": np.arange(s.size, dtype=float),
                    "lat": np.degrees(ys / R),
                    "lon": np.degrees(xs / (R * np.cos(lat0))),
                    "line_code": "0420",
                    "track": "4",
                    "track_id": TRACK,
                    "km_ref_m": np.nan,
                }
            )
        )
    return pd.concat(rows, ignore_index=True)


@pytest.fixture(scope="module")
def displaced(sample_network_db: Path) -> tuple[Network, object]:
    net = read_network(sample_network_db)
    return net, verify_track_points(net, displaced_fixes(net), VerifyConfig())


def test_a_displaced_station_track_is_a_defect_of_its_track_id(displaced: tuple[Network, object]) -> None:
    _, tp = displaced
    assert tp is not None
    d = tp.defects  # type: ignore[attr-defined]
    assert d["track_id"].tolist() == [TRACK]
    row = d.iloc[0]
    assert (row["line_code"], row["track"]) == ("0420", "4")  # display names, not the internal walk
    assert (row["pos_from_m"], row["pos_to_m"]) == (FROM_M, TO_M)
    assert abs(row["shift_m"] - SHIFT_M) < 0.1
    assert "km_from_m" not in d and "line_code" in d
    cov = tp.coverage.set_index("track_id")  # type: ignore[attr-defined]
    assert cov.loc[TRACK, "defects"] == 1 and cov.loc["0420-X1", "defects"] == 0
    assert cov.loc["0420-X1", "line_code"] is None and cov.loc["0420-X1", "track"] is None  # a crossover: no line


def test_the_displaced_points_are_proposed_and_moved_left(displaced: tuple[Network, object]) -> None:
    net, tp = displaced
    p = tp.proposal  # type: ignore[attr-defined]
    assert set(p["track_id"]) == {TRACK}
    inner = p[(p["pos_m"] > FROM_M) & (p["pos_m"] < TO_M)]
    assert inner["pos_m"].tolist() == [220.0, 240.0, 260.0, 280.0, 300.0]
    assert np.abs(inner["shift_m"] - SHIFT_M).max() < 0.15
    moved = proposed_network(net, _line_stub(net), tp).track_points  # type: ignore[arg-type]
    old = net.track_points.set_index(["track_id", "pos_m"])
    new = moved.set_index(["track_id", "pos_m"])
    lat0 = float(np.radians(old["lat"].mean()))
    ox, oy = _plane(old["lat"].to_numpy(), old["lon"].to_numpy(), lat0)
    nx, ny = _plane(new.loc[old.index, "lat"].to_numpy(), new.loc[old.index, "lon"].to_numpy(), lat0)
    dist = pd.Series(np.hypot(nx - ox, ny - oy), index=old.index)
    assert np.abs(dist.loc[[(TRACK, k) for k in inner["pos_m"]]].to_numpy() - SHIFT_M).max() < 0.15
    untouched = ~old.index.isin(list(zip(p["track_id"], p["pos_m"], strict=True)))
    assert dist[untouched].max() < 1e-6  # every other track point stays


def test_the_proposed_source_set_builds_with_the_moved_track_points(
    displaced: tuple[Network, object], tmp_path: Path
) -> None:
    """What ``gis verify --propose`` writes: the source set builds, its track points moved."""
    net, tp = displaced
    src = write_source_set(proposed_network(net, _line_stub(net), tp), tmp_path / "src")  # type: ignore[arg-type]
    build_db(src, tmp_path / "new.sqlite", db_version="proposed")
    new = read_network(tmp_path / "new.sqlite").track_points.set_index(["track_id", "pos_m"])
    old = net.track_points.set_index(["track_id", "pos_m"])
    moved = (new.loc[old.index, "lat"] - old["lat"]).abs() > 1e-9
    assert set(moved[moved].index.get_level_values(0)) == {TRACK}
    assert sorted(moved[moved].index.get_level_values(1)) == sorted(tp.proposal["pos_m"])  # type: ignore[attr-defined]


def _line_stub(net: Network):  # type: ignore[no-untyped-def]
    """A line verification that proposes nothing (only the track points move)."""
    from dbtools.gis.verify.run import verify_fixes

    empty = pd.DataFrame({c: pd.Series([], dtype=float) for c in ("t", "lat", "lon", "km_ref_m")})
    return verify_fixes(net, empty.assign(run_id=pd.Series([], dtype=str), line_code="", track=""))


def test_page_and_json_show_the_track_off_a_line(
    displaced: tuple[Network, object], sample_network_db: Path, browser: Any, tmp_path: Path
) -> None:
    net, tp = displaced
    report = VerifyReport(str(sample_network_db), "sample-1", _line_stub(net), {}, [], net, tp)  # type: ignore[arg-type]
    html = render_html(report)
    assert "Tracks off a line (track_points)" in html and "Proposed track points" in html
    assert "Offsets along the tracks off a line" in html  # the figure of 0420-4
    assert "Failed: 1 defect(s) found." in html
    page = tmp_path / "gis.html"
    page.write_text(html, encoding="utf-8")
    seen = check_page(browser, page, tmp_path / "shots")  # the rendering standard holds with the new section
    assert seen["verdict"].startswith("Failed: ")
    data = report.to_dict()["track_points"]
    assert data["defects"][0]["track_id"] == TRACK and "pos_from_m" in data["defects"][0]


def test_cli_outputs_key_every_row_by_track_id(runner: CliRunner, sample_network_db: Path, tmp_path: Path) -> None:
    logs = Path(__file__).parents[3] / "fieldlogs" / "sample_logs" / "sim-net-turnback"
    env = {"COLUMNS": "200"}
    r = runner.invoke(app, ["gis", "verify", str(sample_network_db), str(logs), "--format", "json", "--workers", "1"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert {c["track_id"] for c in out["cells"]} <= {"0420-U1", "0420-U2", "0420-U3", "0420-U4", "0420-U5"} | {
        f"0420-D{i}" for i in range(1, 7)
    }
    tp_ids = {c["track_id"] for c in out["track_points"]["coverage"]}
    assert tp_ids == {"0420-3", "0420-4", "0420-X1", "0420-X2"}
    assert all(c["line_code"] != c["track_id"] for c in out["track_points"]["coverage"])  # no fake line
    assert out["track_points"]["cells"] and all("pos_from_m" in c for c in out["track_points"]["cells"])
    t = runner.invoke(app, ["gis", "verify", str(sample_network_db), str(logs), "--workers", "1"], env=env)
    assert t.exit_code == 0, t.output
    assert "tracks off a line (track_points)" in t.output and "0420-X2" in t.output
    gj = tmp_path / "v.geojson"
    g = runner.invoke(
        app, ["gis", "verify", str(sample_network_db), str(logs), "--format", "geojson", "--out", str(gj), "-j", "1"]
    )
    assert g.exit_code == 0, g.output
    feats = json.loads(gj.read_text(encoding="utf-8"))["features"]
    on4 = [f for f in feats if f["properties"].get("track_id") == TRACK and f["properties"]["layer"] == "cells"]
    assert on4 and all(f["geometry"] is not None and "pos_from_m" in f["properties"] for f in on4)
