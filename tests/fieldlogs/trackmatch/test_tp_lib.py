"""tp-lib's sample networks and their GNSS points (tests/data/tp-lib, Apache-2.0) matched to
a connected path: every consecutive pair of path tracks joined by a navigable connection."""

from __future__ import annotations

from datetime import timedelta, timezone
from itertools import pairwise
from pathlib import Path

import pandas as pd
import pytest

from dbtools.interchange.rtm_import import import_rtm_geojson
from dbtools.network import Network
from dbtools.sources import read_source_set
from dbtools.topology import topology
from fieldlogs.recorders.geojson import read_geojson
from fieldlogs.trackmatch.match import TrackMatch, match_trace

TP_LIB = Path(__file__).resolve().parents[2] / "data" / "tp-lib"


def _network(tmp: Path, source: Path) -> Network:
    import_rtm_geojson(source, tmp / "src")
    net, findings = read_source_set(tmp / "src")
    assert not [f for f in findings if f.severity == "error"]
    return net


def _match(net: Network, gnss: Path) -> TrackMatch:
    gps = read_geojson(gnss, timezone(timedelta(hours=2))).frames["gps"].sort_values("gnss_time_s")
    t = (gps["gnss_time_s"] - gps["gnss_time_s"].min()).to_numpy()
    return match_trace(net, t, gps["lat"].to_numpy(), gps["lon"].to_numpy())


def connected(net: Network, path: pd.DataFrame) -> bool:
    topo = topology(net)
    rows = list(zip(path["chain"], path["track_id"], strict=True))
    for (ca, a), (cb, b) in pairwise(rows):
        nxt = {x.track_id for d in (1, -1) for x in topo.next_tracks(a, d)}
        if ca == cb and b not in nxt:
            return False
    return True


def test_rinf_kvg_gnss_matched_to_a_connected_path(tmp_path: Path) -> None:
    net = _network(tmp_path, TP_LIB / "rinf-kvg" / "network.geojson")
    r = _match(net, TP_LIB / "rinf-kvg" / "gnss.geojson")
    assert r.summary["fixes"] == 149 and r.summary["matched"] == 149 and r.summary["chains"] == 1
    assert connected(net, r.path) and len(r.path) >= 5
    # ids verbatim from the source
    assert (
        set(r.path["track_id"]) <= set(net.tracks["track_id"])
        and r.path["track_id"].str.startswith("_netelement_").all()
    )
    # the path covers the trace in time order, every fix on a path track
    assert r.path["t_from"].is_monotonic_increasing and r.summary["max_abs_offset_m"] < 15.0
    assert set(r.fixes["track_id"]) <= set(r.path["track_id"])
    assert r.path["probability"].between(0, 1).all() and r.fixes["probability"].between(0, 1).all()


def test_tp_lib_teaching_sample(tmp_path: Path) -> None:
    net = _network(tmp_path, TP_LIB / "sample_network.geojson")
    r = _match(net, TP_LIB / "sample_gnss.geojson")
    assert r.summary["fixes"] == 3 and r.summary["matched"] == 3 and connected(net, r.path)
    assert list(r.path["track_id"]) == ["NE001"]


@pytest.mark.parametrize("broken", ["A", "B"])
def test_connected_detects_a_gap(broken: str) -> None:
    from tests.fieldlogs.trackmatch.nets import make_network

    net = make_network({"A": [(0, 0), (10, 0)], "B": [(10, 0), (20, 0)]}, [("A", "end", "B", "begin", "none")])
    path = pd.DataFrame({"chain": [0, 0], "track_id": ["A", "B"] if broken == "A" else ["B", "A"]})
    assert not connected(net, path)
