"""From ``gnss_obs`` + ``gnss_nav`` frames to per-epoch arrays of corrected pseudoranges.

An *epoch* is one receiver's observations at one ``gnss_time_s``; arrays are (E, S), S the
largest number of satellites an epoch has (padding is ``present = False``). One signal is
used per satellite and epoch, the first of the system's preference list that is present.

The pseudorange model (IS-GPS-200N §20.3.3.3.3.1, §20.3.3.5.2.5) is
ρ_meas = |r_s − r_r| + sagnac + c(b_r − Δt_sv,f) + I_f + T + ε, so the solvers get the
*corrected* pseudorange ρ_c = ρ_meas + c·Δt_sv,f − I_f − T + PRC, to be matched by
|r_s − r_r| + sagnac + c·b_r. Δt_sv,f includes the relativistic term and the group delay and
the SBAS long-term clock correction; r_s the long-term orbit correction. I and T need the
receiver position: ``apply_geometry`` computes them (and azimuth, elevation, σ) at an
approximate position per epoch — metres to kilometres off changes them by millimetres.

``flags`` records why a row is not used (bits below); ``usable`` is present & flags == 0.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Final

import numpy as np
import pandas as pd

from fieldlogs.gnss.atmosphere import iono_delay_m, tropo_delay_m
from fieldlogs.gnss.constants import (
    C_MPS,
    OBS_CN0,
    OBS_LLI,
    OBS_PR,
    OBS_RECEIVER,
    OBS_SAT,
    OBS_SIGNAL,
    OBS_T,
    OBS_TIME,
    SYSTEMS,
    BoolArray,
    FloatArray,
    IntArray,
    StrArray,
    signal_frequency_hz,
    system_of,
)
from fieldlogs.gnss.corrections import match_corrections
from fieldlogs.gnss.ephemeris import NavTable, nav_table, transmission_states
from fieldlogs.gnss.errormodel import ErrorModel, pseudorange_sigma_m
from fieldlogs.gnss.geodesy import azimuth_elevation, ecef_to_geodetic
from schemas.errors import InputError

if TYPE_CHECKING:
    from fieldlogs.gnss.sbas import SbasCorrections

FLAG_NO_EPHEMERIS: Final = 1
FLAG_LOW_ELEVATION: Final = 2
FLAG_LOW_CN0: Final = 4
FLAG_SKY_MASK: Final = 8
FLAG_NAV_MISMATCH: Final = 16
FLAG_PR_DIFFERENCE: Final = 32
FLAG_AUGMENTATION: Final = 64
FLAG_NO_TRACK_SOLUTION: Final = 128
FLAG_EXCLUDED: Final = 256
FLAG_SYSTEM_OFF: Final = 512
FLAG_CODE_CARRIER: Final = 1024
FLAG_NAMES: Final = {
    FLAG_NO_EPHEMERIS: "no_ephemeris",
    FLAG_LOW_ELEVATION: "low_elevation",
    FLAG_LOW_CN0: "low_cn0",
    FLAG_SKY_MASK: "sky_mask",
    FLAG_NAV_MISMATCH: "nav_mismatch",
    FLAG_PR_DIFFERENCE: "pr_difference",
    FLAG_AUGMENTATION: "augmentation_do_not_use",
    FLAG_NO_TRACK_SOLUTION: "no_track_solution",
    FLAG_EXCLUDED: "fde_excluded",
    FLAG_SYSTEM_OFF: "system_not_selected",
    FLAG_CODE_CARRIER: "code_carrier_divergence",
}

DEFAULT_SIGNALS: Final[dict[str, tuple[str, ...]]] = {
    "G": ("C1C", "C1W", "C2L", "C2W", "C5Q"),
    "E": ("C1C", "C1X", "C1B", "C7Q", "C5Q"),
    "J": ("C1C", "C1X", "C2L", "C5Q"),
}


class ObservationError(InputError):
    """An observation frame without a required column."""


def carrier_smoothed(
    obs: pd.DataFrame, window_s: float = 100.0, jump_m: float = 15.0, divergence_window_s: float = 100.0
) -> pd.DataFrame:
    """Carrier-smoothed pseudoranges (Hatch filter in its moving-window form; DO-229's
    airborne equipment smooths over 100 s).

    Per (receiver, satellite, signal) arc: ρ_s(k) = λΦ(k) + mean_{j ∈ window(k)} (ρ(j) − λΦ(j)),
    the window being the last ``window_s`` seconds of the arc. An arc restarts at a gap longer
    than 1.5 epochs, at a loss-of-lock flag (lli bit 0) and where the code-minus-carrier jumps
    by more than ``jump_m`` from the previous epoch (a cycle slip). The ionosphere's code-carrier
    divergence (2ΔI over the window, ~0.1–0.3 m for 100 s at low elevation) is left in.
    Returns a copy with ``pseudorange_m`` replaced where a carrier exists and the columns
    ``smooth_n`` (samples averaged; 1 where unsmoothed) and ``divergence_mps``.

    ``divergence_mps`` is the code-carrier divergence monitor: the least-squares slope of
    ρ − λΦ over the last ``divergence_window_s`` of the arc (NaN until the arc is that long),
    slope = (nΣxy − ΣxΣy)/(nΣx² − (Σx)²) over the window's samples. A fault-free arc drifts at
    2·dI/dt (the ionosphere, centimetres per minute) plus what multipath and noise leave in a
    100 s fit (≤ 0.04 m/s in the simulator's 50-run worst case at 30 dB-Hz); a code-only fault
    ramp drifts at its own rate, and the moving-window smoothing above would hide half a
    window of it (the smoothed code lags a ramp r by r·window/2: 10 m for 0.2 m/s over 100 s),
    so the w-test alone sees it late. ``build_epochs`` flags rows beyond its limit.
    """
    df = obs.copy()
    lam = C_MPS / signal_frequency_hz(system_of(df[OBS_SAT].to_numpy()), df[OBS_SIGNAL].to_numpy(str))
    phase = df["carrier_cycles"].to_numpy(float) * lam if "carrier_cycles" in df.columns else np.full(len(df), np.nan)
    cmc = df[OBS_PR].to_numpy(float) - phase
    key = [OBS_RECEIVER, OBS_SAT, OBS_SIGNAL]
    order = df.sort_values([*key, OBS_TIME], kind="stable").index
    d = df.loc[order, key].assign(_t=df.loc[order, OBS_TIME].to_numpy(float), _cmc=cmc[order])
    same = (d[key] == d[key].shift()).all(axis=1).to_numpy()
    dt = np.diff(d["_t"].to_numpy(), prepend=np.nan)
    step = float(np.nanmedian(dt[same])) if same.any() else 1.0
    lli = df.loc[order, OBS_LLI].fillna(0).to_numpy().astype(np.int64) & 1 if OBS_LLI in df.columns else 0
    jump = np.abs(np.diff(d["_cmc"].to_numpy(), prepend=np.nan)) > jump_m
    new_arc = ~same | (dt > 1.5 * step) | (lli > 0) | jump | ~np.isfinite(d["_cmc"].to_numpy())
    arc = np.cumsum(new_arc)
    n_win = max(round(window_s / step), 1)
    vals = np.nan_to_num(d["_cmc"].to_numpy())
    cs = pd.Series(vals).groupby(arc).cumsum().to_numpy()
    pos = pd.Series(np.ones(arc.size)).groupby(arc).cumsum().to_numpy().astype(np.int64)
    lag = pd.Series(cs).groupby(arc).shift(n_win).fillna(0.0).to_numpy()
    count = np.minimum(pos, n_win)
    mean = (cs - lag) / count
    ok = np.isfinite(d["_cmc"].to_numpy())
    smoothed = np.where(ok, phase[order] + mean, df.loc[order, OBS_PR].to_numpy(float))
    df.loc[order, OBS_PR] = smoothed
    df.loc[order, "smooth_n"] = np.where(ok, count, 1)
    df.loc[order, "divergence_mps"] = _divergence(arc, pos, d["_cmc"].to_numpy(), ok, step, divergence_window_s)
    return pd.DataFrame(df)


def _divergence(
    arc: IntArray, pos: IntArray, cmc: FloatArray, ok: BoolArray, step: float, window_s: float
) -> FloatArray:
    """Moving least-squares slope of ``cmc`` per arc over the last ``window_s`` [m/s]
    (``carrier_smoothed``); NaN where the arc is shorter or has no carrier."""
    n = max(round(window_s / step), 2)
    first = pd.Series(np.where(ok, cmc, np.nan)).groupby(arc).transform("first").to_numpy()
    y = np.where(ok, cmc - np.nan_to_num(first), 0.0)  # relative to the arc's first value: small sums
    x = pos.astype(float)

    def wsum(v: FloatArray) -> FloatArray:
        cs = pd.Series(v).groupby(arc).cumsum()
        return np.asarray((cs - cs.groupby(arc).shift(n).fillna(0.0)).to_numpy(), dtype=np.float64)

    sx, sy, sxx, sxy = wsum(x), wsum(y), wsum(x * x), wsum(x * y)
    full = (pos >= n) & (wsum(ok.astype(float)) == n)  # n samples, all with a carrier
    den = n * sxx - sx * sx
    slope = (n * sxy - sx * sy) / np.where(den > 0, den, np.nan) / step
    return np.asarray(np.where(ok & full, slope, np.nan), dtype=np.float64)


@dataclass
class Epochs:
    """Per-epoch arrays of one or more receivers (module docstring)."""

    receiver: StrArray
    t: FloatArray
    """gnss_time_s of the epoch (receiver time of reception)."""
    t_run: FloatArray
    sat: StrArray
    system: StrArray
    freq_hz: FloatArray
    pr_m: FloatArray
    cn0_dbhz: FloatArray
    sat_pos: FloatArray
    sat_vel: FloatArray
    clock_m: FloatArray
    omega_e: FloatArray
    sv_acc_m: FloatArray
    prc_m: FloatArray
    corr_sigma_m: FloatArray
    corr_atmosphere: BoolArray
    smooth_n: FloatArray
    """Carrier-smoothing samples averaged per row (1: raw code)."""
    present: BoolArray
    flags: IntArray
    corr_udre_m: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    """SBAS σ_UDRE of corrected rows (NaN elsewhere; empty without SBAS): δUDRE scales it."""
    corr_udre_rss: BoolArray = field(default_factory=lambda: np.zeros((0, 0), dtype=bool))
    az: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    el: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    iono_m: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    tropo_m: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    sigma_m: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    pr_corr_m: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))

    @property
    def usable(self) -> BoolArray:
        return np.asarray(self.present & (self.flags == 0), dtype=bool)

    def flag(self, mask: BoolArray, bit: int) -> None:
        """Set ``bit`` where ``mask`` (present rows only)."""
        self.flags = np.where(mask & self.present, self.flags | bit, self.flags)

    def select(self, rows: IntArray | BoolArray) -> Epochs:
        """The epochs ``rows`` (an index or boolean array over E)."""
        kw = {}
        for name in self.__dataclass_fields__:
            v = getattr(self, name)
            kw[name] = v[rows] if v.shape[:1] == self.t.shape else v
        return replace(self, **kw)


def _pick_signals(obs: pd.DataFrame, signals: Mapping[str, Sequence[str]]) -> pd.DataFrame:
    """One row per (receiver, epoch, sat): the first preferred signal present."""
    sysl = system_of(obs[OBS_SAT].to_numpy())
    rank = np.full(len(obs), 10_000, dtype=np.int64)
    sig = obs[OBS_SIGNAL].to_numpy(str)
    for s, prefs in signals.items():
        for r, code in enumerate(prefs):
            rank[(sysl == s) & (sig == code) & (rank == 10_000)] = r
    ok = (rank < 10_000) & np.isfinite(obs[OBS_PR].to_numpy(float))
    df = obs.loc[ok].assign(_rank=rank[ok])
    df = df.sort_values([OBS_RECEIVER, OBS_TIME, OBS_SAT, "_rank"], kind="stable")
    return pd.DataFrame(df.drop_duplicates([OBS_RECEIVER, OBS_TIME, OBS_SAT], keep="first"))


def build_epochs(
    obs: pd.DataFrame,
    nav: pd.DataFrame | NavTable,
    *,
    systems: Sequence[str] = ("G", "E", "J"),
    signals: Mapping[str, Sequence[str]] | None = None,
    corrections: pd.DataFrame | None = None,
    sbas: SbasCorrections | None = None,
    max_divergence_mps: float | None = None,
) -> Epochs:
    """Satellite states and clock corrections for every observation, as (E, S) arrays.

    With ``max_divergence_mps``, rows whose code-carrier divergence (``divergence_mps`` of
    ``carrier_smoothed``) exceeds it in magnitude are flagged ``code_carrier_divergence``.

    With ``sbas`` (a decoded stream with valid messages) its fast and long-term corrections
    apply instead of ``corrections`` (:mod:`fieldlogs.gnss.sbas.clock_orbit`, matched on the
    IODE of the ephemeris in use)."""
    missing = [c for c in (OBS_TIME, OBS_RECEIVER, OBS_SAT, OBS_SIGNAL, OBS_PR) if c not in obs.columns]
    if missing:
        raise ObservationError("missing column", path="gnss_obs frame", column=missing[0])
    table = nav if isinstance(nav, NavTable) else nav_table(nav)
    df = _pick_signals(obs, signals or DEFAULT_SIGNALS)
    df = df.loc[np.isin(system_of(df[OBS_SAT].to_numpy()), list(SYSTEMS))]
    sat = df[OBS_SAT].to_numpy(str)
    sysl = system_of(sat)
    t = df[OBS_TIME].to_numpy(float)
    pr = df[OBS_PR].to_numpy(float)
    sig = df[OBS_SIGNAL].to_numpy(str)
    freq = signal_frequency_hz(sysl, sig)
    band = np.ascontiguousarray(sig.astype("U2")).view("U1").reshape(-1, 2)[:, 1] if sig.size else sig
    tx = transmission_states(table, sat, t, pr, freq, band)
    j = np.where(tx.idx < 0, 0, tx.idx)
    if sbas is not None and not sbas.empty:
        iode = np.where(tx.idx < 0, np.nan, table.field["IODE"][j]) if table.size else np.full(sat.size, np.nan)
        corr = sbas.rows(sat, t, iode)
    else:
        corr = match_corrections(corrections, sat, t)
    acc = table.field["SVacc"][j] if table.size else np.full(sat.size, np.nan)
    flags = np.where(tx.idx < 0, FLAG_NO_EPHEMERIS, 0) | np.where(corr.usable, 0, FLAG_AUGMENTATION)
    flags = flags | np.where(np.isin(sysl, list(systems)), 0, FLAG_SYSTEM_OFF)
    if max_divergence_mps is not None and "divergence_mps" in df.columns:
        div = np.abs(df["divergence_mps"].to_numpy(float))
        flags = flags | np.where(np.nan_to_num(div, nan=0.0) > max_divergence_mps, FLAG_CODE_CARRIER, 0)
    rows = {
        "sat": sat,
        "system": sysl,
        "freq_hz": freq,
        "pr_m": pr,
        "cn0_dbhz": df[OBS_CN0].to_numpy(float) if OBS_CN0 in df.columns else np.full(sat.size, np.nan),
        "sat_pos": tx.pos + corr.dpos_m,
        "sat_vel": tx.vel,
        "clock_m": tx.clock_m + C_MPS * corr.dclock_s,
        "omega_e": tx.omega_e,
        "sv_acc_m": np.where(tx.idx < 0, np.nan, acc),
        "prc_m": corr.prc_m,
        "corr_sigma_m": corr.sigma_m,
        "corr_atmosphere": corr.covers_atmosphere,
        "smooth_n": df["smooth_n"].to_numpy(float) if "smooth_n" in df.columns else np.ones(sat.size),
        "flags": flags.astype(np.int64),
    }
    if corr.udre_sigma_m is not None and corr.udre_rss is not None:
        rows["corr_udre_m"] = corr.udre_sigma_m
        rows["corr_udre_rss"] = corr.udre_rss
    return _to_epochs(df, rows)


_FILL = {"sat": "", "system": "", "corr_atmosphere": False, "corr_udre_rss": False, "flags": 0}


def _to_epochs(df: pd.DataFrame, rows: dict[str, np.ndarray]) -> Epochs:
    """Scatter flat rows into (E, S) arrays keyed by (receiver, gnss_time_s)."""
    keys = df[[OBS_RECEIVER, OBS_TIME]]
    epoch_id = keys.groupby([OBS_RECEIVER, OBS_TIME], sort=True).ngroup().to_numpy()
    n_ep = int(epoch_id.max()) + 1 if epoch_id.size else 0
    slot = pd.Series(epoch_id).groupby(epoch_id).cumcount().to_numpy()
    n_slot = int(slot.max()) + 1 if slot.size else 0
    first = np.unique(epoch_id, return_index=True)[1]
    out: dict[str, np.ndarray] = {}
    for name, v in rows.items():
        shape = (n_ep, n_slot, *v.shape[1:])
        fill = _FILL.get(name, np.nan)
        arr = np.full(shape, fill, dtype=v.dtype if v.dtype.kind in "USbi" else float)
        arr[epoch_id, slot] = v
        out[name] = arr
    present = np.zeros((n_ep, n_slot), dtype=bool)
    present[epoch_id, slot] = True
    t_run = df[OBS_T].to_numpy(float)[first] if OBS_T in df.columns else df[OBS_TIME].to_numpy(float)[first]
    return Epochs(
        receiver=df[OBS_RECEIVER].to_numpy(str)[first],
        t=df[OBS_TIME].to_numpy(float)[first],
        t_run=t_run,
        present=present,
        **out,
    )


def apply_geometry(
    ep: Epochs,
    approx_ecef: FloatArray,
    *,
    iono_params: Mapping[str, Sequence[float]] | None = None,
    error_model: ErrorModel | None = None,
    apply_troposphere: bool = True,
    sbas: SbasCorrections | None = None,
) -> Epochs:
    """Azimuth, elevation, ionosphere, troposphere, σ and the corrected pseudorange at
    approximate receiver positions ``approx_ecef`` (E, 3). Returns a new ``Epochs``.

    With ``sbas`` its ionospheric grid replaces the broadcast model, and σ_UIRE the model's
    σ_iono, wherever the grid covers a row's pierce point (:mod:`fieldlogs.gnss.sbas.grid`; the
    delay is the ionosphere's, so every system's L1/E1 rows take it)."""
    rx = np.asarray(approx_ecef, dtype=float)[:, None, :]
    pos = np.where(ep.present[..., None], ep.sat_pos, rx + np.array([0.0, 0.0, 2.0e7]))
    pos = np.where(np.isfinite(pos), pos, rx + np.array([0.0, 0.0, 2.0e7]))
    az, el = azimuth_elevation(rx, pos)
    lat, lon, h = ecef_to_geodetic(rx[:, 0, :])
    lat_b, lon_b, h_b = lat[:, None], lon[:, None], h[:, None]
    t_b = ep.t[:, None]
    freq = np.where(np.isfinite(ep.freq_hz), ep.freq_hz, 1.57542e9)
    iono = iono_delay_m(ep.system, freq, lat_b, lon_b, az, el, t_b, iono_params)
    iono_sigma = None
    if sbas is not None and not sbas.empty:
        cov, grid_m, grid_sigma = sbas.iono(lat_b, lon_b, az, el, t_b, freq)
        cov = cov & ep.present & ~ep.corr_atmosphere
        iono = np.where(cov, grid_m, iono)
        iono_sigma = np.where(cov, grid_sigma, np.nan)
    corr_sigma = ep.corr_sigma_m
    if sbas is not None and not sbas.empty and ep.corr_udre_m.shape == ep.present.shape:
        has = ep.present & np.isfinite(ep.corr_udre_m)
        if has.any():
            i, j = np.nonzero(has)
            los = pos[i, j] - rx[i, 0]
            los = los / np.linalg.norm(los, axis=1)[:, None]
            corr_sigma = corr_sigma.copy()
            corr_sigma[i, j] = sbas.flt_sigma(
                ep.corr_sigma_m[i, j], ep.corr_udre_m[i, j], ep.corr_udre_rss[i, j], ep.sat[i, j], ep.t[i],
                lat[i], lon[i], los,
            )  # fmt: skip
    tropo = tropo_delay_m(lat_b, h_b, np.maximum(el, np.radians(1.0))) if apply_troposphere else np.zeros_like(el)
    atm = ep.corr_atmosphere
    iono = np.where(atm, 0.0, iono)
    tropo = np.where(atm, 0.0, tropo)
    sigma = pseudorange_sigma_m(
        error_model or ErrorModel(),
        el,
        ep.cn0_dbhz,
        iono,
        ep.sv_acc_m,
        corr_sigma,
        ep.corr_atmosphere,
        ep.smooth_n,
        iono_sigma,
    )
    pr_corr = ep.pr_m + ep.clock_m - iono - tropo + ep.prc_m
    return replace(ep, az=az, el=el, iono_m=iono, tropo_m=tropo, sigma_m=sigma, pr_corr_m=pr_corr)


def epoch_keys(t: FloatArray, tol_s: float = 0.02) -> IntArray:
    """One common index per epoch across receivers: receivers tag their epochs in their own
    clock (an unsteered clock is off by up to a millisecond), so run times closer than
    ``tol_s`` are one epoch (times sorted, a new epoch where the step exceeds ``tol_s``)."""
    ta = np.asarray(t, dtype=float)
    order = np.argsort(ta, kind="stable")
    new = np.concatenate([[True], np.diff(ta[order]) > tol_s]) if ta.size else np.zeros(0, dtype=bool)
    keys = np.empty(ta.size, dtype=np.int64)
    keys[order] = np.cumsum(new) - 1
    return keys


def apply_masks(ep: Epochs, *, elevation_mask_deg: float = 10.0, cn0_mask_dbhz: float = 30.0) -> None:
    """The paper's elevation and C/N0 masks [S002]: flag rows below either (in place)."""
    ep.flag(ep.el < np.radians(elevation_mask_deg), FLAG_LOW_ELEVATION)
    ep.flag(np.nan_to_num(ep.cn0_dbhz, nan=np.inf) < cn0_mask_dbhz, FLAG_LOW_CN0)
