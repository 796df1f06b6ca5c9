"""``gis grid`` for tracks along no line km (centrelines with ``track_id`` → ``track_points``):
hand-computed straights, a turnout curve against the analytic arc, a crossover through two
turnout curves, km from posts, the files and the CLI.

Shapes are drawn in a local azimuthal-equidistant plane (pyproj ``aeqd`` on GRS80 at the
start point: distances from the centre are exact, and over 100 m the plane is true to well
below 1e-9 relative), turned into lon/lat, gridded, and the grid turned back into the plane
to be compared with the analytic shape — independent of the grid's own projection.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pyproj import Transformer
from typer.testing import CliRunner

from cli.main import app
from dbtools.gis.grid import build_grid
from dbtools.gis.io import grid_files
from dbtools.gis.track_grid import grid_positions
from schemas.errors import FindingsError, RefusedError
from schemas.network import TRACK_POINTS
from schemas.tables import BALISES, FEATURE_POINTS

LON0, LAT0 = 139.4, 35.9
TO_LL = Transformer.from_crs(
    f"+proj=aeqd +lat_0={LAT0} +lon_0={LON0} +ellps=GRS80 +units=m", "EPSG:6668", always_xy=True
)
TO_XY = Transformer.from_crs(
    "EPSG:6668", f"+proj=aeqd +lat_0={LAT0} +lon_0={LON0} +ellps=GRS80 +units=m", always_xy=True
)


def own_track(x: np.ndarray, y: np.ndarray, track_id: str = "X1", line_code: str | None = None) -> pd.DataFrame:
    lon, lat = TO_LL.transform(x, y)
    return pd.DataFrame(
        {
            "line_code": line_code,
            "track": None,
            "track_id": track_id,
            "seq": np.arange(1, x.size + 1),
            "lon": lon,
            "lat": lat,
            "height_m": np.nan,
        }
    )


def posts(x: list[float], y: list[float], km: list[float], line_code: str = "0420") -> pd.DataFrame:
    lon, lat = TO_LL.transform(np.asarray(x, dtype=float), np.asarray(y, dtype=float))
    return pd.DataFrame({"line_code": line_code, "km_m": km, "lon": lon, "lat": lat, "km_after_m": np.nan})


NO_POSTS = pd.DataFrame({"line_code": [], "km_m": [], "lon": [], "lat": [], "km_after_m": []})


def back_to_plane(tp: pd.DataFrame) -> tuple[np.ndarray, np.ndarray]:
    x, y = TO_XY.transform(tp["lon"].to_numpy(float), tp["lat"].to_numpy(float))
    return np.asarray(x), np.asarray(y)


def test_grid_positions_every_20_m_and_the_end() -> None:
    assert grid_positions(100.0).tolist() == [0.0, 20.0, 40.0, 60.0, 80.0, 100.0]
    assert grid_positions(30.0).tolist() == [0.0, 20.0, 30.0]
    assert grid_positions(7.5).tolist() == [0.0, 7.5]
    assert grid_positions(40.0004).tolist() == [0.0, 20.0, 40.0004]  # the end replaces a point < 1 mm away


def test_straight_100_m_track() -> None:
    """A straight 100 m track heading 30° east of north, two vertices, heights 10 → 12 m."""
    ux, uy = math.sin(math.radians(30.0)), math.cos(math.radians(30.0))
    cl = own_track(np.array([0.0, 100.0 * ux]), np.array([0.0, 100.0 * uy])).assign(height_m=[10.0, 12.0])
    r = build_grid(cl, NO_POSTS)
    assert r.findings == [] and r.gis.empty
    tp = r.track_points
    assert list(tp.columns) == TRACK_POINTS.column_names
    assert tp["track_id"].tolist() == ["X1"] * 6
    np.testing.assert_allclose(tp["pos_m"], [0, 20, 40, 60, 80, 100], atol=1e-3)
    x, y = back_to_plane(tp)
    np.testing.assert_allclose(x, tp["pos_m"] * ux, atol=0.01)
    np.testing.assert_allclose(y, tp["pos_m"] * uy, atol=0.01)
    np.testing.assert_allclose(tp["height_m"], 10.0 + tp["pos_m"] / 50.0, atol=1e-3)
    assert tp["km_m"].isna().all()  # no line_code: no km
    (s,) = r.own_tracks
    assert (s.track_id, s.points, s.posts_used) == ("X1", 6, 0) and s.length_m == pytest.approx(100.0, abs=1e-3)


def test_turnout_curve_r190_over_30_m_is_on_the_arc() -> None:
    """The diverging curve of a turnout: radius 190 m, 30 m long, turning left from heading
    east, surveyed every 0.5 m. Grid points at 0, 20, 30 m of arc lie on the analytic arc
    (within 1 cm) and the length is R·θ."""
    R, L = 190.0, 30.0
    theta = L / R
    a = np.linspace(0.0, theta, 61)
    cl = own_track(R * np.sin(a), R * (1.0 - np.cos(a)))
    r = build_grid(cl, NO_POSTS)
    assert r.findings == []
    tp = r.track_points
    np.testing.assert_allclose(tp["pos_m"], [0.0, 20.0, 30.0], atol=1e-3)
    (s,) = r.own_tracks
    assert s.length_m == pytest.approx(R * theta, abs=1e-3)  # chords 0.5 m: 9 µm short of the arc
    x, y = back_to_plane(tp)
    phi = tp["pos_m"].to_numpy() / R
    err = np.hypot(x - R * np.sin(phi), y - R * (1.0 - np.cos(phi)))
    assert err.max() < 0.01, err
    # and every point is R from the centre (0, R)
    np.testing.assert_allclose(np.hypot(x, y - R), R, atol=0.01)


def crossover(R: float = 190.0, n: float = 9.0, spacing: float = 4.5) -> tuple[np.ndarray, np.ndarray, float]:
    """A crossover between parallel tracks ``spacing`` apart: turnout curve R turning left
    by the frog angle atan(1/n), a straight, the mirrored curve back to parallel. The
    straight is what is left of the offset: 2R(1 − cos θ) + Ls·sin θ = spacing."""
    theta = math.atan(1.0 / n)
    ls = (spacing - 2.0 * R * (1.0 - math.cos(theta))) / math.sin(theta)
    total = 2.0 * R * theta + ls
    p = np.append(np.arange(0.0, total, 0.25), total)
    x, y = analytic_crossover(p, R, theta, ls)
    return x, y, total


def analytic_crossover(p: np.ndarray, R: float, theta: float, ls: float) -> tuple[np.ndarray, np.ndarray]:
    """Position at arc length ``p`` along the crossover of :func:`crossover`."""
    c1 = R * theta
    x1, y1 = R * math.sin(theta), R * (1.0 - math.cos(theta))
    x2, y2 = x1 + ls * math.cos(theta), y1 + ls * math.sin(theta)
    a1 = np.minimum(p, c1) / R
    on_straight = np.clip(p - c1, 0.0, ls)
    a2 = np.clip(p - c1 - ls, 0.0, c1) / R  # second curve turns right: heading θ − a2
    x = np.where(p <= c1, R * np.sin(a1), np.where(p <= c1 + ls, x1 + on_straight * math.cos(theta), 0.0))
    y = np.where(p <= c1, R * (1.0 - np.cos(a1)), np.where(p <= c1 + ls, y1 + on_straight * math.sin(theta), 0.0))
    # second curve: centre at the right of the heading θ, distance R
    cx, cy = x2 + R * math.sin(theta), y2 - R * math.cos(theta)
    h = theta - a2
    x = np.where(p > c1 + ls, cx - R * np.sin(h), x)
    y = np.where(p > c1 + ls, cy + R * np.cos(h), y)
    return x, y


def test_crossover_through_two_turnout_curves() -> None:
    R, n = 190.0, 9.0
    theta = math.atan(1.0 / n)
    x, y, total = crossover(R, n)
    ls = total - 2.0 * R * theta
    assert abs(y[-1] - 4.5) < 1e-9  # the analytic shape ends on the other track
    r = build_grid(own_track(x, y), NO_POSTS)
    assert r.findings == []
    tp = r.track_points
    pos = tp["pos_m"].to_numpy()
    assert pos[-1] == pytest.approx(total, abs=1e-3) and np.allclose(np.diff(pos[:-1]), 20.0)
    gx, gy = back_to_plane(tp)
    ax, ay = analytic_crossover(pos, R, theta, ls)
    assert np.hypot(gx - ax, gy - ay).max() < 0.01
    assert gy[0] == pytest.approx(0.0, abs=0.01) and gy[-1] == pytest.approx(4.5, abs=0.01)


def test_km_from_the_posts_of_its_line() -> None:
    """A straight 100 m track along x with posts 2 m beside it at x = 10 (km 5k010) and
    x = 90 (km 5k090): km = 5000 + pos, also beyond the posts (slope 1); posts the other way
    round: km = 5100 − pos."""
    cl = own_track(np.array([0.0, 100.0]), np.array([0.0, 0.0]), line_code="0420")
    r = build_grid(cl, posts([10.0, 90.0], [-2.0, -2.0], [5010.0, 5090.0]))
    assert r.findings == []
    np.testing.assert_allclose(r.track_points["km_m"], 5000.0 + r.track_points["pos_m"], atol=1e-3)
    assert r.own_tracks[0].posts_used == 2
    r = build_grid(cl, posts([10.0, 90.0], [-2.0, -2.0], [5090.0, 5010.0]))
    np.testing.assert_allclose(r.track_points["km_m"], 5100.0 - r.track_points["pos_m"], atol=1e-3)


def test_km_posts_that_do_not_run_one_way_give_a_warning_and_no_km() -> None:
    cl = own_track(np.array([0.0, 100.0]), np.array([0.0, 0.0]), line_code="0420")
    r = build_grid(cl, posts([10.0, 50.0, 90.0], [-2.0, -2.0, -2.0], [5010.0, 5090.0, 5050.0]))
    assert [f.rule for f in r.findings] == ["gisinput.track_km_order"]
    assert r.findings[0].keys["track_id"] == "X1" and r.track_points["km_m"].isna().all()


def test_lines_and_own_tracks_together_and_bad_keys() -> None:
    line = pd.DataFrame(
        {
            "line_code": "0420",
            "track": "D",
            "track_id": None,
            "seq": [1, 2],
            "lon": TO_LL.transform(np.array([0.0, 1000.0]), np.array([0.0, 0.0]))[0],
            "lat": TO_LL.transform(np.array([0.0, 1000.0]), np.array([0.0, 0.0]))[1],
            "height_m": np.nan,
        }
    )
    x1 = own_track(np.array([0.0, 100.0]), np.array([0.0, 4.5]), line_code="0420")
    kp = posts([0.0, 1000.0], [0.0, 0.0], [0.0, 1000.0])
    r = build_grid(pd.concat([line, x1], ignore_index=True), kp)
    assert r.findings == []
    assert len(r.gis) == 51 and set(r.track_points["track_id"]) == {"X1"}
    assert r.own_tracks[0].posts_used == 0 and r.track_points["km_m"].isna().all()  # one post near it: no km
    bad = pd.concat([line, x1.assign(track_id=None, line_code=None)], ignore_index=True)
    r = build_grid(bad, kp)
    assert {f.rule for f in r.findings} == {"gisinput.centreline_key"} and len(r.findings) == 2
    assert r.track_points.empty and len(r.gis) == 51


def test_track_id_with_two_lines_is_an_error() -> None:
    cl = own_track(np.array([0.0, 50.0, 100.0]), np.zeros(3)).assign(line_code=["0420", "0420", "0999"])
    r = build_grid(cl, NO_POSTS)
    assert [f.rule for f in r.findings] == ["gisinput.track_lines"] and r.track_points.empty


def write_inputs(tmp_path: Path) -> tuple[Path, Path]:
    x, y, _ = crossover()
    cl = pd.concat(
        [
            own_track(np.array([-200.0, 300.0]), np.zeros(2), "D").assign(track="D", track_id=None, line_code="0420"),
            own_track(x, y, "X1", line_code="0420"),
        ],
        ignore_index=True,
    )
    cp, pp = tmp_path / "centrelines.csv", tmp_path / "kmposts.csv"
    cl.to_csv(cp, index=False)
    posts([-200.0, 10.0, 50.0, 300.0], [0.0] * 4, [0.0, 210.0, 250.0, 500.0]).to_csv(pp, index=False)
    return cp, pp


def test_files_and_cli(tmp_path: Path) -> None:
    cp, pp = write_inputs(tmp_path)
    out = tmp_path / "src" / "gis.csv"
    r = CliRunner().invoke(app, ["gis", "grid", str(cp), "--posts", str(pp), "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "track_points" in r.output and "X1" in r.output
    tp = pd.read_csv(out.parent / "track_points.csv")
    assert list(tp.columns) == TRACK_POINTS.column_names and set(tp["track_id"]) == {"X1"}
    # km from the posts of line 0420 that lie within 50 m of X1 (x = 10 and 50: km = 200 + x)
    gx, _ = back_to_plane(tp)
    np.testing.assert_allclose(tp["km_m"], 200.0 + gx, atol=0.35)  # s vs x: cos(6.3°) over ≤ 60 m
    assert sorted(p.name for p in out.parent.iterdir()) == ["gis.csv", "track_points.csv"]
    with pytest.raises(RefusedError):
        grid_files(cp, pp, out)
    (out.parent / "gis.csv").unlink()
    with pytest.raises(RefusedError, match=r"track_points\.csv exists"):
        grid_files(cp, pp, out)
    assert grid_files(cp, pp, out, force=True).track_points_path == out.parent / "track_points.csv"


def test_a_row_without_a_key_stops_the_files(tmp_path: Path) -> None:
    cp, pp = write_inputs(tmp_path)
    cl = pd.read_csv(cp, dtype=str)
    cl.loc[3, "track_id"] = None
    cl.to_csv(cp, index=False)
    with pytest.raises(FindingsError) as exc:
        grid_files(cp, pp, tmp_path / "out" / "gis.csv")
    (f,) = [f for f in exc.value.findings if f.rule == "gisinput.centreline_key"]
    assert f.row == 5 and "line_code and track" in f.message and not (tmp_path / "out").exists()


def test_geojson_track_id_property(tmp_path: Path) -> None:
    """A GeoJSON LineString with a track_id property is a track of its own."""
    import json

    a = np.linspace(0.0, 30.0 / 190.0, 31)
    lon, lat = TO_LL.transform(190.0 * np.sin(a), 190.0 * (1.0 - np.cos(a)))
    dlon, dlat = TO_LL.transform(np.array([-200.0, 300.0]), np.zeros(2))
    features = [
        {
            "type": "Feature",
            "properties": {"line_code": "0420", "track": "D"},
            "geometry": {
                "type": "LineString",
                "coordinates": [[float(o), float(t)] for o, t in zip(dlon, dlat, strict=True)],
            },
        },
        {
            "type": "Feature",
            "properties": {"track_id": "T1-curve"},
            "geometry": {
                "type": "LineString",
                "coordinates": [[float(o), float(t)] for o, t in zip(lon, lat, strict=True)],
            },
        },
    ]
    cp, pp = tmp_path / "centrelines.geojson", tmp_path / "kmposts.csv"
    cp.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    posts([-200.0, 300.0], [0.0, 0.0], [0.0, 500.0]).to_csv(pp, index=False)
    written = grid_files(cp, pp, tmp_path / "src" / "gis.csv")
    tp = written.result.track_points
    assert tp["track_id"].tolist() == ["T1-curve"] * 3 and tp["pos_m"].tolist() == pytest.approx([0.0, 20.0, 30.0])
    assert len(written.result.gis) == 26 and written.track_points_path is not None


def test_grid_to_db_to_topology(tmp_path: Path) -> None:
    """``gis grid`` → a source set with tracks.csv → ``db build``: the crossover's
    centreline in the DB (dbtools.topology.centreline) is its track_points."""
    from dbtools.build import build_db
    from dbtools.diff import load_network
    from dbtools.topology import all_tracks, centreline

    cp, pp = write_inputs(tmp_path)
    src = tmp_path / "src"
    written = grid_files(cp, pp, src / "gis.csv")
    x1 = written.result.own_tracks[0]
    pd.DataFrame(
        [
            {"track_id": "D", "line_code": "0420", "track": "D", "kind": "main", "km_begin_m": 0.0, "km_end_m": 500.0},
            {
                "track_id": "X1",
                "line_code": None,
                "track": None,
                "kind": "crossover",
                "km_begin_m": None,
                "km_end_m": None,
            },
        ]
    ).assign(length_m=[500.0, round(x1.length_m, 3)]).to_csv(src / "tracks.csv", index=False)
    pd.DataFrame({"line_code": ["0420"], "name": ["test line"]}).to_csv(src / "lines.csv", index=False)
    for table in (BALISES, FEATURE_POINTS):  # required files, empty here
        pd.DataFrame(columns=table.column_names).to_csv(src / f"{table.name}.csv", index=False)
    db = tmp_path / "net.sqlite"
    build_db(src, db, db_version="t")
    net, _ = load_network(db)
    tracks = all_tracks(net)
    cl = centreline(net, tracks[tracks["track_id"] == "X1"].iloc[0])
    assert cl.pos_m[-1] == pytest.approx(x1.length_m, abs=1e-3) and cl.pos_m.size == x1.points
    np.testing.assert_allclose(cl.lat, written.result.track_points["lat"], atol=1e-9)
