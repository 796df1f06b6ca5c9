"""The line rules computed ``BLOCK`` points at a time (grid index, step lengths, track spacing,
operating area, heights) give the findings of one block, whatever the block size: the
block ends fall inside the damaged stretches."""

from __future__ import annotations

import json

import numpy as np
import pytest

import dbtools.gis.index as index_mod
from dbtools.gis.geometry import Projector
from dbtools.network import Network
from dbtools.validate import validate_network
from fieldlogs.simulate.networks.synthetic import build_network, demo_line


@pytest.fixture(scope="module")
def damaged() -> Network:
    net = build_network([demo_line()], Projector(9))
    g = net.gis
    d = np.flatnonzero((g["track"] == "D").to_numpy())
    u = np.flatnonzero((g["track"] == "U").to_numpy())
    g.loc[d[[30, 31, 95]], "lat"] += 0.0004  # spikes and step lengths
    g.loc[d[140], "km_m"] += 3.0  # off the grid
    g.loc[d[170], "lat"] = 20.0  # far outside the area: left out of the index
    g.loc[d[175], "lon"] += 0.02  # just outside the area
    g.loc[u[200:230], "height_m"] += np.linspace(0.0, 5.0, 30)  # a steep stretch
    km_u = g.loc[u[300:340], "km_m"].to_numpy()
    close = d[np.isin(g.loc[d, "km_m"].to_numpy(), km_u)]  # down track 2 m beside the up track
    up = g.loc[u].set_index("km_m").loc[g.loc[close, "km_m"]]
    g.loc[close, "lat"] = up["lat"].to_numpy() + 2e-5
    g.loc[close, "lon"] = up["lon"].to_numpy()
    net.meta["area"] = json.dumps({"lat_min": 35.99, "lat_max": 36.11, "lon_min": 139.79, "lon_max": 139.84})
    return net


def test_any_block_size_gives_the_findings_of_one_block(damaged: Network, monkeypatch: pytest.MonkeyPatch) -> None:
    whole = validate_network(_fresh(damaged))
    rules = {f.rule for f in whole}
    assert {"gis.spike", "gis.step_length", "gis.km_grid", "gis.track_spacing", "schema.range"} <= rules
    assert {"gis.height_grade", "gis.outside_area"} <= rules
    for block in (7, 64, 1000):
        monkeypatch.setattr(index_mod, "BLOCK", block)
        assert validate_network(_fresh(damaged)) == whole


def _fresh(net: Network) -> Network:
    """A network of the same frames without the cached index (built anew)."""
    return Network(dict(net.tables), origin=net.origin, meta=dict(net.meta))
