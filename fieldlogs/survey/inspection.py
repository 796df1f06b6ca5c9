"""Balise statuses, the inspection list of missed balises, and candidate balises.

* **Status** per DB balise (rules in :mod:`fieldlogs.survey.balises`): passes and reads
  come from every run's passes (:mod:`fieldlogs.survey.extract`), the residual from the
  adjustment.
* **Missed** [S003 §6 ③]: a balise never read although runs passed over it (at least
  ``min_missed_passes`` passes) — an unpowered balise that no longer answers, or one whose
  DB row is wrong; the inspection list gives every such pass with its run and time.
* **Candidates**: telegrams the DB does not know (no balise of that kind and content
  within the match window), placed on the track through their chain's trajectory
  (:mod:`fieldlogs.survey.trajectory`), grouped by line, track, kind and content where
  they lie within ``candidate_radius_m`` of each other (each group with the network track
  of its place, ``track_id``); a group read by at least
  ``candidate_runs`` runs is *confirmed* (a balise the DB lacks, or one whose DB row has
  the wrong codes: the nearest DB balise is named).
"""

from __future__ import annotations

from collections.abc import Sequence
from datetime import datetime, timedelta
from typing import cast

import numpy as np
import numpy.typing as npt
import pandas as pd

from dbtools.network import Network
from dbtools.topology import grid_track_ids
from fieldlogs.pipeline.metric import track_metric
from fieldlogs.survey.balises import MISSED, MOVED, OK, UNVERIFIED, Adjustment, qualifies
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.extract import UNKNOWN, RunSurvey
from fieldlogs.survey.groupfix import FIX_COLUMNS, fix_status
from fieldlogs.survey.trajectory import BaliseTable, Trajectory
from schemas.enums import BaliseKind

FloatArray = npt.NDArray[np.float64]
BALISE_COLUMNS = (
    "balise_id",
    "kind",
    "track_id",
    "line_code",
    "station_code",
    "track",
    "signal_type",
    "km_db_m",
    "status",
    "reason",
    "passes",
    "reads",
    "missed_passes",
    "n_estimates",
    "residual_m",
    "ci95_m",
    "spread_m",
    "km_surveyed_m",
)
MISSED_COLUMNS = (
    "balise_id",
    "kind",
    "track_id",
    "line_code",
    "track",
    "km_db_m",
    "run_id",
    "vehicle_id",
    "t_pass",
    "time",
)
CANDIDATE_COLUMNS = (
    "candidate_id",
    "kind",
    "track_id",
    "line_code",
    "track",
    "tel_line_code",
    "tel_station_code",
    "tel_track",
    "tel_signal_type",
    "km_m",
    "ci95_m",
    "runs",
    "reads",
    "confirmed",
    "nearest_balise",
    "nearest_m",
)


def pass_table(runs: Sequence[RunSurvey]) -> pd.DataFrame:
    """Every run's passes with the run's index, id, vehicle and start time."""
    have = [(r, rs) for r, rs in enumerate(runs) if len(rs.passes)]
    if not have:
        return pd.DataFrame(
            columns=["balise_id", "seg", "t_pass", "km_pass_m", "read", "run", "run_id", "vehicle_id", "start_time"]
        )
    out = pd.concat([rs.passes for _, rs in have], ignore_index=True)
    n = [len(rs.passes) for _, rs in have]
    out["run"] = np.repeat([r for r, _ in have], n)
    for col in ("run_id", "vehicle_id", "start_time"):
        out[col] = pd.Series(np.repeat([str(getattr(rs, col)) for _, rs in have], n), dtype="str")
    return out


def _reason(status: str, passes: int, reads: int, n_est: int, cfg: SurveyConfig, unsettled: bool = False) -> str:
    """Why a balise has its status; the text before " (" is the category."""
    if status == MISSED:
        return f"never read (on {passes} passes)"
    if status != UNVERIFIED:
        return ""
    if unsettled:
        return f"adjustment not settled (its flag or anchor still changed after {cfg.max_iterations} rounds)"
    if passes == 0 and reads == 0:
        return "no run passed it"
    if n_est < cfg.min_passes:
        return f"too few usable passes ({n_est} of {cfg.min_passes})"
    return f"inconclusive (the 95 % interval reaches beyond ±{cfg.ok_tolerance_m:g} m)"


def balise_status(
    table: BaliseTable, adj: Adjustment, passes: pd.DataFrame, reads_per_balise: pd.Series, cfg: SurveyConfig
) -> pd.DataFrame:
    """One row per DB balise (:data:`BALISE_COLUMNS`)."""
    f = table.frame
    st = adj.stats
    by = passes.groupby("balise_id")["read"] if len(passes) else None
    n_pass = (by.size() if by is not None else pd.Series(dtype=int)).reindex(f["balise_id"], fill_value=0).to_numpy()
    n_read_pass = (
        (by.sum() if by is not None else pd.Series(dtype=int)).reindex(f["balise_id"], fill_value=0).to_numpy()
    )
    reads = reads_per_balise.reindex(f["balise_id"], fill_value=0).to_numpy(dtype=np.int64)
    mean = st["residual_m"].to_numpy(dtype=float)
    half = st["ci95_m"].to_numpy(dtype=float)
    n_est = st["n_estimates"].to_numpy(dtype=np.int64)
    moved = qualifies(st, cfg)
    with np.errstate(invalid="ignore"):
        ok = (n_est >= cfg.min_passes) & (np.abs(mean) + half <= cfg.ok_tolerance_m)
    missed = (reads == 0) & (n_pass >= cfg.min_missed_passes)
    settled = ~adj.unsettled
    status = np.where(missed, MISSED, np.where(moved & settled, MOVED, np.where(ok & settled, OK, UNVERIFIED)))
    km_db = f["km_actual_m"].to_numpy(dtype=float)
    out = pd.DataFrame(
        {
            "balise_id": f["balise_id"],
            "kind": f["kind"],
            "track_id": f["track_id"],
            "line_code": f["line_code"],
            "track": f["track"],
            "station_code": f["station_code"],
            "signal_type": f["signal_type"].astype(object).where(f["signal_type"].notna(), ""),
            "km_db_m": km_db,
            "status": status,
            "passes": n_pass,
            "reads": reads,
            "missed_passes": n_pass - n_read_pass,
            "n_estimates": n_est,
            "residual_m": mean,
            "ci95_m": half,
            "spread_m": st["spread_m"].to_numpy(dtype=float),
            "km_surveyed_m": km_db - np.where(np.isfinite(mean), mean, np.nan),
        }
    )
    out["reason"] = [
        _reason(s, int(p), int(r), int(n), cfg, bool(u))
        for s, p, r, n, u in zip(
            out["status"], out["passes"], out["reads"], out["n_estimates"], adj.unsettled, strict=True
        )
    ]
    return out[list(BALISE_COLUMNS)]


def _iso(start: str, t: float) -> str:
    try:
        return (datetime.fromisoformat(start) + timedelta(seconds=float(t))).isoformat(timespec="seconds")
    except (ValueError, TypeError):
        return ""


def missed_passes(status: pd.DataFrame, passes: pd.DataFrame) -> pd.DataFrame:
    """The inspection list: every pass over a missed balise, in time order per balise."""
    ids = set(status.loc[status["status"] == MISSED, "balise_id"])
    if not ids or not len(passes):
        return pd.DataFrame(columns=list(MISSED_COLUMNS))
    p = passes[passes["balise_id"].isin(ids)]
    info = status.set_index("balise_id")[["kind", "track_id", "line_code", "track", "km_db_m"]]
    p = p.join(info, on="balise_id")
    p = p.assign(time=[_iso(s, t) for s, t in zip(p["start_time"], p["t_pass"], strict=True)])
    return p.sort_values(["balise_id", "time"], kind="stable")[list(MISSED_COLUMNS)].reset_index(drop=True)


def _locate_unknown(
    runs: Sequence[RunSurvey], traj: dict[tuple[int, int], Trajectory], network: Network
) -> pd.DataFrame:
    """Every unknown telegram (its read's columns) with its run and its km on the surveyed
    chain of its segment (unknown telegrams off every chain's reach are left out)."""
    parts: list[tuple[int, pd.DataFrame, FloatArray]] = []
    for r, rs in enumerate(runs):
        rd = rs.reads
        if not len(rd):
            continue
        u = rd[rd["status"].to_numpy(dtype=object) == UNKNOWN]
        if not len(u):
            continue
        seg, d = u["seg"].to_numpy(dtype=np.int64), u["d_m"].to_numpy(dtype=float)
        line, track = u["line_code"].to_numpy(dtype=object), u["track"].to_numpy(dtype=object)
        km = np.full(len(u), np.nan)
        for k in np.unique(seg).tolist():
            tj = traj.get((r, int(k)))
            if tj is None:
                continue
            at = np.flatnonzero(seg == k)
            c = tj.c_at(d[at])
            for j, cj in zip(at.tolist(), c.tolist(), strict=True):
                if np.isfinite(cj):
                    km[j] = float(track_metric(network, str(line[j]), str(track[j])).km_of_c(cj))
        ok = np.isfinite(km)
        if ok.any():
            parts.append((r, u[ok], km[ok]))
    if not parts:
        return pd.DataFrame()
    out = pd.concat([p[1] for p in parts], ignore_index=True)
    out["run"] = np.repeat([p[0] for p in parts], [len(p[1]) for p in parts])
    out["km_m"] = np.concatenate([p[2] for p in parts])
    return out


def candidates(
    runs: Sequence[RunSurvey],
    traj: dict[tuple[int, int], Trajectory],
    network: Network,
    table: BaliseTable,
    cfg: SurveyConfig,
) -> pd.DataFrame:
    """Groups of unknown telegrams (module docstring, "Candidates")."""
    u = _locate_unknown(runs, traj, network)
    if not len(u):
        return pd.DataFrame(columns=list(CANDIDATE_COLUMNS))
    keys = ["kind", "line_code", "track", "tel_line_code", "tel_station_code", "tel_track", "tel_signal_type"]
    u = u.sort_values([*keys, "km_m"], kind="stable", ignore_index=True)
    new = np.r_[True, (u[keys].to_numpy()[1:] != u[keys].to_numpy()[:-1]).any(axis=1)]
    new |= np.r_[True, np.diff(u["km_m"].to_numpy(dtype=float)) > cfg.candidate_radius_m]
    u["group"] = np.cumsum(new)
    f = table.frame
    rows = []
    for k, g in u.groupby("group", sort=True):
        group = cast(int, k)
        km = g["km_m"].to_numpy(dtype=float)
        n_runs = int(g["run"].nunique())
        on = f[(f["line_code"] == g["line_code"].iloc[0]) & (f["track"] == g["track"].iloc[0])]
        dist = np.abs(on["km_actual_m"].to_numpy(dtype=float) - km.mean())
        j = int(np.argmin(dist)) if dist.size else -1
        line, track = str(g["line_code"].iloc[0]), str(g["track"].iloc[0])
        rows.append(
            {
                **{c: g[c].iloc[0] for c in keys},
                "candidate_id": f"K{group:03d}",
                "track_id": str(grid_track_ids(network, [line], [track], [float(km.mean())])[0]),
                "km_m": float(km.mean()),
                "ci95_m": float(1.96 * km.std(ddof=1) / np.sqrt(km.size)) if km.size > 1 else np.nan,
                "runs": n_runs,
                "reads": int(km.size),
                "confirmed": n_runs >= cfg.candidate_runs,
                "nearest_balise": str(on["balise_id"].iloc[j]) if j >= 0 else "",
                "nearest_m": float(dist[j]) if j >= 0 else np.nan,
            }
        )
    return pd.DataFrame(rows, columns=list(CANDIDATE_COLUMNS))


#: The reason of a group's G balise that is not missed (:mod:`fieldlogs.survey.groups`).
NOT_PLACED = "balise of a group: its place is not surveyed"


def group_status(
    network: Network,
    balise_track_ids: dict[str, str],
    passes: pd.DataFrame,
    reads: pd.Series,
    cfg: SurveyConfig,
    skip: set[str] | frozenset[str] = frozenset(),
    fixes: pd.DataFrame | None = None,
) -> pd.DataFrame:
    """One row per G balise of the network's groups not in ``skip`` (those the adjustment
    places; :data:`BALISE_COLUMNS`, the status of :mod:`fieldlogs.survey.groups`): missed on
    the rule of the other balises, else — where ``fixes`` places it by dead reckoning
    (:func:`fieldlogs.survey.groupfix.group_fixes`) — ok, moved or unverified on that place,
    else unverified."""
    b = network.balises
    g = b[(b["kind"].astype(str) == BaliseKind.G) & ~b["balise_id"].astype(str).isin(skip)] if len(b) else b
    if not len(g):
        return pd.DataFrame()
    ids = g["balise_id"].astype(str)
    by = passes.groupby("balise_id")["read"] if len(passes) else None
    n_pass = (by.size() if by is not None else pd.Series(dtype=int)).reindex(ids, fill_value=0).to_numpy()
    n_read = (by.sum() if by is not None else pd.Series(dtype=int)).reindex(ids, fill_value=0).to_numpy()
    n_reads = reads.reindex(ids, fill_value=0).to_numpy(dtype=np.int64)
    missed = (n_reads == 0) & (n_pass >= cfg.min_missed_passes)
    reason = [
        f"never read (on {p} passes)" if m else (f"{NOT_PLACED} ({r} reads)" if r or p else "no run passed it")
        for m, p, r in zip(missed, n_pass, n_reads, strict=True)
    ]
    status = np.where(missed, MISSED, UNVERIFIED).astype(object)
    fx = (fixes if fixes is not None and len(fixes) else pd.DataFrame(columns=list(FIX_COLUMNS))).set_index("balise_id")
    fx = fx.reindex(ids)
    for j in np.flatnonzero(~missed & fx["n_estimates"].notna().to_numpy()):
        status[j], reason[j] = fix_status(fx.iloc[j], cfg)
    out = pd.DataFrame(
        {
            "balise_id": ids.to_numpy(dtype=object),
            "kind": BaliseKind.G.value,
            "track_id": [balise_track_ids.get(i, "") for i in ids],
            "line_code": g["line_code"].astype(object).where(g["line_code"].notna(), "").to_numpy(),
            "station_code": "",
            "track": g["track"].astype(object).where(g["track"].notna(), "").to_numpy(),
            "signal_type": "",
            "km_db_m": g["km_actual_m"].to_numpy(dtype=float),
            "status": status,
            "reason": reason,
            "passes": n_pass.astype(np.int64),
            "reads": n_reads,
            "missed_passes": (n_pass - n_read).astype(np.int64),
            "n_estimates": fx["n_estimates"].fillna(0).to_numpy(dtype=np.int64),
            "residual_m": fx["residual_m"].to_numpy(dtype=float),
            "ci95_m": fx["ci95_m"].to_numpy(dtype=float),
            "spread_m": fx["spread_m"].to_numpy(dtype=float),
            "km_surveyed_m": fx["km_surveyed_m"].to_numpy(dtype=float),
        }
    )
    return out[list(BALISE_COLUMNS)]
