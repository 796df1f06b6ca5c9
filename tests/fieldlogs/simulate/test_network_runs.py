"""The generator of seeded network runs for the accuracy statistics (issue 31)."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import Projector
from dbtools.network import Network
from dbtools.sources import write_source_set
from fieldlogs.simulate.netsim import network_plan
from fieldlogs.simulate.network_runs import feature_of, feature_tracks, network_runs
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from fieldlogs.simulate.scenario import scenario_from_dict
from fieldlogs.simulate.simulator import simulate_run

NETWORKS = Path(__file__).resolve().parents[2] / "data" / "networks"


@pytest.fixture(scope="module")
def sample(sample_network_db: Path) -> Network:
    return read_network(sample_network_db)


def test_feature_tracks(sample: Network) -> None:
    assert feature_tracks(sample) == ["0420-3", "0420-4", "0420-X1", "0420-X2", "0421-S1"]


def test_many_runs_over_the_sample_network(sample: Network) -> None:
    runs = network_runs(sample, 120, seed=7)
    assert len(runs) == 120
    assert runs[:5] == network_runs(sample, 5, seed=7)  # run i does not depend on n
    assert runs != network_runs(sample, 120, seed=8)
    features = Counter(feature_of(r) for r in runs)
    assert set(features) == set(feature_tracks(sample)) and min(features.values()) >= 10
    no_gps = sum(r.get("sensors", {}).get("gps") is False for r in runs)
    tunnels = sum(bool(r["network"].get("gnss_outages")) for r in runs)
    multipath = sum(bool(r["network"].get("multipath")) for r in runs)
    turnbacks = sum(len(r["network"]["points"]) == 3 for r in runs)
    assert min(no_gps, tunnels, multipath, turnbacks) >= 8
    for r in runs:
        plan = network_plan(sample, scenario_from_dict(r, source=r["name"]))
        on_route = [s.track_id for s in plan.geom.segments]
        assert feature_of(r) in on_route
        lo, hi = min(plan.points_rho), max(plan.points_rho)
        seg = plan.geom.segments[on_route.index(feature_of(r))]
        assert lo < seg.rho0 + seg.length and hi > seg.rho0  # the run passes (part of) its feature


def test_runs_simulate_through_their_feature(sample: Network) -> None:
    for r in network_runs(sample, 3, seed=11):
        streams, _ = simulate_run(sample, scenario_from_dict(r))
        assert feature_of(r) in set(streams["truth"]["track_id"].astype(str))


def test_small_network_and_line_only_db(tmp_path: Path) -> None:
    build_db(NETWORKS / "crossover", tmp_path / "xo.sqlite")
    net = read_network(tmp_path / "xo.sqlite")
    assert feature_tracks(net) == ["X1", "X2"]
    assert {feature_of(r) for r in network_runs(net, 12, seed=1)} == {"X1", "X2"}
    write_source_set(build_network([demo_line()], Projector(9)), tmp_path / "line")
    build_db(tmp_path / "line", tmp_path / "line.sqlite")
    assert network_runs(read_network(tmp_path / "line.sqlite"), 4, seed=1) == []  # no switch to cross
