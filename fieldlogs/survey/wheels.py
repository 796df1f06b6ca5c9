"""Wheel diameters per run and per vehicle from balise intervals, radar and GNSS, with a
consistency check and a maintenance alert.

Distance by pulses is pulses/teeth·π·D with the configured diameter D (run.json
``wheel_diameter_m``); every source measures the run's wheel scale λ = D_true / D, so
D_true = λ·D with the 95 % interval ±1.96·se(λ)·D:

* **balise** — the true distance between two balises is their track length apart
  (:mod:`fieldlogs.survey.balises`); in the pipeline the same wheel error shows as the
  position-correction percentage [S003 §5.2];
* **radar** — the odometry's ground-speed calibration [S004] (:mod:`fieldlogs.survey.wheelaids`);
* **gnss** — track-constrained GNSS [S002] or D-GPS km [S001 §4.2] against the travel
  (:mod:`fieldlogs.survey.wheelaids`; ``gnss_source`` says which).

**Per run** the sources present are combined by their inverse-variance mean
D̂ = Σ wᵢ·Dᵢ / Σ wᵢ, wᵢ = 1/seᵢ², se = 1/√Σ wᵢ. They are *consistent* unless two of them
disagree beyond their intervals (|Dᵢ − Dⱼ| > hᵢ + hⱼ, h the 95 % half-widths: a radar
mounting error, a DB balise or GIS error, a bad GNSS fit); with χ² = Σ wᵢ·(Dᵢ − D̂)² over
k sources the combined se is scaled by √(χ²/(k − 1)) where that exceeds 1 (the Birge ratio:
the sources' spread, where it is larger than their stated errors, widens the interval).

**Per vehicle**, over its runs with an estimate (at least ``min_passes`` of them): the
inverse-variance mean D̂ of the runs' combined estimates, its 95 % interval from the runs'
spread (the between-run differences include the wear between runs; the standard error is
at least the runs' own), the trend (least-squares slope of the runs' D against their start
time, mm per 30 days), and D̂ against the configured diameter of its latest run: an
*alert* beyond ``wheel_alert_share``. Each source is pooled over the vehicle's runs the
same way, and the vehicle is *consistent* unless two sources' pooled intervals are
disjoint (``consistent`` false: a maintainer looks at the sensor or the DB).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import pandas as pd

from fieldlogs.survey.balises import t_quantile
from fieldlogs.survey.config import SurveyConfig
from fieldlogs.survey.extract import RunSurvey
from fieldlogs.survey.wheelaids import AidScale

FloatArray = npt.NDArray[np.float64]
OK, ALERT, UNVERIFIED = "ok", "alert", "unverified"
DAY_S = 86_400.0
#: Two-sided 95 % normal quantile of the per-run intervals.
Z95 = 1.96
#: The sources of a wheel diameter, in the order of the columns.
SOURCES = ("balise", "radar", "gnss")


def combine(d: FloatArray, half: FloatArray) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64], list[Any]]:
    """Row-wise over sources (columns; NaN: absent): the combined value, its 95 %
    half-width, the number of sources and whether they agree (None with fewer than two;
    module docstring)."""
    ok = np.isfinite(d) & np.isfinite(half) & (half > 0)
    w = np.where(ok, 1.0 / np.where(ok, half / Z95, 1.0) ** 2, 0.0)
    sw = w.sum(axis=1)
    k = ok.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(k > 0, np.sum(w * np.nan_to_num(d), axis=1) / sw, np.nan)
        chi2 = np.sum(w * (np.nan_to_num(d) - mean[:, None]) ** 2, axis=1)
        birge = np.sqrt(np.where(k > 1, chi2 / np.maximum(k - 1, 1), 1.0))
        se = np.where(k > 0, np.maximum(birge, 1.0) / np.sqrt(sw), np.nan)
    apart = np.zeros(d.shape[0], dtype=bool)
    for i in range(d.shape[1]):
        for j in range(i + 1, d.shape[1]):
            both = ok[:, i] & ok[:, j]
            apart |= both & (np.abs(d[:, i] - d[:, j]) > half[:, i] + half[:, j])
    agree = [None if n < 2 else not bool(a) for n, a in zip(k.tolist(), apart.tolist(), strict=True)]
    return mean, Z95 * se, k.astype(np.int64), agree


def _aid_columns(runs: Sequence[RunSurvey], name: str) -> tuple[FloatArray, FloatArray, list[str | None]]:
    """λ, se and source of one aid per run (NaN / None where the run has none)."""
    aids: list[AidScale | None] = [getattr(r, name) for r in runs]
    lam = np.array([a.scale if a is not None else np.nan for a in aids], dtype=float)
    se = np.array([a.se if a is not None else np.nan for a in aids], dtype=float)
    return lam, se, [a.source if a is not None else None for a in aids]


def run_wheels(runs: Sequence[RunSurvey], scale: FloatArray, scale_se: FloatArray, used_m: FloatArray) -> pd.DataFrame:
    """One row per run: configured and combined diameter with its interval, whether the
    sources agree, and each source's diameter and interval (``scale``: the balise scales)."""
    cfg_d = np.array([r.wheel_diameter_m for r in runs], dtype=float)
    radar, radar_se, radar_src = _aid_columns(runs, "radar")
    gnss, gnss_se, gnss_src = _aid_columns(runs, "gnss")
    lam = np.column_stack([scale, radar, gnss]) if len(runs) else np.zeros((0, 3))
    se = np.column_stack([scale_se, radar_se, gnss_se]) if len(runs) else np.zeros((0, 3))
    d = lam * cfg_d[:, None]
    with np.errstate(invalid="ignore"):
        half = Z95 * se * cfg_d[:, None]
    mean, ci, k, agree = combine(d, half)
    frame: dict[str, Any] = {
        "run_id": [r.run_id for r in runs],
        "vehicle_id": [r.vehicle_id for r in runs],
        "start_time": [r.start_time for r in runs],
        "configured_m": cfg_d,
        "diameter_m": mean,
        "ci95_m": ci,
        "diff_share": mean / cfg_d - 1.0,
        "sources": k,
        "consistent": agree,
    }
    for j, name in enumerate(SOURCES):
        frame[f"diameter_{name}_m"] = d[:, j]
        frame[f"ci95_{name}_m"] = half[:, j]
        if name == "balise":
            frame["clean_distance_m"] = used_m
    frame["radar_source"] = radar_src
    frame["gnss_source"] = gnss_src
    return pd.DataFrame(frame)


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


def pool(d: FloatArray, half: FloatArray, min_runs: int) -> tuple[float, float, int]:
    """A vehicle's runs pooled (module docstring): mean, 95 % half-width, runs used (NaN
    with fewer than ``min_runs``)."""
    ok = np.isfinite(d) & np.isfinite(half) & (half > 0)
    n = int(ok.sum())
    if n < min_runs or n < 2:
        return float("nan"), float("nan"), n
    x, se_run = d[ok], half[ok] / Z95
    w = 1.0 / se_run**2
    mean = float(np.sum(w * x) / np.sum(w))
    se = max(float(np.std(x, ddof=1)) / np.sqrt(n), float(np.sqrt(1.0 / np.sum(w))))
    return mean, float(t_quantile(n - 1)) * se, n


VEHICLE_COLUMNS = [
    "vehicle_id",
    "runs",
    "runs_estimated",
    "configured_m",
    "diameter_m",
    "ci95_m",
    "diff_share",
    "trend_mm_per_30d",
    "status",
    "consistent",
    *[c.format(s) for s in SOURCES for c in ("diameter_{}_m", "ci95_{}_m", "runs_{}")],
]


def _vehicle(vid: object, g: pd.DataFrame, cfg: SurveyConfig) -> dict[str, Any]:
    g = g.sort_values("start_time", kind="stable")
    latest_cfg = float(g["configured_m"].iloc[-1])
    d, half = g["diameter_m"].to_numpy(dtype=float), g["ci95_m"].to_numpy(dtype=float)
    mean, ci, n = pool(d, half, cfg.min_passes)
    row: dict[str, Any] = {"vehicle_id": vid, "runs": len(g), "runs_estimated": n, "configured_m": latest_cfg}
    row.update(diameter_m=mean, ci95_m=ci, diff_share=mean / latest_cfg - 1.0, trend_mm_per_30d=np.nan)
    if np.isfinite(mean):
        ok = np.isfinite(d)
        row["trend_mm_per_30d"] = _trend_mm_per_30d(g["start_time"][ok], d[ok])
        row["status"] = ALERT if abs(mean / latest_cfg - 1.0) > cfg.wheel_alert_share else OK
    else:
        row["status"] = UNVERIFIED
    means, halves = np.full((1, len(SOURCES)), np.nan), np.full((1, len(SOURCES)), np.nan)
    for j, s in enumerate(SOURCES):
        col_d, col_h = g[f"diameter_{s}_m"].to_numpy(dtype=float), g[f"ci95_{s}_m"].to_numpy(dtype=float)
        m, h, k = pool(col_d, col_h, cfg.min_passes)
        row.update({f"diameter_{s}_m": m, f"ci95_{s}_m": h, f"runs_{s}": k})
        means[0, j], halves[0, j] = m, h
    row["consistent"] = combine(means, halves)[3][0]
    return row


def vehicle_wheels(per_run: pd.DataFrame, cfg: SurveyConfig) -> pd.DataFrame:
    """One row per vehicle (module docstring)."""
    rows = [_vehicle(vid, g, cfg) for vid, g in per_run.groupby("vehicle_id", sort=True)]
    return pd.DataFrame(rows, columns=VEHICLE_COLUMNS)
