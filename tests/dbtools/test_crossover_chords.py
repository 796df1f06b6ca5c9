"""The crossover-angle rule's chords by track code (``coded_chord_azimuths``, track_points as
read from a DB) are those by track id (``chord_azimuths``), bit for bit, and so is the worst
deviation of every crossover end (``topology_geometry._worst_deviation``)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dbtools.network import Network
from dbtools.rules.topology_geometry import _crossover_ends, _worst_deviation
from dbtools.rules.track_geometry import chord_azimuths, coded_chord_azimuths, track_geometry
from dbtools.sources import read_source_set
from dbtools.topology import all_tracks, track_codes
from schemas.network import TRACK_POINTS
from tests.dbtools.test_topology_golden import synthetic


@pytest.fixture(scope="module")
def net(tmp_path_factory: pytest.TempPathFactory) -> Network:
    network, _ = read_source_set(synthetic(tmp_path_factory.mktemp("xo") / "src"))
    return network


def worst(net: Network) -> pd.DataFrame:
    tracks = all_tracks(net)
    ref = _crossover_ends(net, tracks)
    assert ref is not None
    return _worst_deviation(net, track_geometry(net, tracks), ref)


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.data())
def test_chords_by_code_are_the_chords_by_id(net: Network, data: st.DataObject) -> None:
    codes = track_codes(net)
    own = codes.of[(TRACK_POINTS.name, "track_id")]
    picked = data.draw(st.lists(st.sampled_from(sorted(set(own.tolist()))), min_size=1, max_size=8))
    cid, az = coded_chord_azimuths(net, np.array(picked, dtype=np.int64))
    by_id = chord_azimuths(net.track_points, {str(codes.uniques[c]) for c in picked})
    assert [str(codes.uniques[c]) for c in cid] == by_id["track_id"].tolist()
    assert az.tobytes() == by_id["az"].to_numpy(float).tobytes()


def test_worst_deviation_by_code_is_that_by_id(net: Network) -> None:
    coded = worst(net)
    assert len(coded) > 4
    tp = net.track_points
    shuffled = Network({**net.tables, TRACK_POINTS.name: tp.iloc[::-1].reset_index(drop=True)})  # not sorted: by id
    pd.testing.assert_frame_equal(coded, worst(shuffled), check_exact=True)


def test_a_crossover_without_points_has_no_worst_deviation(net: Network) -> None:
    tp = net.track_points
    gone = worst(net)["track_id"].iloc[0]
    cut = Network({**net.tables, TRACK_POINTS.name: tp[tp["track_id"] != gone].reset_index(drop=True)})
    assert gone not in set(worst(cut)["track_id"])
    pd.testing.assert_frame_equal(worst(cut), worst(net)[worst(net)["track_id"] != gone].reset_index(drop=True))
