"""Wheel diameters from balise intervals: per run and per vehicle, with a maintenance alert.

Distance by pulses is pulses/teeth·π·D with the configured diameter D (run.json
``wheel_diameter_m``); the true distance between two balises is their track length apart,
so the run's wheel scale λ (:mod:`fieldlogs.survey.balises`) gives its true diameter
D_true = λ·D, 95 % interval ±t₀.₉₇₅·se(λ)·D. In the pipeline the same wheel error shows as
the position-correction percentage [S003 §5.2]: a correction amount is the wheel's scale
error over the travel since the previous correction.

Per vehicle, over its runs with an estimate (at least ``min_passes`` of them): the
inverse-variance mean D̂, its 95 % interval from the runs' spread (the between-run
differences include the wear between runs; the standard error is at least the runs' own),
the trend (least-squares slope of the runs' D_true against their start time, mm per 30
days), and D̂ against the configured diameter of its latest run: an *alert* beyond
``wheel_alert_share``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.survey.balises import t_quantile
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.extract import RunSurvey

FloatArray = npt.NDArray[np.float64]
OK, ALERT, UNVERIFIED = "ok", "alert", "unverified"
DAY_S = 86_400.0


def run_wheels(runs: Sequence[RunSurvey], scale: FloatArray, scale_se: FloatArray, used_m: FloatArray) -> pd.DataFrame:
    """One row per run: configured and estimated diameter, interval, clean travel used."""
    cfg_d = np.array([r.wheel_diameter_m for r in runs], dtype=float)
    est = scale * cfg_d
    with np.errstate(invalid="ignore"):
        half = 1.96 * scale_se * cfg_d
    return pd.DataFrame(
        {
            "run_id": [r.run_id for r in runs],
            "vehicle_id": [r.vehicle_id for r in runs],
            "start_time": [r.start_time for r in runs],
            "configured_m": cfg_d,
            "diameter_m": est,
            "ci95_m": half,
            "diff_share": est / cfg_d - 1.0,
            "clean_distance_m": used_m,
        }
    )


def _trend_mm_per_30d(t: pd.Series, d: FloatArray) -> float:
    secs = pd.to_datetime(t, utc=True, errors="coerce", format="ISO8601")
    ok = secs.notna().to_numpy() & np.isfinite(d)
    if ok.sum() < 3:
        return float("nan")
    x = (secs[ok] - secs[ok].min()).dt.total_seconds().to_numpy(dtype=float) / DAY_S
    if np.ptp(x) <= 0:
        return float("nan")
    slope = np.polyfit(x, d[ok], 1)[0]
    return float(slope * 1000.0 * 30.0)


def vehicle_wheels(per_run: pd.DataFrame, cfg: SurveyConfig) -> pd.DataFrame:
    """One row per vehicle (module docstring)."""
    rows = []
    for vid, g in per_run.groupby("vehicle_id", sort=True):
        g = g.sort_values("start_time", kind="stable")
        ok = g[np.isfinite(g["diameter_m"].to_numpy(dtype=float))]
        n = len(ok)
        latest_cfg = float(g["configured_m"].iloc[-1])
        row = {"vehicle_id": vid, "runs": len(g), "runs_estimated": n, "configured_m": latest_cfg}
        row.update(diameter_m=np.nan, ci95_m=np.nan, diff_share=np.nan, trend_mm_per_30d=np.nan)
        if n >= cfg.min_passes:
            d = ok["diameter_m"].to_numpy(dtype=float)
            se_run = ok["ci95_m"].to_numpy(dtype=float) / 1.96
            w = 1.0 / np.maximum(se_run, 1e-9) ** 2
            mean = float(np.sum(w * d) / np.sum(w))
            se = max(float(np.std(d, ddof=1)) / np.sqrt(n), float(np.sqrt(1.0 / np.sum(w))))
            row.update(
                diameter_m=mean,
                ci95_m=float(t_quantile(n - 1)) * se,
                diff_share=mean / latest_cfg - 1.0,
                trend_mm_per_30d=_trend_mm_per_30d(ok["start_time"], d),
            )
            row["status"] = ALERT if abs(mean / latest_cfg - 1.0) > cfg.wheel_alert_share else OK
        else:
            row["status"] = UNVERIFIED
        rows.append(row)
    cols = [
        "vehicle_id",
        "runs",
        "runs_estimated",
        "configured_m",
        "diameter_m",
        "ci95_m",
        "diff_share",
        "trend_mm_per_30d",
        "status",
    ]
    return pd.DataFrame(rows, columns=cols)
