"""Balise rules on a network: ETCS balise groups (SPEC §8.2, SUBSET-026 §3.4, §7: NID_C,
NID_BG, N_PIG, N_TOTAL) and identification along routes (SPEC §8.1, §3 "balise.ambiguous").

A balise stands on a track (``track_id``, or else the track of its line and U/D/S track
whose km range holds its ``km_actual_m``) at the distance from the track's begin where its
km lies (|km − km at begin| along a line grid; interpolated in ``track_points.km_m``
elsewhere). The rows of one group identity (NID_C, NID_BG) on one track within
``group_span_m`` of each other are one *place* of the group.

* ``balise.group_fields`` (error) — a G row without nid_c, nid_bg, n_pig or n_total. Fix:
  fill them from the balise's telegram data.
* ``balise.group_members`` (error) — within a place: two balises with the same N_PIG, an
  N_PIG ≥ N_TOTAL, N_TOTAL differing between its balises or not equal to the number of
  balises. Fix: the group's rows.
* ``balise.group_duplicate`` (error) — one group identity at two places (NID_C:NID_BG must be
  unique: a group read is an absolute fix) that lie farther apart than the identification
  window along every route. Fix: the identity of one of them.
* ``topology.balise_ambiguous`` (error) — two groups of the same identity, or two C balises
  with the same signal type governed by different initial pairs (the same pair's are
  ``balise.ambiguous``), reachable from each other along a route of the network within the
  identification window ``id_window_m``: after a switch the onboard unit cannot tell them
  apart. Fix: another identity or signal type for one of them.
* ``topology.balise_position`` (error) — a balise with a track whose km does not lie on that
  track (outside its km range by more than ``km_jump_m``), or that no track holds. Fix: the
  track_id or km.

The route walk starts only at balises whose identity (group identity or C signal type)
occurs at more than one place, runs both ways along the navigable graph in integer codes
(``Topology.graph``: the successors of each track and direction, as ``Topology.next_tracks``) and stops at
the window: linear in the number of such balises, each walk bounded by the tracks within
the window; all walks run at once over arrays (:mod:`dbtools.rules.route_walk`).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
import pandas as pd
import pyarrow as pa
import pyarrow.compute as pc

from dbtools.network import Network
from dbtools.rules.common import Locator, capped, column, isin, py, texts
from dbtools.rules.config import ValidationConfig
from dbtools.rules.route_walk import Walkers, walk
from dbtools.topology import all_tracks, first_rows, topology, track_codes
from schemas.enums import BaliseKind, Severity
from schemas.findings import Finding
from schemas.tables import BALISE_GROUP_COLUMNS, BALISES

T = BALISES.name
F64 = npt.NDArray[np.float64]


def locate(net: Network) -> tuple[npt.NDArray[np.object_], F64]:
    """Track id and distance from the track's begin of every balise (None/NaN: not placed)."""
    b, tr, codes = net.balises, all_tracks(net), track_codes(net)
    n = len(b)
    tid = column(b, "track_id") if "track_id" in b.columns else np.full(n, None, dtype=object)
    km = column(b, "km_actual_m")
    tid = tid.copy()
    at = np.full(n, -1, dtype=np.int64)  # the first row of ``tr`` holding each balise's track id
    if "track_id" in b.columns:
        at = codes.rows(BALISES.name, "track_id")
        tid[at < 0] = None  # unknown: topology.invalid_reference
    free = np.flatnonzero(pd.isna(tid))
    if free.size:
        _along_km(net, tr, free, km[free], tid, at)
    redo = np.flatnonzero(at < 0)  # placed by the merge, or not placed: looked up as before
    if redo.size:
        held = tr["track_id"].dtype
        at[redo] = first_rows(
            tr["track_id"], pd.Series(tid[redo], dtype=held if isinstance(held, pd.StringDtype) else object)
        )
    pos = np.full(n, np.nan)
    has = np.flatnonzero(at >= 0)
    k0, k1 = (tr[k].to_numpy(dtype=float, na_value=np.nan)[at[has]] for k in ("km_begin_m", "km_end_m"))
    lo, hi = np.minimum(k0, k1), np.maximum(k0, k1)
    inside = (km[has] >= lo - 1.0) & (km[has] <= hi + 1.0)
    pos[has[inside]] = np.abs(km[has[inside]] - k0[inside])
    _from_points(net, tid, km, pos)
    return tid, pos


def _along_km(
    net: Network,
    tr: pd.DataFrame,
    free: npt.NDArray[np.intp],
    km: F64,
    tid: npt.NDArray[np.object_],
    at: npt.NDArray[np.int64],
) -> None:
    """Place the balises ``free`` (no known track id; ``km`` theirs) on the tracks of ``tr``
    (:func:`all_tracks`) along their line and track whose km range holds their km: their
    ``tid`` and, by the sorted search, ``at`` (the first row of ``tr`` with that id)."""
    b, codes = net.balises, track_codes(net)
    rows = np.flatnonzero((tr["line_code"].notna() & tr["km_begin_m"].notna() & tr["km_end_m"].notna()).to_numpy())
    along = tr.iloc[rows]
    pairs = codes.line_tracks
    best = _by_km(along, pairs.of["all_tracks"][rows], pairs.of[BALISES.name][free], km)
    if best is None:
        hit = _by_km_merge(along, column(b, "line_code")[free], column(b, "track")[free], km)
        tid[free] = np.where(pd.notna(hit), hit, tid[free])
        return
    ids = texts(along["track_id"])
    found = np.flatnonzero(best < len(along))
    found = found[pd.notna(ids[best[found]])]
    tid[free[found]] = ids[best[found]]
    at[free[found]] = codes.first[codes.of[("all_tracks", "track_id")][rows[best[found]]]]


def _by_km_merge(
    along: pd.DataFrame, line: npt.NDArray[np.object_], track: npt.NDArray[np.object_], km: F64
) -> npt.NDArray[np.object_]:
    """For each (line, track, km): the first track of ``along`` (in its order) of that line
    and track whose km range holds km (±1e-6 m), else None."""
    q = pd.DataFrame({"i": np.arange(len(km)), "line_code": line, "track": track})
    cand = along[["track_id", "line_code", "track", "km_begin_m", "km_end_m"]].astype(
        {"line_code": object, "track": object}
    )
    m = q.merge(cand, on=["line_code", "track"])
    k = km[m["i"].to_numpy()]
    lo = np.minimum(m["km_begin_m"].to_numpy(float), m["km_end_m"].to_numpy(float))
    hi = np.maximum(m["km_begin_m"].to_numpy(float), m["km_end_m"].to_numpy(float))
    m = m[(k >= lo - 1e-6) & (k <= hi + 1e-6)].drop_duplicates("i")
    out = np.full(len(km), None, dtype=object)
    out[m["i"].to_numpy()] = texts(m["track_id"])
    return out


def _by_km(
    along: pd.DataFrame, cg: npt.NDArray[np.int64], qg: npt.NDArray[np.int64], km: F64
) -> npt.NDArray[np.int64] | None:
    """:func:`_by_km_merge` by a sorted search, for the usual case: no key missing, finite km
    ranges of at least 1 mm that do not overlap within a line and track (touching ends may
    both hold a km: the first in ``along`` is taken). ``cg``/``qg``: the line/track codes of
    ``along``'s rows and of the queries (:attr:`dbtools.topology.TrackCodes.line_tracks`, −1:
    missing). The position in ``along`` of each query's track (``len(along)``: none); None
    when that does not hold."""
    if len(along) == 0 or (cg < 0).any() or (qg < 0).any():
        return None
    k0, k1 = column(along, "km_begin_m"), column(along, "km_end_m")
    lo, hi = np.minimum(k0, k1), np.maximum(k0, k1)
    if not (np.isfinite(lo).all() and np.isfinite(hi).all() and np.all(hi - lo >= 1e-3)):
        return None
    order = np.lexsort((lo, cg))
    cg, lo, hi = cg[order], lo[order], hi[order]
    same = cg[1:] == cg[:-1]
    if np.any(same & (lo[1:] < hi[:-1])):
        return None  # overlapping ranges: the general path
    span = float(hi.max() - lo.min()) + 10.0
    base = float(lo.min())
    at = np.searchsorted(cg * span + (lo - 1e-6 - base), qg * span + (km - base), side="right") - 1
    best = np.full(len(km), len(along))  # position in ``along`` of the first track holding km
    for d in (-2, -1, 0, 1):
        j = np.clip(at + d, 0, len(lo) - 1)
        holds = (cg[j] == qg) & (km >= lo[j] - 1e-6) & (km <= hi[j] + 1e-6)
        best = np.where(holds, np.minimum(best, order[j]), best)
    return np.asarray(best, dtype=np.int64)


def _from_points(net: Network, tid: npt.NDArray[np.object_], km: F64, pos: F64) -> None:
    """Position by the km of ``track_points`` (tracks along no line km range)."""
    tp = net.track_points
    todo = np.flatnonzero(np.isnan(pos) & pd.notna(tid))
    if todo.size == 0:
        return
    todo = todo[isin(tid[todo], texts(tp["track_id"]))]
    if todo.size == 0:
        return
    groups = dict(iter(tp[tp["km_m"].notna()].groupby("track_id", observed=True)))
    for i in todo:
        g = groups.get(tid[i])
        if g is None:
            continue
        k, p = g["km_m"].to_numpy(float), g["pos_m"].to_numpy(float)
        order = np.argsort(k)
        if k.size and k.min() - 1.0 <= km[i] <= k.max() + 1.0 and np.all(np.diff(k[order]) > 0):
            pos[i] = float(np.interp(km[i], k[order], p[order]))


def check_balise_network(net: Network, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """The rules of the module doc."""
    b = net.balises
    if b.empty:
        return []
    absent = [c.name for c in BALISE_GROUP_COLUMNS if c.name not in b.columns]
    if absent:  # a frame made before schema version 2 (a v1 DB reads with them empty)
        b = b.assign(**dict.fromkeys(absent, np.nan))
    out: list[Finding] = []
    cap, file = config.max_findings_per_rule, loc.file(T)
    bid, kind = column(b, "balise_id"), column(b, "kind")
    is_g = kind == BaliseKind.G.value
    cols = ("nid_c", "nid_bg", "n_pig", "n_total")
    missing = {c: np.isnan(column(b, c)) for c in cols}
    bad = np.flatnonzero(is_g & np.any([missing[c] for c in cols], axis=0))
    out += capped(
        "balise.group_fields",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "balise.group_fields",
            Severity.ERROR,
            T,
            "G balise needs " + ", ".join(c for c in cols if missing[c][i]),
            keys={"balise_id": py(bid[i])},
            column=next(c for c in cols if missing[c][i]),
            **loc.at(T, i),
        ),
        cap,
        file,
    )
    has_track = net.tracks.size > 0 or ("track_id" in b.columns and b["track_id"].notna().any())
    tid, pos = locate(net) if has_track else (np.full(len(b), None, dtype=object), np.full(len(b), np.nan))
    if has_track:
        out += _unplaced(b, tid, pos, is_g, loc, cap)
    places = _places(b, tid, pos, is_g & ~np.any([missing[c] for c in cols], axis=0), config)
    out += _members(b, places, loc, cap)
    walked = _ambiguous(net, b, tid, pos, places, config, loc, out) if has_track else set()
    out += _duplicates(b, places, walked, config, loc, cap)
    return out


def _unplaced(
    b: pd.DataFrame, tid: npt.NDArray[np.object_], pos: F64, is_g: npt.NDArray[np.bool_], loc: Locator, cap: int
) -> list[Finding]:
    given = column(b, "track_id") if "track_id" in b.columns else np.full(len(b), None, dtype=object)
    bad = np.flatnonzero(np.isnan(pos) & (pd.notna(given) | is_g))
    bid, km = column(b, "balise_id"), column(b, "km_actual_m")
    return capped(
        "topology.balise_position",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "topology.balise_position",
            Severity.ERROR,
            T,
            f"balise {bid[i]} at km {km[i]:g} lies on no track"
            + (f" (km outside track {tid[i]}'s km range)" if pd.notna(tid[i]) else " of its line and track"),
            keys={"balise_id": py(bid[i])},
            column="track_id" if pd.notna(given[i]) else "km_actual_m",
            value=py(km[i]),
            **loc.at(T, i),
        ),
        cap,
        loc.file(T),
    )


def _places(
    b: pd.DataFrame, tid: npt.NDArray[np.object_], pos: F64, ok: npt.NDArray[np.bool_], config: ValidationConfig
) -> pd.DataFrame:
    """Rows of complete G balises with ``place`` (id of one place of one identity)."""
    f = pd.DataFrame(
        {
            "row": np.flatnonzero(ok),
            "nid_c": column(b, "nid_c")[ok],
            "nid_bg": column(b, "nid_bg")[ok],
            "n_pig": column(b, "n_pig")[ok],
            "n_total": column(b, "n_total")[ok],
            "track_id": pd.Series(tid[ok], dtype=object).fillna(""),
            "pos": np.nan_to_num(pos[ok], nan=np.inf),
            "km": column(b, "km_actual_m")[ok],
        }
    )
    # sorted by nid_c, nid_bg, track id (its text's rank: no object sort), pos, km — stably
    rank = np.asarray(pc.rank(pa.array(f["track_id"].to_numpy(), type=pa.string()), tiebreaker="dense"), dtype=np.int64)
    cols = [f[k].to_numpy(dtype=float) for k in ("km", "pos")]
    order = np.lexsort((*cols, rank, f["nid_bg"].to_numpy(dtype=float), f["nid_c"].to_numpy(dtype=float)))
    f = f.iloc[order]
    ident = f[["nid_c", "nid_bg"]].to_numpy()
    new_id = np.r_[True, np.any(ident[1:] != ident[:-1], axis=1)] if len(f) else np.zeros(0, dtype=bool)
    tr = rank[order]
    where = np.where(np.isfinite(f["pos"].to_numpy()), f["pos"].to_numpy(), f["km"].to_numpy())
    far = np.r_[True, (tr[1:] != tr[:-1]) | (np.abs(np.diff(where)) > config.group_span_m)] if len(f) else new_id
    f["place"] = np.cumsum(new_id | far) - 1
    return f


def _members(b: pd.DataFrame, places: pd.DataFrame, loc: Locator, cap: int) -> list[Finding]:
    places = places.assign(pig_dup=places.duplicated(["place", "n_pig"]).to_numpy())
    g = places.groupby("place")
    stats = g.agg(
        n=("row", "size"),
        row=("row", "first"),
        tot_lo=("n_total", "min"),
        tot_hi=("n_total", "max"),
        pig_max=("n_pig", "max"),
        pig_dup=("pig_dup", "any"),
        nid_c=("nid_c", "first"),
        nid_bg=("nid_bg", "first"),
    )
    bad = stats[
        stats["pig_dup"]
        | (stats["pig_max"] >= stats["tot_hi"])
        | (stats["tot_lo"] != stats["tot_hi"])
        | (stats["tot_hi"] != stats["n"])
    ].reset_index(drop=True)

    def why(r: pd.Series) -> str:
        parts = []
        if r["pig_dup"]:
            parts.append("two balises share one N_PIG")
        if r["pig_max"] >= r["tot_hi"]:
            parts.append(f"N_PIG {int(r['pig_max'])} is not below N_TOTAL {int(r['tot_hi'])}")
        if r["tot_lo"] != r["tot_hi"]:
            parts.append(f"N_TOTAL differs between its balises ({int(r['tot_lo'])}–{int(r['tot_hi'])})")
        elif r["tot_hi"] != r["n"]:
            parts.append(f"N_TOTAL is {int(r['tot_hi'])} but the group has {int(r['n'])} balise(s)")
        return "; ".join(parts)

    bid = column(b, "balise_id")
    return capped(
        "balise.group_members",
        Severity.ERROR,
        T,
        np.arange(len(bad)),
        lambda j: Finding(
            "balise.group_members",
            Severity.ERROR,
            T,
            f"group {int(bad['nid_c'][j])}:{int(bad['nid_bg'][j])} (balise {bid[int(bad['row'][j])]}…): "
            + why(bad.iloc[j]),
            keys={"nid_c": int(bad["nid_c"][j]), "nid_bg": int(bad["nid_bg"][j])},
            **loc.at(T, int(bad["row"][j])),
        ),
        cap,
        loc.file(T),
    )


def _duplicates(
    b: pd.DataFrame,
    places: pd.DataFrame,
    walked: set[tuple[int, int]],
    config: ValidationConfig,
    loc: Locator,
    cap: int,
) -> list[Finding]:
    first = places.drop_duplicates("place")
    first = first[first.duplicated(["nid_c", "nid_bg"], keep=False)]
    bid = column(b, "balise_id")
    hits: list[tuple[int, int, str]] = []
    for _, grp in first.groupby(["nid_c", "nid_bg"]):
        rows = grp["row"].to_numpy()
        for other in rows[1:]:
            pair = (min(int(rows[0]), int(other)), max(int(rows[0]), int(other)))
            if pair not in walked:
                hits.append((int(other), int(rows[0]), f"{int(grp['nid_c'].iloc[0])}:{int(grp['nid_bg'].iloc[0])}"))
    return capped(
        "balise.group_duplicate",
        Severity.ERROR,
        T,
        np.arange(len(hits)),
        lambda j: Finding(
            "balise.group_duplicate",
            Severity.ERROR,
            T,
            f"group identity {hits[j][2]} of balise {bid[hits[j][0]]} is already used by balise {bid[hits[j][1]]} at "
            "another place: a group read must name one place",
            keys={"balise_id": py(bid[hits[j][0]]), "other_balise_id": py(bid[hits[j][1]])},
            value=hits[j][2],
            **loc.at(T, hits[j][0]),
        ),
        cap,
        loc.file(T),
    )


def _ambiguous(
    net: Network,
    b: pd.DataFrame,
    tid: npt.NDArray[np.object_],
    pos: F64,
    places: pd.DataFrame,
    config: ValidationConfig,
    loc: Locator,
    out: list[Finding],
) -> set[tuple[int, int]]:
    """The route walk (module doc); returns the (row, row) pairs it reported."""
    kind, sig = column(b, "kind"), column(b, "signal_type")
    found = _walk(net, _walkers(places, kind, sig, tid, pos), tid, pos, _pair_codes(b), config.id_window_m)
    w = config.id_window_m

    bid = column(b, "balise_id")
    hits = sorted(found)
    out += capped(
        "topology.balise_ambiguous",
        Severity.ERROR,
        T,
        np.arange(len(hits)),
        lambda j: Finding(
            "topology.balise_ambiguous",
            Severity.ERROR,
            T,
            f"balises {bid[hits[j][0]]} and {bid[hits[j][1]]} carry the same "
            + ("group identity" if kind[hits[j][0]] == BaliseKind.G.value else f"signal type '{sig[hits[j][0]]}'")
            + f" and are {found[hits[j]]:.1f} m apart along a route (identification window {w:g} m)",
            keys={"balise_id": py(bid[hits[j][1]]), "other_balise_id": py(bid[hits[j][0]])},
            value=round(float(found[hits[j]]), 3),
            limit=w,
            **loc.at(T, hits[j][1]),
        ),
        config.max_findings_per_rule,
        loc.file(T),
    )
    return set(hits)


def _walkers(
    places: pd.DataFrame,
    kind: npt.NDArray[np.object_],
    sig: npt.NDArray[np.object_],
    tid: npt.NDArray[np.object_],
    pos: F64,
) -> Walkers:
    """One walker per place of a G identity (its first row; the identity NID_C:NID_BG as whole
    numbers), then one per C balise with a signal type (the identity its signal type), kept
    where the identity has more than one walker and the balise is placed on a track."""
    reps = places.drop_duplicates("place")
    g_rows = reps["row"].to_numpy(dtype=np.int64)
    whole = pd.MultiIndex.from_arrays([np.trunc(reps[k].to_numpy(dtype=float)) for k in ("nid_c", "nid_bg")])
    g_ident, g_uniq = pd.factorize(whole)
    c_rows = np.flatnonzero((kind == BaliseKind.C.value) & pd.notna(sig))
    c_ident, _ = pd.factorize(pd.Index(np.array([str(x) for x in sig[c_rows]], dtype=object)))
    rows = np.concatenate([g_rows, c_rows]).astype(np.int64)
    ident = np.concatenate([g_ident, len(g_uniq) + c_ident]).astype(np.int64)
    is_c = np.r_[np.zeros(len(g_rows), dtype=bool), np.ones(len(c_rows), dtype=bool)]
    placed = pd.notna(tid) & np.isfinite(pos)
    keep = (np.bincount(ident, minlength=1)[ident] > 1) & np.asarray(placed, dtype=bool)[rows]
    return Walkers(rows[keep], ident[keep], is_c[keep])


def _pair_codes(b: pd.DataFrame) -> list[int]:
    """(line, station, track) of each balise as one integer: equal triples (a missing part
    equal to a missing part) get equal codes."""
    pair_code = np.zeros(len(b), dtype=np.int64)
    for k in ("line_code", "station_code", "track"):
        code, uniq = pd.factorize(b[k], use_na_sentinel=False)
        pair_code = pair_code * (len(uniq) + 1) + code
    return [int(x) for x in pair_code.tolist()]


def _walk(
    net: Network, walkers: Walkers, tid: npt.NDArray[np.object_], pos: F64, pair: list[int], w: float
) -> dict[tuple[int, int], float]:
    """The route walk of each walker both ways within ``w`` (:mod:`dbtools.rules.route_walk`):
    (row, row) → the shortest route distance found between two balises of one identity (C
    balises of the same (line, station, track) ``pair`` code excepted)."""
    g = topology(net).graph
    at = np.full(len(tid), -1, dtype=np.int64)
    at[walkers.rows] = g.codes(tid[walkers.rows])  # every located balise's track is one of the graph
    return walk(g, walkers, at, pos, pair, w)
