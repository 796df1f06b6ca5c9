"""Satellite position, velocity and clock from broadcast ephemerides (GPS LNAV, Galileo I/NAV and F/NAV, QZSS).

All functions take arrays of (ephemeris row, time) pairs and evaluate them at once.

Orbit (IS-GPS-200N §20.3.3.4.3, Table 20-IV; Galileo OS SIS ICD §5.1.1; IS-QZSS-PNT
uses the GPS algorithm), with each system's μ and Ω̇e (see ``constants``):

* A = (√A)², n = √(μ/A³) + Δn, t_k = t − Toe (continuous seconds, so no week crossover);
* M_k = M0 + n·t_k; Kepler's equation M_k = E_k − e·sin E_k solved by Newton's iteration
  E ← E − (E − e sin E − M)/(1 − e cos E) from E0 = M (quadratic convergence; 1e-14 rad);
* ν_k = atan2(√(1−e²)·sin E, cos E − e); Φ = ν + ω;
* harmonic corrections δu = Cus sin 2Φ + Cuc cos 2Φ, δr = Crs sin 2Φ + Crc cos 2Φ,
  δi = Cis sin 2Φ + Cic cos 2Φ; u = Φ + δu; r = A(1 − e cos E) + δr; i = i0 + δi + IDOT·t_k;
* Ω_k = Ω0 + (Ω̇ − Ω̇e)·t_k − Ω̇e·Toe; x' = r cos u, y' = r sin u;
  x = x' cos Ω − y' cos i sin Ω, y = x' sin Ω + y' cos i cos Ω, z = y' sin i (ECEF at t);
* velocity: the time derivatives of the same (IS-GPS-200N Table 20-IV, "SV velocity"):
  Ė = n/(1 − e cos E), ν̇ = Ė√(1−e²)/(1 − e cos E), di/dt = IDOT + 2ν̇(Cis cos 2Φ − Cic sin 2Φ),
  u̇ = ν̇ + 2ν̇(Cus cos 2Φ − Cuc sin 2Φ), ṙ = eAĖ sin E + 2ν̇(Crs cos 2Φ − Crc sin 2Φ), Ω̇_k = Ω̇ − Ω̇e.

Clock (IS-GPS-200N §20.3.3.3.3.1; Galileo OS SIS ICD §5.1.3–5.1.5):
Δt_sv = af0 + af1(t − toc) + af2(t − toc)² + Δt_r, relativistic Δt_r = F·e·√A·sin E_k, and
the single-frequency group delay: GPS/QZSS (§20.3.3.3.3.2) (Δt_sv)_f = Δt_sv − (f_L1/f)²·TGD;
Galileo (§5.1.5) (Δt_sv)_f = Δt_sv − (f_E1/f)²·BGD(E1, Ex), Ex = E5b for I/NAV clocks and
E5a for F/NAV clocks. GPS L5 from LNAV uses the same TGD scaling (the CNAV ISCs are not in
RINEX LNAV records): a decimetre-level approximation.

Ephemeris selection: per (satellite, time) the healthy record (health == 0) with the
nearest Toe, used only inside its fit interval |t − Toe| ≤ FitIntvl/2 (GPS FitIntvl hours,
4 h when absent; QZSS fit-interval flag 0 → 2 h, 1 → 4 h; Galileo 4 h either side as the
nominal validity). Galileo signals in E1/E5b take I/NAV records, E5a F/NAV records (DataSrc
bit 1); a satellite without the preferred kind falls back to the other. Transmission times
(TransTime) are not enforced: the core is post-processing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fieldlogs.gnss.constants import (
    C_MPS,
    F_L1_HZ,
    GAL_FNAV_BITS,
    NAV_KEPLER,
    SYSTEMS,
    WEEK_S,
    BoolArray,
    FloatArray,
    IntArray,
    StrArray,
    system_of,
)
from schemas.errors import InputError

KIND_ANY = 0
KIND_INAV = 1
KIND_FNAV = 2


class EphemerisError(InputError):
    """A navigation frame that lacks a required column."""


@dataclass(frozen=True)
class NavTable:
    """A ``gnss_nav`` frame as arrays, rows of supported systems only, sorted by (key, Toe)."""

    sat: StrArray
    system: StrArray
    kind: IntArray
    key: IntArray
    """Integer code of (sat, kind); selection searches within it."""
    toe_s: FloatArray
    toc_s: FloatArray
    fit_half_s: FloatArray
    healthy: BoolArray
    mu: FloatArray
    omega_e: FloatArray
    f_rel: FloatArray
    field: dict[str, FloatArray]
    keys: dict[tuple[str, int], int]

    @property
    def size(self) -> int:
        return int(self.toe_s.size)


def nav_table(nav: pd.DataFrame) -> NavTable:
    """Arrays of the supported rows of a ``gnss_nav`` frame (GLONASS/BeiDou/SBAS rows are dropped)."""
    missing = [c for c in ("sat", "toc_gps_s", "week", *NAV_KEPLER) if c not in nav.columns]
    if missing:
        raise EphemerisError("missing column", path="gnss_nav frame", column=missing[0])
    sysl = system_of(nav["sat"].to_numpy())
    keep = np.isin(sysl, list(SYSTEMS))
    df = nav.loc[keep].reset_index(drop=True)
    sysl = sysl[keep]
    data_src = df["DataSrc"].to_numpy(float) if "DataSrc" in df.columns else np.full(len(df), np.nan)
    ds = np.nan_to_num(data_src, nan=0.0).astype(np.int64)
    kind = np.where(sysl == "E", np.where(ds & GAL_FNAV_BITS, KIND_FNAV, KIND_INAV), KIND_ANY)
    sats = df["sat"].to_numpy(str)
    pairs = pd.Series([f"{s}|{k}" for s, k in zip(sats, kind, strict=True)])
    codes, uniq = pd.factorize(pairs, sort=True)
    keys = {(u.split("|")[0], int(u.split("|")[1])): i for i, u in enumerate(uniq)}
    toe = df["week"].to_numpy(float) * WEEK_S + df["Toe"].to_numpy(float)
    order = np.lexsort((toe, codes))
    fields = {c: df[c].to_numpy(float)[order] for c in (*NAV_KEPLER, "BGDe5a", "BGDe5b") if c in df.columns}
    for c in ("BGDe5a", "BGDe5b"):
        fields.setdefault(c, np.zeros(len(df)))
    sysl = sysl[order]
    fit = np.nan_to_num(fields["FitIntvl"], nan=0.0)
    fit_half = np.select(
        [(sysl == "G") & (fit > 0), sysl == "J"],
        [fit * 1800.0, np.where(fit > 0, 7200.0, 3600.0)],
        default=np.array([SYSTEMS[s].fit_half_s for s in sysl]) if len(sysl) else np.zeros(0),
    )
    consts = [SYSTEMS[s] for s in sysl]
    return NavTable(
        sat=sats[order],
        system=sysl,
        kind=kind[order].astype(np.int64),
        key=codes[order].astype(np.int64),
        toe_s=toe[order],
        toc_s=df["toc_gps_s"].to_numpy(float)[order],
        fit_half_s=fit_half.astype(float),
        healthy=np.nan_to_num(fields["health"], nan=1.0) == 0,
        mu=np.array([c.mu_m3ps2 for c in consts], dtype=float),
        omega_e=np.array([c.omega_e_radps for c in consts], dtype=float),
        f_rel=np.array([c.f_rel_s_per_sqrtm for c in consts], dtype=float),
        field=fields,
        keys=keys,
    )


def _select_key(table: NavTable, key: IntArray, t: FloatArray) -> IntArray:
    """Nearest healthy Toe within the fit interval for integer keys (−1: none)."""
    ok = table.healthy
    rows = np.flatnonzero(ok)
    if rows.size == 0:
        return np.full(t.shape, -1, dtype=np.int64)
    span = 1e10  # combined sort key: key·1e10 + Toe (Toe < 1e10 s, exact in float64)
    comb = table.key[rows] * span + table.toe_s[rows]
    q = np.where(key >= 0, key * span + t, -1.0)
    pos = np.searchsorted(comb, q)
    lo = np.clip(pos - 1, 0, rows.size - 1)
    hi = np.clip(pos, 0, rows.size - 1)
    d_lo = np.where(table.key[rows[lo]] == key, np.abs(t - table.toe_s[rows[lo]]), np.inf)
    d_hi = np.where(table.key[rows[hi]] == key, np.abs(t - table.toe_s[rows[hi]]), np.inf)
    pick = np.where(d_hi < d_lo, rows[hi], rows[lo])
    dist = np.minimum(d_lo, d_hi)
    valid = (key >= 0) & np.isfinite(dist) & (dist <= table.fit_half_s[pick])
    return np.where(valid, pick, -1).astype(np.int64)


def select_ephemeris(table: NavTable, sat: StrArray, t: FloatArray, band: StrArray | None = None) -> IntArray:
    """Row of ``table`` to use for each (sat, t) — see the module docstring; −1 where none.

    ``band`` is the RINEX band digit of the signal ('1', '5', '7', ...); it selects Galileo
    I/NAV (E1, E5b) or F/NAV (E5a) records.
    """
    sat = np.asarray(sat, dtype=str)
    t = np.asarray(t, dtype=float)
    sysl = system_of(sat)
    band_a = np.full(sat.shape, "1") if band is None else np.asarray(band, dtype=str)
    want = np.where(sysl == "E", np.where(band_a == "5", KIND_FNAV, KIND_INAV), KIND_ANY)
    other = np.where(want == KIND_FNAV, KIND_INAV, np.where(want == KIND_INAV, KIND_FNAV, -1))
    uniq, inv = np.unique(np.char.add(np.char.add(sat, "|"), want.astype(str)), return_inverse=True)
    uniq_o, inv_o = np.unique(np.char.add(np.char.add(sat, "|"), other.astype(str)), return_inverse=True)

    def lookup(names: StrArray, inverse: IntArray) -> IntArray:
        codes = np.array([table.keys.get((n.split("|")[0], int(n.split("|")[1])), -1) for n in names], dtype=np.int64)
        return codes[inverse.reshape(sat.shape)] if codes.size else np.full(sat.shape, -1, dtype=np.int64)

    idx = _select_key(table, lookup(uniq, inv), t)
    miss = (idx < 0) & (other >= 0)
    if miss.any():
        idx[miss] = _select_key(table, lookup(uniq_o, inv_o)[miss], t[miss])
    return idx


def eccentric_anomaly(mean_anomaly: FloatArray, ecc: FloatArray, tol: float = 1e-14) -> FloatArray:
    """Solve Kepler's equation M = E − e sin E by Newton's iteration (IS-GPS-200N Table 20-IV)."""
    m = np.asarray(mean_anomaly, dtype=float)
    e = np.asarray(ecc, dtype=float)
    ea = m.copy()
    for _ in range(30):
        step = (ea - e * np.sin(ea) - m) / (1.0 - e * np.cos(ea))
        ea = ea - step
        if not np.any(np.abs(step) > tol):
            break
    return ea


@dataclass(frozen=True)
class SatStates:
    """ECEF position [m] and velocity [m/s] at t, clock offset Δt_sv [s] (polynomial +
    relativistic, before the group delay) and its rate [s/s]; NaN for rows without ephemeris."""

    pos: FloatArray
    vel: FloatArray
    clock_s: FloatArray
    clock_rate: FloatArray
    relativistic_s: FloatArray
    ecc_anomaly: FloatArray


def _g(table: NavTable, name: str, idx: IntArray) -> FloatArray:
    return table.field[name][idx]


def satellite_states(table: NavTable, idx: IntArray, t: FloatArray) -> SatStates:
    """Evaluate ephemeris rows ``idx`` at GPS times ``t`` (module docstring equations)."""
    idx = np.asarray(idx, dtype=np.int64)
    t = np.asarray(t, dtype=float)
    bad = idx < 0
    j = np.where(bad, 0, idx)
    if table.size == 0:
        nan = np.full(t.shape, np.nan)
        nan3 = np.full((*t.shape, 3), np.nan)
        return SatStates(nan3, nan3.copy(), nan, nan.copy(), nan.copy(), nan.copy())
    a = _g(table, "sqrtA", j) ** 2
    e = _g(table, "Eccentricity", j)
    tk = t - table.toe_s[j]
    n0 = np.sqrt(table.mu[j] / a**3)
    n = n0 + _g(table, "DeltaN", j)
    ea = eccentric_anomaly(_g(table, "M0", j) + n * tk, e)
    sin_e, cos_e = np.sin(ea), np.cos(ea)
    one_m = 1.0 - e * cos_e
    nu = np.arctan2(np.sqrt(1.0 - e * e) * sin_e, cos_e - e)
    phi = nu + _g(table, "omega", j)
    s2, c2 = np.sin(2.0 * phi), np.cos(2.0 * phi)
    cus, cuc = _g(table, "Cus", j), _g(table, "Cuc", j)
    crs, crc = _g(table, "Crs", j), _g(table, "Crc", j)
    cis, cic = _g(table, "Cis", j), _g(table, "Cic", j)
    u = phi + cus * s2 + cuc * c2
    r = a * one_m + crs * s2 + crc * c2
    idot = _g(table, "IDOT", j)
    inc = _g(table, "Io", j) + cis * s2 + cic * c2 + idot * tk
    we = table.omega_e[j]
    om_dot = _g(table, "OmegaDot", j) - we
    om = _g(table, "Omega0", j) + om_dot * tk - we * _g(table, "Toe", j)
    xp, yp = r * np.cos(u), r * np.sin(u)
    co, so, ci, si = np.cos(om), np.sin(om), np.cos(inc), np.sin(inc)
    pos = np.stack([xp * co - yp * ci * so, xp * so + yp * ci * co, yp * si], axis=-1)
    # velocity (Table 20-IV)
    e_dot = n / one_m
    nu_dot = e_dot * np.sqrt(1.0 - e * e) / one_m
    di = idot + 2.0 * nu_dot * (cis * c2 - cic * s2)
    du = nu_dot + 2.0 * nu_dot * (cus * c2 - cuc * s2)
    dr = e * a * e_dot * sin_e + 2.0 * nu_dot * (crs * c2 - crc * s2)
    dxp = dr * np.cos(u) - r * du * np.sin(u)
    dyp = dr * np.sin(u) + r * du * np.cos(u)
    vel = np.stack(
        [
            -xp * om_dot * so + dxp * co - dyp * so * ci - yp * (om_dot * co * ci - di * so * si),
            xp * om_dot * co + dxp * so + dyp * co * ci - yp * (om_dot * so * ci + di * co * si),
            dyp * si + yp * di * ci,
        ],
        axis=-1,
    )
    # clock (§20.3.3.3.3.1)
    dtc = t - table.toc_s[j]
    sqrt_a = _g(table, "sqrtA", j)
    rel = table.f_rel[j] * e * sqrt_a * sin_e
    af0, af1, af2 = _g(table, "SVclockBias", j), _g(table, "SVclockDrift", j), _g(table, "SVclockDriftRate", j)
    clock = af0 + af1 * dtc + af2 * dtc**2 + rel
    rate = af1 + 2.0 * af2 * dtc + table.f_rel[j] * e * sqrt_a * cos_e * e_dot
    if bad.any():
        for arr in (pos, vel):
            arr[bad] = np.nan
        for arr1 in (clock, rate, rel, ea):
            arr1[bad] = np.nan
    return SatStates(pos, vel, clock, rate, rel, ea)


def clock_polynomial_s(table: NavTable, idx: IntArray, t: FloatArray) -> FloatArray:
    """af0 + af1(t − toc) + af2(t − toc)² [s] (no relativistic term, no group delay)."""
    j = np.where(idx < 0, 0, idx)
    dtc = t - table.toc_s[j]
    out = _g(table, "SVclockBias", j) + _g(table, "SVclockDrift", j) * dtc + _g(table, "SVclockDriftRate", j) * dtc**2
    return np.where(idx < 0, np.nan, out)


def group_delay_s(table: NavTable, idx: IntArray, freq_hz: FloatArray) -> FloatArray:
    """Single-frequency group delay to subtract from Δt_sv [s] (module docstring)."""
    j = np.where(idx < 0, 0, idx)
    gamma = (F_L1_HZ / np.asarray(freq_hz, dtype=float)) ** 2
    gal = table.system[j] == "E"
    bgd = np.where(table.kind[j] == KIND_FNAV, _g(table, "BGDe5a", j), _g(table, "BGDe5b", j))
    tgd = np.nan_to_num(np.where(gal, bgd, _g(table, "TGD", j)), nan=0.0)
    return np.where(idx < 0, np.nan, gamma * tgd)


@dataclass(frozen=True)
class Transmission:
    """Satellite state at signal transmission for each observation row."""

    idx: IntArray
    t_tx: FloatArray
    """GPS time of transmission [s]."""
    pos: FloatArray
    """ECEF at t_tx (the frame of the transmission epoch; see ``sagnac_m``)."""
    vel: FloatArray
    clock_m: FloatArray
    """c·(Δt_sv − group delay): add to the pseudorange."""
    clock_rate: FloatArray
    omega_e: FloatArray


def transmission_states(
    table: NavTable, sat: StrArray, t_rx: FloatArray, pseudorange_m: FloatArray, freq_hz: FloatArray, band: StrArray
) -> Transmission:
    """Satellite states at transmission (IS-GPS-200N §20.3.3.3.3.1).

    t_sv = t_rx − ρ/c is exact in the satellite's time scale whatever the receiver clock
    (that is what a pseudorange is); t = t_sv − Δt_sv(t_sv) with Δt_sv evaluated twice
    (its sensitivity to t is ~1e-11 s/s). The ephemeris is selected at t_rx.
    """
    idx = select_ephemeris(table, sat, t_rx, band)
    t_sv = np.asarray(t_rx, dtype=float) - np.asarray(pseudorange_m, dtype=float) / C_MPS
    t = t_sv - clock_polynomial_s(table, idx, t_sv)
    st = satellite_states(table, idx, t)
    t = t_sv - st.clock_s
    st = satellite_states(table, idx, t)
    clock = st.clock_s - group_delay_s(table, idx, freq_hz)
    we = np.where(idx < 0, np.nan, table.omega_e[np.where(idx < 0, 0, idx)]) if table.size else np.full(t.shape, np.nan)
    return Transmission(idx, t, st.pos, st.vel, C_MPS * clock, st.clock_rate, we)


def sagnac_m(sat_pos: FloatArray, rx_pos: FloatArray, omega_e: FloatArray | float) -> FloatArray:
    """Earth-rotation (Sagnac) range term (Ω̇e/c)(x_s·y_r − y_s·x_r) [m].

    With the satellite at its transmission position in the ECEF frame of transmission and the
    receiver in the frame of reception, the geometric range is |r_s − r_r| + this term to first
    order in Ω̇e·τ (the rotation of the ECEF frame during the signal's travel that the
    IS-GPS-200 user algorithm leaves to the user; the same form as RTKLIB's geodist). Its
    bound Ω̇e·R_E·r_s/c is ~40 m for GPS and ~65 m for a GEO.
    """
    w = np.asarray(omega_e, dtype=float)
    return (w / C_MPS) * (sat_pos[..., 0] * rx_pos[..., 1] - sat_pos[..., 1] * rx_pos[..., 0])
