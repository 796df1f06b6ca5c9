"""The paper's input checks before positioning [S002 fig. 2].

1. **Navigation data compared between receivers.** Records of the same satellite and Toe
   held by two receivers must agree field by field (|Δ| ≤ atol + rtol·|x|: RINEX prints 12
   significant digits). A satellite with a disagreeing record is dropped while that record
   would be in use (|t − Toe| ≤ its fit half-interval) — a bit error in one receiver's
   navigation message, or a receiver software fault, is discarded.
2. **Pseudorange differences between antennas.** For a satellite seen by receivers a and b
   in the same epoch, d = ρ_a − ρ_b = −û·(A_a − A_b) + c(b_a − b_b) + ε, and |û·(A_a − A_b)| ≤ D,
   the antenna separation. The common clock term c(b_a − b_b) is unknown: it is taken as the
   value inside the most intervals [d_i − D − tol, d_i + D + tol] (interval stabbing over the
   epoch's satellites); satellites whose interval misses it are dropped in both receivers.
   Without the baseline's direction this catches for certain an error beyond 2(D + tol) and a
   smaller one only where the other satellites leave it no room.
3. Elevation and C/N0 masks: ``observables.apply_masks``; sky masks: ``skymask``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import NAV_KEPLER, SYSTEMS, WEEK_S, BoolArray, FloatArray
from fieldlogs.gnss.observables import FLAG_NAV_MISMATCH, FLAG_PR_DIFFERENCE, Epochs, epoch_keys

_COMPARED = tuple(c for c in NAV_KEPLER if c not in ("TransTime", "SVacc", "FitIntvl"))


@dataclass(frozen=True)
class NavMismatch:
    """Satellites to drop in time windows: (sat, t_from, t_to, field, receivers)."""

    table: pd.DataFrame


def compare_navigation(navs: Mapping[str, pd.DataFrame], rtol: float = 1e-9, atol: float = 1e-12) -> NavMismatch:
    """Disagreeing (sat, Toe) records between every pair of receivers (module docstring)."""
    names = sorted(navs)
    out = []
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            na = navs[a].assign(_toe=navs[a]["week"] * WEEK_S + navs[a]["Toe"])
            nb = navs[b].assign(_toe=navs[b]["week"] * WEEK_S + navs[b]["Toe"])
            keys = ["sat", "_toe"] + (["DataSrc"] if "DataSrc" in na.columns and "DataSrc" in nb.columns else [])
            m = na.merge(nb, on=keys, suffixes=("_a", "_b"))
            if m.empty:
                continue
            bad_any = np.zeros(len(m), dtype=bool)
            first = np.full(len(m), "", dtype=object)
            for col in _COMPARED:
                if f"{col}_a" not in m.columns:
                    continue
                xa, xb = m[f"{col}_a"].to_numpy(float), m[f"{col}_b"].to_numpy(float)
                bad = ~(np.isclose(xa, xb, rtol=rtol, atol=atol) | (np.isnan(xa) & np.isnan(xb)))
                first = np.where(bad & ~bad_any, col, first)
                bad_any |= bad
            if bad_any.any():
                mb = m.loc[bad_any]
                half = _fit_half(mb["sat"].to_numpy(str), mb["FitIntvl_a"].to_numpy(float))
                toe = mb["_toe"].to_numpy(float)
                out.append(
                    pd.DataFrame(
                        {
                            "sat": mb["sat"].to_numpy(str),
                            "t_from": toe - half,
                            "t_to": toe + half,
                            "field": first[bad_any].astype(str),
                            "receivers": f"{a},{b}",
                        }
                    )
                )
    cols = ["sat", "t_from", "t_to", "field", "receivers"]
    return NavMismatch(pd.concat(out, ignore_index=True) if out else pd.DataFrame(columns=cols))


def _fit_half(sat: np.ndarray, fit_hours: FloatArray) -> FloatArray:
    """Fit half-interval [s] as ``ephemeris`` uses it (GPS FitIntvl/2, QZSS flag, Galileo 4 h)."""
    sysl = np.char.upper(sat.astype("U1"))
    fit = np.nan_to_num(fit_hours, nan=0.0)
    gps = np.where(fit > 0, fit * 1800.0, SYSTEMS["G"].fit_half_s)
    qzs = np.where(fit > 0, 7200.0, SYSTEMS["J"].fit_half_s)
    return np.where(sysl == "G", gps, np.where(sysl == "J", qzs, SYSTEMS["E"].fit_half_s))


def flag_nav_mismatch(ep: Epochs, mismatch: NavMismatch) -> None:
    """Flag rows of satellites inside a mismatch window (in place)."""
    tab = mismatch.table
    for sat, t_from, t_to in zip(  # a handful of windows, not rows
        tab["sat"].to_numpy(str), tab["t_from"].to_numpy(float), tab["t_to"].to_numpy(float), strict=True
    ):
        hit = (ep.sat == sat) & (ep.t[:, None] >= t_from) & (ep.t[:, None] <= t_to)
        ep.flag(hit, FLAG_NAV_MISMATCH)


def pseudorange_difference_check(
    pr_a: FloatArray, pr_b: FloatArray, both: BoolArray, separation_m: float, tol_m: float
) -> BoolArray:
    """Rows (E, S) of satellites failing the antenna-separation check (module docstring).

    ``pr_a``/``pr_b`` are the two receivers' pseudoranges of the same satellites in the same
    slots, ``both`` where both exist. Epochs with fewer than 2 common satellites pass.
    """
    d = np.where(both, pr_a - pr_b, np.nan)
    half = separation_m + tol_m
    cand = np.concatenate([d, d - half, d + half], axis=1)
    inside = np.abs(d[:, None, :] - cand[:, :, None]) <= half + 1e-9
    count = np.sum(inside & both[:, None, :], axis=2)
    count = np.where(np.isfinite(cand), count, -1)
    best = cand[np.arange(d.shape[0]), np.argmax(count, axis=1)]
    fail = both & (np.abs(d - best[:, None]) > half + 1e-9)
    return np.asarray(fail & (both.sum(axis=1) >= 2)[:, None], dtype=bool)


def check_receiver_pair(ep: Epochs, name_a: str, name_b: str, separation_m: float, tol_m: float = 8.0) -> int:
    """Apply ``pseudorange_difference_check`` to two receivers of ``ep`` (epochs matched on the
    run clock t_run by ``observables.epoch_keys``, satellites by id); flags both receivers' rows
    in place, returns the count."""
    keys = epoch_keys(ep.t_run)
    ia = np.flatnonzero(ep.receiver == name_a)
    ib = np.flatnonzero(ep.receiver == name_b)
    ta = pd.Series(ia, index=keys[ia])
    tb = pd.Series(ib, index=keys[ib])
    ta, tb = ta[~ta.index.duplicated()], tb[~tb.index.duplicated()]
    common = ta.index.intersection(tb.index)
    ea, eb = ta.loc[common].to_numpy(), tb.loc[common].to_numpy()
    if ea.size == 0:
        return 0
    sat_a, sat_b = ep.sat[ea], ep.sat[eb]
    match = (sat_a[:, :, None] == sat_b[:, None, :]) & (sat_a[:, :, None] != "")
    has = match.any(axis=2)
    jb = np.argmax(match, axis=2)
    ok_a = ep.usable[ea] & has
    ok_b = np.take_along_axis(ep.usable[eb], jb, axis=1)
    both = ok_a & ok_b
    pr_a = ep.pr_m[ea]
    pr_b = np.take_along_axis(ep.pr_m[eb], jb, axis=1)
    fail = pseudorange_difference_check(pr_a, pr_b, both, separation_m, tol_m)
    fa = np.zeros_like(ep.present)
    fa[ea] = fail
    ii, jj = np.nonzero(fail)
    fa[eb[ii], jb[ii, jj]] = True
    ep.flag(fa, FLAG_PR_DIFFERENCE)
    return int(fail.sum())
