"""One run's GNSS positioning: pre-checks, the constrained solution per receiver and jointly,
the antenna-distance check, and the unconstrained solution beside it [S002].

Chain per epoch (the paper's fig. 2): navigation data compared between receivers →
pseudorange differences against the antenna separation → elevation, C/N0 and sky masks →
(SBAS/D-GPS corrections in ``observables``) → track-constrained solution per receiver with
fault detection and exclusion → the computed distance between the two antennas
|A_a(s_a) − A_b(s_b)| compared with the real one |A_a(s) − A_b(s)| (tolerance
k_ff·√(σ_a² + σ_b²) + 0.5 m); epochs failing it are marked ``antenna_distance``.

Geometry (azimuth, elevation, atmosphere, σ) is evaluated at the prior's track point when a
prior is given, else in two passes: at the track's middle, then at the first solution.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fieldlogs.gnss.constrained import STATUS_NAMES, STATUS_OK, ConstrainedConfig, Rows, solve_constrained
from fieldlogs.gnss.errormodel import ErrorModel
from fieldlogs.gnss.lsq import solve_lsq
from fieldlogs.gnss.observables import (
    FLAG_SKY_MASK,
    Epochs,
    apply_geometry,
    apply_masks,
    build_epochs,
    carrier_smoothed,
)
from fieldlogs.gnss.prechecks import check_receiver_pair, compare_navigation, flag_nav_mismatch
from fieldlogs.gnss.skymask import SkyMask
from fieldlogs.gnss.track import Antenna, TrackLine


@dataclass(frozen=True)
class PositionConfig:
    """Masks and solver settings of a run."""

    systems: tuple[str, ...] = ("G", "E", "J")
    elevation_mask_deg: float = 10.0
    cn0_mask_dbhz: float = 30.0
    pr_difference_tol_m: float = 8.0
    max_pdop: float = 6.0
    smoothing_s: float | None = 100.0
    """Carrier-smoothing window (``observables.carrier_smoothed``); None: raw code."""
    error_model: ErrorModel = field(default_factory=ErrorModel)
    solver: ConstrainedConfig = field(default_factory=ConstrainedConfig)


@dataclass
class PositionResult:
    """Per receiver × epoch results (``epochs``) and the prepared observations."""

    epochs: pd.DataFrame
    observations: Epochs
    mdb_m: np.ndarray
    """Minimal detectable bias of every row of ``observations`` (NaN: unused or unmonitored)."""


def receiver_rows(ep: Epochs, direction: np.ndarray) -> Rows:
    """Solver rows (K = 1) of the epochs ``ep`` (one receiver's)."""
    return Rows(
        sat_pos=np.nan_to_num(ep.sat_pos, nan=0.0),
        pr_m=np.nan_to_num(ep.pr_corr_m, nan=0.0),
        sigma_m=np.nan_to_num(ep.sigma_m, nan=1.0),
        usable=ep.usable & np.isfinite(ep.pr_corr_m),
        omega_e=np.nan_to_num(ep.omega_e, nan=0.0),
        receiver=np.zeros(ep.pr_m.shape, dtype=np.int64),
        direction=direction,
    )


def _prior_for(ep: Epochs, prior: pd.DataFrame | None) -> tuple[np.ndarray, np.ndarray] | None:
    """Prior (s, σ) at each epoch's run time (``prior`` columns t, s_m, sigma_m; linear interpolation)."""
    if prior is None:
        return None
    p = prior.sort_values("t")
    s = np.interp(ep.t_run, p["t"].to_numpy(float), p["s_m"].to_numpy(float))
    sig = np.interp(ep.t_run, p["t"].to_numpy(float), p["sigma_m"].to_numpy(float))
    return s, sig


def _geometry(
    ep: Epochs, track: TrackLine, s_approx: np.ndarray, iono: Mapping[str, Sequence[float]] | None, cfg: PositionConfig
) -> Epochs:
    flags = ep.flags.copy()
    out = apply_geometry(ep, track.point(np.clip(s_approx, 0.0, track.length_m)), iono_params=iono, error_model=cfg.error_model)
    out.flags = flags
    apply_masks(out, elevation_mask_deg=cfg.elevation_mask_deg, cn0_mask_dbhz=cfg.cn0_mask_dbhz)
    return out


def position_run(
    obs: pd.DataFrame,
    nav: pd.DataFrame | Mapping[str, pd.DataFrame],
    track: TrackLine,
    antennas: Mapping[str, Antenna],
    *,
    iono: Mapping[str, Sequence[float]] | None = None,
    corrections: pd.DataFrame | None = None,
    sky_mask: SkyMask | None = None,
    prior: pd.DataFrame | None = None,
    direction: float = 1.0,
    cfg: PositionConfig | None = None,
) -> PositionResult:
    """Position every receiver-epoch of ``obs`` on ``track`` (module docstring).

    ``nav`` is one frame, or one per receiver (then compared, and merged).
    """
    cfg = cfg or PositionConfig()
    if isinstance(nav, pd.DataFrame):
        merged, mismatch = nav, None
    else:
        mismatch = compare_navigation(nav)
        merged = pd.concat(list(nav.values()), ignore_index=True).drop_duplicates(["sat", "week", "Toe", "DataSrc"])
    if cfg.smoothing_s:
        obs = carrier_smoothed(obs, cfg.smoothing_s)
    ep = build_epochs(obs, merged, systems=cfg.systems, corrections=corrections)
    if mismatch is not None:
        flag_nav_mismatch(ep, mismatch)
    names = sorted(antennas)
    missing = sorted(set(np.unique(ep.receiver)) - set(names))
    if missing:
        raise KeyError(f"no antenna given for receiver(s) {', '.join(missing)}")
    if len(names) == 2:
        a, b = (antennas[n] for n in names)
        sep = float(np.linalg.norm([a.along_m - b.along_m, a.lateral_m - b.lateral_m, a.height_m - b.height_m]))
        check_receiver_pair(ep, names[0], names[1], sep, cfg.pr_difference_tol_m)
    pr = _prior_for(ep, prior)
    s_approx = pr[0] if pr is not None else np.full(ep.t.size, 0.5 * track.length_m)
    ep = _geometry(ep, track, s_approx, iono, cfg)
    if sky_mask is not None:
        ep.flag(sky_mask.blocked(ep.az, ep.el), FLAG_SKY_MASK)
    dirs = np.full(ep.t.size, float(direction))
    mdb = np.full(ep.present.shape, np.nan)
    sols = _solve_receivers(ep, track, antennas, names, dirs, pr, cfg, mdb)
    if pr is None:  # second pass: geometry at the first solution
        s1 = np.where(np.isfinite(sols["s_m"].to_numpy()), sols["s_m"].to_numpy(), s_approx)
        ep2 = _geometry(replace_flags(ep), track, s1, iono, cfg)
        if sky_mask is not None:
            ep2.flag(sky_mask.blocked(ep2.az, ep2.el), FLAG_SKY_MASK)
        ep = ep2
        sols = _solve_receivers(ep, track, antennas, names, dirs, None, cfg, mdb, s_init=s1)
    table = _with_lsq(ep, sols, cfg)
    if len(names) == 2:
        table = _antenna_distance(table, track, antennas, names, direction, cfg)
    return PositionResult(table, ep, mdb)


def replace_flags(ep: Epochs) -> Epochs:
    """A copy of ``ep`` with the geometry-dependent flags (masks) cleared."""
    from dataclasses import replace

    from fieldlogs.gnss.observables import FLAG_LOW_CN0, FLAG_LOW_ELEVATION

    keep = ~np.int64(FLAG_LOW_ELEVATION | FLAG_LOW_CN0 | FLAG_SKY_MASK)
    return replace(ep, flags=ep.flags & keep)


def _solve_receivers(
    ep: Epochs,
    track: TrackLine,
    antennas: Mapping[str, Antenna],
    names: list[str],
    dirs: np.ndarray,
    prior: tuple[np.ndarray, np.ndarray] | None,
    cfg: PositionConfig,
    mdb: np.ndarray,
    s_init: np.ndarray | None = None,
) -> pd.DataFrame:
    """Constrained solution of each receiver's epochs (K = 1 each)."""
    out = pd.DataFrame(index=np.arange(ep.t.size))
    for name in names:
        sel = np.flatnonzero(ep.receiver == name)
        if sel.size == 0:
            continue
        sub = ep.select(sel)
        pr = None
        if prior is not None:
            pr = (prior[0][sel], prior[1][sel])
        sol = solve_constrained(
            track,
            receiver_rows(sub, dirs[sel]),
            [antennas[name]],
            cfg.solver,
            s_init=None if s_init is None else s_init[sel],
            prior=pr,
        )
        out.loc[sel, "s_m"] = sol.s
        out.loc[sel, "clock_m"] = sol.clock_m[:, 0]
        out.loc[sel, "sigma_m"] = sol.sigma_s
        out.loc[sel, "uncertainty_m"] = sol.uncertainty_m
        out.loc[sel, "protection_m"] = sol.protection_m
        out.loc[sel, "adop"] = sol.adop
        out.loc[sel, "test"] = sol.test
        out.loc[sel, "dof"] = sol.dof
        out.loc[sel, "n_used"] = sol.n_used
        out.loc[sel, "n_excluded"] = sol.excluded.sum(axis=1) + sol.no_track.sum(axis=1)
        out.loc[sel, "status_code"] = sol.status
        mdb[sel] = sol.mdb_m
        ep.flag(_scatter(ep, sel, sol.excluded), 256)
        ep.flag(_scatter(ep, sel, sol.no_track), 128)
    out["status"] = out["status_code"].map(STATUS_NAMES)
    return out


def _scatter(ep: Epochs, sel: np.ndarray, rows: np.ndarray) -> np.ndarray:
    full = np.zeros_like(ep.present)
    full[sel] = rows
    return full


def _with_lsq(ep: Epochs, sols: pd.DataFrame, cfg: PositionConfig) -> pd.DataFrame:
    lsq = solve_lsq(
        np.nan_to_num(ep.sat_pos, nan=0.0),
        np.nan_to_num(ep.pr_corr_m, nan=0.0),
        np.nan_to_num(ep.sigma_m, nan=1.0),
        ep.usable & np.isfinite(ep.pr_corr_m),
        ep.system,
        np.nan_to_num(ep.omega_e, nan=0.0),
        max_pdop=cfg.max_pdop,
    )
    table = pd.DataFrame({"t": ep.t_run, "gnss_time_s": ep.t, "receiver": ep.receiver})
    table = pd.concat([table, sols], axis=1)
    table["available"] = table["status_code"] == STATUS_OK
    table["lsq_available"] = lsq.available
    table["lsq_n_used"] = lsq.n_used
    table["lsq_pdop"] = lsq.pdop
    table[["lsq_x_m", "lsq_y_m", "lsq_z_m"]] = lsq.pos
    table["n_usable"] = ep.usable.sum(axis=1)
    return table


def _antenna_distance(
    table: pd.DataFrame, track: TrackLine, antennas: Mapping[str, Antenna], names: list[str], direction: float, cfg: PositionConfig
) -> pd.DataFrame:
    """The paper's final check: computed vs real distance between the two antennas."""
    a, b = names
    ta = table[table["receiver"] == a].set_index(np.round(table.loc[table["receiver"] == a, "t"], 3))
    tb = table[table["receiver"] == b].set_index(np.round(table.loc[table["receiver"] == b, "t"], 3))
    common = ta.index.intersection(tb.index)
    pa, _ = track.antenna(ta.loc[common, "s_m"].to_numpy(float), antennas[a], direction)
    pb, _ = track.antenna(tb.loc[common, "s_m"].to_numpy(float), antennas[b], direction)
    mid = 0.5 * (ta.loc[common, "s_m"].to_numpy(float) + tb.loc[common, "s_m"].to_numpy(float))
    ra, _ = track.antenna(mid, antennas[a], direction)
    rb, _ = track.antenna(mid, antennas[b], direction)
    computed = np.linalg.norm(pa - pb, axis=1)
    real = np.linalg.norm(ra - rb, axis=1)
    tol = cfg.solver.k_fault_free * np.hypot(ta.loc[common, "sigma_m"].to_numpy(float), tb.loc[common, "sigma_m"].to_numpy(float)) + 0.5
    ok = np.abs(computed - real) <= tol
    both = ta.loc[common, "available"].to_numpy(bool) & tb.loc[common, "available"].to_numpy(bool)
    check = pd.DataFrame({"t_key": common, "antenna_distance_m": computed, "antenna_distance_real_m": real, "antenna_distance_ok": ok | ~both})
    table = table.assign(t_key=np.round(table["t"], 3)).merge(check, on="t_key", how="left").drop(columns="t_key")
    table["antenna_distance_ok"] = table["antenna_distance_ok"].fillna(True).astype(bool)
    return table
