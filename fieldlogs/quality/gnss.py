"""``logs check`` of the raw GNSS streams and of the vehicle geometry against the streams.

gnss_obs (long format, one row per receiver × epoch × satellite × signal):
* satellite ids ``G07``-style (``schemas.gnss.SAT_RE``), signals ``C1C``-style
  (``SIGNAL_RE``);
* per receiver, ``t`` never going back in file order (unsorted: ``logs repair`` sorts);
* the key (receiver, t, sat, signal) unique;
* ``gnss_time_s − t`` the same on every row (one time base: the run's t0), to 1 ms.

gnss_nav: satellite ids; ``toc_gps_s`` present; the orbit fields each system needs
(GPS/Galileo/QZSS: sqrtA, Eccentricity, M0, Toe, week; GLONASS: X, Y, Z) present,
sqrtA in [1000, 10000] m^½ and the eccentricity in [0, 0.5); exact duplicate rows.

gnss_sbas (one row per received message, every GEO in one stream): per GEO (``prn``), ``t``
never going back in file order; the key (prn, t) unique — two GEOs may log in the same
second, one GEO sends one message a second (an exact repeat is a warning, another message
under the same key an error).

Vehicle against streams: every gnss_obs receiver has an antenna in run.json's vehicle
block (warning when the run has no vehicle block).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from schemas.enums import Severity
from schemas.gnss import SAT_RE, SIGNAL_RE

if TYPE_CHECKING:
    from fieldlogs.quality.file_findings import FileFindings as _Out
    from fieldlogs.runs.handle import Run

KEPLER_NEEDED = ("sqrtA", "Eccentricity", "M0", "Toe", "week")
GLONASS_NEEDED = ("X", "Y", "Z")
SQRT_A_RANGE = (1000.0, 10000.0)
TIME_BASE_TOLERANCE_S = 1e-3


def _pattern(out: _Out, frame: pd.DataFrame, column: str, pattern: Any, what: str) -> None:
    s = frame[column].astype("string")
    bad = np.flatnonzero(s.notna().to_numpy() & ~s.str.fullmatch(pattern.pattern).fillna(False).to_numpy(dtype=bool))
    vals = s.to_numpy(dtype=object)
    out.rows(
        "log.gnss_id",
        Severity.ERROR,
        bad,
        lambda k: f"'{vals[bad[k]]}' is not {what}",
        column=column,
        value=lambda k: vals[bad[k]],
    )


def check_gnss_obs(out: _Out, frame: pd.DataFrame) -> None:
    _pattern(out, frame, "sat", SAT_RE, "a satellite id like G07, E11, J02, R05")
    _pattern(out, frame, "signal", SIGNAL_RE, "a RINEX 3 pseudorange code like C1C or C5Q")
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    rec = frame["receiver"].astype("string").fillna("").to_numpy(dtype=object)
    out.rows(
        "log.unsorted",
        Severity.ERROR,
        _per_group_back(rec, t),
        lambda k: "epoch earlier than the receiver's row before (logs repair sorts them)",
        column="t",
    )
    keys = frame[["receiver", "t", "sat", "signal"]]
    dup = np.flatnonzero(keys.duplicated(keep="first").to_numpy())
    out.rows(
        "log.duplicate_key",
        Severity.ERROR,
        dup,
        lambda k: "(receiver, t, sat, signal) repeats an earlier row",
        column="t",
    )
    off = frame["gnss_time_s"].to_numpy(dtype=float, na_value=np.nan) - t
    ok = np.isfinite(off)
    if ok.any():
        ref = float(np.median(off[ok]))
        far = np.flatnonzero(ok & (np.abs(off - ref) > TIME_BASE_TOLERANCE_S))
        out.rows(
            "log.time_base",
            Severity.ERROR,
            far,
            lambda k: f"gnss_time_s − t is {off[far[k]]:.3f} s, other rows {ref:.3f} s: not one time base",
            column="gnss_time_s",
            value=lambda k: float(off[far[k]]),
            limit=ref,
        )


def _missing_msg(letter: np.ndarray, miss: np.ndarray, c: str) -> Callable[[int], str]:
    return lambda k: f"{letter[miss[k]]} ephemeris without {c}"


def _range_msg(
    v: np.ndarray, bad: np.ndarray, c: str, lo: float, hi: float
) -> tuple[Callable[[int], str], Callable[[int], float]]:
    return (lambda k: f"{c} = {v[bad[k]]:.6g} is outside [{lo:g}, {hi:g})"), (lambda k: float(v[bad[k]]))


def check_gnss_nav(out: _Out, frame: pd.DataFrame) -> None:
    _pattern(out, frame, "sat", SAT_RE, "a satellite id like G07, E11, J02, R05")
    letter = frame["sat"].astype("string").str[:1].fillna("").to_numpy(dtype=object)
    for needed, systems in ((KEPLER_NEEDED, ("G", "E", "J")), (GLONASS_NEEDED, ("R",))):
        rows = np.isin(letter, systems)
        for c in needed:
            miss = np.flatnonzero(rows & frame[c].isna().to_numpy())
            out.rows("log.nav_field", Severity.ERROR, miss, _missing_msg(letter, miss, c), column=c)
    for c, lo, hi in (("sqrtA", *SQRT_A_RANGE), ("Eccentricity", 0.0, 0.5)):
        v = frame[c].to_numpy(dtype=float, na_value=np.nan)
        with np.errstate(invalid="ignore"):
            bad = np.flatnonzero((v < lo) | (v >= hi))
        msg, val = _range_msg(v, bad, c, lo, hi)
        out.rows("log.nav_range", Severity.ERROR, bad, msg, column=c, value=val, limit=[lo, hi])
    dup = np.flatnonzero(frame.duplicated(keep="first").to_numpy())
    out.rows("log.duplicate_row", Severity.WARNING, dup, lambda k: "ephemeris repeats an earlier row exactly")
    _check_nav_week(out, frame, letter)


def _check_nav_week(out: _Out, frame: pd.DataFrame, letter: np.ndarray) -> None:
    """Toe (week·604800 + Toe) more than a week from the record's own epoch toc: the week is
    not the continuous one (RINEX 3.05 Table A6) — a 10-bit broadcast week (mod 1024,
    IS-GPS-200 §20.3.3.3.1.1) left unresolved, which matches no observation epoch."""
    kepler = np.isin(letter, ("G", "E", "J"))
    week = frame["week"].to_numpy(dtype=float, na_value=np.nan)
    off = (week * 604_800.0 + frame["Toe"].to_numpy(dtype=float, na_value=np.nan)) - frame["toc_gps_s"].to_numpy(
        dtype=float, na_value=np.nan
    )
    weeks = off / 604_800.0
    with np.errstate(invalid="ignore"):
        bad = np.flatnonzero(kepler & (np.abs(weeks) > 1.0))
    out.rows(
        "log.nav_week",
        Severity.ERROR,
        bad,
        lambda k: (
            f"week {week[bad[k]]:.0f} puts Toe {weeks[bad[k]]:+.0f} weeks from the record epoch toc: a 10-bit "
            "week (modulo 1024, IS-GPS-200 §20.3.3.3.1.1) not resolved — no ephemeris matches the observations "
            "(logs import resolves it against the record epoch)"
        ),
        column="week",
        value=lambda k: float(week[bad[k]]),
    )


def check_receivers(run: Run) -> list[Any]:
    """gnss_obs receivers without an antenna in run.json's vehicle block."""
    from schemas.findings import Finding

    obs = run.stream("gnss_obs") if run.has("gnss_obs") else None
    if obs is None or not len(obs):
        return []
    vehicle = run.raw_json.get("vehicle")
    file = str(run.stream_file("gnss_obs"))
    if not isinstance(vehicle, dict):
        return [
            Finding(
                "vehicle.missing",
                Severity.WARNING,
                "vehicle",
                "gnss_obs present but run.json has no vehicle block: the antennas' positions are unknown",
                file=file,
                column="receiver",
            )
        ]
    ants = vehicle.get("antennas")
    known = {str(a.get("receiver")) for a in (ants if isinstance(ants, list) else []) if isinstance(a, dict)}
    missing = sorted(set(obs["receiver"].dropna().astype(str)) - known)
    if not missing:
        return []
    return [
        Finding(
            "vehicle.receiver",
            Severity.ERROR,
            "gnss_obs",
            f"receiver(s) {', '.join(missing)} have no antenna in run.json vehicle.antennas",
            file=file,
            column="receiver",
            value=missing,
            limit=sorted(known),
        )
    ]


def _per_group_back(group: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Rows whose ``t`` is earlier than the row before them of the same group (file order)."""
    order = np.argsort(group, kind="stable")
    same = group[order][1:] == group[order][:-1]
    return np.sort(order[np.flatnonzero(same & (np.diff(t[order]) < 0)) + 1])


def check_gnss_sbas(out: _Out, frame: pd.DataFrame) -> None:
    t = frame["t"].to_numpy(dtype=float, na_value=np.nan)
    prn = frame["prn"].astype("string").fillna("").to_numpy(dtype=object)
    back = _per_group_back(prn, t)
    out.rows(
        "log.unsorted",
        Severity.ERROR,
        back,
        lambda k: "message earlier than the GEO's row before (logs repair sorts them)",
        column="t",
    )
    exact = frame.duplicated(keep="first").to_numpy()
    key = frame.duplicated(subset=["prn", "t"], keep="first").to_numpy()
    same, other = np.flatnonzero(exact), np.flatnonzero(key & ~exact)
    out.rows("log.duplicate_row", Severity.WARNING, same, lambda k: "message repeats an earlier row exactly")
    out.rows(
        "log.duplicate_key",
        Severity.ERROR,
        other,
        lambda k: "(prn, t) repeats an earlier row with another message: a GEO sends one message a second",
        column="t",
    )
