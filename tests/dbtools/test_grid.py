"""``gis grid``: hand-computed grids from straight lines, breaks, bad inputs, and the
round trip synthetic alignment → dense survey → grid → :func:`synthetic.gis_grid`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from dbtools.gis.geometry import GEOD, Projector
from dbtools.gis.grid import build_grid
from dbtools.gis.io import grid_files, read_centrelines
from fieldlogs.simulate.networks.survey import centreline_vertices, km_posts
from fieldlogs.simulate.networks.synthetic import demo_line, gis_grid
from schemas.errors import FindingsError, InputError, RefusedError

LON0, LAT0 = 139.4, 35.9
#: Longitude 1000 m east of LON0 along the parallel LAT0.
LON1 = float(GEOD.fwd(LON0, LAT0, 90.0, 1000.0)[0])


def east(metres: float | np.ndarray) -> np.ndarray:
    """Longitude ``metres`` east of LON0 along the parallel (linear: < 1 mm over 1 km)."""
    return LON0 + (LON1 - LON0) * np.asarray(metres, dtype=float) / 1000.0


def line(track: str = "D", lons: list[float] | None = None, heights: list[float] | None = None) -> pd.DataFrame:
    lons = lons if lons is not None else [LON0, LON1]
    n = len(lons)
    return pd.DataFrame(
        {
            "line_code": "0420",
            "track": track,
            "seq": np.arange(1, n + 1),
            "lon": lons,
            "lat": LAT0,
            "height_m": heights if heights is not None else [np.nan] * n,
        }
    )


def posts(
    at_m: list[float], km: list[float], km_after: list[float] | None = None, north_m: float = 0.0
) -> pd.DataFrame:
    lat = LAT0 + north_m / 111_000.0
    return pd.DataFrame(
        {
            "line_code": "0420",
            "km_m": km,
            "lon": east(at_m),
            "lat": lat,
            "km_after_m": km_after if km_after is not None else [np.nan] * len(km),
        }
    )


def spacing(g: pd.DataFrame) -> np.ndarray:
    _, _, d = GEOD.inv(
        g["lon"].to_numpy()[:-1], g["lat"].to_numpy()[:-1], g["lon"].to_numpy()[1:], g["lat"].to_numpy()[1:]
    )
    return np.asarray(d)


def test_straight_line_posts_at_both_ends() -> None:
    r = build_grid(line(), posts([0.0, 1000.0], [0.0, 1000.0]))
    assert r.findings == []
    g = r.gis
    assert len(g) == 51
    np.testing.assert_array_equal(g["km_m"], np.arange(0.0, 1001.0, 20.0))
    assert np.ptp(g["lat"]) < 1e-6  # ~0.1 m: the chord of a parallel bulges 14 mm
    np.testing.assert_allclose(spacing(g), 20.0, atol=1e-3)
    assert g["lon"].iloc[0] == pytest.approx(LON0, abs=1e-9)
    assert g["lon"].iloc[-1] == pytest.approx(LON1, abs=1e-9)
    assert g["height_m"].isna().all()
    assert r.zones == {"0420": 9}


def test_km_origin_from_the_first_post() -> None:
    g = build_grid(line(), posts([0.0, 1000.0], [1000.0, 2000.0])).gis
    assert g["km_m"].iloc[0] == 1000.0 and g["km_m"].iloc[-1] == 2000.0
    assert g["lon"].iloc[0] == pytest.approx(LON0, abs=1e-9)


def test_single_post_extrapolates_with_slope_one() -> None:
    g = build_grid(line(), posts([500.0], [5005.0])).gis
    # km 4505 … 5505 on the line: grid 4520 … 5500, the 4520 point 15 m from the west end
    np.testing.assert_array_equal(g["km_m"], np.arange(4520.0, 5501.0, 20.0))
    _, _, d = GEOD.inv(LON0, LAT0, g["lon"].iloc[0], g["lat"].iloc[0])
    assert d == pytest.approx(15.0, abs=1e-3)


def test_post_beside_the_line_is_projected() -> None:
    on = build_grid(line(), posts([0.0, 1000.0], [0.0, 1000.0])).gis
    off = build_grid(line(), posts([0.0, 1000.0], [0.0, 1000.0], north_m=12.0))
    assert off.findings == []
    assert off.tracks[0].post_offset_m == pytest.approx(12.0, abs=0.05)  # left of eastward = north
    np.testing.assert_allclose(off.gis["lon"], on["lon"], atol=1e-9)


def test_break_multiple_of_20() -> None:
    r = build_grid(line(), posts([0.0, 500.0, 1000.0], [0.0, 500.0, 1100.0], [np.nan, 600.0, np.nan]))
    assert r.findings == []
    km = r.gis["km_m"].to_numpy()
    np.testing.assert_array_equal(km, np.r_[np.arange(0.0, 501.0, 20.0), np.arange(600.0, 1101.0, 20.0)])
    assert r.km_breaks[["km_from_m", "km_to_m"]].values.tolist() == [[500.0, 600.0]]
    at = r.gis.set_index("km_m")
    _, _, d = GEOD.inv(at.loc[500.0, "lon"], at.loc[500.0, "lat"], at.loc[600.0, "lon"], at.loc[600.0, "lat"])
    assert d < 1e-3  # both kilometrages of the break post name the same place
    assert r.tracks[0].breaks == 1


def test_break_between_grid_points() -> None:
    # km 0 → 505 over the first 500 m, then 613 → 1113 over the next 500 m
    r = build_grid(line(), posts([0.0, 500.0, 1000.0], [0.0, 505.0, 1113.0], [np.nan, 613.0, np.nan]))
    assert r.km_breaks[["km_from_m", "km_to_m"]].values.tolist() == [[500.0, 620.0]]
    at = r.gis.set_index("km_m")
    _, _, d500 = GEOD.inv(LON0, LAT0, at.loc[500.0, "lon"], at.loc[500.0, "lat"])
    _, _, d620 = GEOD.inv(LON0, LAT0, at.loc[620.0, "lon"], at.loc[620.0, "lat"])
    assert d500 == pytest.approx(500.0 * 500.0 / 505.0, abs=1e-3)
    assert d620 == pytest.approx(507.0, abs=1e-3)


def test_polyline_drawn_from_high_km_is_reversed() -> None:
    fwd = build_grid(line(), posts([0.0, 1000.0], [0.0, 1000.0])).gis
    back = build_grid(line(lons=[LON1, LON0]), posts([0.0, 1000.0], [0.0, 1000.0]))
    assert back.tracks[0].reversed
    pd.testing.assert_frame_equal(back.gis, fwd)


def test_heights_interpolated() -> None:
    g = build_grid(line(heights=[10.0, 20.0]), posts([0.0, 1000.0], [0.0, 1000.0])).gis
    assert g.set_index("km_m").loc[500.0, "height_m"] == pytest.approx(15.0, abs=1e-3)


def test_both_tracks_share_the_posts() -> None:
    north = LAT0 + 3.8 / 111_000.0
    cl = pd.concat([line("D").assign(lat=north), line("U")], ignore_index=True)  # trains keep left
    r = build_grid(cl, posts([0.0, 1000.0], [0.0, 1000.0], north_m=1.9))
    assert r.findings == []
    assert sorted(t.track for t in r.tracks) == ["D", "U"]
    offsets = {t.track: t.post_offset_m for t in r.tracks}  # posts on the line centre, between the tracks
    assert offsets["D"] == pytest.approx(-1.9, abs=0.01) and offsets["U"] == pytest.approx(1.9, abs=0.01)
    assert (r.gis.groupby("track").size() == 51).all()


@pytest.mark.parametrize(
    ("kw", "rule"),
    [
        ({"at_m": [0.0, 500.0, 1000.0], "km": [0.0, 700.0, 600.0]}, "gisinput.km_order"),
        ({"at_m": [0.0, 1000.0], "km": [0.0, 1000.0], "north_m": 80.0}, "gisinput.post_off_track"),
        (
            {"at_m": [0.0, 500.0, 1000.0], "km": [0.0, 500.0, 1000.0], "km_after": [np.nan, 400.0, np.nan]},
            "gisinput.break_backwards",
        ),
        ({"at_m": [0.0, 1000.0], "km": [0.0, 1200.0]}, "gisinput.post_spacing"),
    ],
)
def test_post_problems(kw: dict[str, object], rule: str) -> None:
    r = build_grid(line(), posts(**kw))  # type: ignore[arg-type]
    assert rule in {f.rule for f in r.findings}


def test_post_of_unknown_line_and_track_without_posts() -> None:
    p = posts([0.0, 1000.0], [0.0, 1000.0]).assign(line_code="0999")
    rules = {f.rule for f in build_grid(line(), p).findings}
    assert {"gisinput.unknown_line", "gisinput.no_posts"} <= rules


def test_post_beyond_the_track_end_is_not_used() -> None:
    # a post 100 m past the east end lies on the line's extension: not used, and reported
    r = build_grid(line(), posts([0.0, 1000.0, 1100.0], [0.0, 1000.0, 1100.0]))
    assert [f.rule for f in r.findings] == ["gisinput.post_off_track"]


# -- files ---------------------------------------------------------------------------------


def write_inputs(tmp_path: Path, cl: pd.DataFrame | None = None, kp: pd.DataFrame | None = None) -> tuple[Path, Path]:
    cp, pp = tmp_path / "centrelines.csv", tmp_path / "kmposts.csv"
    (line() if cl is None else cl).to_csv(cp, index=False)
    (posts([0.0, 1000.0], [0.0, 1000.0]) if kp is None else kp).to_csv(pp, index=False)
    return cp, pp


def test_grid_files_writes_gis_format_atomically(tmp_path: Path) -> None:
    cp, pp = write_inputs(tmp_path)
    out = tmp_path / "src" / "gis.csv"
    written = grid_files(cp, pp, out)
    assert out.read_text().splitlines()[0] == "line_code,track,km_m,lat,lon,height_m"
    back = pd.read_csv(out, dtype={"line_code": str})
    assert len(back) == 51 and back["line_code"].iloc[0] == "0420"
    assert written.km_breaks_path is None and not (out.parent / "km_breaks.csv").exists()
    assert [p.name for p in out.parent.iterdir()] == ["gis.csv"]  # no temp files left
    with pytest.raises(RefusedError):
        grid_files(cp, pp, out)
    grid_files(cp, pp, out, force=True)


def test_grid_files_writes_km_breaks_beside_the_output(tmp_path: Path) -> None:
    kp = posts([0.0, 500.0, 1000.0], [0.0, 500.0, 1100.0], [np.nan, 600.0, np.nan])
    kp["km_m"] = ["0k000", "0k500", "1k100"]  # railway notation is accepted
    cp, pp = write_inputs(tmp_path, kp=kp)
    out = tmp_path / "src" / "gis.csv"
    written = grid_files(cp, pp, out)
    assert written.km_breaks_path == out.parent / "km_breaks.csv"
    kb = pd.read_csv(written.km_breaks_path, dtype={"line_code": str})
    assert kb.to_dict("records") == [{"line_code": "0420", "track": "D", "km_from_m": 500.0, "km_to_m": 600.0}]
    # the breaks go away: the stale file is removed only with --force
    cp, pp = write_inputs(tmp_path)
    with pytest.raises(RefusedError):
        grid_files(cp, pp, out)
    assert grid_files(cp, pp, out, force=True).removed_stale == out.parent / "km_breaks.csv"


def test_output_must_not_overwrite_an_input(tmp_path: Path) -> None:
    cp, pp = write_inputs(tmp_path)
    with pytest.raises(RefusedError):
        grid_files(cp, pp, pp, force=True)


def findings_of(tmp_path: Path, cl: pd.DataFrame | None = None, kp: pd.DataFrame | None = None) -> list:
    cp, pp = write_inputs(tmp_path, cl, kp)
    with pytest.raises(FindingsError) as exc:
        grid_files(cp, pp, tmp_path / "out" / "gis.csv")
    assert not (tmp_path / "out").exists()  # nothing written
    return exc.value.findings


def test_missing_column(tmp_path: Path) -> None:
    fs = findings_of(tmp_path, cl=line().drop(columns=["seq"]))
    assert [(f.rule, f.column) for f in fs if f.severity == "error"] == [("schema.missing_column", "seq")]


def test_misspelled_column_gets_a_suggestion(tmp_path: Path) -> None:
    fs = findings_of(tmp_path, kp=posts([0.0, 1000.0], [0.0, 1000.0]).rename(columns={"lon": "lng"}))
    missing = next(f for f in fs if f.rule == "schema.missing_column")
    assert missing.column == "lon" and "'lng'" in missing.message and "misspelled" in missing.message
    assert str(missing.file).endswith("kmposts.csv")


def test_text_in_lon_names_file_row_and_column(tmp_path: Path) -> None:
    cl = line().astype({"lon": object})
    cl.loc[1, "lon"] = "139.4x"
    fs = findings_of(tmp_path, cl=cl)
    f = next(f for f in fs if f.rule == "schema.type")
    assert (f.row, f.column, f.value) == (3, "lon", "139.4x")
    assert str(f.file).endswith("centrelines.csv")


def test_unknown_track(tmp_path: Path) -> None:
    fs = findings_of(tmp_path, cl=line(track="X"))
    f = next(f for f in fs if f.rule == "schema.enum")
    assert f.column == "track" and f.row == 2 and "U, D, S" in f.message


def test_post_far_from_track_names_its_row(tmp_path: Path) -> None:
    kp = posts([0.0, 1000.0], [0.0, 1000.0])
    kp.loc[1, "lat"] = LAT0 + 0.01  # 1.1 km north
    f = next(f for f in findings_of(tmp_path, kp=kp) if f.rule == "gisinput.post_off_track")
    assert f.row == 3 and str(f.file).endswith("kmposts.csv") and f.severity == "error"


def test_unreadable_inputs(tmp_path: Path) -> None:
    _, pp = write_inputs(tmp_path)
    with pytest.raises(InputError):
        grid_files(tmp_path / "nope.csv", pp, tmp_path / "gis.csv")
    bad = tmp_path / "bad.geojson"
    bad.write_text("{not json")
    with pytest.raises(InputError):
        grid_files(bad, pp, tmp_path / "gis.csv")


def geojson(cl: pd.DataFrame) -> dict[str, object]:
    feats = []
    for (code, track), g in cl.groupby(["line_code", "track"]):
        coords = [[lon, lat, h] for lon, lat, h in zip(g["lon"], g["lat"], g["height_m"], strict=True)]
        feats.append(
            {
                "type": "Feature",
                "properties": {"line_code": code, "track": track},
                "geometry": {"type": "LineString", "coordinates": coords},
            }
        )
    return {"type": "FeatureCollection", "features": feats}


def test_geojson_centrelines_give_the_same_grid(tmp_path: Path) -> None:
    cl = line(heights=[10.0, 20.0])
    cp, pp = write_inputs(tmp_path, cl=cl)
    gj = tmp_path / "centrelines.geojson"
    gj.write_text(json.dumps(geojson(cl)))
    a = grid_files(cp, pp, tmp_path / "a" / "gis.csv")
    b = grid_files(gj, pp, tmp_path / "b" / "gis.csv")
    assert (tmp_path / "a" / "gis.csv").read_text() == (tmp_path / "b" / "gis.csv").read_text()
    assert a.result.tracks == b.result.tracks


def test_geojson_problems_are_located_by_feature(tmp_path: Path) -> None:
    data = geojson(line())
    data["features"][0]["geometry"]["coordinates"][1][0] = "east"  # type: ignore[index]
    data["features"].append({"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [0, 0]}})  # type: ignore[attr-defined]
    gj = tmp_path / "c.geojson"
    gj.write_text(json.dumps(data))
    read = read_centrelines(gj)
    msgs = {f.rule: f.message for f in read.findings}
    assert msgs["schema.type"].startswith("feature 1, vertex 2:")
    assert "Point" in msgs["gisinput.geometry"]


# -- round trip ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("epsg", "x0", "y0"), [(6677, 0.0, 0.0), (32632, 500_000.0, 5_000_000.0), (32756, 330_000.0, 6_250_000.0)]
)
def test_round_trip_synthetic_alignment(epsg: int, x0: float, y0: float) -> None:
    """Dense survey (5 m vertices, posts every km on the line centre) → grid ≈ gis_grid, in
    Japan and (the survey's derived UTM zone) in Italy and Australia."""
    spec, projector = demo_line(x0=x0, y0=y0), Projector.from_epsg(epsg)
    a = spec.alignment
    kms = np.unique(np.r_[a.km0, np.arange(np.ceil(a.km0 / 1000.0) * 1000.0, a.km_end, 1000.0), a.km_end])
    r = build_grid(centreline_vertices(spec, projector, 5.0), km_posts(spec, projector, kms))
    assert r.findings == []
    assert set(r.zones.values()) == ({9} if epsg == 6677 else {0}) and r.epsg == epsg
    want = gis_grid(spec, projector)
    got = want.merge(r.gis, on=["line_code", "track", "km_m"], how="outer", suffixes=("", "_grid"), indicator=True)
    assert (got["_merge"] == "both").all()  # the same kms on both tracks
    _, _, err = GEOD.inv(got["lon"], got["lat"], got["lon_grid"], got["lat_grid"])
    assert np.max(err) < 0.05
    assert np.max(np.abs(got["height_m"] - got["height_m_grid"])) < 0.01
