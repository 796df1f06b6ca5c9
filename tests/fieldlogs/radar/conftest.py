"""Shared by the radar tests: the synthetic demo network and one short simulated radar run."""

from __future__ import annotations

from pathlib import Path

import pytest

from dbtools.build import build_db
from dbtools.database import read_network
from dbtools.gis.geometry import Projector
from dbtools.network import Network
from dbtools.sources import write_source_set
from fieldlogs.runs.write import write_run
from fieldlogs.simulate.networks.synthetic import build_network, demo_line
from tests.fieldlogs.radar.runs import simulate_radar_run


@pytest.fixture(scope="session")
def demo_net(tmp_path_factory: pytest.TempPathFactory) -> Network:
    root = tmp_path_factory.mktemp("radar-demo")
    write_source_set(build_network([demo_line()], Projector(9)), root / "src")
    build_db(root / "src", root / "net.sqlite", db_version="2026.01-test")
    return read_network(root / "net.sqlite")


@pytest.fixture(scope="session")
def radar_run(demo_net: Network, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Run 1 of ``runs.py`` (overpass, track U) at 25 km/h, written as Parquet."""
    streams, meta = simulate_radar_run(1, demo_net, top_kmh=25.0)
    return write_run(tmp_path_factory.mktemp("radar-run") / "run", meta, streams)
