"""The bundled sample network (Kawagoe Line): builds cleanly, is what it claims to be, and
its GIS grid is exactly what ``gis grid`` makes of its packaged survey."""

from __future__ import annotations

import json
import tomllib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.build import build_db
from dbtools.gis.geometry import GEOD, Projector
from dbtools.sample_network import PACKAGE_DIR, sample_raw_dir, sample_source_dir, sample_survey_dir
from fieldlogs.simulate.networks.sample_fit import project_brute
from schemas.enums import Severity

REPORT = json.loads((PACKAGE_DIR / "fit_report.json").read_text(encoding="utf-8"))


def read(name: str) -> pd.DataFrame:
    return pd.read_csv(sample_source_dir() / f"{name}.csv", dtype={"line_code": str, "station_code": str})


def test_sample_builds_and_validates_cleanly(tmp_path: Path) -> None:
    from dbtools.validate import validate_path

    result = build_db(sample_source_dir(), tmp_path / "sample.sqlite", db_version="test")
    assert result.warnings == []
    assert result.rows["lines"] == 1
    errors = [f for f in validate_path(tmp_path / "sample.sqlite") if f.severity == Severity.ERROR]
    assert errors == []


def test_gis_two_tracks_every_20_m_3_8_m_apart() -> None:
    gis = read("gis")
    assert set(gis["line_code"]) == {"0420"} and set(gis["track"]) == {"D", "U"}
    by_track = {t: g.sort_values("km_m").reset_index(drop=True) for t, g in gis.groupby("track")}
    d, u = by_track["D"], by_track["U"]
    for g in (d, u):
        assert (np.diff(g["km_m"]) == 20.0).all()
        _, _, step = GEOD.inv(g["lon"][:-1], g["lat"][:-1], g["lon"][1:], g["lat"][1:])
        np.testing.assert_allclose(step, 20.0, rtol=0.01)  # inner/outer track in curves: ≤ 20·3.8/2/295 m
        assert g["height_m"].notna().all()
    np.testing.assert_array_equal(d["km_m"], u["km_m"])
    assert (d["km_m"].iloc[0], d["km_m"].iloc[-1]) == (REPORT["km0_m"], REPORT["km_end_m"])
    _, _, apart = GEOD.inv(d["lon"], d["lat"], u["lon"], u["lat"])
    np.testing.assert_allclose(apart, 3.8, atol=0.01)
    grade = np.diff(d["height_m"]) / 20.0
    assert np.max(np.abs(grade)) <= 0.015 + 1e-3


def test_feature_points_at_the_fitted_curves() -> None:
    fp = read("feature_points")
    for _, g in fp.groupby("track"):
        assert g["feature_id"].nunique() >= 5
        assert (g.groupby("feature_id").size() == 6).all()
    radii = fp.loc[fp["radius_m"] > 0, "radius_m"]
    assert 250 < radii.min() and radii.max() < 2000
    # every fitted curve with room for its straight checks has a feature point
    assert fp["feature_id"].nunique() == len(REPORT["curves"])


def test_balises_at_all_six_real_stations() -> None:
    b = read("balises")
    pairs = b[b["kind"].isin(["I1", "I2"])]
    assert sorted(pairs["station_code"].unique()) == ["01", "02", "03", "04", "05", "06"]
    both = pairs.groupby("station_code")["track"].nunique()
    assert (both[["02", "03", "04", "05"]] == 2).all()  # the line's ends: pairs inside the grid only
    shifted = b[b["km_equipment_m"] != b["km_actual_m"]]
    assert len(shifted) > 0
    np.testing.assert_allclose(shifted["km_equipment_m"] - shifted["km_actual_m"], REPORT["realigned"]["shift_m"])
    names = [s["name"] for s in REPORT["stations"]]
    assert names == ["Kawagoe", "Nishi-Kawagoe", "Matoba", "Kasahata", "Musashi-Takahagi", "Komagawa"]
    assert REPORT["stations"][0]["km_m"] == 16100.0
    assert read("lines")["name"].tolist() == ["Kawagoe Line (sample)"]


def test_fitted_centreline_within_reported_tolerance_of_the_raw_vertices() -> None:
    raw = pd.read_csv(sample_raw_dir() / "kawagoe_line.csv").sort_values("seq")
    assert len(raw) == REPORT["vertices"] == 127
    cl = pd.read_csv(sample_survey_dir() / "centrelines.csv", dtype={"line_code": str})
    d = cl[cl["track"] == "D"].sort_values("seq")
    u = cl[cl["track"] == "U"].sort_values("seq")
    proj = Projector(REPORT["zone"])
    dx, dy = proj.to_xy(d["lon"].to_numpy(), d["lat"].to_numpy())
    ux, uy = proj.to_xy(u["lon"].to_numpy(), u["lat"].to_numpy())
    cx, cy = (dx + ux) / 2, (dy + uy) / 2  # the line centre, midway between the tracks
    cs = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(cx), np.diff(cy)))])
    rx, ry = proj.to_xy(raw["lon"].to_numpy(), raw["lat"].to_numpy())
    s, off = project_brute(rx, ry, cs, cx, cy)
    inside = (s > 1e-6) & (s < cs[-1] - 1e-6)
    assert inside.sum() == REPORT["vertices_inside"]
    rms = float(np.sqrt(np.mean(off[inside] ** 2)))
    assert rms == pytest.approx(REPORT["deviation_rms_m"], abs=0.05)
    assert np.max(np.abs(off[inside])) == pytest.approx(REPORT["deviation_max_m"], abs=0.05)
    assert REPORT["deviation_rms_m"] < 5.0 and REPORT["deviation_max_m"] < 10.0


def test_gis_grid_on_the_packaged_survey_reproduces_sources_gis(tmp_path: Path) -> None:
    out = tmp_path / "gis.csv"
    survey = sample_survey_dir()
    r = CliRunner().invoke(
        app,
        ["gis", "grid", str(survey / "centrelines.csv"), "--posts", str(survey / "kmposts.csv"), "--out", str(out)],
    )
    assert r.exit_code == 0, r.output
    assert not (tmp_path / "km_breaks.csv").exists()
    if out.read_text() != (sample_source_dir() / "gis.csv").read_text():  # same bytes on the same PROJ
        got, want = pd.read_csv(out, dtype={"line_code": str}), read("gis")
        pd.testing.assert_frame_equal(got, want, check_exact=False, atol=2e-9, rtol=0)


def test_packaged_files_are_package_data() -> None:
    cfg = tomllib.loads((Path(__file__).parents[2] / "pyproject.toml").read_text())
    patterns = cfg["tool"]["setuptools"]["package-data"]["dbtools.sample_network"]
    for folder, names in (
        ("sources", ["gis", "balises", "feature_points", "lines"]),
        ("survey", ["centrelines", "kmposts"]),
        ("raw", ["kawagoe_line", "kawagoe_stations"]),
    ):
        assert f"{folder}/*.csv" in patterns
        for n in names:
            assert (PACKAGE_DIR / folder / f"{n}.csv").is_file()
    assert (PACKAGE_DIR / "SOURCE.md").is_file()
