"""dbtools.topology.TrackCodes.line_tracks: the network's one coding of its (line, track)
pairs, and what reads it — the grid of each track in the track geometry, the grid extent of
the open-end rule and the balises' placement by line, track and km — against the look-ups
by text each made before, and the balises' places ordered by their track id's rank as by its
text (issue 30)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from dbtools.network import Network, canonical, empty_frame
from dbtools.rules.balise_groups import _by_km, _by_km_merge, _places, locate
from dbtools.rules.config import ValidationConfig
from dbtools.rules.track_geometry import track_geometry
from dbtools.topology import LineTrackCodes, all_tracks, grid_extents, track_codes
from schemas.tables import BALISES, DB_TABLES

Pairs = Sequence[tuple[str | None, str | None]]


def frame(pairs: Pairs) -> pd.DataFrame:
    return pd.DataFrame(
        {"line_code": [a for a, _ in pairs], "track": [b for _, b in pairs]}, dtype=pd.StringDtype("pyarrow")
    )


def test_hand_computed() -> None:
    """Grid L1/1, L1/2, L2/1; tracks L2/1, (none)/1, L3/1, L1/2; balises L3/1, L1/(none),
    L1/1; a table without the columns. Codes in order of first appearance: L1/1 0, L1/2 1,
    L2/1 2, L3/1 3, −1 where a part is missing; grid rows 0, 1, 2 and none for L3/1."""
    grid = frame([("L1", "1"), ("L1", "2"), ("L2", "1")])
    tracks = frame([("L2", "1"), (None, "1"), ("L3", "1"), ("L1", "2")])
    balises = frame([("L3", "1"), ("L1", None), ("L1", "1")])
    codes = LineTrackCodes.of_frames(
        {"grid_extents": grid, "all_tracks": tracks, BALISES.name: balises, "other": pd.DataFrame({"x": [1, 2]})}
    )
    assert codes.of["grid_extents"].tolist() == [0, 1, 2]
    assert codes.of["all_tracks"].tolist() == [2, -1, 3, 1]
    assert codes.of[BALISES.name].tolist() == [3, -1, 0]
    assert codes.of["other"].tolist() == [-1, -1]
    assert codes.grid.tolist() == [0, 1, 2, -1]
    assert codes.grid_rows("all_tracks").tolist() == [2, -1, -1, 1]
    assert codes.grid_rows(BALISES.name).tolist() == [-1, -1, 0]
    empty = LineTrackCodes.of_frames({"all_tracks": pd.DataFrame({"x": [1]})})
    assert empty.grid_rows("all_tracks").tolist() == [-1]


part = st.one_of(st.none(), st.sampled_from(["A", "B", "C"]))
pairs = st.lists(st.tuples(part, part), max_size=12)


@settings(max_examples=80, deadline=None)
@given(st.lists(st.tuples(st.sampled_from("ABC"), st.sampled_from("ABC")), unique=True, max_size=6), pairs, pairs)
def test_codes_are_the_text_look_ups(grid: list[tuple[str, str]], tracks: Pairs, balises: Pairs) -> None:
    """Equal codes exactly for equal complete pairs; the grid row of each row is the
    ``MultiIndex`` look-up of its pair in the grid's (as the rules made it before)."""
    frames = {"grid_extents": frame(grid), "all_tracks": frame(tracks), BALISES.name: frame(balises)}
    codes = LineTrackCodes.of_frames(frames)
    rows = [(t, p) for t, f in frames.items() for p in zip(f["line_code"], f["track"], strict=True)]
    flat = np.concatenate([codes.of[t] for t in frames])
    for (_, p), c in zip(rows, flat, strict=True):
        assert (c < 0) == (pd.isna(p[0]) or pd.isna(p[1]))
    for (_, p), c in zip(rows, flat, strict=True):
        for (_, q), d in zip(rows, flat, strict=True):
            if c >= 0 and d >= 0:
                assert (c == d) == (p == q)
    index = pd.MultiIndex.from_tuples(grid) if grid else None
    for t in ("all_tracks", BALISES.name):
        f = frames[t]
        want = (
            index.get_indexer(pd.MultiIndex.from_arrays([f["line_code"].astype(object), f["track"].astype(object)]))
            if index is not None and len(f)
            else np.full(len(f), -1)
        )
        complete = (f["line_code"].notna() & f["track"].notna()).to_numpy()
        assert codes.grid_rows(t).tolist() == np.where(complete, want, -1).tolist()


def line_network(seed: int) -> Network:
    """Three lines of two tracks on a 20 m grid (km 0–2000, each its own wiggle); declared
    tracks along them between random km (some off the grid, some of a line and track without
    a grid: L4; L3 has only its implied tracks), crossovers of track_points, balises by line,
    track and km (every fourth before km 0: on no track; every fifth with a track id)."""
    rng = np.random.default_rng(seed)
    gis = []
    for li, line in enumerate(("L1", "L2", "L3")):
        for ti, tr in enumerate(("U", "D")):
            km = np.arange(0.0, 2001.0, 20.0)
            gis.append(
                pd.DataFrame(
                    {
                        "line_code": line,
                        "track": tr,
                        "km_m": km,
                        "lat": 35.0 + li * 0.1 + ti * 4e-5 + 1e-6 * np.sin(km / (100.0 + 50 * li)),
                        "lon": 139.0 + km / 91_000.0,
                    }
                )
            )
    tracks: list[tuple[str, str | None, str | None, str, float, float, float]] = []
    k = 0
    for line in ("L1", "L2", "L4"):
        for tr in ("U", "D"):
            cuts = np.sort(rng.uniform(0.0, 2000.0, 3))
            for a, b in zip(np.r_[0.0, cuts], np.r_[cuts, 2000.0], strict=True):
                tracks.append((f"T{k}", line, tr, "main", a if k % 2 else b, b if k % 2 else a, abs(b - a)))
                k += 1
    for j in range(3):
        tracks.append((f"X{j}", None, None, "crossover", np.nan, np.nan, 60.0))
    t = pd.DataFrame(tracks, columns=["track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m"])
    tp = pd.DataFrame(
        {
            "track_id": [f"X{j}" for j in range(3) for _ in range(4)],
            "pos_m": np.tile([0.0, 20.0, 40.0, 60.0], 3),
            "lat": 35.0 + rng.uniform(0, 1e-4, 12),
            "lon": 139.0 + rng.uniform(0, 1e-3, 12),
            "km_m": np.nan,
        }
    )
    n_b = 30
    bal = pd.DataFrame(
        {
            "balise_id": [f"B{i}" for i in range(n_b)],
            "kind": "G",
            "line_code": rng.choice(["L1", "L2", "L3", "L4"], n_b),
            "track": rng.choice(["U", "D"], n_b),
            "km_actual_m": np.where(np.arange(n_b) % 4 == 0, -30.0, rng.uniform(0.0, 2000.0, n_b)),
            "track_id": [("X1" if i % 7 == 0 else "T3") if i % 5 == 0 else None for i in range(n_b)],
        }
    )
    frames = {"gis": pd.concat(gis, ignore_index=True), "tracks": t, "track_points": tp, BALISES.name: bal}
    tables = {x.name: canonical(x, frames[x.name]) if x.name in frames else empty_frame(x) for x in DB_TABLES}
    return Network(tables, origin="test")


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000))
def test_geometry_by_codes_is_geometry_by_ids(seed: int) -> None:
    """The track geometry of :func:`all_tracks` (grid rows and track_points groups by the
    network's codes) equals that of a copy of it (looked up by text, as before), bit for bit."""
    net = line_network(seed)
    assert "start" in grid_extents(net).columns  # the grid as read from a DB: the coded path
    tracks = all_tracks(net)
    ext = grid_extents(net)
    grid = pd.MultiIndex.from_arrays([ext["line_code"].astype(object), ext["track"].astype(object)])
    pairs = pd.MultiIndex.from_arrays([tracks["line_code"].astype(object), tracks["track"].astype(object)])
    assert tracks["implied"].sum() == 2  # L3's two
    assert track_codes(net).line_tracks.grid_rows("all_tracks").tolist() == grid.get_indexer(pairs).tolist()
    coded, by_text = track_geometry(net, tracks), track_geometry(net, tracks.copy())
    pd.testing.assert_frame_equal(coded, by_text, check_exact=True)
    on_grid = (tracks["line_code"] != "L4").to_numpy(dtype=bool, na_value=True)  # L4: no grid
    assert coded["geo_length_m"].notna().to_numpy().tolist() == on_grid.tolist()


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000))
def test_balises_placed_by_codes_as_by_the_merge(seed: int) -> None:
    """Balises without a track id: the track :func:`locate` gives them (the sorted search on
    the shared codes) is the one the merge of their line, track and km finds."""
    net = line_network(seed)
    tr, b = all_tracks(net), net.balises
    tid, pos = locate(net)
    mask = (tr["line_code"].notna() & tr["km_begin_m"].notna() & tr["km_end_m"].notna()).to_numpy()
    free = np.flatnonzero(b["track_id"].isna().to_numpy())
    along = tr[mask]
    km = b["km_actual_m"].to_numpy(float)[free]
    merged = _by_km_merge(along, b["line_code"].to_numpy(object)[free], b["track"].to_numpy(object)[free], km)
    assert [None if pd.isna(x) else x for x in tid[free]] == [None if pd.isna(x) else x for x in merged]
    pairs = track_codes(net).line_tracks
    best = _by_km(along, pairs.of["all_tracks"][mask], pairs.of[BALISES.name][free], km)
    assert best is not None  # the sorted search, not the merge, placed them
    placed = [x for x in merged if x is not None]
    assert placed and len(placed) < len(free)  # some before km 0: on no track
    known = np.flatnonzero(b["track_id"].notna().to_numpy())
    assert tid[known].tolist() == b["track_id"].iloc[known].tolist()
    assert np.isfinite(pos[free]).sum() == len(placed)


@settings(max_examples=60, deadline=None)
@given(
    st.lists(
        st.tuples(
            st.sampled_from([1.0, 2.0]),
            st.sampled_from([5.0, 6.0]),
            st.one_of(st.none(), st.sampled_from(["T10", "T9", "X", "T1"])),
            st.one_of(st.just(np.nan), st.sampled_from([0.0, -0.0, 3.0, 90.0])),
            st.one_of(st.just(np.nan), st.sampled_from([100.0, 103.0, 300.0])),
        ),
        max_size=14,
    )
)
def test_places_in_the_order_of_the_text_sort(rows: list[tuple[float, float, str | None, float, float]]) -> None:
    """The balises of :func:`_places` ordered (by the track id's rank) as the sort of the
    columns with the ids as text did (stable; NaN km last, a missing id as the empty text)."""
    n = len(rows)
    b = pd.DataFrame(
        {
            "nid_c": [r[0] for r in rows],
            "nid_bg": [r[1] for r in rows],
            "n_pig": 0.0,
            "n_total": 1.0,
            "km_actual_m": [r[4] for r in rows],
        },
        index=pd.RangeIndex(n),
    )
    tid = np.array([r[2] for r in rows], dtype=object)
    pos = np.array([r[3] for r in rows], dtype=float)
    got = _places(b, tid, pos, np.ones(n, dtype=bool), ValidationConfig())
    ref = pd.DataFrame(
        {
            "row": np.arange(n),
            "nid_c": b["nid_c"],
            "nid_bg": b["nid_bg"],
            "track_id": pd.Series(tid, dtype=object).fillna(""),
            "pos": np.nan_to_num(pos, nan=np.inf),
            "km": b["km_actual_m"],
        }
    ).sort_values(["nid_c", "nid_bg", "track_id", "pos", "km"], kind="stable")
    assert got["row"].tolist() == ref["row"].tolist()
    far = ref["track_id"].to_numpy(dtype=object)
    where = np.where(np.isfinite(ref["pos"]), ref["pos"], ref["km"])
    ident = ref[["nid_c", "nid_bg"]].to_numpy()
    new = np.r_[True, np.any(ident[1:] != ident[:-1], axis=1)] if n else np.zeros(0, dtype=bool)
    cut = np.r_[True, (far[1:] != far[:-1]) | (np.abs(np.diff(where)) > ValidationConfig().group_span_m)] if n else new
    assert got["place"].tolist() == (np.cumsum(new | cut) - 1).tolist()


def test_implied_tracks_keep_their_grid_rows() -> None:
    """Implied tracks are sorted by id ("A1:D" < "A:D": ':' sorts after '1') but the grid by
    line and track: each implied row's code is still that of its own grid; a line whose
    track is declared implies nothing."""
    gis = pd.DataFrame(
        [(line, tr, 20.0 * i, 35.0, 139.0 + i * 1e-4) for line in ("A", "A1", "B") for tr in "DU" for i in range(3)],
        columns=["line_code", "track", "km_m", "lat", "lon"],
    )
    decl = pd.DataFrame(
        [("T", "B", "D", "main", 0.0, 40.0, 40.0)],
        columns=["track_id", "line_code", "track", "kind", "km_begin_m", "km_end_m", "length_m"],
    )
    frames = {"gis": gis, "tracks": decl}
    net = Network({x.name: canonical(x, frames[x.name]) if x.name in frames else empty_frame(x) for x in DB_TABLES})
    tracks = all_tracks(net)
    assert tracks["track_id"].tolist() == ["T", "A1:D", "A1:U", "A:D", "A:U", "B:U"]
    # grid rows: A/D 0, A/U 1, A1/D 2, A1/U 3, B/D 4, B/U 5
    assert track_codes(net).line_tracks.grid_rows("all_tracks").tolist() == [4, 2, 3, 0, 1, 5]
