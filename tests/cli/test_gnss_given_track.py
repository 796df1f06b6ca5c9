"""``gnss position --line --track`` runs no pipeline (issue 32 item 13): a GNSS-only copy of
a run (tacho and imu removed) is positioned on the given track, with the facing from the
fixes' motion, and its epochs equal the full run's; a static receiver states the facing
unknown and widens its bound by half the two facings' difference."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner, Result

from cli.main import app
from dbtools.database import read_network
from fieldlogs.gnss.facing import MIN_TRAVEL_M, facing_from_motion
from tests.fieldlogs.gnss.runs import simulate_gnss_run

#: The same solver on the same observations, track and facing: equal to the last bit that JSON keeps.
KM_TOLERANCE_M = 1e-6


def invoke(*args: object) -> Result:
    return CliRunner().invoke(app, [str(a) for a in args], env={"COLUMNS": "200"})


@pytest.fixture(scope="module")
def runs(sample_db: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    base = tmp_path_factory.mktemp("given")
    full = simulate_gnss_run(read_network(sample_db), base / "full", seed=8, length_m=1500.0)
    only = base / "gnss-only"
    shutil.copytree(full, only)
    removed = [p for p in only.iterdir() if p.name.split(".")[0] in ("tacho", "imu")]
    assert {p.name.split(".")[0] for p in removed} == {"tacho", "imu"}
    for p in removed:
        p.unlink()
    return full, only


def _doc(run: Path, db: Path, *extra: object) -> dict:  # type: ignore[type-arg]
    res = invoke("gnss", "position", run, "--db", db, "--format", "json", *extra)
    assert res.exit_code == 0, res.output
    return json.loads(res.output)  # type: ignore[no-any-return]


def test_a_gnss_only_run_is_positioned_on_the_given_track(runs: tuple[Path, Path], sample_db: Path) -> None:
    full, only = runs
    # before: --facing auto ran the pipeline, which refused the run ('no tacho stream')
    given = _doc(only, sample_db, "--line", "0420", "--track", "D")
    assert (given["track_source"], given["facing"]) == ("given", "increasing_km")
    assert given["facing_source"].startswith("the fixes' motion")
    assert given["availability"]["constrained"] > 0.95
    ref = _doc(full, sample_db)  # the pipeline's track and facing on the full run
    assert (ref["line_code"], ref["track"], ref["facing"], ref["facing_source"]) == (
        "0420", "D", "increasing_km", "pipeline",
    )  # fmt: skip
    a = pd.DataFrame(given["epochs"]).set_index(["t", "receiver"])
    b = pd.DataFrame(ref["epochs"]).set_index(["t", "receiver"])
    assert a.index.equals(b.index)
    ok = a["available"] & b["available"]
    assert ok.mean() > 0.95 and (a["available"] == b["available"]).all()
    np.testing.assert_allclose(a.loc[ok, "km_m"], b.loc[ok, "km_m"], rtol=0, atol=KM_TOLERANCE_M)
    np.testing.assert_allclose(a.loc[ok, "uncertainty_m"], b.loc[ok, "uncertainty_m"], rtol=0, atol=KM_TOLERANCE_M)


def test_the_pipeline_still_refuses_a_gnss_only_run_without_the_track(runs: tuple[Path, Path], sample_db: Path) -> None:
    res = invoke("gnss", "position", runs[1], "--db", sample_db)
    assert res.exit_code == 2  # no track decided: usage, naming what to give
    assert "give --line and --track" in res.stderr and "no tacho stream" in res.stderr


def test_facing_by_hand() -> None:
    t = np.arange(6.0)
    sig = np.full(6, 0.5)
    forward = pd.DataFrame({"t": t, "km_m": 1000.0 + 10.0 * t, "sigma_m": sig})  # 50 m toward increasing km
    assert facing_from_motion(forward, None).direction == 1
    assert "F end assumed leading" in facing_from_motion(forward, None).source
    cab_r = pd.DataFrame({"t": [0.0], "direction": ["R"]})  # running reversed: the F end trails
    assert facing_from_motion(forward, cab_r).direction == -1
    back = forward.assign(km_m=1000.0 - 10.0 * t)
    assert facing_from_motion(back, None).direction == -1
    # static: steps within 3·√2·σ are noise, no travel → unknown, and said why
    still = forward.assign(km_m=1000.0 + np.array([0.0, 1.0, -0.5, 0.8, 0.2, -1.0]))
    d = facing_from_motion(still, None)
    assert d.direction == 0 and d.travel_m < MIN_TRAVEL_M and d.source.startswith("unknown (static")
    # back and forth: 40 m each way, no cab stream → unknown
    shunt = pd.DataFrame({"t": t[:5], "km_m": [1000.0, 1020.0, 1040.0, 1020.0, 1000.0], "sigma_m": sig[:5]})
    assert facing_from_motion(shunt, None).direction == 0


def test_a_static_receiver_states_the_facing_unknown(runs: tuple[Path, Path], sample_db: Path, tmp_path: Path) -> None:
    """The GNSS-only run cut to its first epochs, at rest (standstill at the start of a simulated run)."""
    only = runs[1]
    static = tmp_path / "static"
    shutil.copytree(only, static)
    obs_file = next(p for p in static.iterdir() if p.name.startswith("gnss_obs"))
    obs = pd.read_parquet(obs_file) if obs_file.suffix == ".parquet" else pd.read_csv(obs_file)
    truth = pd.read_parquet(next(p for p in static.iterdir() if p.name.startswith("truth")))
    t_move = float(truth.loc[truth["speed_mps"].abs() > 1e-6, "t"].min())  # the end of the first standstill
    obs = obs[obs["t"] < t_move - 0.5]
    assert obs["t"].nunique() >= 3
    if obs_file.suffix == ".parquet":
        obs.to_parquet(obs_file, index=False)
    else:
        obs.to_csv(obs_file, index=False)
    doc = _doc(static, sample_db, "--line", "0420", "--track", "D")
    assert doc["facing"] == "unknown" and doc["facing_source"].startswith("unknown (static")
    plus = _doc(static, sample_db, "--line", "0420", "--track", "D", "--facing", "increasing")
    minus = _doc(static, sample_db, "--line", "0420", "--track", "D", "--facing", "decreasing")
    u, p, m = (pd.DataFrame(x["epochs"]).set_index(["t", "receiver"]) for x in (doc, plus, minus))
    ok = u["available"]
    assert ok.any()
    np.testing.assert_allclose(u.loc[ok, "km_m"], 0.5 * (p.loc[ok, "km_m"] + m.loc[ok, "km_m"]), atol=1e-6)
    half = 0.5 * (p.loc[ok, "km_m"] - m.loc[ok, "km_m"]).abs()
    assert (half > 0.1).all()  # the antennas sit off the reference point: the facing matters
    widest = np.fmax(p.loc[ok, "uncertainty_m"], m.loc[ok, "uncertainty_m"])
    np.testing.assert_allclose(u.loc[ok, "uncertainty_m"], widest + half, atol=1e-6)


def test_a_10_bit_week_is_refused_not_0_percent(runs: tuple[Path, Path], sample_db: Path, tmp_path: Path) -> None:
    """gnss_nav written with the broadcast week (mod 1024): before, every epoch read
    'too_few_satellites' and the command exited 0 with 0 % availability."""
    bad = tmp_path / "week"
    shutil.copytree(runs[1], bad)
    nav_file = next(p for p in bad.iterdir() if p.name.startswith("gnss_nav"))
    nav = pd.read_parquet(nav_file)
    nav["week"] = nav["week"] % 1024
    nav.to_parquet(nav_file, index=False)
    res = invoke("gnss", "position", bad, "--db", sample_db, "--line", "0420", "--track", "D")
    assert res.exit_code == 1
    assert "10-bit GPS week" in res.stderr and "navigation weeks" in res.stderr
