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

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from dbtools.network import Network, canonical
from schemas.enums import Navigability, TrackEnd, TrackKind
from schemas.network import NETWORK_TRACKS

BEGIN, END = TrackEnd.BEGIN.value, TrackEnd.END.value


def implied_track_id(line_code: str, track: str) -> str:
    """The id of the track a line grid implies where no declared track covers it."""
    return f"{line_code}:{track}"


def _grid_extents(gis: pd.DataFrame) -> pd.DataFrame:
    """Lowest and highest km of each (line_code, track) of the grid."""
    if gis.empty:
        return pd.DataFrame({"line_code": [], "track": [], "km_lo": [], "km_hi": []})
    g = gis.groupby(["line_code", "track"], sort=True, observed=True)["km_m"].agg(["min", "max"]).reset_index()
    return g.rename(columns={"min": "km_lo", "max": "km_hi"})


def all_tracks(net: Network) -> pd.DataFrame:
    """Declared tracks and implied line tracks, in the columns of ``tracks`` plus ``implied``."""

    def build() -> pd.DataFrame:
        declared = net.tracks
        ext = _grid_extents(net.gis)
        covered = set(zip(declared["line_code"].astype(object), declared["track"].astype(object), strict=True))
        keep = [(lc, tr) not in covered for lc, tr in zip(ext["line_code"], ext["track"], strict=True)]
        ext = ext[np.asarray(keep, dtype=bool)] if len(ext) else ext
        implied = pd.DataFrame(
            {
                "track_id": [
                    implied_track_id(str(a), str(b)) for a, b in zip(ext["line_code"], ext["track"], strict=True)
                ],
                "line_code": ext["line_code"].astype(object),
                "track": ext["track"].astype(object),
                "kind": TrackKind.MAIN.value,
                "km_begin_m": ext["km_lo"].astype(float),
                "km_end_m": ext["km_hi"].astype(float),
                "length_m": (ext["km_hi"] - ext["km_lo"]).astype(float),
                "name": None,
            }
        )
        out = pd.concat(
            [declared.assign(implied=False), canonical(NETWORK_TRACKS, implied).assign(implied=True)],
            ignore_index=True,
        )
        return out.reset_index(drop=True)

    return net.cached(("topology", "all_tracks"), build)


@dataclass(frozen=True)
class Exit:
    """Where a train leaving a track end may go: the other track, the end it enters at, the
    direction it then travels on it, and the switch passed (if any)."""

    track_id: str
    end: str
    direction: int
    switch_id: str | None


@dataclass
class Topology:
    """Adjacency of track ends; see the module docstring for the rules."""

    tracks: pd.DataFrame
    exits: dict[tuple[str, str], list[Exit]] = field(default_factory=dict)
    """(track_id, end) → where a train leaving there may go."""
    joined: dict[tuple[str, str], list[tuple[str, str, str]]] = field(default_factory=dict)
    """(track_id, end) → every (other track, other end, navigability as seen from here)
    connected there, navigable or not."""

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


def topology(net: Network) -> Topology:
    """The graph of the network's track ends (built once per loaded network)."""

    def build() -> Topology:
        topo = Topology(all_tracks(net), defaultdict(list), defaultdict(list))
        c = net.connections
        keys = ("track_a", "end_a", "track_b", "end_b", "navigability")
        cols = [c[k].astype(object).where(c[k].notna(), None).to_numpy() for k in keys]
        sw = c["switch_id"].astype(object).where(c["switch_id"].notna(), None).to_numpy()
        joined, exits = topo.joined, topo.exits
        for ta, ea, tb, eb, nav, s in zip(*cols, sw, strict=True):
            switch = None if s is None else str(s)
            joined[(ta, ea)].append((tb, eb, nav))
            joined[(tb, eb)].append((ta, ea, _SEEN_FROM_B.get(nav, nav)))
            if nav in _FORWARD:
                exits[(ta, ea)].append(Exit(tb, eb, 1 if eb == BEGIN else -1, switch))
            if nav in _BACKWARD:
                exits[(tb, eb)].append(Exit(ta, ea, 1 if ea == BEGIN else -1, switch))
        topo.exits, topo.joined = dict(topo.exits), dict(topo.joined)
        return topo

    return net.cached(("topology", "graph"), build)


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
