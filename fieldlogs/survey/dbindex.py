"""The DB's balises arranged for identifying telegrams by content and place (built once per
loaded network, :meth:`~dbtools.network.Network.cached`).

A telegram carries [S003 §4]: I1 the line code, I2 the station code and the track, C the
signal type. Candidates of a telegram are the DB balises of its kind with those codes (I1:
on its line, any track; I2: on the segment's line with its station and track; C: on the
segment's line/track) whose track's running direction (:func:`schemas.enums.direction_sign`)
is the direction of motion; the nearest in km within the match window is the one read.

On a network the DB also holds the G balises of European balise groups, whose telegram
names its group and place in it (NID_C, NID_BG, N_PIG: unique in the DB, SPEC §8.3): such a
telegram is identified by that content alone, wherever the run is (:meth:`BaliseIndex.identify_group`)
— never an unknown telegram. Every balise has its network track (:attr:`BaliseIndex.track_ids`):
its own ``track_id`` where the DB gives one, else the track of the line grid holding its km
(:func:`dbtools.topology.grid_track_ids`: the implied ``LINE:TRACK`` on a line-only DB).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from dbtools.topology import grid_track_ids
from schemas.enums import BaliseKind, direction_sign

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Group:
    """Balises sharing a look-up key, as arrays."""

    ids: npt.NDArray[np.object_]
    km: FloatArray
    line_code: npt.NDArray[np.object_]
    track: npt.NDArray[np.object_]
    direction: npt.NDArray[np.int64]

    def nearest(self, km: float, motion: int, window: float) -> tuple[str, str, str, float] | None:
        ok = self.direction == motion
        if not ok.any():
            return None
        dist = np.where(ok, np.abs(self.km - km), np.inf)
        j = int(np.argmin(dist))
        if not dist[j] <= window:
            return None
        return str(self.ids[j]), str(self.line_code[j]), str(self.track[j]), float(dist[j])

    def against(self, km: float, motion: int, window: float) -> bool:
        return bool(((self.direction != motion) & (np.abs(self.km - km) <= window)).any())


def _group(frame: pd.DataFrame) -> Group:
    tracks = frame["track"].astype(str).to_numpy(dtype=object)
    return Group(
        frame["balise_id"].astype(str).to_numpy(dtype=object),
        frame["km_actual_m"].to_numpy(dtype=float),
        frame["line_code"].astype(str).to_numpy(dtype=object),
        tracks,
        np.array([direction_sign(t) for t in tracks], dtype=np.int64),
    )


@dataclass(frozen=True)
class BaliseIndex:
    """Look-ups of the module docstring."""

    i1: dict[str, Group]
    """line code → I1 balises."""
    i2: dict[tuple[str, str, str], Group]
    """(line, station, track) → the I2 of that pair."""
    c: dict[tuple[str, str, str], Group]
    """(line, track, signal type) → C balises."""
    tracks: dict[tuple[str, str], Group]
    """(line, track) → every balise on it."""
    groups: dict[tuple[int, int, int], tuple[str, str, str]] = field(default_factory=dict)
    """(NID_C, NID_BG, N_PIG) → (balise id, line, track) of a G balise."""
    track_ids: dict[str, str] = field(default_factory=dict)
    """balise id → its network track (module docstring)."""
    CODES = ("kind", "line_code", "station_code", "track", "signal_type")
    GROUP_CODES = ("nid_c", "nid_bg", "n_pig")

    def identify_group(self, tel: dict[str, Any]) -> tuple[str, str, str] | None:
        """(balise id, line, track) of a G telegram's balise by its NID_C, NID_BG and N_PIG, or None."""
        try:
            key = (int(tel["nid_c"]), int(tel["nid_bg"]), int(tel["n_pig"]))
        except (KeyError, TypeError, ValueError):
            return None
        return self.groups.get(key)

    def _group_for(self, tel: dict[str, Any], line: str, track: str) -> Group | None:
        kind = tel["kind"]
        if kind == BaliseKind.I1:
            return self.i1.get(tel["tel_line_code"])
        if kind == BaliseKind.I2:
            return self.i2.get((line, tel["tel_station_code"], tel["tel_track"]))
        if kind == BaliseKind.C:
            return self.c.get((line, track, tel["tel_signal_type"]))
        return None

    def identify(
        self, tel: dict[str, Any], line: str, track: str, motion: int, window: float
    ) -> tuple[str, str, str, float] | None:
        """(balise id, line, track, |Δkm|) of the balise read, or None."""
        group = self._group_for(tel, line, track)
        return None if group is None else group.nearest(float(tel["km_est_m"]), motion, window)

    def against(self, tel: dict[str, Any], line: str, motion: int, window: float = 50.0) -> bool:
        """A balise with this content lies here but on a track running the other way."""
        group = self._group_for(tel, line, str(tel.get("track") or ""))
        return group is not None and group.against(float(tel["km_est_m"]), motion, window)

    def on_track(self, line: str, track: str, motion: int) -> Group | None:
        """Balises of a line/track, when its running direction is ``motion``."""
        group = self.tracks.get((line, track))
        if group is None or direction_sign(track) != motion:
            return None
        return group


def balise_index(network: Network) -> BaliseIndex:
    """Build the look-ups from the DB's balise table."""
    groups, track_ids = _network_keys(network)
    b = network.s003_balises
    if not len(b):
        return BaliseIndex({}, {}, {}, {}, groups, track_ids)
    b = b.assign(
        line_code=b["line_code"].astype(str),
        track=b["track"].astype(str),
        station_code=b["station_code"].astype(str),
        signal_type=b["signal_type"].astype(object).where(b["signal_type"].notna(), "").astype(str),
        kind=b["kind"].astype(str),
    )
    i1 = {str(k): _group(g) for k, g in b[b["kind"] == BaliseKind.I1].groupby("line_code")}
    i2 = {
        (str(k[0]), str(k[1]), str(k[2])): _group(g)
        for k, g in b[b["kind"] == BaliseKind.I2].groupby(["line_code", "station_code", "track"])
    }
    c = {
        (str(k[0]), str(k[1]), str(k[2])): _group(g)
        for k, g in b[b["kind"] == BaliseKind.C].groupby(["line_code", "track", "signal_type"])
    }
    tracks = {(str(k[0]), str(k[1])): _group(g) for k, g in b.groupby(["line_code", "track"])}
    return BaliseIndex(i1, i2, c, tracks, groups, track_ids)


def surveyed_balises(network: Network) -> pd.DataFrame:
    """The balises the survey places by dead reckoning between their neighbours: the I1/I2/C
    ones, and the G balises of groups that lie along a line — their line and local track
    from their row, or where it names none from their track's ``tracks`` row (a station
    track along the line: ``0420-3`` is track ``3``). A G balise on a track off every line
    (a crossover) is left out: its passes and reads are counted (:mod:`fieldlogs.survey.groups`)."""

    def build() -> pd.DataFrame:
        b = network.s003_balises
        g = _placed_groups(network)
        return b if not len(g) else pd.concat([b, g], ignore_index=True)

    return network.cached("survey_surveyed_balises", build)


def _placed_groups(network: Network) -> pd.DataFrame:
    b = network.balises
    g = b[b["kind"].astype(str) == BaliseKind.G] if len(b) else b
    if not len(g) or "track_id" not in g:
        return g.iloc[0:0]
    t = network.tracks
    names = t.assign(track_id=t["track_id"].astype(str)).drop_duplicates("track_id").set_index("track_id")
    tid = g["track_id"].astype(object).where(g["track_id"].notna(), "").astype(str)
    own = g["track"].astype(object).where(g["track"].notna(), "").astype(str).to_numpy(dtype=object)
    named = names["track"].astype(object).reindex(tid).fillna("").astype(str).to_numpy(dtype=object)
    track = np.where(own != "", own, named)
    line = g["line_code"].astype(object).where(g["line_code"].notna(), "").astype(str)
    out = g.assign(track=track, station_code="", signal_type="")
    keep = (line.to_numpy(dtype=object) != "") & (track != "") & np.isfinite(g["km_actual_m"].to_numpy(dtype=float))
    placed: pd.DataFrame = out[np.asarray(keep, dtype=bool)].reset_index(drop=True)
    return placed


def _network_keys(network: Network) -> tuple[dict[tuple[int, int, int], tuple[str, str, str]], dict[str, str]]:
    """The G balises by (NID_C, NID_BG, N_PIG), and every balise's track id (module docstring)."""
    b = network.balises
    if not len(b):
        return {}, {}
    ids = b["balise_id"].astype(str).to_numpy(dtype=object)
    line = b["line_code"].astype(object).where(b["line_code"].notna(), "").astype(str)
    track = b["track"].astype(object).where(b["track"].notna(), "").astype(str)
    tid = grid_track_ids(network, line, track, b["km_actual_m"].to_numpy(dtype=float))
    if "track_id" in b:
        own = b["track_id"].to_numpy(dtype=object, na_value="")
        tid = np.where(own != "", own, tid)
    groups: dict[tuple[int, int, int], tuple[str, str, str]] = {}
    placed = _placed_groups(network).set_index("balise_id")["track"].astype(str).to_dict()
    if all(c in b for c in BaliseIndex.GROUP_CODES):
        g = b[(b["kind"].astype(str) == BaliseKind.G) & b["nid_c"].notna() & b["nid_bg"].notna() & b["n_pig"].notna()]
        g = g.assign(track=[placed.get(str(i), t) for i, t in zip(g["balise_id"], g["track"], strict=True)])
        nid = [g[c].to_numpy(dtype=float).astype(np.int64).tolist() for c in BaliseIndex.GROUP_CODES]
        names = [g[c].astype(object).where(g[c].notna(), "").astype(str).tolist() for c in ("line_code", "track")]
        for i, bid in enumerate(g["balise_id"].astype(str).tolist()):
            groups[(nid[0][i], nid[1][i], nid[2][i])] = (bid, names[0][i], names[1][i])
    return groups, dict(zip(ids.tolist(), [str(t) for t in tid], strict=True))
