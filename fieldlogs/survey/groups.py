"""The G balises of European balise groups on a network: their passes, reads and status,
per network track (``track_id``).

A G telegram names its balise by content (NID_C, NID_BG, N_PIG; :mod:`fieldlogs.survey.dbindex`),
so its reads need no place. Its *passes* do: a G balise lies on one track (its ``track_id``),
at a place on that track's coordinate — the line km where the track lies along a line (its
``tracks`` row names a line; the positions there carry km), else the distance from the
track's begin, ``pos_m``, found from its km through the track's ``track_points`` (their
``km_m`` column, linear between them). A run's cycles on one track (determined or
uncertain, one cab direction) form a stretch with coordinate u (km, or pos off a line, as
:mod:`fieldlogs.survey.extract` keeps them); the balise at place p is *passed* when
min(u + m) < p < max(u − m), m the position's margin plus ``pass_margin_m`` [S003 §6 ③:
an unpowered balise shows as a pass without a read], at the cycle whose u is nearest p; it
is *read* when an identified read of it falls in the stretch's time span. A read is always
a pass: a read no such pass holds (read before the position named the track, which is what
a group tells an ambiguous position) counts as a pass of its own.

Status: a G balise along a line is placed like the I1/I2/C balises, by dead reckoning
between its neighbours (:func:`fieldlogs.survey.dbindex.surveyed_balises`,
:mod:`fieldlogs.survey.balises`), with these passes; one on a track off every line (a
crossover: no line km to place it on) gets :func:`fieldlogs.survey.inspection.group_status`
— **missed** when never read on at least ``min_missed_passes`` passes (the rule of the
other balises), otherwise the status of its place by dead reckoning from each run's earlier
reference (:func:`run_placements` here per run, :mod:`fieldlogs.survey.groupfix` over runs).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.masks import run_around
from dbtools.network import Network
from fieldlogs.survey.config import SurveyConfig
from schemas.enums import BaliseKind

FloatArray = npt.NDArray[np.float64]
#: Reads of one balise closer than this in time are one pass; a read this close to a pass is that pass [s].
SAME_PASS_S = 30.0
#: One dead-reckoned read of a G balise off every line (:mod:`fieldlogs.survey.groupfix`).
PLACEMENT_COLUMNS = ("balise_id", "track_id", "t_read", "pos_ref_m", "travel_m", "reader_m", "margin_m")


def group_places(network: Network) -> pd.DataFrame:
    """balise_id, track_id, place (km along a line, else pos along the track; NaN where
    neither is known), off_line (its track lies along no line) and group (NID_C/NID_BG, else
    the balise id) of every G balise with a track (module docstring)."""
    b = network.balises
    empty = pd.DataFrame({"balise_id": [], "track_id": [], "place": [], "off_line": [], "group": []})
    if not len(b) or "track_id" not in b:
        return empty
    g = b[(b["kind"].astype(str) == BaliseKind.G) & b["track_id"].notna()]
    if not len(g):
        return empty
    tid = g["track_id"].astype(str).to_numpy(dtype=object)
    km = g["km_actual_m"].to_numpy(dtype=float)
    place = km.copy()
    t = network.tracks
    on_line = set(t.loc[t["line_code"].notna(), "track_id"].astype(str))
    tp = network.track_points
    for track in set(tid) - on_line:
        at = np.flatnonzero(tid == track)
        k, p = track_km(tp, track)
        inside = (km[at] >= k[0]) & (km[at] <= k[-1]) if k.size >= 2 else np.zeros(at.size, dtype=bool)
        place[at] = np.where(inside, np.interp(km[at], k, p) if k.size >= 2 else np.nan, np.nan)
    ids = g["balise_id"].astype(str).to_numpy(dtype=object)
    group = ids.copy()
    if "nid_c" in g and "nid_bg" in g:
        coded = (g["nid_c"].notna() & g["nid_bg"].notna()).to_numpy()
        nid = [g[c].to_numpy(dtype=float, na_value=np.nan) for c in ("nid_c", "nid_bg")]
        group[coded] = [f"{int(a)}/{int(b)}" for a, b in zip(nid[0][coded], nid[1][coded], strict=True)]
    off = np.array([t not in on_line for t in tid], dtype=bool)
    return pd.DataFrame({"balise_id": ids, "track_id": tid, "place": place, "off_line": off, "group": group})


def track_km(track_points: pd.DataFrame, track: str) -> tuple[FloatArray, FloatArray]:
    """km and pos of a track's ``track_points`` that carry a km, sorted by km (the km ↔ pos
    mapping, linear between them)."""
    tp = track_points
    pts = tp[(tp["track_id"].astype(str) == track) & tp["km_m"].notna()].sort_values("km_m")
    return pts["km_m"].to_numpy(dtype=float), pts["pos_m"].to_numpy(dtype=float)


def group_passes(
    places: pd.DataFrame,
    t: FloatArray,
    u: FloatArray,
    margin: FloatArray,
    track_id: npt.NDArray[np.object_],
    known: npt.NDArray[np.bool_],
    reads: pd.DataFrame,
    cfg: SurveyConfig,
) -> pd.DataFrame:
    """Every pass of one run over a G balise (module docstring; ``reads``: the run's
    identified reads, ``balise_id`` and ``t``): ``balise_id``, ``seg``
    (−1: a stretch of cycles on one track, not a survey segment), ``t_pass``, ``km_pass_m``
    (the balise's place), ``read``."""
    cols: dict[str, list[object]] = {"balise_id": [], "seg": [], "t_pass": [], "km_pass_m": [], "read": []}
    if not len(places) or not t.size:
        return pd.DataFrame(cols)
    key = np.where(known, track_id, "")
    change = np.r_[True, key[1:] != key[:-1]]
    starts = np.flatnonzero(change)
    ends = np.r_[starts[1:], key.size]
    read_t: dict[str, FloatArray] = {}
    for bid, g in reads.groupby("balise_id") if len(reads) else ():
        read_t[str(bid)] = g["t"].to_numpy(dtype=float)
    by_track = {str(k): g for k, g in places.groupby("track_id")}
    m_all = np.where(np.isfinite(margin), margin, np.inf) + cfg.pass_margin_m
    for a, b in zip(starts.tolist(), ends.tolist(), strict=True):
        here = by_track.get(str(key[a])) if key[a] else None
        if here is None:
            continue
        uu, mm = u[a:b], m_all[a:b]
        ok = np.isfinite(uu)
        if not ok.any():
            continue
        p = here["place"].to_numpy(dtype=float)
        passed = np.isfinite(p) & (np.min((uu + mm)[ok]) < p) & (np.max((uu - mm)[ok]) > p)
        for bid, pb in zip(here["balise_id"].to_numpy()[passed], p[passed], strict=True):
            j = a + int(np.nanargmin(np.abs(uu - pb)))
            rt = read_t.get(str(bid), np.zeros(0))
            cols["balise_id"].append(str(bid))
            cols["seg"].append(-1)
            cols["t_pass"].append(float(t[j]))
            cols["km_pass_m"].append(float(pb))
            cols["read"].append(bool(((rt >= t[a]) & (rt <= t[b - 1])).any()))
    _read_passes(cols, read_t, dict(zip(places["balise_id"], places["place"], strict=True)))
    return pd.DataFrame(cols)


def _read_passes(cols: dict[str, list[object]], read_t: dict[str, FloatArray], place: dict[str, float]) -> None:
    """A read is a pass: reads of a balise that no pass above holds (the run read it before
    its position named the track — the group is what told it the track) are added as passes
    of their own, reads closer than :data:`SAME_PASS_S` apart being one."""
    held: dict[str, list[float]] = {}
    for bid, tp, rd in zip(cols["balise_id"], cols["t_pass"], cols["read"], strict=True):
        if rd:
            held.setdefault(str(bid), []).append(float(tp))  # type: ignore[arg-type]
    for bid, times in read_t.items():
        if bid not in place:
            continue
        last = -np.inf
        for tr in np.sort(times).tolist():
            near = any(abs(tr - h) <= SAME_PASS_S for h in held.get(bid, []))
            if not near and tr - last > SAME_PASS_S:
                cols["balise_id"].append(bid)
                cols["seg"].append(-1)
                cols["t_pass"].append(tr)
                cols["km_pass_m"].append(place[bid])
                cols["read"].append(True)
            last = tr


@dataclass(frozen=True)
class TrackTrace:
    """Per cycle of one run: time, travel, place (km, or pos off a line), margin, track, cab,
    and whether the position is known (determined or uncertain)."""

    t: FloatArray
    d: FloatArray
    u: FloatArray
    margin: FloatArray
    track_id: npt.NDArray[np.object_]
    cab: npt.NDArray[np.int64]
    known: npt.NDArray[np.bool_]


def _first_of_pass(times: FloatArray, t_read: float) -> float:
    """The earliest read of the group in the pass holding ``t_read``: reads of the group
    closer than :data:`SAME_PASS_S` in a chain back from it."""
    before = np.sort(times[times <= t_read])[::-1]
    first = t_read
    for tb in before.tolist():
        if first - tb > SAME_PASS_S:
            break
        first = min(first, tb)
    return first


def _motion(tr: TrackTrace, i: int) -> int:
    """σ: the sign of the place's change over the stretch of known cycles on cycle ``i``'s
    track with its cab (0 when it does not move)."""
    a, b = run_around(tr.known & (tr.track_id == tr.track_id[i]) & (tr.cab == tr.cab[i]), i)
    return int(np.sign(tr.u[b] - tr.u[a])) if np.isfinite(tr.u[b] - tr.u[a]) else 0


def run_placements(
    places: pd.DataFrame, tr: TrackTrace, reads: pd.DataFrame, reader_x_m: float, distance_pct: float
) -> pd.DataFrame:
    """One row per identified read of a G balise off every line that has a reference
    (:mod:`fieldlogs.survey.groupfix`): :data:`PLACEMENT_COLUMNS`, the travel σ-signed and
    not yet scaled by the run's wheel scale."""
    cols: dict[str, list[object]] = {c: [] for c in PLACEMENT_COLUMNS}
    off = places[places["off_line"].astype(bool) & np.isfinite(places["place"].to_numpy(dtype=float))]
    if not len(off) or not len(reads) or not tr.t.size:
        return pd.DataFrame(cols)
    track = dict(zip(off["balise_id"], off["track_id"], strict=True))
    group = dict(zip(places["balise_id"], places["group"], strict=True))
    rid = reads["balise_id"].astype(str).to_numpy(dtype=object)
    rt = reads["t"].to_numpy(dtype=float)
    rgroup = np.array([group.get(b, "") for b in rid], dtype=object)
    for bid, t_read in zip(rid, rt, strict=True):
        if bid not in track:
            continue
        i = int(np.searchsorted(tr.t, _first_of_pass(rt[rgroup == group[bid]], float(t_read)), side="left")) - 1
        ok = i >= 0 and tr.known[i] and tr.track_id[i] == track[bid] and np.isfinite([tr.u[i], tr.margin[i]]).all()
        sigma = _motion(tr, i) if ok else 0
        if sigma == 0:
            continue
        dd = float(np.interp(t_read, tr.t, tr.d)) - float(tr.d[i])
        row = (bid, track[bid], float(t_read), float(tr.u[i]), sigma * dd, sigma * int(tr.cab[i]) * reader_x_m)
        for c, v in zip(PLACEMENT_COLUMNS, (*row, float(tr.margin[i]) + distance_pct / 100.0 * abs(dd)), strict=True):
            cols[c].append(v)
    return pd.DataFrame(cols)
