"""dbtools.topology.track_codes: the network's one factorisation of its track ids, and what
the topology rules read from it (first/last rows, the graph's codes, a port's track length)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import Network, empty_frame
from dbtools.rules.topology_tables import ALL_PORTS, held_objects, picked_objects, port_lengths
from dbtools.topology import Topology, all_tracks, connection_rows, first_rows, track_codes
from schemas.model import Table
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES, TRACK_POINTS
from schemas.tables import BALISES, GIS

Ids = Sequence[str | None]


def network(tracks: Ids, a: Ids, b: Ids, ports: Sequence[Ids], tp: Ids, balises: Ids) -> Network:
    """Declared tracks in the given row order (length 10·(row + 1) m), connections a–b
    (end→begin, both ways), one switch per row of ``ports`` (a1, b1, b2, a2), track_points
    and balises naming the given ids, every table in the given row order; no line grid (no
    implied track)."""
    t = pd.DataFrame({"track_id": tracks, "kind": "main", "length_m": 10.0 * (1 + np.arange(len(tracks)))})
    c = pd.DataFrame({"track_a": a, "end_a": "end", "track_b": b, "end_b": "begin", "navigability": "both"})
    sw = pd.DataFrame(
        {
            "switch_id": [f"S{k}" for k in range(len(ports))],
            "type": "point",
            **{f"{p}_track": [row[k] for row in ports] for k, p in enumerate(ALL_PORTS)},
            **{f"{p}_end": "begin" for p in ALL_PORTS},
        }
    )
    points = pd.DataFrame({"track_id": tp, "pos_m": np.arange(len(tp), dtype=float), "lat": 35.0, "lon": 139.0})
    bal = pd.DataFrame({"balise_id": [f"B{k}" for k in range(len(balises))], "track_id": balises})
    frames = ((NETWORK_TRACKS, t), (CONNECTIONS, c), (SWITCHES, sw), (TRACK_POINTS, points), (BALISES, bal))
    return Network({GIS.name: empty_frame(GIS), **{table.name: typed(table, frame) for table, frame in frames}})


def typed(table: Table, frame: pd.DataFrame) -> pd.DataFrame:
    """``frame`` with the table's declared columns and dtypes, in its own row order."""
    empty = empty_frame(table)
    return pd.DataFrame(
        {
            c: pd.Series(frame[c] if c in frame.columns else [None] * len(frame), dtype=empty[c].dtype)
            for c in empty.columns
        }
    )


def test_hand_computed() -> None:
    """Declared A, B, A; connections B–A, X–A, (missing)–B; a switch A / Z / − / −;
    track_points B, Q; balises (missing), A. Codes in order of first appearance: A 0, B 1,
    X 2, missing 3, Z 4, Q 5; A's first row 0 and last row 2."""
    net = network(["A", "B", "A"], ["B", "X", None], ["A", "A", "B"], [["A", "Z", None, None]], ["B", "Q"], [None, "A"])
    tracks = all_tracks(net)
    assert tracks["track_id"].tolist() == ["A", "B", "A"]
    codes = track_codes(net)
    assert [None if pd.isna(u) else u for u in codes.uniques] == ["A", "B", "X", None, "Z", "Q"]
    assert codes.of[("all_tracks", "track_id")].tolist() == [0, 1, 0]
    assert codes.first.tolist() == [0, 1, -1, -1, -1, -1]
    assert codes.last.tolist() == [2, 1, -1, -1, -1, -1]
    ca, cb = connection_rows(net, tracks)
    assert ca.tolist() == [1, -1, -1] and cb.tolist() == [0, 0, 1]
    assert codes.rows(TRACK_POINTS.name, "track_id").tolist() == [1, -1]
    assert codes.rows(BALISES.name, "track_id").tolist() == [-1, 0]
    # port lengths: the last row of the port's track (A: row 2, 30 m), NaN for no track
    lengths = port_lengths(net, tracks, [0, 1, 2, 3])  # port-major rows: a1, b1, b2, a2 of the one switch
    assert lengths[0] == 30.0 and np.isnan(lengths[1:]).all()


ids = st.lists(st.one_of(st.none(), st.sampled_from("ABCDE")), max_size=12)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(st.sampled_from("ABCDEF"), max_size=8),
    st.lists(st.tuples(st.one_of(st.none(), st.sampled_from("ABCDEFG")), st.sampled_from("ABCDEFG")), max_size=10),
    ids,
    ids,
)
def test_the_codes_give_what_each_look_up_gave(
    tracks: list[str], conns: list[tuple[str | None, str]], tp: Ids, bal: Ids
) -> None:
    """First rows of the connections' tracks as :func:`first_rows` finds them; the last row
    of each track's id; the graph built on the codes the same as the graph factorised alone."""
    a, b = [x for x, _ in conns], [y for _, y in conns]
    net = network(list(tracks), a, b, [], [x for x in tp if x is not None], bal)
    t, c = all_tracks(net), net.connections
    ca, cb = connection_rows(net, t)
    assert ca.tolist() == first_rows(t["track_id"], c["track_a"]).tolist()
    assert cb.tolist() == first_rows(t["track_id"], c["track_b"]).tolist()
    codes = track_codes(net)
    ids_ = t["track_id"].tolist()
    last = [max(k for k, x in enumerate(ids_) if x == y) for y in ids_]
    assert codes.last[codes.of[("all_tracks", "track_id")]].tolist() == last
    bal_rows = codes.rows(BALISES.name, "track_id")
    held = net.balises["track_id"]
    assert bal_rows.tolist() == [ids_.index(x) if not pd.isna(x) and x in ids_ else -1 for x in held]
    alone, shared = Topology(t, c).graph, Topology(t, c, lambda: codes).graph
    assert alone.names.tolist() == shared.names.tolist()
    for k in ("length", "ptr", "succ"):
        assert np.array_equal(getattr(alone, k), getattr(shared, k), equal_nan=True)


@given(st.lists(st.integers(0, 15), max_size=16))
def test_picked_objects_are_the_held_ones(rows: list[int]) -> None:
    """The text of some rows, picked from the column as held or from the whole column
    converted once: the same objects (NaN for missing)."""
    net = network(["A"], list("ABCDEFGHIJKLMNOP"), [None if k % 3 else "A" for k in range(16)], [], [], [])
    r = np.array(rows, dtype=np.int64)
    for name in ("track_a", "track_b"):
        picked = picked_objects(net, CONNECTIONS.name, name, r)
        whole = held_objects(net, CONNECTIONS.name, name)[r]
        assert [None if pd.isna(x) else x for x in picked] == [None if pd.isna(x) else x for x in whole]
        assert all(isinstance(x, str) or (isinstance(x, float) and np.isnan(x)) for x in picked)
