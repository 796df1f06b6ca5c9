"""Balise rules (SPEC §3 "uniqueness" and "cross-table", SPEC §5.2).

An initial pair is keyed by (line_code, station_code, track); a C balise names its governing
pair with the same three columns. ``sign`` below is +1 on D and S tracks (km increasing in
the running direction) and −1 on U.

* ``balise.pair_count`` (error) — a pair key does not have exactly one I1 and one I2. Fix: give
  the pair key exactly one I1 and one I2 row (delete the duplicate, add the missing balise, or
  correct line_code/station_code/track of a row filed under the wrong pair).
* ``balise.pair_spacing`` (error) — |km(I2) − km(I1)| differs from 5 m by more than
  ``pair_spacing_tolerance_m``. Fix: correct ``km_actual_m`` of the I1 or I2 row from the
  survey (or the tolerance in the validation config if the pair really stands farther apart).
* ``balise.pair_order`` (error) — I2 is not after I1 in running direction
  (sign·(km(I2) − km(I1)) ≤ 0). Fix: swap the kinds of the two rows (I1 comes first in running
  direction), or correct the track (U runs toward decreasing km).
* ``balise.c_pair`` (error) — a C balise names a pair that has no I1. Fix: add the pair's I1
  row, or correct the C balise's line_code/station_code/track to name an existing pair.
* ``balise.c_fields`` (error) — a C balise without ``signal_type`` or ``dist_from_initial_m``.
  Fix: fill ``signal_type`` and ``dist_from_initial_m`` of the C row.
* ``balise.initial_fields`` (warning) — an I1/I2 row carries ``signal_type`` or
  ``dist_from_initial_m`` (they are ignored). Fix: empty those cells of the I1/I2 row.
* ``balise.ambiguous`` (error) — two C balises after the same pair with the same signal type
  whose ``dist_from_initial_m`` differ by ≤ ``id_window_m``: the onboard unit cannot tell them
  apart. Fix: give one of them another signal type, or move it outside the window (correct its
  ``dist_from_initial_m`` if it is wrong).
* ``balise.c_direction`` (warning) — a C balise lies behind its governing pair in running
  direction, so the travel distance since the pair can never reach it. Fix: correct the C
  balise's km or track, or name the pair that is before it in running direction.
* ``balise.dist_from_initial`` (warning) — ``dist_from_initial_m`` differs from
  |km(C) − km(I1)| by more than ``dist_tolerance_m``. Fix: correct ``dist_from_initial_m`` (or
  ``km_actual_m``) so that both agree.
* ``balise.key_fields`` (error) — an I1, I2 or C row without line_code or station_code, or
  whose track is not U, D or S: the pair key (and a C balise's governing pair) needs all
  three (G rows may leave them empty: a group names itself by NID_C/NID_BG). Fix: fill them.
* ``balise.km_equipment`` (error) — ``km_equipment_m`` differs from ``km_actual_m`` by
  more than ``km_equipment_tolerance_m`` (a typing error in one of them). Fix: correct the
  one that was mistyped.
* ``balise.outside_gis`` (error) — ``km_actual_m`` is outside the GIS km range of the
  balise's line/track (or the line/track has no GIS at all). Fix: correct ``km_actual_m``,
  line_code or track, or extend the GIS grid to that km.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.gis.index import GridIndex
from dbtools.rules.common import Locator, capped, column, fmt_km, group_ids, py
from dbtools.rules.config import ValidationConfig
from schemas.enums import S003_KINDS, BaliseKind, Severity, Track
from schemas.findings import Finding
from schemas.model import KM_PLAUSIBLE_M
from schemas.tables import BALISES

T = BALISES.name
F64 = npt.NDArray[np.float64]
Obj = npt.NDArray[Any]


def check_balises(balises: pd.DataFrame, grid: GridIndex, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """All balise rules (see module docstring)."""
    out: list[Finding] = []
    cap = config.max_findings_per_rule
    file = loc.file(T)
    if balises.empty:
        return out
    bid = column(balises, "balise_id")
    kind = column(balises, "kind")
    line, station, track = column(balises, "line_code"), column(balises, "station_code"), column(balises, "track")
    sig, km = column(balises, "signal_type"), column(balises, "km_actual_m")
    dist = column(balises, "dist_from_initial_m")
    out += _key_fields(bid, kind, line, station, track, loc, cap)
    out += _km_equipment(bid, km, column(balises, "km_equipment_m"), config, loc)
    # pair key of every row → pair id (−1 when a key column is missing)
    pid = group_ids(balises, ("line_code", "station_code", "track"))
    keyed = pid >= 0
    sign = np.where(track == Track.UP.value, -1.0, 1.0)
    is_i1, is_i2, is_c = kind == BaliseKind.I1.value, kind == BaliseKind.I2.value, kind == BaliseKind.C.value

    def keys(i: int) -> dict[str, object]:
        return {"balise_id": py(bid[i])}

    def pair_keys(i: int) -> dict[str, object]:
        return {"line_code": py(line[i]), "station_code": py(station[i]), "track": py(track[i])}

    n_pairs = int(pid.max()) + 1 if keyed.any() else 0
    n1 = np.bincount(pid[is_i1 & keyed], minlength=n_pairs)
    n2 = np.bincount(pid[is_i2 & keyed], minlength=n_pairs)
    # first row of every pair id that has any I1/I2 row, for the finding's location
    initial = np.flatnonzero((is_i1 | is_i2) & keyed)
    first_row = np.full(n_pairs, -1, dtype=np.int64)
    first_row[pid[initial][::-1]] = initial[::-1]

    # balise.pair_count
    bad = np.flatnonzero(((n1 != 1) | (n2 != 1)) & (first_row >= 0))
    out += capped(
        "balise.pair_count",
        Severity.ERROR,
        T,
        bad,
        lambda p: Finding(
            "balise.pair_count",
            Severity.ERROR,
            T,
            f"initial pair has {n1[p]} I1 and {n2[p]} I2 balise(s); exactly one of each is required",
            keys=pair_keys(int(first_row[p])),
            value=[int(n1[p]), int(n2[p])],
            limit=[1, 1],
            **loc.at(T, int(first_row[p])),
        ),
        cap,
        file,
    )

    # km of the (single) I1 and I2 of each complete pair
    i1_row = np.full(n_pairs, -1, dtype=np.int64)
    i2_row = np.full(n_pairs, -1, dtype=np.int64)
    r1 = np.flatnonzero(is_i1 & keyed)
    r2 = np.flatnonzero(is_i2 & keyed)
    i1_row[pid[r1]] = r1
    i2_row[pid[r2]] = r2
    complete = np.flatnonzero((n1 == 1) & (n2 == 1))
    a, b = i1_row[complete], i2_row[complete]
    with np.errstate(invalid="ignore"):
        delta = km[b] - km[a]
        spacing_bad = np.abs(np.abs(delta) - config.pair_spacing_m) > config.pair_spacing_tolerance_m
        order_bad = sign[a] * delta <= 0

    def pair_finding(rule: str, j: int, msg: str, value: object, limit: object) -> Finding:
        return Finding(
            rule, Severity.ERROR, T, msg, keys=pair_keys(int(a[j])), value=value, limit=limit, **loc.at(T, int(b[j]))
        )

    lo = config.pair_spacing_m - config.pair_spacing_tolerance_m
    hi = config.pair_spacing_m + config.pair_spacing_tolerance_m
    out += capped(
        "balise.pair_spacing",
        Severity.ERROR,
        T,
        np.flatnonzero(spacing_bad),
        lambda j: pair_finding(
            "balise.pair_spacing",
            j,
            f"I1 {bid[a[j]]} and I2 {bid[b[j]]} are {abs(delta[j]):.2f} m apart, expected "
            f"{config.pair_spacing_m:g} ± {config.pair_spacing_tolerance_m:g} m",
            round(float(abs(delta[j])), 3),
            [lo, hi],
        ),
        cap,
        file,
    )
    out += capped(
        "balise.pair_order",
        Severity.ERROR,
        T,
        np.flatnonzero(order_bad),
        lambda j: pair_finding(
            "balise.pair_order",
            j,
            f"I2 {bid[b[j]]} (km {fmt_km(km[b[j]])}) is not after I1 {bid[a[j]]} (km {fmt_km(km[a[j]])}) "
            f"in the running direction of track {track[a[j]]} "
            f"({'km decreasing' if sign[a[j]] < 0 else 'km increasing'})",
            round(float(delta[j]), 3),
            "> 0" if sign[a[j]] > 0 else "< 0",
        ),
        cap,
        file,
    )

    # C balises
    c_rows = np.flatnonzero(is_c)
    gov_i1 = np.full(len(balises), -1, dtype=np.int64)
    has_pid = c_rows[pid[c_rows] >= 0]
    gov_i1[has_pid] = i1_row[pid[has_pid]]
    bad = c_rows[gov_i1[c_rows] < 0]
    out += capped(
        "balise.c_pair",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "balise.c_pair",
            Severity.ERROR,
            T,
            f"C balise names initial pair ({line[i]}, {station[i]}, {track[i]}), which has no I1 balise",
            keys=keys(i),
            value=[py(line[i]), py(station[i]), py(track[i])],
            **loc.at(T, i),
        ),
        cap,
        file,
    )
    missing_sig = pd.isna(sig)
    missing_dist = np.isnan(dist)
    bad = c_rows[missing_sig[c_rows] | missing_dist[c_rows]]
    out += capped(
        "balise.c_fields",
        Severity.ERROR,
        T,
        bad,
        lambda i: Finding(
            "balise.c_fields",
            Severity.ERROR,
            T,
            "C balise needs "
            + " and ".join(
                n for n, m in (("signal_type", missing_sig[i]), ("dist_from_initial_m", missing_dist[i])) if m
            ),
            keys=keys(i),
            column="signal_type" if missing_sig[i] else "dist_from_initial_m",
            **loc.at(T, i),
        ),
        cap,
        file,
    )
    bad = np.flatnonzero((is_i1 | is_i2) & (~missing_sig | ~missing_dist))
    out += capped(
        "balise.initial_fields",
        Severity.WARNING,
        T,
        bad,
        lambda i: Finding(
            "balise.initial_fields",
            Severity.WARNING,
            T,
            f"{kind[i]} balise carries signal_type/dist_from_initial_m, which only C balises use (ignored)",
            keys=keys(i),
            column="signal_type" if not missing_sig[i] else "dist_from_initial_m",
            **loc.at(T, i),
        ),
        cap,
        file,
    )

    # balise.ambiguous: same pair and signal type, |Δ dist| ≤ window (sorted: neighbours suffice)
    amb = c_rows[(pid[c_rows] >= 0) & ~missing_sig[c_rows] & ~missing_dist[c_rows]]
    if len(amb) > 1:
        sig_code, _ = pd.factorize(pd.Series(sig[amb], dtype=object))
        order = np.lexsort((dist[amb], sig_code, pid[amb]))
        s = amb[order]
        sc = sig_code[order]
        same = (pid[s[1:]] == pid[s[:-1]]) & (sc[1:] == sc[:-1])
        gap = dist[s[1:]] - dist[s[:-1]]
        hit = np.flatnonzero(same & (gap <= config.id_window_m))
        out += capped(
            "balise.ambiguous",
            Severity.ERROR,
            T,
            hit,
            lambda j: Finding(
                "balise.ambiguous",
                Severity.ERROR,
                T,
                f"C balises {bid[s[j]]} and {bid[s[j + 1]]} both carry signal type '{sig[s[j]]}' after pair "
                f"({line[s[j]]}, {station[s[j]]}, {track[s[j]]}) and their distances from I1 differ by only "
                f"{gap[j]:.1f} m (identification window ±{config.id_window_m:g} m): identification is ambiguous",
                keys={"balise_id": py(bid[s[j + 1]]), "other_balise_id": py(bid[s[j]])},
                value=round(float(gap[j]), 3),
                limit=config.id_window_m,
                **loc.at(T, int(s[j + 1])),
            ),
            cap,
            file,
        )

    # C vs its governing I1: direction and travel distance
    gc = c_rows[(gov_i1[c_rows] >= 0)]
    gi = gov_i1[gc]
    with np.errstate(invalid="ignore"):
        ahead = sign[gi] * (km[gc] - km[gi])
        behind = ahead <= 0
        dist_err = np.abs(dist[gc] - np.abs(km[gc] - km[gi]))
        dist_bad = dist_err > config.dist_tolerance_m
    out += capped(
        "balise.c_direction",
        Severity.WARNING,
        T,
        np.flatnonzero(behind),
        lambda j: Finding(
            "balise.c_direction",
            Severity.WARNING,
            T,
            f"C balise at km {fmt_km(km[gc[j]])} lies behind I1 {bid[gi[j]]} (km {fmt_km(km[gi[j]])}) "
            f"in the running direction of track {track[gc[j]]}: it can never be identified from that pair",
            keys=keys(int(gc[j])),
            value=round(float(ahead[j]), 3),
            limit="> 0",
            column="km_actual_m",
            **loc.at(T, int(gc[j])),
        ),
        cap,
        file,
    )
    out += capped(
        "balise.dist_from_initial",
        Severity.WARNING,
        T,
        np.flatnonzero(dist_bad),
        lambda j: Finding(
            "balise.dist_from_initial",
            Severity.WARNING,
            T,
            f"dist_from_initial_m is {dist[gc[j]]:.2f} m but the C balise is "
            f"{abs(km[gc[j]] - km[gi[j]]):.2f} m from I1 {bid[gi[j]]} by km_actual_m",
            keys=keys(int(gc[j])),
            value=round(float(dist[gc[j]]), 3),
            limit=round(float(abs(km[gc[j]] - km[gi[j]])), 3),
            column="dist_from_initial_m",
            **loc.at(T, int(gc[j])),
        ),
        cap,
        file,
    )

    # balise.outside_gis (a G balise only where its line and track have a grid: a group on a
    # track along no line's km is checked against its track by dbtools.rules.topology)
    rows = np.flatnonzero(pd.notna(line) & pd.notna(track) & np.isfinite(km))
    gid = grid.track_ids(line[rows], track[rows])
    keep = (kind[rows] != BaliseKind.G.value) | (gid >= 0)
    rows, gid = rows[keep], gid[keep]
    kmin, kmax = grid.km_range(gid)
    with np.errstate(invalid="ignore"):
        outside = (gid < 0) | (km[rows] < kmin - config.km_epsilon_m) | (km[rows] > kmax + config.km_epsilon_m)
    out += capped(
        "balise.outside_gis",
        Severity.ERROR,
        T,
        np.flatnonzero(outside),
        lambda j: Finding(
            "balise.outside_gis",
            Severity.ERROR,
            T,
            (
                f"no GIS grid for line {line[rows[j]]} track {track[rows[j]]}"
                if gid[j] < 0
                else f"km {fmt_km(km[rows[j]])} is outside the GIS range {fmt_km(kmin[j])}–{fmt_km(kmax[j])} "
                f"of line {line[rows[j]]} track {track[rows[j]]}"
            ),
            keys=keys(int(rows[j])),
            value=py(km[rows[j]]),
            limit=None if gid[j] < 0 else [py(kmin[j]), py(kmax[j])],
            column="km_actual_m",
            **loc.at(T, int(rows[j])),
        ),
        cap,
        file,
    )
    return out


def _key_fields(bid: Obj, kind: Obj, line: Obj, station: Obj, track: Obj, loc: Locator, cap: int) -> list[Finding]:
    """``balise.key_fields`` (module docstring) of the balises' columns (:func:`column`)."""
    s003 = np.isin(kind, [k.value for k in S003_KINDS])
    tracks = [t.value for t in Track]
    bad_track = ~np.isin(np.where(pd.isna(track), "", track).astype(str), tracks)
    missing = pd.isna(line) | pd.isna(station)

    def finding(i: int) -> Finding:
        if bad_track[i]:
            what, col, value = f"is on track '{py(track[i]) or ''}', not U, D or S", "track", py(track[i])
        else:
            col = "line_code" if pd.isna(line[i]) else "station_code"
            what, value = f"has no {col}", None
        return Finding(
            "balise.key_fields",
            Severity.ERROR,
            T,
            f"{kind[i]} balise {bid[i]} {what}: initial pairs and C balises are keyed by line, station and track",
            keys={"balise_id": py(bid[i])},
            column=col,
            value=value,
            **loc.at(T, i),
        )

    return capped(
        "balise.key_fields", Severity.ERROR, T, np.flatnonzero(s003 & (bad_track | missing)), finding, cap, loc.file(T)
    )


def _km_equipment(bid: Obj, actual: F64, equipment: F64, config: ValidationConfig, loc: Locator) -> list[Finding]:
    """``balise.km_equipment`` (module docstring) of the balises' columns (:func:`column`)."""
    tol = config.km_equipment_tolerance_m
    with np.errstate(invalid="ignore", over="ignore"):
        off = np.abs(equipment - actual)
    plausible = (np.abs(actual) <= KM_PLAUSIBLE_M) & (np.abs(equipment) <= KM_PLAUSIBLE_M)  # else schema.range
    bad = np.flatnonzero(plausible & (off > tol))

    def finding(i: int) -> Finding:
        return Finding(
            "balise.km_equipment",
            Severity.ERROR,
            T,
            f"balise {bid[i]}: km_equipment_m {fmt_km(equipment[i])} is {off[i]:.1f} m from km_actual_m "
            f"{fmt_km(actual[i])} (at most {tol:g} m): one of them is mistyped",
            keys={"balise_id": py(bid[i])},
            column="km_equipment_m",
            value={"km_equipment_m": py(equipment[i]), "km_actual_m": py(actual[i])},
            limit=tol,
            **loc.at(T, i),
        )

    return capped("balise.km_equipment", Severity.ERROR, T, bad, finding, config.max_findings_per_rule, loc.file(T))
