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
other balises), otherwise **unverified**, its place not surveyed.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from fieldlogs.survey.config import SurveyConfig
from schemas.enums import BaliseKind

FloatArray = npt.NDArray[np.float64]
#: Reads of one balise closer than this in time are one pass; a read this close to a pass is that pass [s].
SAME_PASS_S = 30.0


def group_places(network: Network) -> pd.DataFrame:
    """balise_id, track_id, place (km along a line, else pos along the track; NaN where
    neither is known) of every G balise with a track (module docstring)."""
    b = network.balises
    empty = pd.DataFrame({"balise_id": [], "track_id": [], "place": []})
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
        pts = tp[(tp["track_id"].astype(str) == track) & tp["km_m"].notna()].sort_values("km_m")
        k, p = pts["km_m"].to_numpy(dtype=float), pts["pos_m"].to_numpy(dtype=float)
        inside = (km[at] >= k[0]) & (km[at] <= k[-1]) if k.size >= 2 else np.zeros(at.size, dtype=bool)
        place[at] = np.where(inside, np.interp(km[at], k, p) if k.size >= 2 else np.nan, np.nan)
    return pd.DataFrame(
        {"balise_id": g["balise_id"].astype(str).to_numpy(dtype=object), "track_id": tid, "place": place}
    )


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
