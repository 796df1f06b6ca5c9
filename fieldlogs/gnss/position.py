"""One run's GNSS positioning: pre-checks, the constrained solution per receiver and jointly,
the antenna-distance check, and the unconstrained solution beside it [S002].

Chain per epoch (the paper's fig. 2): navigation data compared between receivers →
pseudorange differences against the antenna separation → elevation, C/N0 and sky masks →
code-carrier divergence of the smoothed arcs (``observables.carrier_smoothed``: a satellite
whose code drifts from its carrier faster than ``max_divergence_mps`` is dropped) →
(SBAS/MSAS or D-GPS corrections in ``observables``, ``sbas``) → track-constrained solution per
receiver with fault detection and exclusion → the computed distance between the two antennas
|A_a(s_a) − A_b(s_b)| compared with the real one |A_a(s) − A_b(s)| (tolerance
k_ff·√(σ_a² + σ_b²) + 0.5 m); epochs failing it are marked ``antenna_distance``.

Geometry (azimuth, elevation, atmosphere, σ) is evaluated at the prior's track point when a
prior is given, else in two passes: at the track's middle, then at the first solution. Without
a prior the Gauss–Newton starts from the projection onto the track of the unconstrained
solution where that one is available and within 100 m of the track, else from the coarse
search along the whole track. Receivers' epochs are paired by ``observables.epoch_keys``
(their own clocks tag them up to a millisecond apart).
Epochs the satellites alone cannot carry (one satellite, poor geometry, an unresolved fault)
are then solved again with the receiver's coasted clock (``coasting``) as one more
observation; those that pass are marked ``clock_aided``. This goes beyond the paper's method
(it needs the receiver clock stable over a minute, which every TCXO receiver is).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from fieldlogs.gnss.coasting import predict_clock
from fieldlogs.gnss.constrained import STATUS_NAMES, STATUS_OK, ConstrainedConfig, Rows, solve_constrained
from fieldlogs.gnss.errormodel import ErrorModel
from fieldlogs.gnss.lsq import solve_lsq
from fieldlogs.gnss.observables import (
    FLAG_EXCLUDED,
    FLAG_LOW_CN0,
    FLAG_LOW_ELEVATION,
    FLAG_NO_TRACK_SOLUTION,
    FLAG_SKY_MASK,
    Epochs,
    apply_geometry,
    apply_masks,
    build_epochs,
    carrier_smoothed,
    epoch_keys,
)
from fieldlogs.gnss.prechecks import check_receiver_pair, compare_navigation, flag_nav_mismatch
from fieldlogs.gnss.skymask import SkyMask
from fieldlogs.gnss.track import Antenna, TrackLine
from schemas.errors import UsageError

if TYPE_CHECKING:
    from fieldlogs.gnss.sbas import SbasCorrections


@dataclass(frozen=True)
class PositionConfig:
    """Masks and solver settings of a run."""

    systems: tuple[str, ...] = ("G", "E", "J")
    elevation_mask_deg: float = 10.0
    cn0_mask_dbhz: float = 30.0
    pr_difference_tol_m: float = 8.0
    max_pdop: float = 6.0
    clock_coasting: bool = True
    """Re-solve failed epochs with each receiver's predicted clock (``coasting``)."""
    smoothing_s: float | None = 100.0
    """Carrier-smoothing window (``observables.carrier_smoothed``); None: raw code."""
    max_divergence_mps: float | None = 0.1
    """Code-carrier divergence limit of the smoothed arcs (``observables.carrier_smoothed``,
    100 s fit): a satellite drifting faster is flagged ``code_carrier_divergence``; None: off."""
    use_sbas: bool = True
    """Apply a run's SBAS/MSAS messages where it has them (``ontrack``)."""
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
    ep: Epochs,
    track: TrackLine,
    s_approx: np.ndarray,
    iono: Mapping[str, Sequence[float]] | None,
    sky_mask: SkyMask | None,
    cfg: PositionConfig,
    sbas: SbasCorrections | None = None,
) -> Epochs:
    """Geometry at the track points s_approx, then the elevation, C/N0 and sky masks."""
    flags = ep.flags.copy()
    pts = track.point(np.clip(s_approx, 0.0, track.length_m))
    out = apply_geometry(ep, pts, iono_params=iono, error_model=cfg.error_model, sbas=sbas)
    out.flags = flags
    apply_masks(out, elevation_mask_deg=cfg.elevation_mask_deg, cn0_mask_dbhz=cfg.cn0_mask_dbhz)
    if sky_mask is not None:
        out.flag(sky_mask.blocked(out.az, out.el), FLAG_SKY_MASK)
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
    sbas: SbasCorrections | None = None,
) -> PositionResult:
    """Position every receiver-epoch of ``obs`` on ``track`` (module docstring).

    ``nav`` is one frame, or one per receiver (then compared, and merged). ``sbas``: decoded
    SBAS/MSAS messages (:class:`fieldlogs.gnss.sbas.SbasCorrections`), applied instead of
    ``corrections`` (giving both is refused).
    """
    cfg = cfg or PositionConfig()
    if sbas is not None and corrections is not None:
        raise UsageError("give either SBAS messages or a corrections frame, not both")
    names = sorted(antennas)
    ep = _prepare(obs, nav, antennas, names, corrections, cfg, sbas)
    pr = _prior_for(ep, prior)
    s_approx = pr[0] if pr is not None else np.full(ep.t.size, 0.5 * track.length_m)
    ep = _geometry(ep, track, s_approx, iono, sky_mask, cfg, sbas)
    dirs = np.full(ep.t.size, float(direction))
    seed = _lsq_seed(ep, track, antennas, dirs, cfg) if pr is None else None
    sol = _solve_receivers(ep, track, antennas, names, dirs, pr, cfg, s_init=seed)
    if pr is None:  # second pass: geometry at the first solution
        s1 = np.where(np.isfinite(sol.table["s_m"].to_numpy()), sol.table["s_m"].to_numpy(), s_approx)
        ep = _geometry(replace_flags(ep), track, s1, iono, sky_mask, cfg, sbas)
        sol = _solve_receivers(ep, track, antennas, names, dirs, None, cfg, s_init=s1)
    if cfg.clock_coasting:
        sol = _coast(ep, track, antennas, names, dirs, pr, cfg, sol, sbas)
    table = _with_lsq(ep, sol.table, cfg)  # the classical receiver: masks and pre-checks, no FDE
    ep.flag(sol.excluded, FLAG_EXCLUDED)
    ep.flag(sol.no_track, FLAG_NO_TRACK_SOLUTION)
    if len(names) == 2:
        table = _antenna_distance(table, track, antennas, names, direction, cfg)
    return PositionResult(table, ep, sol.mdb)


def _lsq_seed(
    ep: Epochs, track: TrackLine, antennas: Mapping[str, Antenna], dirs: np.ndarray, cfg: PositionConfig
) -> np.ndarray:
    """Start s of the epochs whose unconstrained solution is available and within
    ``SEED_MAX_OFFSET_M`` of the track: its projection, less the antenna's along-track offset;
    NaN elsewhere (those epochs get the coarse search along the whole track)."""
    lsq = solve_lsq(
        np.nan_to_num(ep.sat_pos, nan=0.0),
        np.nan_to_num(ep.pr_corr_m, nan=0.0),
        np.nan_to_num(ep.sigma_m, nan=1.0),
        ep.usable & np.isfinite(ep.pr_corr_m),
        ep.system,
        np.nan_to_num(ep.omega_e, nan=0.0),
        max_pdop=cfg.max_pdop,
    )
    seed = np.full(ep.t.size, np.nan)
    ok = np.flatnonzero(lsq.available)
    if ok.size:
        s_ant = track.project(lsq.pos[ok])
        near = np.linalg.norm(lsq.pos[ok] - track.point(s_ant), axis=1) <= SEED_MAX_OFFSET_M
        along = np.array([antennas[r].along_m if r in antennas else 0.0 for r in ep.receiver[ok]])
        seed[ok[near]] = (s_ant - dirs[ok] * along)[near]
    return seed


#: An unconstrained solution farther than this from the track seeds no constrained one [m].
SEED_MAX_OFFSET_M = 100.0


def _prepare(
    obs: pd.DataFrame,
    nav: pd.DataFrame | Mapping[str, pd.DataFrame],
    antennas: Mapping[str, Antenna],
    names: list[str],
    corrections: pd.DataFrame | None,
    cfg: PositionConfig,
    sbas: SbasCorrections | None = None,
) -> Epochs:
    """Epoch arrays with the navigation comparison and the antenna-separation check applied."""
    if isinstance(nav, pd.DataFrame):
        merged, mismatch = nav, None
    else:
        mismatch = compare_navigation(nav)
        merged = pd.concat(list(nav.values()), ignore_index=True).drop_duplicates(["sat", "week", "Toe", "DataSrc"])
    if cfg.smoothing_s:
        obs = carrier_smoothed(obs, cfg.smoothing_s)
    ep = build_epochs(
        obs, merged, systems=cfg.systems, corrections=corrections, sbas=sbas, max_divergence_mps=cfg.max_divergence_mps
    )
    if mismatch is not None:
        flag_nav_mismatch(ep, mismatch)
    missing = sorted(set(np.unique(ep.receiver)) - set(names))
    if missing:
        raise UsageError(f"no antenna given for receiver(s) {', '.join(missing)}")
    if len(names) == 2:
        a, b = (antennas[n] for n in names)
        sep = float(np.linalg.norm([a.along_m - b.along_m, a.lateral_m - b.lateral_m, a.height_m - b.height_m]))
        check_receiver_pair(ep, names[0], names[1], sep, cfg.pr_difference_tol_m)
    return ep


def replace_flags(ep: Epochs) -> Epochs:
    """A copy of ``ep`` with the geometry-dependent flags (masks) cleared."""
    keep = ~np.int64(FLAG_LOW_ELEVATION | FLAG_LOW_CN0 | FLAG_SKY_MASK)
    return replace(ep, flags=ep.flags & keep)


@dataclass
class _Solved:
    table: pd.DataFrame
    excluded: np.ndarray
    no_track: np.ndarray
    mdb: np.ndarray


_COLUMNS = (
    "s_m", "clock_m", "sigma_clock_m", "sigma_m", "uncertainty_m", "protection_m", "adop", "test", "dof",
    "n_used", "n_excluded", "residual_rms_m", "status_code",
)  # fmt: skip


def _solve_receivers(
    ep: Epochs,
    track: TrackLine,
    antennas: Mapping[str, Antenna],
    names: list[str],
    dirs: np.ndarray,
    prior: tuple[np.ndarray, np.ndarray] | None,
    cfg: PositionConfig,
    s_init: np.ndarray | None = None,
    subset: np.ndarray | None = None,
    clock: tuple[np.ndarray, np.ndarray] | None = None,
) -> _Solved:
    """Constrained solution of each receiver's epochs (K = 1 each), optionally only ``subset``
    (boolean over E) and with clock predictions ``clock`` (value, σ over E)."""
    n_e = ep.t.size
    cols: dict[str, np.ndarray] = {c: np.full(n_e, np.nan) for c in _COLUMNS}
    out = _Solved(
        pd.DataFrame(), np.zeros_like(ep.present), np.zeros_like(ep.present), np.full(ep.present.shape, np.nan)
    )
    for name in names:
        sel = np.flatnonzero((ep.receiver == name) & (True if subset is None else subset))
        if sel.size == 0:
            continue
        rows = receiver_rows(ep.select(sel), dirs[sel])
        if clock is not None:
            rows = replace(rows, clock_prior_m=clock[0][sel, None], clock_prior_sigma_m=clock[1][sel, None])
        sol = solve_constrained(
            track,
            rows,
            [antennas[name]],
            cfg.solver,
            s_init=None if s_init is None else s_init[sel],
            prior=None if prior is None else (prior[0][sel], prior[1][sel]),
        )
        for c, v in (
            ("s_m", sol.s), ("clock_m", sol.clock_m[:, 0]), ("sigma_clock_m", sol.sigma_clock_m[:, 0]),
            ("sigma_m", sol.sigma_s), ("uncertainty_m", sol.uncertainty_m), ("protection_m", sol.protection_m),
            ("adop", sol.adop), ("test", sol.test), ("dof", sol.dof), ("n_used", sol.n_used),
            ("n_excluded", sol.excluded.sum(axis=1) + sol.no_track.sum(axis=1)),
            ("residual_rms_m", _rms(sol.residual_m)), ("status_code", sol.status),
        ):  # fmt: skip
            cols[c][sel] = v
        out.excluded[sel], out.no_track[sel], out.mdb[sel] = sol.excluded, sol.no_track, sol.mdb_m
    out.table = pd.DataFrame(cols)
    out.table["status"] = out.table["status_code"].map(STATUS_NAMES)
    out.table["clock_aided"] = False
    return out


def _rms(residual_m: np.ndarray) -> np.ndarray:
    """RMS of the used rows' residuals per epoch (NaN without any)."""
    n = np.isfinite(residual_m).sum(axis=1)
    ss = np.nansum(np.where(np.isfinite(residual_m), residual_m, 0.0) ** 2, axis=1)
    return np.where(n > 0, np.sqrt(ss / np.maximum(n, 1)), np.nan)


def clock_segments(ep: Epochs, sbas: SbasCorrections | None) -> np.ndarray:
    """The receiver of each epoch, made distinct per stretch of one GEO in use (or none): the
    receiver clock solved with one GEO's corrections is not carried to epochs corrected by
    another or by none, since each refers the satellite clocks to its own time
    (``sbas.geo_select``)."""
    rx = np.asarray(ep.receiver, dtype=str)
    if sbas is None or sbas.empty:
        return rx
    from fieldlogs.gnss.sbas.geo_select import NO_GEO

    tl = sbas.timeline
    prev = np.concatenate([[NO_GEO], tl.prn[:-1]])
    change = tl.t[tl.prn != prev]
    seg = np.searchsorted(change, np.asarray(ep.t, dtype=float), side="right")
    return np.char.add(np.char.add(rx, "#"), seg.astype(str))


def _coast(
    ep: Epochs,
    track: TrackLine,
    antennas: Mapping[str, Antenna],
    names: list[str],
    dirs: np.ndarray,
    prior: tuple[np.ndarray, np.ndarray] | None,
    cfg: PositionConfig,
    sol: _Solved,
    sbas: SbasCorrections | None = None,
) -> _Solved:
    """Re-solve the epochs the satellites alone could not carry with a coasted clock
    (``coasting``); keep the re-solved epochs that pass. With SBAS the clock is coasted within
    one stretch of the GEO in use only (``clock_segments``)."""
    ok = (sol.table["status_code"] == STATUS_OK).to_numpy()
    pred, sig = predict_clock(
        clock_segments(ep, sbas), ep.t_run, sol.table["clock_m"].to_numpy(), sol.table["sigma_clock_m"].to_numpy(), ok
    )
    redo = ~ok & np.isfinite(sig) & (ep.usable.sum(axis=1) >= 1)
    if not redo.any():
        return sol
    again = _solve_receivers(ep, track, antennas, names, dirs, prior, cfg, subset=redo, clock=(pred, sig))
    take = redo & (again.table["status_code"] == STATUS_OK).to_numpy()
    sol.table.loc[take, list(_COLUMNS)] = again.table.loc[take, list(_COLUMNS)].to_numpy()
    sol.table.loc[take, "status"] = "ok"
    sol.table.loc[take, "clock_aided"] = True
    for name in ("excluded", "no_track", "mdb"):
        getattr(sol, name)[take] = getattr(again, name)[take]
    return sol


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
    table: pd.DataFrame,
    track: TrackLine,
    antennas: Mapping[str, Antenna],
    names: list[str],
    direction: float,
    cfg: PositionConfig,
) -> pd.DataFrame:
    """The paper's final check: computed vs real distance between the two antennas."""
    a, b = names
    table = table.assign(t_key=epoch_keys(table["t"].to_numpy(float)))
    ta = table[table["receiver"] == a].drop_duplicates("t_key").set_index("t_key")
    tb = table[table["receiver"] == b].drop_duplicates("t_key").set_index("t_key")
    common = ta.index.intersection(tb.index)
    pa, _ = track.antenna(ta.loc[common, "s_m"].to_numpy(float), antennas[a], direction)
    pb, _ = track.antenna(tb.loc[common, "s_m"].to_numpy(float), antennas[b], direction)
    mid = 0.5 * (ta.loc[common, "s_m"].to_numpy(float) + tb.loc[common, "s_m"].to_numpy(float))
    ra, _ = track.antenna(mid, antennas[a], direction)
    rb, _ = track.antenna(mid, antennas[b], direction)
    computed = np.linalg.norm(pa - pb, axis=1)
    real = np.linalg.norm(ra - rb, axis=1)
    tol = (
        cfg.solver.k_fault_free
        * np.hypot(ta.loc[common, "sigma_m"].to_numpy(float), tb.loc[common, "sigma_m"].to_numpy(float))
        + 0.5
    )
    ok = np.abs(computed - real) <= tol
    both = ta.loc[common, "available"].to_numpy(bool) & tb.loc[common, "available"].to_numpy(bool)
    check = pd.DataFrame(
        {
            "t_key": common,
            "antenna_distance_m": computed,
            "antenna_distance_real_m": real,
            "antenna_distance_ok": ok | ~both,
        }
    )
    table = table.merge(check, on="t_key", how="left").drop(columns="t_key")
    table["antenna_distance_ok"] = table["antenna_distance_ok"].fillna(True).astype(bool)
    return table
