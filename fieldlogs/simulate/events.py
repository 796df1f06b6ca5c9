"""Event streams: balise telegrams and cab (direction / PTO) events.

A balise is passed when the true km crosses its ``km_actual_m`` (the reference point of the
vehicle carries the antenna). Within one move the km is monotone, so each crossing time is
a ``searchsorted`` plus a linear interpolation; reversals cross balises again in the other
order. Telegram contents [S003 §4]: I1 carries the line code, I2 the station code and the
track, C the signal type; other fields are empty. A kind G balise (an ETCS group, SUBSET-026)
carries its group's NID_C, NID_BG, its N_PIG and the group size: read in N_PIG order one way
and reversed the other, it tells the direction of travel. A vehicle with a reader in each cab
(``balise.readers_x_m``) has every balise read by both, each at its own place on the vehicle.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import pandas as pd

from fieldlogs.simulate.running import Motion
from schemas.enums import BaliseKind, CabDirection

BALISE_COLUMNS = ["t", "kind", "line_code", "station_code", "track", "signal_type"]
#: The telegram fields of a kind G balise (ETCS group), written only where the run reads one.
GROUP_COLUMNS = ("nid_c", "nid_bg", "n_pig", "n_total")


def track_balises(balises: pd.DataFrame, line_code: str, track: str) -> pd.DataFrame:
    return balises[(balises["line_code"] == line_code) & (balises["track"] == track)].reset_index(drop=True)


def balise_events(balises: pd.DataFrame, motion: Motion, rng: np.random.Generator, miss_p: float) -> pd.DataFrame:
    b_km = balises["km_actual_m"].to_numpy(dtype=float)
    hit_t: list[np.ndarray] = []
    hit_i: list[np.ndarray] = []
    for m, mv in enumerate(motion.moves):
        idx = np.flatnonzero(motion.move == m)
        if len(idx) < 2:
            continue
        s = mv.direction * motion.km[idx]  # non-decreasing within a move
        s = np.maximum.accumulate(s)  # guard against float noise at standstill
        inside = (mv.direction * b_km > s[0]) & (mv.direction * b_km <= s[-1])
        which = np.flatnonzero(inside)
        if len(which) == 0:
            continue
        target = mv.direction * b_km[which]
        j = np.searchsorted(s, target, side="left")  # first sample at or beyond the balise
        j = np.clip(j, 1, len(s) - 1)
        s0, s1 = s[j - 1], s[j]
        frac = np.where(s1 > s0, (target - s0) / np.where(s1 > s0, s1 - s0, 1.0), 1.0)
        t = motion.t[idx[j - 1]] + frac * (motion.t[idx[j]] - motion.t[idx[j - 1]])
        hit_t.append(t)
        hit_i.append(which)
    if not hit_t:
        return pd.DataFrame({c: pd.Series([], dtype="float64" if c == "t" else "string") for c in BALISE_COLUMNS})
    t_all = np.concatenate(hit_t)
    i_all = np.concatenate(hit_i)
    if miss_p > 0:
        keep = rng.random(len(t_all)) >= miss_p
        t_all, i_all = t_all[keep], i_all[keep]
    order = np.argsort(t_all, kind="stable")
    t_all, i_all = t_all[order], i_all[order]
    rows = balises.iloc[i_all].reset_index(drop=True)
    kind = rows["kind"].astype("string")
    is_i1, is_i2, is_c = kind == BaliseKind.I1, kind == BaliseKind.I2, kind == BaliseKind.C
    na = pd.Series(pd.NA, index=rows.index, dtype="string")
    out = pd.DataFrame(
        {
            "t": np.round(t_all, 3),
            "kind": kind,
            "line_code": rows["line_code"].astype("string").where(is_i1, na),
            "station_code": rows["station_code"].astype("string").where(is_i2, na),
            "track": rows["track"].astype("string").where(is_i2, na),
            "signal_type": rows["signal_type"].astype("string").where(is_c, na),
        }
    )
    is_g = kind == BaliseKind.G
    if is_g.any():  # an ETCS group balise's telegram: its group identity and place in the group
        for c in GROUP_COLUMNS:
            out[c] = rows[c].astype("Int64").mask(~is_g)
    return out


def reader_events(
    balises: pd.DataFrame,
    motion: Motion,
    km_of_sigma: Callable[[np.ndarray], np.ndarray],
    rng: np.random.Generator,
    miss_p: float,
    readers_x_m: tuple[float, ...],
) -> pd.DataFrame:
    """Telegrams of a vehicle with a balise reader in each cab [S003 §2]: the F cab's reader
    ``readers_x_m[0]`` and the R cab's ``readers_x_m[1]`` forward of the reference point, each
    passing a balise when its own km (σ + facing·x) crosses it; the ``reader`` column says which."""
    frames = []
    for name, x in zip((CabDirection.FORWARD.value, CabDirection.REVERSE.value), readers_x_m, strict=True):
        frame = balise_events(balises, replace(motion, km=km_of_sigma(motion.sigma + motion.facing * x)), rng, miss_p)
        frame["reader"] = pd.array([name] * len(frame), dtype="string")
        frames.append(frame)
    return pd.concat(frames, ignore_index=True).sort_values("t", kind="stable").reset_index(drop=True)


def cab_events(motion: Motion) -> pd.DataFrame:
    t, direction, pto = zip(*motion.cab_events, strict=True)
    return pd.DataFrame(
        {
            "t": np.asarray(t, dtype=float),
            "direction": pd.array(direction, dtype="string"),
            "pto": pd.array(pto, dtype="Int64"),
        }
    )
