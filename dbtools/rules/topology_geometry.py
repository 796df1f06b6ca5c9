"""The geometric topology rules ``topology.gap``, ``topology.track_length`` and
``topology.crossover_angle`` (documented in :mod:`dbtools.rules.topology`), over the track
geometry of :mod:`dbtools.rules.track_geometry`.

Crossover angle [S001 §8(c); SPEC §8.1]: a crossover leaves the main track at a turnout of
switch number n, whose frog angle is α = atan(1/n). The measured angle is the largest angle
between any chord of the crossover's ``track_points`` and the main track's axis at the switch
(the outward azimuth of the non-crossover track joined there, taken modulo 180°); it is
compared with α as the ratio measured/α.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network, sorted_by
from dbtools.rules.common import Locator, capped, column, py, texts
from dbtools.rules.config import ValidationConfig
from dbtools.rules.track_geometry import (
    chord_azimuths,
    coded_chord_azimuths,
    distance_m,
    end_coordinates,
    is_begin,
    track_geometry,
)
from dbtools.topology import BEGIN, connection_rows, first_rows, track_codes
from schemas.enums import Severity, TrackKind
from schemas.findings import Finding
from schemas.network import CONNECTIONS, NETWORK_TRACKS


def check_geometry(net: Network, tracks: pd.DataFrame, config: ValidationConfig, loc: Locator) -> list[Finding]:
    ref = _crossover_ends(net, tracks)
    axes = np.zeros(len(tracks), dtype=bool)  # the only azimuths the rules use: the crossovers' main-track axes
    if ref is not None:
        axes[ref["rows"].to_numpy()] = True
    key = ("rules", "track_geometry", config.length_tolerance_m, config.length_tolerance_rel)
    geo = net.cached(key, lambda: track_geometry(net, tracks, partial(_length_in_doubt, net, config), axes))
    return (
        _gaps(net, tracks, geo, config, loc)
        + _lengths(net, geo, config, loc)
        + _crossover_angles(net, geo, ref, config, loc)
    )


def _gaps(
    net: Network, tracks: pd.DataFrame, geo: pd.DataFrame, config: ValidationConfig, loc: Locator
) -> list[Finding]:
    c = net.connections
    if c.empty:
        return []
    ra, rb = connection_rows(net, tracks)
    ok = (ra >= 0) & (rb >= 0)
    rows = np.flatnonzero(ok)
    la, lo_a, _ = end_coordinates(geo, ra[ok], is_begin(c["end_a"])[ok])
    lb, lo_b, _ = end_coordinates(geo, rb[ok], is_begin(c["end_b"])[ok])
    gap = distance_m(la, lo_a, lb, lo_b)
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(gap > config.connection_gap_m)
    # the text only when there is a finding
    ta, tb, ea, eb = (
        column(c, k) if bad.size else np.empty(0, dtype=object) for k in ("track_a", "track_b", "end_a", "end_b")
    )
    return capped(
        "topology.gap",
        Severity.ERROR,
        CONNECTIONS.name,
        bad,
        lambda j: Finding(
            "topology.gap",
            Severity.ERROR,
            CONNECTIONS.name,
            f"{ta[rows[j]]} {ea[rows[j]]} and {tb[rows[j]]} {eb[rows[j]]} are joined but {gap[j]:.1f} m apart "
            f"(limit {config.connection_gap_m:g} m)",
            keys={"track_a": py(ta[rows[j]]), "track_b": py(tb[rows[j]])},
            value=round(float(gap[j]), 3),
            limit=config.connection_gap_m,
            **loc.at(CONNECTIONS.name, int(rows[j])),
        ),
        config.max_findings_per_rule,
        loc.file(CONNECTIONS.name),
    )


#: Margin [m] by which a length's bracket must clear its limit to be decided without the exact
#: length (far above the rounding of the comparison, far below any tolerance).
LENGTH_MARGIN_M = 1e-6


def _length_in_doubt(net: Network, config: ValidationConfig, low: np.ndarray, high: np.ndarray) -> np.ndarray:
    """Rows of :func:`dbtools.topology.all_tracks` whose centreline length the track-length
    rule needs exactly: a declared track whose length bracket [low, high] does not prove
    |length_m − real| ≤ max(tol, rel·real) for every real in it (the worst real is an end of
    the bracket; the limit is smallest at ``low``) — the tracks with a finding and those near
    their limit. Undeclared rows (implied tracks) and a missing length_m: never."""
    n = len(net.tracks)
    out = np.zeros(len(low), dtype=bool)
    stated = column(net.tracks, "length_m").astype(float)
    lo, hi = low[:n], high[:n]
    worst = np.maximum(np.abs(stated - lo), np.abs(stated - hi))
    lim = np.maximum(config.length_tolerance_m, config.length_tolerance_rel * lo)
    with np.errstate(invalid="ignore"):
        out[:n] = worst > lim - LENGTH_MARGIN_M
    return out


def _lengths(net: Network, geo: pd.DataFrame, config: ValidationConfig, loc: Locator) -> list[Finding]:
    n = len(net.tracks)
    if n == 0:
        return []
    stated = column(net.tracks, "length_m")
    real = geo["geo_length_m"].to_numpy(float)[:n]
    tid = column(net.tracks, "track_id")
    lim = np.maximum(config.length_tolerance_m, config.length_tolerance_rel * real)
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(np.abs(stated - real) > lim)
    t = NETWORK_TRACKS.name
    return capped(
        "topology.track_length",
        Severity.ERROR,
        t,
        bad,
        lambda i: Finding(
            "topology.track_length",
            Severity.ERROR,
            t,
            f"track {tid[i]}: length_m {stated[i]:.1f} m but its centreline is {real[i]:.1f} m long "
            f"(tolerance {lim[i]:.1f} m)",
            keys={"track_id": py(tid[i])},
            value=py(stated[i]),
            limit=round(float(real[i]), 3),
            column="length_m",
            **loc.at(t, i),
        ),
        config.max_findings_per_rule,
        loc.file(t),
    )


def _crossover_ends(net: Network, tracks: pd.DataFrame) -> pd.DataFrame | None:
    """The switch ends of crossovers (the module doc), one row per (crossover, end) — the
    first connection end of the crossover (``track``, ``end``) naming a switch whose
    ``switch_number`` is known and joining a track that is no crossover (``other``,
    ``other_end``; ``rows``: its first row in ``tracks``) — with ``switch_id`` and ``n``;
    None when there is none. A track id given twice has the kind of its last row. Ids are
    looked up by Arrow's hashing of the text as held (:func:`first_rows`)."""
    if net.track_points.empty:
        return None
    codes = track_codes(net)  # ``tracks`` is all_tracks
    last = codes.last[codes.of[("all_tracks", "track_id")]]  # the last row of each row's id
    kind = tracks["kind"] == TrackKind.CROSSOVER.value  # False where missing
    is_xo = np.asarray(kind.to_numpy(dtype=bool, na_value=False), dtype=bool)[last]
    if not is_xo.any():
        return None
    c, sw = net.connections, net.switches
    # each connection's switch number: that of the last switch row of its switch_id (NaN: none)
    last_sw = (len(sw) - 1) - first_rows(sw["switch_id"].iloc[::-1].reset_index(drop=True), c["switch_id"])
    number = np.append(sw["switch_number"].to_numpy(dtype=float, na_value=np.nan), np.nan)[last_sw]
    rows_of = dict(zip("ab", connection_rows(net, tracks), strict=True))
    sides = []  # the incidence table's order: every end a, then every end b
    for a, b in (("a", "b"), ("b", "a")):
        f_t, f_o = rows_of[a], rows_of[b]
        xo_t = (f_t >= 0) & is_xo[np.maximum(f_t, 0)]
        main_o = (f_o >= 0) & ~is_xo[np.maximum(f_o, 0)]
        hit = np.flatnonzero(xo_t & main_o & c["switch_id"].notna().to_numpy())
        sides.append((a, b, hit[np.isfinite(number[hit])]))
    # the first row of each (track, end): tracks by code (equal ids, equal codes), ends as held
    code = np.concatenate([codes.of[(CONNECTIONS.name, f"track_{a}")][hit] for a, _, hit in sides])
    end = pd.concat([c[f"end_{a}"].iloc[hit] for a, _, hit in sides], ignore_index=True)
    first = ~pd.DataFrame({"code": code, "end": end}).duplicated().to_numpy()
    if not first.any():
        return None
    kept = [(a, b, hit[part]) for (a, b, hit), part in zip(sides, np.split(first, [sides[0][2].size]), strict=True)]

    def held(column_of: Callable[[str, str], str]) -> npt.NDArray[Any]:
        """The text (as :func:`texts`) of a column of the kept ends, side a then side b."""
        return np.concatenate([texts(c[column_of(a, b)].iloc[hit]) for a, b, hit in kept])

    return pd.DataFrame(
        {
            "track": held(lambda a, _: f"track_{a}"),
            "end": held(lambda a, _: f"end_{a}"),
            "other_end": held(lambda _, b: f"end_{b}"),
            "switch_id": held(lambda *_: "switch_id"),
            "rows": np.concatenate([rows_of[b][hit] for _, b, hit in kept]),
            "n": np.concatenate([number[hit] for _, _, hit in kept]),
            "code": code[first],
        }
    )


def _worst_deviation(net: Network, geo: pd.DataFrame, ref: pd.DataFrame) -> pd.DataFrame:
    """Per switch end of a crossover (``ref``, one row per crossover and end): the largest
    angle ``dev`` [deg] between a chord of the crossover and the main track's axis (taken
    modulo 180°), in (track_id, end) order; ends without a chord or an end are left out."""
    ref = ref[ref["end"].notna().to_numpy()]
    axis = end_coordinates(geo, ref["rows"].to_numpy(), ref["other_end"].to_numpy(dtype=object) == BEGIN)[2]
    tp = net.track_points
    cid: npt.NDArray[Any]
    if sorted_by(tp, ("track_id", "pos_m")):  # as read from a DB: the chords by track code, no text
        track = ref["code"].to_numpy(dtype=np.int64)
        cid, az = coded_chord_azimuths(net, track)
    else:
        track = ref["track"].to_numpy(dtype=object)
        chords = chord_azimuths(tp, set(ref["track"]))
        cid, az = chords["track_id"].to_numpy(dtype=object), chords["az"].to_numpy(float)
    start = np.flatnonzero(np.r_[True, cid[1:] != cid[:-1]]) if len(cid) else np.zeros(0, dtype=np.int64)
    run = pd.Index(cid[start])  # each track's chords come as one run
    at = run.get_indexer(pd.Index(track))
    has = np.flatnonzero(at >= 0)
    s0, cnt = start[at[has]], np.diff(np.r_[start, len(cid)])[at[has]]
    each = np.repeat(np.arange(has.size), cnt)
    chord = np.repeat(s0 - np.r_[0, np.cumsum(cnt)[:-1]], cnt) + np.arange(int(cnt.sum()))
    dev = np.abs((az[chord] - axis[has][each] + 90.0) % 180.0 - 90.0)
    worst = ref.iloc[has][["track", "end", "switch_id", "n"]].rename(columns={"track": "track_id"})
    worst["dev"] = np.fmax.reduceat(dev, np.r_[0, np.cumsum(cnt)[:-1]]) if dev.size else np.zeros(0)
    key = list(zip(worst["track_id"].tolist(), worst["end"].tolist(), strict=True))
    return worst.iloc[sorted(range(len(key)), key=key.__getitem__)].reset_index(drop=True)


def _crossover_angles(
    net: Network, geo: pd.DataFrame, ref: pd.DataFrame | None, config: ValidationConfig, loc: Locator
) -> list[Finding]:
    if ref is None:
        return []
    worst = _worst_deviation(net, geo, ref)
    worst["alpha"] = np.degrees(np.arctan(1.0 / worst["n"].to_numpy(float)))
    worst["ratio"] = worst["dev"] / worst["alpha"]
    lo, hi = config.crossover_angle_range
    bad = worst[(worst["ratio"] < lo) | (worst["ratio"] > hi)].reset_index(drop=True)
    ids = net.tracks["track_id"]
    named = pd.Series(bad["track_id"].to_numpy(dtype=object), dtype=ids.dtype)
    last = len(ids) - 1 - first_rows(ids.iloc[::-1].reset_index(drop=True), named)  # the id's last row
    row_of = np.where(last < len(ids), last, -1)

    cols = {k: bad[k].tolist() for k in bad.columns}

    def build(j: int) -> Finding:
        r = {k: v[j] for k, v in cols.items()}
        i = int(row_of[j]) if row_of[j] >= 0 else None
        return Finding(
            "topology.crossover_angle",
            Severity.WARNING,
            NETWORK_TRACKS.name,
            f"crossover {r['track_id']} leaves the main track at switch {r['switch_id']} ({r['end']}) at up to "
            f"{r['dev']:.2f}° but the switch number 1:{r['n']:g} gives atan(1/n) = {r['alpha']:.2f}° "
            f"(ratio {r['ratio']:.2f}, allowed {lo:g}–{hi:g})",
            keys={"track_id": py(r["track_id"]), "switch_id": py(r["switch_id"])},
            value=round(float(r["dev"]), 4),
            limit=[round(lo * float(r["alpha"]), 4), round(hi * float(r["alpha"]), 4)],
            **(loc.at(NETWORK_TRACKS.name, i) if i is not None else {}),
        )

    return capped(
        "topology.crossover_angle",
        Severity.WARNING,
        NETWORK_TRACKS.name,
        np.arange(len(bad)),
        build,
        config.max_findings_per_rule,
        loc.file(NETWORK_TRACKS.name),
    )
