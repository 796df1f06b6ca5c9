"""Track-selective figures of a run against ground truth on a network [Heirich 2016].

The truth stream carries the true track (``track_id``) and the distance along it from its
begin (``pos_m``); the positions carry the claimed ``track_id`` and the ``state``. Per output
cycle i (truth sampled at the cycle's time as :func:`fieldlogs.pipeline.truth.compare_with_truth`
does, the last truth row at or before t):

* travel Δs_i = |v_true(t_i)| · (t_i − t_{i−1}) [m] (0 on the first cycle);
* *parallel*: another track's centreline lies within ``radius_m`` (20 m, Heirich's definition)
  — any track but those a train may pass to or from the true track (a navigable connection):
  the continuation beyond a switch or joint does not count, while the other branch right after
  a facing switch (joined to the true branch by a ``none`` relation) does;
* *selected*: the state is ``determined`` on the true track; *wrong*: ``determined`` on
  another track (a wrong-track claim — must never happen);

and the figures are

    selectivity = Σ_{parallel ∧ selected} Δs / Σ_{parallel} Δs,

ambiguous or undetermined distance counting as not selected. A **facing switch passage** is
a change of the true track from A to B where a train leaving A at that end could have taken
more than one navigable exit (:func:`dbtools.topology.topology`); it is *resolved* at the
first determined cycle at or after the passage: correctly when that cycle's claimed track is
the true one, and the distance after the switch until resolved is the true travel between
the passage and that cycle. A passage followed by no determined cycle stays unresolved.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.track_candidates import find_candidates, segment_tree
from dbtools.gis.track_segments import TrackGeometry, build_geometry
from dbtools.network import Network
from dbtools.topology import BEGIN, END, topology
from schemas.enums import PositionState

F64 = npt.NDArray[np.float64]
Bool = npt.NDArray[np.bool_]
Text = npt.NDArray[np.object_]

#: Another track within this distance makes the true position "parallel track" [m] (Heirich 2016).
PARALLEL_RADIUS_M = 20.0


def _text(frame: pd.DataFrame, column: str) -> npt.NDArray[np.object_]:
    if column not in frame:
        return np.full(len(frame), "", dtype=object)
    return frame[column].astype("string").fillna("").to_numpy(dtype=object)


def _truth_at(positions: pd.DataFrame, truth: pd.DataFrame) -> tuple[F64, npt.NDArray[np.int64]]:
    """Cycle times and, per cycle, the index of the last truth row at or before it."""
    t = positions["t"].to_numpy(dtype=float)
    tt = truth["t"].to_numpy(dtype=float)
    return t, np.clip(np.searchsorted(tt, t, side="right") - 1, 0, max(len(tt) - 1, 0))


def _plane_points(geo: TrackGeometry, track: Text, pos: F64) -> tuple[F64, F64, Bool]:
    """Plane (x, y) of (track_id, pos_m) points by linear interpolation on the track's
    segments; ``known`` is False where the track is not in the network."""
    index = geo.index_of
    k = np.array([index.get(str(tid), -1) for tid in track], dtype=np.int64)
    known = (k >= 0) & np.isfinite(pos)
    x, y = np.full(len(k), np.nan), np.full(len(k), np.nan)
    if not known.any() or len(geo.seg_track) == 0:
        return x, y, known & False
    # segments are grouped per track in track order and by s0 within a track
    order = np.lexsort((geo.s0, geo.seg_track))
    key = geo.seg_track[order] * 1.0e9 + geo.s0[order]
    sel = np.flatnonzero(known)
    q = k[sel] * 1.0e9 + pos[sel]
    j = np.clip(np.searchsorted(key, q, side="right") - 1, 0, len(key) - 1)
    seg = order[j]
    same = geo.seg_track[seg] == k[sel]
    u = np.clip((pos[sel] - geo.s0[seg]) / np.maximum(geo.ds[seg], 1e-12), 0.0, 1.0)
    x[sel] = np.where(same, geo.x0[seg] + u * geo.dx[seg], np.nan)
    y[sel] = np.where(same, geo.y0[seg] + u * geo.dy[seg], np.nan)
    known[sel] &= same
    return x, y, known


def parallel_mask(
    network: Network, track: npt.NDArray[np.object_], pos: F64, radius_m: float = PARALLEL_RADIUS_M
) -> npt.NDArray[np.bool_]:
    """Per true position (track_id, pos_m): does another track, not navigably joined to the
    true one, lie within ``radius_m``?"""
    geo = build_geometry(network)
    x, y, known = _plane_points(geo, track, pos)
    out = np.zeros(len(track), dtype=bool)
    sel = np.flatnonzero(known)
    if not len(sel):
        return out
    cand = find_candidates(geo, segment_tree(geo), x[sel], y[sel], radius_m, max_tracks=len(geo.track_ids))
    fix = np.repeat(np.arange(len(sel)), np.diff(cand.offsets))
    own = np.array([geo.index_of[str(t)] for t in track[sel]], dtype=np.int64)
    joined = _navigably_joined(network, geo)
    other = cand.track != own[fix]
    pair = own[fix] * len(geo.track_ids) + cand.track
    hit = np.zeros(len(sel), dtype=bool)
    np.logical_or.at(hit, fix[other & ~np.isin(pair, joined)], True)
    out[sel] = hit
    return out


def _navigably_joined(network: Network, geo: TrackGeometry) -> npt.NDArray[np.int64]:
    """Codes a·n + b of the track pairs (a, b) a train may pass between (either way)."""
    index, n = geo.index_of, len(geo.track_ids)
    codes = [
        index[a] * n + index[b]
        for (a, _), exits in topology(network).exits.items()
        for e in exits
        for b in (e.track_id,)
        if a in index and b in index
    ]
    codes += [(c % n) * n + c // n for c in codes]
    return np.array(sorted(set(codes)), dtype=np.int64)


def compare_tracks(positions: pd.DataFrame, truth: pd.DataFrame, network: Network) -> pd.DataFrame:
    """Per output cycle: true and claimed track, travel Δs, and the parallel/selected/wrong flags."""
    t, idx = _truth_at(positions, truth)
    true_track = _text(truth, "track_id")[idx]
    true_pos = truth["pos_m"].to_numpy(dtype=float, na_value=np.nan)[idx]
    v = np.abs(truth["speed_mps"].to_numpy(dtype=float, na_value=0.0))[idx]
    ds = np.zeros(len(t))
    ds[1:] = v[1:] * np.diff(t)
    claimed = _text(positions, "track_id")
    determined = positions["state"].to_numpy(dtype=object) == PositionState.DETERMINED.value
    known = true_track != ""
    return pd.DataFrame(
        {
            "t": t,
            "true_track_id": true_track,
            "true_pos_m": true_pos,
            "track_id": claimed,
            "state": positions["state"].to_numpy(dtype=object),
            "ds_m": ds,
            "parallel": parallel_mask(network, true_track, true_pos) & known,
            "selected": determined & known & (claimed == true_track),
            "wrong": determined & known & (claimed != true_track),
        }
    )


def switch_passages(truth: pd.DataFrame, network: Network) -> pd.DataFrame:
    """Switch passages of the true route: t, switch, from and to track, and whether facing.

    A change of the true track from A to B is a passage of a switch when A's end left there has
    more than one navigable exit (*facing*: the train was taken to one of them) or its one exit
    passes a switch (*trailing*: from a branch onto the toe); a change at a plain joint is none."""
    tracks = _text(truth, "track_id")
    pos = truth["pos_m"].to_numpy(dtype=float, na_value=np.nan)
    t = truth["t"].to_numpy(dtype=float)
    topo = topology(network)
    rows: list[dict[str, Any]] = []
    for i in np.flatnonzero((tracks[1:] != tracks[:-1]) & (tracks[1:] != "") & (tracks[:-1] != "")) + 1:
        a, b = str(tracks[i - 1]), str(tracks[i])
        length = _length(network, a)
        # the end left: the nearer one to the last true position on A
        end = END if np.isfinite(length) and abs(length - pos[i - 1]) < abs(pos[i - 1]) else BEGIN
        exits = topo.exits.get((a, end), [])
        switch = next((e.switch_id for e in exits if e.track_id == b), None)
        if len(exits) < 2 and switch is None:
            continue
        rows.append({"t": float(t[i]), "switch_id": switch, "from_track": a, "to_track": b, "facing": len(exits) >= 2})
    return pd.DataFrame(rows, columns=["t", "switch_id", "from_track", "to_track", "facing"]).astype({"facing": bool})


def facing_passages(truth: pd.DataFrame, network: Network) -> pd.DataFrame:
    """Facing switch passages of the true route: t, switch, from and to track
    (:func:`switch_passages` that split the route)."""
    return facing_only(switch_passages(truth, network))


def facing_only(passages: pd.DataFrame) -> pd.DataFrame:
    """The facing ones of :func:`switch_passages`, as :func:`facing_passages` gives them."""
    return passages.loc[passages["facing"], ["t", "switch_id", "from_track", "to_track"]].reset_index(drop=True)


def selectivity_cap(parallel_m: float, passages: int, margin_m: float) -> float:
    """The highest parallel-track selectivity a run of ``parallel_m`` metres of parallel track
    with ``passages`` switch passages on it can reach when every position's along-track margin
    is at least ``margin_m`` at the switches: 1 − 2·n·m / D.

    A claim is determined only when its whole interval [p̂ − m, p̂ + m] lies on one track
    (:mod:`fieldlogs.pipeline.claims`), so it is ambiguous while p̂ is within m of the joint; with
    an error e = p̂ − p that changes little over the passage (the D-GPS bias decorrelates over
    minutes), that is 2m of true travel per passage — parallel track, since right at a switch the
    other branch lies beside the true one — however fast the branch taken is known. The cap
    counts nothing else (run start, resolving a facing switch, fail-safe spells)."""
    if parallel_m <= 0.0:
        return float("nan")
    return max(1.0 - 2.0 * passages * margin_m / parallel_m, 0.0)


def margin_allowed(target: float, parallel_m: float, passages: int) -> float:
    """The largest margin at every switch passage that leaves a selectivity of ``target``
    reachable (the inverse of :func:`selectivity_cap`): (1 − target)·D / (2n) [m]."""
    return float("inf") if passages == 0 else (1.0 - target) * parallel_m / (2.0 * passages)


def _length(network: Network, track_id: str) -> float:
    geo = build_geometry(network)
    k = geo.index_of.get(track_id)
    return float("nan") if k is None else float(geo.length_m[k])


def switch_resolution(cmp: pd.DataFrame, passages: pd.DataFrame) -> pd.DataFrame:
    """Per facing passage: resolved (bool), correct (bool) and the distance after the switch
    until the first determined cycle [m] (NaN when never resolved)."""
    t = cmp["t"].to_numpy(dtype=float)
    determined = (cmp["state"].to_numpy(dtype=object) == PositionState.DETERMINED.value) & (
        cmp["true_track_id"].to_numpy(dtype=object) != ""
    )
    det_idx = np.flatnonzero(determined)
    travelled = np.cumsum(cmp["ds_m"].to_numpy(dtype=float))
    out = passages.copy()
    resolved, correct, dist = [], [], []
    for tp in passages["t"].to_numpy(dtype=float):
        i0 = int(np.searchsorted(t, tp, side="left"))
        j = det_idx[np.searchsorted(det_idx, i0) :]
        if not len(j) or i0 >= len(t):
            resolved.append(False)
            correct.append(False)
            dist.append(float("nan"))
            continue
        k = int(j[0])
        resolved.append(True)
        correct.append(bool(cmp["selected"].iloc[k]))
        dist.append(float(travelled[k] - travelled[i0]))
    out["resolved"] = np.array(resolved, dtype=bool)
    out["correct"] = np.array(correct, dtype=bool)
    out["distance_m"] = np.array(dist, dtype=float)
    return out


@dataclass(frozen=True)
class TrackFigures:
    """Track-selective figures of one or more runs (sums, so runs add up)."""

    parallel_m: float = 0.0
    selected_parallel_m: float = 0.0
    wrong_cycles: int = 0
    determined_cycles: int = 0
    passages: int = 0
    resolved_correct: int = 0
    resolved_wrong: int = 0
    resolution_m: tuple[float, ...] = ()

    @classmethod
    def of(cls, cmp: pd.DataFrame, res: pd.DataFrame) -> TrackFigures:
        par = cmp["parallel"].to_numpy(dtype=bool)
        ds = cmp["ds_m"].to_numpy(dtype=float)
        det = cmp["state"].to_numpy(dtype=object) == PositionState.DETERMINED.value
        ok = res["resolved"].to_numpy(dtype=bool) & res["correct"].to_numpy(dtype=bool)
        bad = res["resolved"].to_numpy(dtype=bool) & ~res["correct"].to_numpy(dtype=bool)
        return cls(
            float(ds[par].sum()),
            float(ds[par & cmp["selected"].to_numpy(dtype=bool)].sum()),
            int(cmp["wrong"].sum()),
            int(det.sum()),
            len(res),
            int(ok.sum()),
            int(bad.sum()),
            tuple(float(d) for d in res["distance_m"].to_numpy(dtype=float)[ok]),
        )

    def __add__(self, other: TrackFigures) -> TrackFigures:
        return TrackFigures(
            self.parallel_m + other.parallel_m,
            self.selected_parallel_m + other.selected_parallel_m,
            self.wrong_cycles + other.wrong_cycles,
            self.determined_cycles + other.determined_cycles,
            self.passages + other.passages,
            self.resolved_correct + other.resolved_correct,
            self.resolved_wrong + other.resolved_wrong,
            self.resolution_m + other.resolution_m,
        )

    def summary(self) -> dict[str, Any]:
        """Selectivity and switch figures as shares (0–1) and metres; None where undefined."""
        return {
            "parallel_km": self.parallel_m / 1000.0,
            "selectivity": self.selected_parallel_m / self.parallel_m if self.parallel_m > 0 else None,
            "wrong_track_cycles": self.wrong_cycles,
            "determined_cycles": self.determined_cycles,
            "facing_switches": self.passages,
            "switches_resolved_correctly": self.resolved_correct / self.passages if self.passages else None,
            "switches_resolved_wrongly": self.resolved_wrong,
            "median_resolution_m": float(np.median(self.resolution_m)) if self.resolution_m else None,
        }


def track_figures(positions: pd.DataFrame, truth: pd.DataFrame, network: Network) -> TrackFigures:
    """The figures of one run (see the module docstring)."""
    cmp = compare_tracks(positions, truth, network)
    return TrackFigures.of(cmp, switch_resolution(cmp, facing_passages(truth, network)))
