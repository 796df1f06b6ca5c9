"""Audit reports: per route, run or vehicle aggregates from an audit database (SPEC §7).

Position-correction percentages are aggregated over individual corrections (balise and
feature point), as the papers report them (0.29 % Tohoku line, 0.37 % Kawagoe line,
target 0.5 %).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pandas as pd

from fieldlogs.auditdb import read_meta, read_table

By = Literal["route", "run", "vehicle"]
CORRECTION_TYPES = ("balise_correction", "feature_correction")
ROUTE_KEYS = ["line_code", "track", "direction"]


@dataclass
class Report:
    by: str
    target_pct: float
    groups: pd.DataFrame
    """One row per route / run / vehicle."""
    routes: pd.DataFrame
    runs: pd.DataFrame
    corrections: pd.DataFrame
    """Every correction with its route, amount, % and distance since the previous one."""
    meta: dict[str, str]
    failed_runs: pd.DataFrame


def _details(frame: pd.DataFrame) -> list[dict[str, Any]]:
    return [json.loads(d) if isinstance(d, str) and d else {} for d in frame["detail"]]


def build_report(audit_path: Path, *, by: By = "route", target_pct: float = 0.5) -> Report:
    runs_all = read_table(audit_path, "runs")
    events = read_table(audit_path, "events")
    meta = read_meta(audit_path)
    runs = runs_all[runs_all["status"] == "ok"].copy()
    failed = runs_all[runs_all["status"] == "error"][["run_path", "error"]].reset_index(drop=True)
    for c in ROUTE_KEYS:
        runs[c] = runs[c].fillna("—")
    ev = events.merge(runs[["run_path", "run_id", "vehicle_id", *ROUTE_KEYS]], on="run_path", how="inner")
    corr = ev[ev["type"].isin(CORRECTION_TYPES)].copy()
    corr["distance_since_m"] = [d.get("distance_since_correction_m", np.nan) for d in _details(corr)]
    slips = ev[ev["type"].isin(["slip", "slide"])].copy()
    sd = _details(slips)
    slips["readhered"] = [bool(d.get("readhered")) for d in sd]
    slips["max_error_m"] = [float(d.get("max_error_m") or 0.0) for d in sd]
    refused = ev[ev["type"] == "feature_refused"].copy()
    refused["reasons"] = [",".join(d.get("failed", [])) or "unknown" for d in _details(refused)]

    keys = {"route": ROUTE_KEYS, "run": ["run_path"], "vehicle": ["vehicle_id"]}[by]
    routes = _aggregate(runs, corr, slips, refused, ev, ROUTE_KEYS, target_pct)
    groups = routes if by == "route" else _aggregate(runs, corr, slips, refused, ev, keys, target_pct)
    if by == "run":
        groups = runs[["run_path", "run_id", "vehicle_id", *ROUTE_KEYS]].merge(groups, on="run_path", how="left")
    run_view = runs[
        [
            "run_path",
            "run_id",
            "vehicle_id",
            "line_code",
            "track",
            "direction",
            "distance_m",
            "n_corrections",
            "mean_correction_pct",
            "max_correction_pct",
            "n_slips",
            "n_failsafe",
            "n_anomalies",
            "max_margin_m",
        ]
    ].reset_index(drop=True)
    return Report(
        by,
        target_pct,
        groups.reset_index(drop=True),
        routes.reset_index(drop=True),
        run_view,
        corr.reset_index(drop=True),
        meta,
        failed,
    )


def _aggregate(
    runs: pd.DataFrame,
    corr: pd.DataFrame,
    slips: pd.DataFrame,
    refused: pd.DataFrame,
    ev: pd.DataFrame,
    keys: list[str],
    target: float,
) -> pd.DataFrame:
    base = runs.groupby(keys, dropna=False).agg(
        n_runs=("run_path", "size"),
        distance_m=("distance_m", "sum"),
        n_failsafe=("n_failsafe", "sum"),
        n_anomalies=("n_anomalies", "sum"),
        gps_decisions=("gps_decisions", "sum"),
    )
    pct = corr.dropna(subset=["correction_pct"]).groupby(keys, dropna=False)["correction_pct"]
    stats = pd.DataFrame(
        {
            "n_corrections": corr.groupby(keys, dropna=False).size(),
            "mean_correction_pct": pct.mean(),
            "median_correction_pct": pct.median(),
            "max_correction_pct": pct.max(),
            "share_above_target": pct.apply(lambda s: float((s > target).mean())),
            "n_balise_corrections": corr[corr["type"] == "balise_correction"].groupby(keys, dropna=False).size(),
            "n_feature_corrections": corr[corr["type"] == "feature_correction"].groupby(keys, dropna=False).size(),
        }
    )
    sl = slips.groupby(keys, dropna=False).agg(
        n_slips=("type", "size"), n_slips_readhered=("readhered", "sum"), max_slip_error_m=("max_error_m", "max")
    )
    rf = refused.groupby(keys, dropna=False).agg(
        n_feature_refused=("type", "size"), refusal_reasons=("reasons", lambda s: _count_reasons(s))
    )
    anomalies = ev[ev["type"] == "balise_anomaly"].groupby(keys, dropna=False).size().rename("n_balise_anomalies")
    out = base.join(stats, how="left").join(sl, how="left").join(rf, how="left").join(anomalies, how="left")
    for c in (
        "n_corrections",
        "n_balise_corrections",
        "n_feature_corrections",
        "n_slips",
        "n_slips_readhered",
        "n_feature_refused",
        "n_balise_anomalies",
    ):
        out[c] = out[c].fillna(0).astype(int)
    out["refusal_reasons"] = out["refusal_reasons"].fillna("")
    return out.reset_index()


def _count_reasons(s: pd.Series) -> str:
    counts: dict[str, int] = {}
    for item in s:
        for r in str(item).split(","):
            counts[r] = counts.get(r, 0) + 1
    return ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))


def _num(v: Any) -> Any:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, (np.floating,)):
        return float(v)
    return v


def report_json(report: Report) -> dict[str, Any]:
    """The documented, stable JSON shape."""
    routes = [
        {
            "line_code": r.line_code,
            "track": r.track,
            "direction": r.direction,
            "n_runs": _num(r.n_runs),
            "n_corrections": _num(r.n_corrections),
            "distance_m": _num(r.distance_m),
            "mean_correction_pct": _num(r.mean_correction_pct),
            "median_correction_pct": _num(r.median_correction_pct),
            "max_correction_pct": _num(r.max_correction_pct),
            "share_above_target": _num(r.share_above_target),
        }
        for r in report.routes.itertuples()
    ]
    runs = [
        {
            "run_id": r.run_id,
            "vehicle_id": r.vehicle_id,
            "line_code": r.line_code,
            "track": r.track,
            "n_corrections": _num(r.n_corrections),
            "mean_correction_pct": _num(r.mean_correction_pct),
            "n_slips": _num(r.n_slips),
            "n_failsafe": _num(r.n_failsafe),
        }
        for r in report.runs.itertuples()
    ]
    return {
        "target_pct": report.target_pct,
        "routes": routes,
        "runs": runs,
        "failed_runs": [{"run_path": r.run_path, "error": r.error} for r in report.failed_runs.itertuples()],
    }
