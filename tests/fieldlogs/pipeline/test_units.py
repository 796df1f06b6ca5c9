"""One positioning unit per cab [S003 §2] (:mod:`fieldlogs.pipeline.units`): the other cab's
view of a run, the comparison of the two units, and ``trainpos run --unit``."""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from cli.main import app
from dbtools.database import read_network
from fieldlogs.pipeline.run import own_reader, run_pipeline
from fieldlogs.pipeline.units import compare_units, mirrored_block, mirrored_streams, unit_run
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.samples_net import network_sample_scenarios
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run
from schemas.errors import UsageError


def _positions(km: list[float], margin: list[float], state: list[str], track: list[str]) -> pd.DataFrame:
    return pd.DataFrame(
        {"t": np.arange(len(km)) * 0.1, "km_m": km, "margin_m": margin, "state": state, "track_id": track}
    )


def test_compare_units_hand_computed() -> None:
    d, u, a = "determined", "undetermined", "ambiguous"
    f = _positions([100.0, 110.0, 120.0, 130.0, 140.0, 150.0], [5.0] * 6, [u, d, d, d, d, a], ["A"] * 6)
    # cycle 0: R undetermined; 1: 3 m apart (≤ 10); 2: 10.5 m (> 5 + 5); 3: same km on track B;
    # 4: 9 m with margins 5 + 4; 5: 20 m while F is ambiguous (margins 5 + 16)
    r = _positions(
        [np.nan, 107.0, 109.5, 130.0, 131.0, 130.0],
        [9.0, 5.0, 5.0, 5.0, 4.0, 16.0],
        [u, d, d, d, d, d],
        ["", "A", "A", "B", "A", "A"],
    )
    frame, s = compare_units(f, r)
    assert frame["difference_m"].tolist()[1:] == pytest.approx([3.0, 10.5, 0.0, 9.0, 20.0])
    assert frame["disagree"].tolist() == [False, False, True, True, False, False]
    assert s["cycles_compared"] == 5
    assert s["max_abs_difference_m"] == pytest.approx(20.0)
    assert s["max_difference_share_of_bound"] == pytest.approx(1.05)  # 10.5 / 10
    assert (s["cycles_beyond_margins"], s["cycles_on_other_tracks"]) == (1, 1)
    assert s["disagreements"] == [[pytest.approx(0.2), pytest.approx(0.3)]]


def test_the_other_cab_sees_the_body_turned_half_round() -> None:
    streams = {
        "imu": pd.DataFrame(
            {"t": [0.0], "ax": [0.5], "ay": [-0.2], "az": [9.8], "wx": [0.01], "wy": [0.0], "wz": [0.03]}
        ),
        "tacho": pd.DataFrame({"t": [0.0, 0.1], "pulses": [0, 3], "direction": [0, -1]}),
        "cab": pd.DataFrame({"t": [0.0, 9.0], "direction": ["F", "R"]}),
        "truth": pd.DataFrame({"t": [0.0], "speed_mps": [-0.4]}),
    }
    m = mirrored_streams(streams)
    imu = m["imu"].iloc[0]
    assert (imu["ax"], imu["ay"], imu["az"], imu["wx"], imu["wz"]) == (-0.5, 0.2, 9.8, -0.01, 0.03)
    assert not np.signbit(m["imu"]["wy"].to_numpy()).any()  # no negative zero
    assert m["tacho"]["direction"].tolist() == [0, 1]
    assert m["cab"]["direction"].tolist() == ["R", "F"]
    assert m["truth"]["speed_mps"].tolist() == [0.4]
    vehicle = {"balise_reader": {"x_m": 9.5, "y_m": 0.0}, "gnss_antennas": [{"id": "A", "x_m": -3.0, "y_m": 0.4}]}
    assert mirrored_block(vehicle) == {
        "balise_reader": {"x_m": -9.5, "y_m": -0.0},
        "gnss_antennas": [{"id": "A", "x_m": 3.0, "y_m": -0.4}],
    }
    assert mirrored_block({"looks_toward": "F", "x_m": True}) == {"looks_toward": "R", "x_m": True}
    twice = mirrored_streams(m)
    for name, frame in streams.items():
        pd.testing.assert_frame_equal(twice[name], frame, check_dtype=False)


@pytest.fixture(scope="module")
def turnback(sample_network_db: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample turnback (cab change on station track 4), rolling back 3 m at its uphill
    starts, with a two-phase tacho, recording one set of sensors (unit R turns them round)."""
    net = read_network(sample_network_db)
    over = dict(network_sample_scenarios(net)["sim-net-turnback"])
    over["running"] = {"rollback_m": 3.0}
    over["tacho"] = {"two_phase": True}
    over["cab_r"] = {"sensors": False}
    streams, meta = simulate_run(net, scenario_from_dict(over, source="test"))
    return write_run(tmp_path_factory.mktemp("units") / "turnback", meta, streams)


def test_both_units_agree_on_a_turnback(turnback: Path, sample_network_db: Path) -> None:
    """Each unit forward to its own cab gives the same positions: the pipeline does not depend
    on which end it calls F (through the cab change and the rollbacks)."""
    net = read_network(sample_network_db)
    pos = {}
    with tempfile.TemporaryDirectory() as tmp:
        for unit in ("F", "R"):
            pos[unit] = run_pipeline(unit_run(read_run(turnback), unit, Path(tmp) / unit), net).positions
    assert pos["F"]["state"].tolist() == pos["R"]["state"].tolist()
    _, s = compare_units(pos["F"], pos["R"])
    assert s["cycles_compared"] > 3000
    assert s["max_abs_difference_m"] < 1e-6
    assert s["disagreements"] == []


def test_run_unit_both_cli(turnback: Path, sample_network_db: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    out = tmp_path / "out"
    res = runner.invoke(
        app, ["run", str(turnback), "--db", str(sample_network_db), "--out", str(out), "--unit", "both"]
    )
    assert res.exit_code == 0, res.output
    for unit in ("F", "R"):
        assert {p.name for p in (out / unit).iterdir()} >= {"positions.parquet", "events.csv", "summary.json"}
    cmp = json.loads((out / "units.json").read_text(encoding="utf-8"))
    assert cmp["cycles_beyond_margins"] == 0 and cmp["disagreements"] == []
    assert cmp["unit_r"] == {
        "view": "the F cab's streams turned round (the run has no R cab streams)",
        "streams": {"imu": "imu", "tacho": "tacho", "gps": "gps"},
    }
    assert "Units F and R compared" in res.output
    bad = runner.invoke(
        app, ["run", str(turnback), "--db", str(sample_network_db), "--out", str(tmp_path / "x"), "--unit", "Q"]
    )
    assert bad.exit_code == UsageError.exit_code
    assert "--unit must be F, R or both" in bad.output
    assert not (tmp_path / "x").exists()


def test_own_reader_keeps_the_units_cab() -> None:
    b = pd.DataFrame(
        {"t": [1.0, 2.0, 3.0], "kind": ["C", "C", "C"], "reader": pd.array(["F", "R", None], dtype="string")}
    )
    assert own_reader(b)["t"].tolist() == [1.0, 3.0]
    assert own_reader(mirrored_streams({"balise": b})["balise"])["t"].tolist() == [2.0, 3.0]
    plain = b.drop(columns="reader")
    assert own_reader(plain) is plain


def test_a_reader_per_cab_two_independent_units(sample_network_db: Path, tmp_path: Path) -> None:
    """The turnback with a balise reader in each cab 9.5 m from the reference point: each unit
    corrects on its own reader's telegrams, so the units differ, and agree within their margins."""
    net = read_network(sample_network_db)
    over = dict(network_sample_scenarios(net)["sim-net-turnback"])
    over["running"] = {"rollback_m": 3.0}
    over["tacho"] = {"two_phase": True}
    over["balise"] = {"readers_x_m": [9.5, -9.5]}
    over["cab_r"] = {"sensors": False}
    streams, meta = simulate_run(net, scenario_from_dict(over, source="test"))
    assert streams["balise"]["reader"].value_counts().to_dict() == {"F": 14, "R": 14}
    assert meta.vehicle is not None and meta.vehicle["balise_reader_r"] == {"x_m": -9.5, "y_m": 0.0}
    folder = write_run(tmp_path / "two-readers", meta, streams)
    pos = {}
    for unit in ("F", "R"):
        res = run_pipeline(unit_run(read_run(folder), unit, tmp_path / unit), net)
        pos[unit] = res.positions
        judged = res.positions[res.positions["state"] != "undetermined"]
        assert len(judged) > 3000
    _, s = compare_units(pos["F"], pos["R"])
    assert 0.5 < s["max_abs_difference_m"] < 20.0
    assert s["cycles_beyond_margins"] == 0 and s["cycles_on_other_tracks"] == 0 and s["disagreements"] == []
