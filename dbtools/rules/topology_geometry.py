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

from functools import partial

import numpy as np
import pandas as pd

from dbtools.network import Network
from dbtools.rules.common import Locator, capped, column, py, texts
from dbtools.rules.config import ValidationConfig
from dbtools.rules.track_geometry import chord_azimuths, distance_m, end_coordinates, track_geometry
from dbtools.topology import first_rows
from schemas.enums import Severity, TrackKind
from schemas.findings import Finding
from schemas.network import CONNECTIONS, NETWORK_TRACKS


def check_geometry(
    net: Network, tracks: pd.DataFrame, inc: pd.DataFrame, config: ValidationConfig, loc: Locator
) -> list[Finding]:
    key = ("rules", "track_geometry", config.length_tolerance_m, config.length_tolerance_rel)
    geo = net.cached(key, lambda: track_geometry(net, tracks, partial(_length_in_doubt, net, config)))
    pos = pd.Series(np.arange(len(tracks)), index=texts(tracks["track_id"]))
    pos = pos[~pos.index.duplicated()]
    return (
        _gaps(net, tracks, geo, config, loc)
        + _lengths(net, geo, config, loc)
        + _crossover_angles(net, tracks, geo, pos, inc, config, loc)
    )


def _gaps(
    net: Network, tracks: pd.DataFrame, geo: pd.DataFrame, config: ValidationConfig, loc: Locator
) -> list[Finding]:
    c = net.connections
    if c.empty:
        return []
    ra, rb = (first_rows(tracks["track_id"], c[k]) for k in ("track_a", "track_b"))
    ea, eb = column(c, "end_a"), column(c, "end_b")
    ok = (ra >= 0) & (rb >= 0)
    rows = np.flatnonzero(ok)
    la, lo_a, _ = end_coordinates(geo, ra[ok], ea[ok])
    lb, lo_b, _ = end_coordinates(geo, rb[ok], eb[ok])
    gap = distance_m(la, lo_a, lb, lo_b)
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(gap > config.connection_gap_m)
    ta, tb = (column(c, k) if bad.size else np.empty(0, dtype=object) for k in ("track_a", "track_b"))
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


def _crossover_angles(
    net: Network,
    tracks: pd.DataFrame,
    geo: pd.DataFrame,
    pos: pd.Series,
    inc: pd.DataFrame,
    config: ValidationConfig,
    loc: Locator,
) -> list[Finding]:
    ids = texts(tracks["track_id"])
    kinds = pd.Series(texts(tracks["kind"]), index=ids)
    kinds = kinds[~kinds.index.duplicated(keep="last")]  # a track id given twice: its last row
    xo = set(kinds.index[(kinds == TrackKind.CROSSOVER.value).to_numpy()])
    if not xo or net.track_points.empty:
        return []
    sw = net.switches
    number = dict(zip(column(sw, "switch_id"), column(sw, "switch_number"), strict=True))
    ref = inc[inc["track"].isin(list(xo)) & inc["switch_id"].notna()].copy()
    other = pd.Index(texts(ref["other"]), dtype=object)
    ref = ref[(kinds.reindex(other).to_numpy() != TrackKind.CROSSOVER.value) & (pos.index.get_indexer(other) >= 0)]
    ref["n"] = [number.get(s, np.nan) for s in texts(ref["switch_id"])]
    ref = ref[np.isfinite(ref["n"].to_numpy(float))].drop_duplicates(["track", "end"])
    if ref.empty:
        return []
    rows = pos.to_numpy(dtype=np.int64)[pos.index.get_indexer(pd.Index(texts(ref["other"])))]
    ref["axis"] = end_coordinates(geo, rows, texts(ref["other_end"]))[2]
    chords = chord_azimuths(net.track_points, set(ref["track"]))
    m = chords.merge(ref.rename(columns={"track": "track_id"}), on="track_id")
    m["dev"] = np.abs((m["az"] - m["axis"] + 90.0) % 180.0 - 90.0)
    worst = m.groupby(["track_id", "end", "switch_id", "n"], sort=True)["dev"].max().reset_index()
    worst["alpha"] = np.degrees(np.arctan(1.0 / worst["n"].to_numpy(float)))
    worst["ratio"] = worst["dev"] / worst["alpha"]
    lo, hi = config.crossover_angle_range
    bad = worst[(worst["ratio"] < lo) | (worst["ratio"] > hi)].reset_index(drop=True)
    tid = column(net.tracks, "track_id") if len(bad) else np.empty(0, dtype=object)
    row_of = {t: i for i, t in enumerate(tid)}

    cols = {k: bad[k].tolist() for k in bad.columns}

    def build(j: int) -> Finding:
        r = {k: v[j] for k, v in cols.items()}
        i = row_of.get(r["track_id"])
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
