"""The network of a loaded DB as a graph of track ends (SPEC §8.1).

Tracks are the declared ``tracks`` plus one *implied* track for every line and track of the
``gis`` grid that no declared track covers: a line-only DB (U/D/S) is a network of one track
per line and track, with no connections. An implied track's id is ``LINE:TRACK``
(:func:`implied_track_id`), its begin at the lowest km of its grid.

Travel on a track is in direction +1 (begin → end, ``pos`` growing) or −1. Leaving a track
at an end, a train may enter every track connected at that end whose connection is
navigable that way: ``both``, ``AB`` from A to B, ``BA`` from B to A; never ``none``. It
enters the other track at the connected end and so travels on it away from that end:
+1 when it entered at the begin, −1 at the end.
"""

from __future__ import annotations

import sys
from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from dbtools.network import Network, canonical_with_index, sorted_by
from dbtools.rules.common import texts
from schemas.enums import Navigability, TrackEnd, TrackKind
from schemas.network import CONNECTIONS, NETWORK_TRACKS, SWITCHES, TRACK_POINTS
from schemas.tables import BALISES

if TYPE_CHECKING:
    from dbtools.gis.index import GridIndex

BEGIN, END = TrackEnd.BEGIN.value, TrackEnd.END.value


def implied_track_id(line_code: str, track: str) -> str:
    """The id of the track a line grid implies where no declared track covers it."""
    return f"{line_code}:{track}"


def grid_track_ids(
    net: Network, line_code: npt.ArrayLike, track: npt.ArrayLike, km: npt.ArrayLike
) -> npt.NDArray[np.object_]:
    """The track id of each point (line_code, track, km) of a line grid: the declared track
    of that line and track whose km span holds it — the one begun last at or below km
    (the first one below its begin, the last one past its end) — else the implied
    ``LINE:TRACK`` (:func:`implied_track_id`). The points are grouped once; one search per
    declared line/track."""
    lc = np.asarray(line_code, dtype=object).astype(str)
    tr = np.asarray(track, dtype=object).astype(str)
    k = np.asarray(km, dtype=float)
    out = np.asarray(np.char.add(np.char.add(lc.astype(str), ":"), tr.astype(str)), dtype=object)
    d = net.tracks
    d = d[d["line_code"].notna() & d["track"].notna()]
    if not len(d) or not out.size:
        return out
    points = pd.Series(out).groupby(out, sort=False).indices  # LINE:TRACK → its points
    for (line, name), g in d.groupby([d["line_code"].astype(str), d["track"].astype(str)], sort=False):
        on = points.get(implied_track_id(str(line), str(name)))
        if on is None:
            continue
        lo = np.fmin(
            g["km_begin_m"].to_numpy(dtype=float, na_value=np.nan), g["km_end_m"].to_numpy(float, na_value=np.nan)
        )
        order = np.argsort(np.where(np.isnan(lo), -np.inf, lo), kind="stable")
        starts = np.where(np.isnan(lo), -np.inf, lo)[order]
        j = np.clip(np.searchsorted(starts, k[on], side="right") - 1, 0, len(order) - 1)
        out[on] = g["track_id"].astype(str).to_numpy(dtype=object)[order][j]
    return out


def grid_extents(net: Network) -> pd.DataFrame:
    """Lowest and highest km of each (line_code, track) of the grid, in (line_code, track)
    order (built once per loaded network); for a grid sorted by line, track and km (as read
    from a DB) also ``start``, the row where each one's run begins."""
    return net.cached(("topology", "grid_extents"), lambda: _grid_extents(net.gis, _whole_grid(net)))


def _whole_grid(net: Network) -> GridIndex | None:
    """The network's grid index when already built and holding every GIS row in frame order:
    its runs of (line, track) are then the grid's (no second factorization of the grid's text)."""
    if "dbtools.gis.index" not in sys.modules:  # no grid index was built (and pyproj stays unloaded)
        return None
    from dbtools.gis.index import built_grid_index

    grid = built_grid_index(net)
    return grid if grid is not None and grid.gis is net.gis and grid.whole_frame else None


def _grid_extents(gis: pd.DataFrame, grid: GridIndex | None = None) -> pd.DataFrame:
    if gis.empty:
        return pd.DataFrame({"line_code": [], "track": [], "km_lo": [], "km_hi": []})
    if grid is not None:  # sorted, every key given: the grid index's runs are the rows' runs
        return pd.DataFrame(
            {
                "start": grid.start,
                "line_code": grid.lines,
                "track": grid.tracks,
                "km_lo": np.fmin.reduceat(grid.km, grid.start),
                "km_hi": np.fmax.reduceat(grid.km, grid.start),
            }
        )
    if sorted_by(gis, ("line_code", "track", "km_m")):  # as read from a DB: runs of rows, no group-by
        line, _ = pd.factorize(gis["line_code"])
        track, _ = pd.factorize(gis["track"])
        start = np.flatnonzero(np.r_[True, (line[1:] != line[:-1]) | (track[1:] != track[:-1])])
        km = gis["km_m"].to_numpy(dtype=float, na_value=np.nan)
        return pd.DataFrame(
            {
                "start": start,
                "line_code": gis["line_code"].iloc[start].to_numpy(),
                "track": gis["track"].iloc[start].to_numpy(),
                "km_lo": np.fmin.reduceat(km, start),
                "km_hi": np.fmax.reduceat(km, start),
            }
        )
    g = gis.groupby(["line_code", "track"], sort=True, observed=True)["km_m"].agg(["min", "max"]).reset_index()
    return g.rename(columns={"min": "km_lo", "max": "km_hi"})


def all_tracks(net: Network) -> pd.DataFrame:
    """Declared tracks and implied line tracks, in the columns of ``tracks`` plus ``implied``."""
    return _all_tracks(net)[0]


def _all_tracks(net: Network) -> tuple[pd.DataFrame, npt.NDArray[np.int64]]:
    """:func:`all_tracks` and the row of :func:`grid_extents` behind each implied track
    (built once per loaded network)."""

    def build() -> tuple[pd.DataFrame, npt.NDArray[np.int64]]:
        declared = net.tracks
        ext = grid_extents(net)
        kept = np.flatnonzero(_implied(net)) if len(ext) else np.arange(len(ext))
        ext = ext.iloc[kept]
        implied = pd.DataFrame(
            {
                "track_id": [
                    implied_track_id(str(a), str(b)) for a, b in zip(ext["line_code"], ext["track"], strict=True)
                ],
                "line_code": ext["line_code"].to_numpy(dtype=object),
                "track": ext["track"].to_numpy(dtype=object),
                "kind": TrackKind.MAIN.value,
                "km_begin_m": ext["km_lo"].to_numpy(dtype=float),
                "km_end_m": ext["km_hi"].to_numpy(dtype=float),
                "length_m": (ext["km_hi"] - ext["km_lo"]).to_numpy(dtype=float),
                "name": None,
            },
            index=pd.Index(kept),
        )
        implied, rows = canonical_with_index(NETWORK_TRACKS, implied)  # sorted by id: each one's grid row
        out = pd.concat([declared.assign(implied=False), implied.assign(implied=True)], ignore_index=True)
        return out.reset_index(drop=True), np.asarray(rows, dtype=np.int64)

    return net.cached(("topology", "all_tracks"), build)


def _line_track_codes(net: Network) -> LineTrackCodes:
    """The (line, track) pairs of the grid, the declared tracks and the balises coded once
    (:class:`LineTrackCodes`; built once per loaded network)."""
    return net.cached(
        ("topology", "line_track_codes"),
        lambda: LineTrackCodes.of_frames(
            {"grid_extents": grid_extents(net), NETWORK_TRACKS.name: net.tracks, BALISES.name: net.balises}
        ),
    )


def _implied(net: Network) -> npt.NDArray[np.bool_]:
    """Which rows of :func:`grid_extents` no declared track's line and track covers."""
    codes = _line_track_codes(net)
    covered = np.zeros(len(codes.grid) + 1, dtype=bool)  # the last slot: −1, a missing part
    covered[codes.of[NETWORK_TRACKS.name]] = True
    covered[-1] = False
    ext = codes.of["grid_extents"]
    return np.asarray(~covered[ext], dtype=bool)  # −1 reads the last slot: not covered


@dataclass(frozen=True)
class Exit:
    """Where a train leaving a track end may go: the other track, the end it enters at, the
    direction it then travels on it, and the switch passed (if any)."""

    track_id: str
    end: str
    direction: int
    switch_id: str | None


@dataclass(frozen=True)
class Graph:
    """The navigable graph in integer codes, for walks over the whole network.

    Every track id of ``tracks`` and of ``connections`` (a missing id included) has a code:
    ``names[code]``. A *state* ``2 · code + k`` is a train on that track travelling towards
    its end (k = 1, direction +1) or its begin (k = 0, direction −1); the states it may go
    to on leaving there are ``succ[ptr[state]:ptr[state + 1]]`` (CSR), the rules of the
    module docstring. ``length[code]`` is the track's ``length_m`` (the last row of an id
    given twice; 0 for an id no track has)."""

    names: pd.Index
    length: npt.NDArray[np.float64]
    ptr: npt.NDArray[np.int64]
    succ: npt.NDArray[np.int64]

    def codes(self, ids: npt.ArrayLike) -> npt.NDArray[np.int64]:
        """Codes of track ids (−1: no such id)."""
        return np.asarray(self.names.get_indexer(pd.Index(np.asarray(ids, dtype=object))), dtype=np.int64)


class Topology:
    """Adjacency of track ends; see the module docstring for the rules. ``exits`` and
    ``joined`` are dicts keyed by (track_id, end), made on first use; :attr:`graph` holds
    the same navigable adjacency in integer arrays."""

    def __init__(
        self, tracks: pd.DataFrame, connections: pd.DataFrame, codes: Callable[[], TrackCodes] | None = None
    ) -> None:
        """``codes``: the network's :func:`track_codes` (of these tracks and connections), for
        :attr:`graph`; the ids are factorised here without it."""
        self.tracks, self.connections, self._codes = tracks, connections, codes

    @cached_property
    def _cols(self) -> list[npt.NDArray[np.object_]]:
        c = self.connections
        keys = ("track_a", "end_a", "track_b", "end_b", "navigability", "switch_id")
        return [c[k].astype(object).where(c[k].notna(), None).to_numpy() for k in keys]

    @cached_property
    def _dicts(self) -> tuple[dict[tuple[str, str], list[Exit]], dict[tuple[str, str], list[tuple[str, str, str]]]]:
        exits: defaultdict[tuple[str, str], list[Exit]] = defaultdict(list)
        joined: defaultdict[tuple[str, str], list[tuple[str, str, str]]] = defaultdict(list)
        for ta, ea, tb, eb, nav, s in zip(*self._cols, strict=True):
            switch = None if s is None else str(s)
            joined[(ta, ea)].append((tb, eb, nav))
            joined[(tb, eb)].append((ta, ea, _SEEN_FROM_B.get(nav, nav)))
            if nav in _FORWARD:
                exits[(ta, ea)].append(Exit(tb, eb, 1 if eb == BEGIN else -1, switch))
            if nav in _BACKWARD:
                exits[(tb, eb)].append(Exit(ta, ea, 1 if ea == BEGIN else -1, switch))
        return dict(exits), dict(joined)

    @property
    def exits(self) -> dict[tuple[str, str], list[Exit]]:
        """(track_id, end) → where a train leaving there may go."""
        return self._dicts[0]

    @property
    def joined(self) -> dict[tuple[str, str], list[tuple[str, str, str]]]:
        """(track_id, end) → every (other track, other end, navigability as seen from here)
        connected there, navigable or not."""
        return self._dicts[1]

    @cached_property
    def graph(self) -> Graph:
        """The navigable adjacency in codes (:class:`Graph`)."""
        t, c = self.tracks, self.connections
        if self._codes is not None:  # the first three columns the network's codes are made of
            held = self._codes()
            ct, ca, cb = (held.of[key] for key in TRACK_ID_COLUMNS[:3])
            uniq = held.uniques[: 1 + max((int(x.max()) for x in (ct, ca, cb) if len(x)), default=-1)]
        else:
            ids = pd.concat([t["track_id"], c["track_a"], c["track_b"]], ignore_index=True)
            codes, uniq = pd.factorize(ids, use_na_sentinel=False)  # a missing id is one more id
            n_t, n_c = len(t), len(c)
            ct, ca, cb = codes[:n_t], codes[n_t : n_t + n_c], codes[n_t + n_c :]
        names = pd.Index(texts(pd.Series(uniq)), dtype="object")
        length = np.zeros(len(names))
        last = len(ct) - 1 - np.unique(ct[::-1], return_index=True)[1]  # the last row of each id
        length[ct[last]] = t["length_m"].to_numpy(dtype=float, na_value=np.nan)[last]
        nav = c["navigability"]
        end_a, end_b, begin_a, begin_b = (_is(c[k], e) for e in (END, BEGIN) for k in ("end_a", "end_b"))
        leave_a = _is(nav, *_FORWARD) & (begin_a | end_a)
        leave_b = _is(nav, *_BACKWARD) & (begin_b | end_b)
        src = np.concatenate([2 * ca[leave_a] + end_a[leave_a], 2 * cb[leave_b] + end_b[leave_b]])
        dst = np.concatenate([2 * cb[leave_a] + begin_b[leave_a], 2 * ca[leave_b] + begin_a[leave_b]])
        order = np.argsort(src, kind="stable")
        ptr = np.searchsorted(src[order], np.arange(2 * len(names) + 1)).astype(np.int64)
        return Graph(names, length, ptr, dst[order].astype(np.int64))

    @property
    def track_ids(self) -> list[str]:
        return [str(t) for t in self.tracks["track_id"]]

    def next_tracks(self, track_id: str, direction: int) -> list[Exit]:
        """The tracks a train on ``track_id`` travelling ``direction`` may enter next."""
        return self.exits.get((track_id, END if direction > 0 else BEGIN), [])

    def degree(self, track_id: str, end: str) -> int:
        """How many connections meet this track end."""
        return len(self.joined.get((track_id, end), []))


_SEEN_FROM_B = {
    Navigability.A_TO_B.value: Navigability.B_TO_A.value,
    Navigability.B_TO_A.value: Navigability.A_TO_B.value,
}
_FORWARD = frozenset((Navigability.BOTH.value, Navigability.A_TO_B.value))
_BACKWARD = frozenset((Navigability.BOTH.value, Navigability.B_TO_A.value))


def first_rows(ids: pd.Series, values: pd.Series) -> npt.NDArray[np.int64]:
    """For each of ``values``: the first position in ``ids`` holding it (−1: none), by
    Arrow's hash look-up when both are held as Arrow text."""
    to_a, to_b = getattr(ids.array, "__arrow_array__", None), getattr(values.array, "__arrow_array__", None)
    if to_a is not None and to_b is not None:
        a, b = to_a(), to_b()
        if a.type == b.type and (pa.types.is_string(a.type) or pa.types.is_large_string(a.type)):
            at = pc.index_in(b, value_set=a.combine_chunks() if isinstance(a, pa.ChunkedArray) else a)
            return np.asarray(pc.fill_null(at, -1).to_numpy(zero_copy_only=False), dtype=np.int64)
    index = pd.Index(texts(ids), dtype="object")
    first = ~index.duplicated()
    pos = np.flatnonzero(first)
    at = index[first].get_indexer(pd.Index(texts(values), dtype="object"))
    return np.where(at >= 0, pos[np.maximum(at, 0)], -1).astype(np.int64)


#: The switch ports, in the order of the port table (:func:`dbtools.rules.topology_tables.port_table`).
SWITCH_PORT_NAMES = ("a1", "b1", "b2", "a2")

#: Where a track id is named, in the order :func:`track_codes` factorises them (the first
#: three as :attr:`Topology.graph` does: its codes are theirs). ``all_tracks``: the rows of
#: :func:`all_tracks`.
TRACK_ID_COLUMNS = (
    ("all_tracks", "track_id"),
    (CONNECTIONS.name, "track_a"),
    (CONNECTIONS.name, "track_b"),
    *((SWITCHES.name, f"{p}_track") for p in SWITCH_PORT_NAMES),
    (TRACK_POINTS.name, "track_id"),
    (BALISES.name, "track_id"),
)


@dataclass(frozen=True)
class TrackCodes:
    """Every track id the network's tables name, factorised once per loaded network (issue
    30: ≥ 50,000 tracks; each topology and balise rule used to hash the text again): equal
    ids have equal codes, a missing id is one more code (``pd.factorize(…,
    use_na_sentinel=False)`` of the columns of :data:`TRACK_ID_COLUMNS` one after the other,
    codes in order of first appearance). ``of[(table, column)]``: the codes of that column's
    rows (absent: the table has no such column); ``first``/``last``: per code the first/last
    row of :func:`all_tracks` holding it (−1: none); ``uniques[code]``: the id."""

    of: dict[tuple[str, str], npt.NDArray[np.int64]]
    first: npt.NDArray[np.int64]
    last: npt.NDArray[np.int64]
    uniques: pd.Index
    line_track_codes: Callable[[], LineTrackCodes] = field(repr=False, compare=False)

    def rows(self, table: str, column: str) -> npt.NDArray[np.int64]:
        """The first row of :func:`all_tracks` holding each row's id (−1: none)."""
        return np.asarray(self.first[self.of[(table, column)]], dtype=np.int64)

    @cached_property
    def line_tracks(self) -> LineTrackCodes:
        """The (line_code, track) pairs of the tables of :data:`LINE_TRACK_TABLES` (made on
        first use: the track matcher never asks for them)."""
        return self.line_track_codes()


#: Where a (line_code, track) pair is named, in the order :class:`LineTrackCodes` codes them:
#: the rows of :func:`grid_extents`, the declared tracks, the balises (and so every row of
#: :func:`all_tracks`: the declared tracks', then the implied ones' grid rows').
LINE_TRACK_TABLES = ("grid_extents", NETWORK_TRACKS.name, BALISES.name)


@dataclass(frozen=True)
class LineTrackCodes:
    """Every (line_code, track) pair of the tables of :data:`LINE_TRACK_TABLES`, coded once
    per loaded network (issue 30: the grid look-ups of the track geometry, the open-end rule
    and the balises' placement used to build a ``MultiIndex`` of 83,000 text pairs each):
    equal pairs have equal codes (in order of first appearance), −1 where the line or the
    track is missing or the table has no such columns. ``of[table]``: the codes of the
    table's rows; ``grid[code]``: the row of :func:`grid_extents` holding that pair (−1: the
    grid has no such line and track)."""

    of: dict[str, npt.NDArray[np.int64]]
    grid: npt.NDArray[np.int64]

    @staticmethod
    def of_frames(frames: dict[str, pd.DataFrame]) -> LineTrackCodes:
        """The codes of the frames (by table name, :data:`LINE_TRACK_TABLES`): each text
        column factorised once over all the tables, then the pairs of the two codes."""
        named = {t: f for t, f in frames.items() if "line_code" in f.columns and "track" in f.columns}
        of = {t: np.full(len(f), -1, dtype=np.int64) for t, f in frames.items()}
        if not named:
            return LineTrackCodes(of, np.empty(0, dtype=np.int64))
        sizes = [len(f) for f in named.values()]
        line, _ = pd.factorize(pd.concat([f["line_code"] for f in named.values()], ignore_index=True))
        track, tracks = pd.factorize(pd.concat([f["track"] for f in named.values()], ignore_index=True))
        pair = line.astype(np.int64) * (len(tracks) + 1) + track
        ok = (line >= 0) & (track >= 0)
        codes = np.full(len(pair), -1, dtype=np.int64)
        codes[ok], uniques = pd.factorize(pair[ok])
        parts = np.split(codes, np.cumsum(sizes)[:-1])
        of.update(zip(named, parts, strict=True))
        grid = np.full(len(uniques), -1, dtype=np.int64)
        ext = of.get("grid_extents", np.empty(0, dtype=np.int64))
        at = np.flatnonzero(ext >= 0)[::-1]  # the first row of each pair wins
        grid[ext[at]] = at
        return LineTrackCodes(of, grid)

    def with_all_tracks(self, implied: npt.NDArray[np.int64]) -> LineTrackCodes:
        """These codes (of the grid's rows, the declared tracks' and the balises') with those
        of :func:`all_tracks`: the declared tracks', then those of its implied tracks' grid
        rows ``implied``."""
        rows = np.concatenate([self.of[NETWORK_TRACKS.name], self.of["grid_extents"][implied]])
        return LineTrackCodes({**self.of, "all_tracks": rows}, self.grid)

    def grid_rows(self, table: str) -> npt.NDArray[np.int64]:
        """The row of :func:`grid_extents` of each row's line and track (−1: none)."""
        codes = self.of[table]
        return np.where(codes >= 0, self.grid[np.maximum(codes, 0)] if len(self.grid) else -1, -1)


def track_codes(net: Network) -> TrackCodes:
    """The network's :class:`TrackCodes` (built once per loaded network)."""

    def build() -> TrackCodes:
        tables = {**net.tables, "all_tracks": all_tracks(net)}
        named = [(key, tables[key[0]][key[1]]) for key in TRACK_ID_COLUMNS if key[1] in tables[key[0]].columns]
        codes, uniques = pd.factorize(pd.concat([s for _, s in named], ignore_index=True), use_na_sentinel=False)
        parts = np.split(codes.astype(np.int64), np.cumsum([len(s) for _, s in named])[:-1])
        of = {key: part for (key, _), part in zip(named, parts, strict=True)}
        own = of[("all_tracks", "track_id")]
        first, last = np.full(len(uniques), -1, dtype=np.int64), np.full(len(uniques), -1, dtype=np.int64)
        seen, at = np.unique(own, return_index=True)  # the first row of each code
        first[seen] = at
        seen, at = np.unique(own[::-1], return_index=True)
        last[seen] = len(own) - 1 - at
        return TrackCodes(
            of,
            first,
            last,
            uniques,
            lambda: _line_track_codes(net).with_all_tracks(_all_tracks(net)[1]),
        )

    return net.cached(("topology", "track_codes"), build)


def connection_rows(net: Network, tracks: pd.DataFrame) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.int64]]:
    """For every connection: the first row of ``tracks`` holding its ``track_a`` and its
    ``track_b`` (−1: none) — from :func:`track_codes` when ``tracks`` is :func:`all_tracks`
    (the topology rules all ask for it), else one hash look-up of both."""
    if tracks is all_tracks(net):
        codes = track_codes(net)
        return codes.rows(CONNECTIONS.name, "track_a"), codes.rows(CONNECTIONS.name, "track_b")
    c = net.connections
    both = first_rows(tracks["track_id"], pd.concat([c["track_a"], c["track_b"]], ignore_index=True))
    return both[: len(c)], both[len(c) :]


def _is(values: pd.Series, *options: str) -> npt.NDArray[np.bool_]:
    """``values[i]`` is one of the options (False where missing)."""
    return np.asarray(values.isin(list(options)).to_numpy(dtype=bool, na_value=False), dtype=bool)


def topology(net: Network) -> Topology:
    """The graph of the network's track ends (built once per loaded network, shared by the
    rules and the track matcher; its parts are made on first use)."""
    return net.cached(
        ("topology", "graph"), lambda: Topology(all_tracks(net), net.connections, lambda: track_codes(net))
    )


@dataclass(frozen=True)
class Centreline:
    """A track's centreline from begin to end: distance from the begin, lat/lon [deg] and the
    line km where the track has one (NaN elsewhere)."""

    track_id: str
    pos_m: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    km_m: np.ndarray


def centreline(net: Network, track: pd.Series) -> Centreline:
    """The centreline of one row of :func:`all_tracks`: its ``track_points`` when it has
    any, else the ``gis`` grid of its line and track between its end km (ordered from its
    begin; ``pos`` = |km − km at begin|, the grid's km being metres along the track)."""
    tid = str(track["track_id"])
    tp = net.track_points
    own = tp[tp["track_id"] == tid]
    if len(own):
        own = own.sort_values("pos_m")
        return Centreline(
            tid,
            own["pos_m"].to_numpy(float),
            own["lat"].to_numpy(float),
            own["lon"].to_numpy(float),
            own["km_m"].to_numpy(dtype=float, na_value=np.nan),
        )
    empty = np.empty(0)
    if pd.isna(track["line_code"]) or pd.isna(track["km_begin_m"]) or pd.isna(track["km_end_m"]):
        return Centreline(tid, empty, empty, empty, empty)
    g = _line_grid(net, str(track["line_code"]), str(track["track"]))
    k0, k1 = float(track["km_begin_m"]), float(track["km_end_m"])
    lo, hi = min(k0, k1), max(k0, k1)
    km = g["km_m"].to_numpy(float)
    sel = (km >= lo - 1e-6) & (km <= hi + 1e-6)
    km, lat, lon = km[sel], g["lat"].to_numpy(float)[sel], g["lon"].to_numpy(float)[sel]
    order = np.argsort(km) if k1 >= k0 else np.argsort(-km)
    km, lat, lon = km[order], lat[order], lon[order]
    return Centreline(tid, np.abs(km - k0), lat, lon, km)


def _line_grid(net: Network, line_code: str, track: str) -> pd.DataFrame:
    groups = net.cached(
        ("topology", "gis_groups"),
        lambda: dict(iter(net.gis.groupby(["line_code", "track"], sort=False, observed=True))),
    )
    empty = net.gis.iloc[0:0]
    return groups.get((line_code, track), empty)
