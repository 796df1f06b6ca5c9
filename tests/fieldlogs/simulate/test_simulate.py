"""``trainpos simulate``: CLI, scenario files, run folders and the sample-run generator."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.atomic import MARKER
from dbtools.build import build_db
from dbtools.gis.geometry import PolylineIndex, Projector
from dbtools.gis.georef import projector_for_points
from dbtools.sources import write_source_set
from fieldlogs.quality.checks import check_run, load_db_refs
from fieldlogs.runs.handle import read_run
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.samples import make_sample_runs
from fieldlogs.simulate.scenario import DEFAULT_SCENARIO, Scenario, ScenarioError, load_scenario, scenario_from_dict


@pytest.fixture(scope="module")
def demo_db(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("demo")
    write_source_set(build_network([demo_line()], Projector(9)), root / "src")
    build_db(root / "src", root / "net.sqlite", db_version="2026.01-test")
    return root / "net.sqlite"


def invoke(*args: str) -> object:
    return CliRunner().invoke(app, [str(a) for a in args])


def test_cli_writes_a_readable_run(demo_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    res = invoke("simulate", "--db", demo_db, "--out", out, "--seed", "5")
    assert res.exit_code == 0, res.output
    assert "SIM-0900-D-5" in res.output
    run = read_run(out)
    assert run.meta is not None
    assert run.meta.db_version == "2026.01-test"
    assert run.meta.start_time.endswith("+09:00")
    assert run.meta.vehicle_kind == "train" and run.meta.wheel_diameter_m == 0.86 and run.meta.teeth == 90
    assert set(run.streams_present()) == {"tacho", "imu", "balise", "gps", "cab", "truth"}
    assert all(p.suffix == ".parquet" for p in out.iterdir() if p.name not in ("run.json", MARKER))
    streams = run.load_all()
    assert run.findings == []
    st = run.raw_json["sim_truth"]
    assert st["seed"] == 5 and len(st["slip_episodes"]) == 4
    assert 0.86 * 0.995 <= st["wheel_diameter_true_m"] <= 0.86
    assert streams["imu"]["t"].diff().dropna().round(6).eq(0.01).all()
    assert streams["tacho"]["pulses"].is_monotonic_increasing


def test_cli_csv_force_and_refusal(demo_db: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    scen = tmp_path / "short.toml"
    scen.write_text('[route]\ntrack = "U"\npath_km_m = [9000, 7000]\n[sensors]\nradar = true\n', encoding="utf-8")
    res = invoke("simulate", "--db", demo_db, "--out", out, "--scenario", scen, "--format", "csv")
    assert res.exit_code == 0, res.output
    assert (out / "imu.csv").is_file() and (out / "radar.csv").is_file()
    truth = read_run(out).stream("truth")
    assert truth is not None and truth["km_m"].iloc[-1] == pytest.approx(7000.0, abs=0.01)
    res = invoke("simulate", "--db", demo_db, "--out", out, "--scenario", scen)
    assert res.exit_code == 3
    assert "--force" in res.stderr
    res = invoke("simulate", "--db", demo_db, "--out", out, "--scenario", scen, "--force")
    assert res.exit_code == 0
    assert (out / "imu.parquet").is_file() and not (out / "imu.csv").exists()


@pytest.mark.parametrize(
    ("text", "key", "what"),
    [
        ('[route]\nlin_code = "0900"\n', "route.lin_code", "did you mean 'line_code'"),
        ('[running]\nline_speed_kmh = "fast"\n', "running.line_speed_kmh", "expected a number"),
        ("[slip]\nslips = 1.5\n", "slip.slips", "expected an integer"),
        ("[gps]\noutages_km_m = [[1, 2, 3]]\n", "gps.outages_km_m[0]", "expected an array of 2 numbers"),
        ("[sensors]\nimu = 1\n", "sensors.imu", "expected true or false"),
        ("[tunnel]\nkm = 1\n", "tunnel", "unknown key"),
        ('[run]\nstart_time = "2026-01-15T10:00:00"\n', "run.start_time", "offset"),
        ("[slip]\ndepth = [0.5, 0.2]\n", "slip.depth", "low ≤ high"),
        ('[[slip.episodes]]\nt0_s = 5\nduration_s = 2\nkind = "spin"\ndepth = 0.2\n', "slip.episodes[0].kind", "slip"),
    ],
)
def test_bad_scenario_names_file_and_key(demo_db: Path, tmp_path: Path, text: str, key: str, what: str) -> None:
    scen = tmp_path / "bad.toml"
    scen.write_text(text, encoding="utf-8")
    res = invoke("simulate", "--db", demo_db, "--out", tmp_path / "run", "--scenario", scen)
    assert res.exit_code == 2, res.output
    err = " ".join(res.stderr.split())
    assert "bad.toml" in err and f"key '{key}'" in err and what in err
    assert "Traceback" not in res.output
    assert not (tmp_path / "run").exists()


def test_invalid_toml_and_missing_scenario(demo_db: Path, tmp_path: Path) -> None:
    scen = tmp_path / "broken.toml"
    scen.write_text("[route\n", encoding="utf-8")
    res = invoke("simulate", "--db", demo_db, "--out", tmp_path / "r", "--scenario", scen)
    assert res.exit_code == 2 and "not valid TOML" in res.stderr
    res = invoke("simulate", "--db", demo_db, "--out", tmp_path / "r", "--scenario", tmp_path / "none.toml")
    assert res.exit_code == 2 and "no such scenario file" in res.stderr


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--line", "9999"], "line '9999' is not in the DB"),
        (["--line", "0900", "--track", "S"], "line '0900' has no track 'S'"),
        (["--track", "X"], "must be U, D, S"),
    ],
)
def test_unknown_line_or_track(demo_db: Path, tmp_path: Path, args: list[str], message: str) -> None:
    res = invoke("simulate", "--db", demo_db, "--out", tmp_path / "run", *args)
    assert res.exit_code == 2, res.output
    assert message in " ".join(res.stderr.split())


def test_path_outside_the_gis_range(demo_db: Path, tmp_path: Path) -> None:
    scen = tmp_path / "far.toml"
    scen.write_text("[route]\npath_km_m = [2000, 50000]\n", encoding="utf-8")
    res = invoke("simulate", "--db", demo_db, "--out", tmp_path / "run", "--scenario", scen)
    assert res.exit_code == 2
    assert "key 'route.path_km_m'" in res.stderr and "outside the GIS range" in " ".join(res.stderr.split())


def test_unreadable_db(tmp_path: Path) -> None:
    bad = tmp_path / "x.sqlite"
    bad.write_text("not a db", encoding="utf-8")
    res = invoke("simulate", "--db", bad, "--out", tmp_path / "run")
    assert res.exit_code == 2 and "not an SQLite database" in res.stderr


def test_help_has_example() -> None:
    res = invoke("simulate", "--help")
    assert res.exit_code == 0 and "Example: trainpos simulate" in res.output


# -- scenario file -------------------------------------------------------------------------
def test_default_toml_matches_the_dataclasses_and_documents_every_knob() -> None:
    assert load_scenario() == Scenario()
    lines = DEFAULT_SCENARIO.read_text(encoding="utf-8").splitlines()
    for i, line in enumerate(lines):
        stripped = line.strip()
        if stripped and not stripped.startswith(("#", "[")) and "=" in stripped:
            assert "#" in line, f"default.toml line {i + 1} has no comment: {line}"


def test_scenario_from_dict_errors_and_overrides() -> None:
    s = scenario_from_dict(
        {"route": {"track": "U"}, "slip": {"episodes": [{"t0_s": 1, "duration_s": 2, "kind": "slide", "depth": 0.2}]}}
    )
    assert s.route.track == "U" and s.slip.episodes[0].kind == "slide" and s.slip.episodes[0].t0_s == 1.0
    assert s.running == Scenario().running
    with pytest.raises(ScenarioError) as exc:
        scenario_from_dict({"slip": {"episodes": [{"t0_s": 1, "kind": "slip", "depth": 0.2}]}}, source="x.toml")
    assert "x.toml, key 'slip.episodes[0].duration_s'" in str(exc.value)
    with pytest.raises(ScenarioError, match="key 'seed'"):
        scenario_from_dict({"seed": True})


# -- sample runs ---------------------------------------------------------------------------
def test_make_sample_runs(demo_db: Path, tmp_path: Path) -> None:
    folders = make_sample_runs(demo_db, tmp_path / "samples")
    names = [p.name for p in folders]
    assert names == ["sim-d-slips", "sim-u-tunnel", "sim-d-reversal", "sim-d-evening", "sim-u-evening", "sim-road-rail"]
    total = sum(f.stat().st_size for p in folders for f in p.iterdir())
    assert total < 8_000_000
    runs = {p.name: read_run(p) for p in folders}
    refs = load_db_refs(demo_db)
    for name, run in runs.items():
        run.load_all()
        assert run.findings == [], name
        # `logs check` finds no errors (slip warnings are expected)
        assert [f for f in check_run(run.folder, refs) if f.severity == "error"] == [], name
        assert 300 <= run.raw_json["sim_truth"]["duration_s"] <= 900, name
    kinds = {e["kind"] for r in runs.values() for e in r.raw_json["sim_truth"]["slip_episodes"]}
    assert kinds == {"slip", "slide"}
    assert any(e["on_grade_curve"] for e in runs["sim-d-slips"].raw_json["sim_truth"]["slip_episodes"])
    # directions: km up on D, down on U
    d_km = runs["sim-d-slips"].stream("truth")["km_m"]
    u_km = runs["sim-u-tunnel"].stream("truth")["km_m"]
    assert d_km.iloc[-1] > d_km.iloc[0] and u_km.iloc[-1] < u_km.iloc[0]
    assert (runs["sim-u-tunnel"].stream("gps")["fix"] == 0).sum() > 5
    assert runs["sim-d-reversal"].stream("cab")["direction"].tolist() == ["F", "R"]
    rr = runs["sim-road-rail"]
    assert rr.meta is not None and rr.meta.vehicle_kind == "road_rail"
    assert set(rr.streams_present()) == {"gps", "cab", "tacho", "truth"}
    pto = rr.stream("cab")["pto"].tolist()
    assert pto[0] == 0 and pto[1] == 1 and pto[-1] == 0
    assert "R" in rr.stream("cab")["direction"].tolist()
    truth = rr.stream("truth")
    assert truth["km_m"].isna().iloc[0] and truth["km_m"].isna().iloc[-1]
    assert np.nanmax(truth["km_m"]) - np.nanmin(truth["km_m"]) == pytest.approx(600.0, abs=0.1)
    # standing on the road before going on rail: ~8 m beside the track (GPS error σ 1.5 m)
    gps = rr.stream("gps")
    g = build_network([demo_line()], Projector(9)).gis
    g = g[g["track"] == "D"]
    proj = projector_for_points(g["lat"], g["lon"])
    index = PolylineIndex(*proj.to_xy(g["lon"], g["lat"]), g["km_m"])
    off = index.project(*proj.to_xy(gps["lon"].iloc[:50], gps["lat"].iloc[:50])).offset_m
    assert np.abs(np.median(off)) == pytest.approx(8.0, abs=4.0)
    assert json.loads((folders[0] / "run.json").read_text(encoding="utf-8"))["db_version"] == "2026.01-test"
