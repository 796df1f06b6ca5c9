"""The bundled sample network's station, crossover pair and junction
(:mod:`fieldlogs.simulate.networks.sample_junctions`) and the sample runs over them
(:mod:`fieldlogs.simulate.samples_net`)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from dbtools.database import read_network
from dbtools.network import Network
from dbtools.topology import all_tracks
from fieldlogs.quality.checks import check_run, load_db_refs
from fieldlogs.runs.handle import read_run
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.networks.sample_junctions import TRACK_SPACING
from fieldlogs.simulate.networks.turnout import radius_for_extent, reverse_curves
from fieldlogs.simulate.samples_net import network_sample_scenarios
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run


@pytest.fixture(scope="module")
def sample(sample_network_db: Path) -> Network:
    return read_network(sample_network_db)


def test_turnout_geometry_hand_computed() -> None:
    """Crossover of the sample: 1:10, 60 m between toes, tracks 3.8 m apart."""
    alpha = math.atan(0.1)
    r = radius_for_extent(60.0, TRACK_SPACING, 10.0)
    assert r == pytest.approx((60.0 - 38.0) / (2 * math.tan(alpha / 2)))
    p = reverse_curves(0.0, 0.0, TRACK_SPACING, 10.0, r, -1.0)
    assert p.at(p.length)[:2] == pytest.approx((60.0, -TRACK_SPACING), abs=1e-9)
    assert p.pieces[0] == pytest.approx((r * alpha, -1.0 / r))


def test_sample_network_tables(sample: Network) -> None:
    tracks = all_tracks(sample)
    assert not tracks["implied"].any()  # both tracks of 0420 are split at the switches
    kinds = tracks.groupby("kind").size().to_dict()
    assert kinds == {"crossover": 2, "main": 12, "station": 2}
    assert len(sample.switches) == 9
    # the crossovers are longer than the 60 m of km they span (S003: 渡り線)
    x = tracks[tracks["kind"] == "crossover"]
    assert (x["length_m"] > 60.0).all() and (x["length_m"] < 60.3).all()
    g = sample.balises[sample.balises["kind"] == "G"]
    assert len(g) == 22 and set(g["n_pig"]) == {0, 1}
    assert set(sample.s003_balises["kind"]) == {"I1", "I2", "C"}  # the line's S003 balises unchanged


def test_sample_network_runs(sample: Network, sample_network_db: Path, tmp_path: Path) -> None:
    refs = load_db_refs(sample_network_db)
    scenarios = network_sample_scenarios(sample)
    assert list(scenarios) == ["sim-net-crossover", "sim-net-station", "sim-net-junction", "sim-net-turnback"]
    ids: dict[str, list[str]] = {}
    for name, over in scenarios.items():
        streams, meta = simulate_run(sample, scenario_from_dict(over, source=name))
        folder = write_run(tmp_path / name, meta, streams)
        run = read_run(folder)
        run.load_all()
        assert run.findings == [], name
        assert [f for f in check_run(folder, refs) if f.severity == "error"] == [], name
        tid = streams["truth"]["track_id"].astype(str).to_numpy()
        ids[name] = [str(t) for i, t in enumerate(tid) if i == 0 or t != tid[i - 1]]
        assert 300 <= meta.extra["sim_truth"]["duration_s"] <= 900, name
    assert ids["sim-net-crossover"] == ["0420-U5", "0420-U4", "0420-X1", "0420-D3", "0420-D2", "0420-D1"]
    assert ids["sim-net-station"][:3] == ["0420-D1", "0420-3", "0420-D3"]
    assert ids["sim-net-junction"][-1] == "0421-S1"
    assert ids["sim-net-turnback"] == ["0420-U5", "0420-U4", "0420-U3", "0420-4", "0420-U3", "0420-U4", "0420-U5"]


def test_station_stop_on_track_3_without_gnss(sample: Network) -> None:
    streams, _ = simulate_run(sample, scenario_from_dict(network_sample_scenarios(sample)["sim-net-station"]))
    truth, gps = streams["truth"], streams["gps"]
    on3 = truth["track_id"] == "0420-3"
    stopped = on3 & (truth["speed_mps"] == 0.0)
    assert stopped.sum() >= 200  # the 30 s dwell at 10 Hz, less the smoothing window
    assert truth.loc[stopped, "pos_m"].to_numpy() == pytest.approx(280.0, abs=0.01)
    t_roof = truth.loc[on3 & truth["pos_m"].between(160.0, 390.0), "t"]
    fix = np.interp(t_roof, gps["t"], gps["fix"])
    assert (fix == 0).mean() > 0.9
