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

**Errors.** A source's own standard error sᵢ (the fit's: the balise reads' stretches
(:mod:`fieldlogs.survey.balises`), radar frames, the GNSS Gauss–Markov GLS or its
sandwich) is independent between sources and runs. The balise and GNSS scales are both
measured against the GIS grid's track length c (:mod:`fieldlogs.pipeline.metric`),
so a relative error ε of that length (1σ g = ``track_length_sigma_pct``: the GIS survey's
scale, the height datum — an orthometric height 40 m off the ellipsoid is 0.0006 % —, the
noise of the grid points lengthening the chord sum by ≈ σ_p²/s², 0.0006 % for σ_p = 5 cm
on 20 m steps) moves both by λ·ε at once, in every run on that grid; the radar does not see
it. A source's interval is ±1.96·D·√(sᵢ² + gᵢ²), gᵢ = λᵢ·g for balise and GNSS, 0 for radar.

**Per run** the sources present are combined by generalised least squares with the
covariance C = diag(sᵢ²) + g·gᵀ (Sherman–Morrison: with wᵢ = 1/sᵢ², a = Σ wᵢgᵢ,
b = Σ wᵢgᵢ², 1ᵀC⁻¹x = Σ wᵢxᵢ − a·Σ wᵢgᵢxᵢ/(1 + b)): D̂ = 1ᵀC⁻¹D / 1ᵀC⁻¹1,
se² = 1/1ᵀC⁻¹1 — without a shared term the inverse-variance mean. With χ² = rᵀC⁻¹r
(r = D − D̂) over k sources se is scaled by the Birge ratio √(χ²/(k − 1)) where that exceeds
1: sources that disagree beyond their stated errors widen the interval. The shared part
of D̂ is Σ cᵢgᵢ (c = C⁻¹1/1ᵀC⁻¹1, column ``ci95_grid_m`` as a 95 % half-width): it does not
average out over runs. The sources are *consistent* unless two of them disagree beyond
their intervals (|Dᵢ − Dⱼ| > hᵢ + hⱼ, h the 95 % half-widths: a radar mounting error, a DB
balise or GIS error, a bad GNSS fit).

**Per vehicle**, over its runs with an estimate (at least ``min_passes`` of them): the
inverse-variance mean D̂ of the runs' combined estimates by their independent parts
(uᵢ² = (hᵢ/1.96)² − (grid part)²), whose standard error is the runs' spread (the between-run
differences include the wear between runs), at least the runs' own: u = max(s/√n,
1/√Σ uᵢ⁻²), and the 95 % interval ±√((t₀.₉₇₅,ₙ₋₁·u)² + (1.96·ḡ)²) with ḡ the runs' mean
shared part (fully correlated: it is the same grid). The trend (least-squares slope of the
runs' D against their start time, mm per 30 days), and D̂ against the configured diameter
of its latest run: an *alert* beyond ``wheel_alert_share``. Each source is pooled over the
vehicle's runs the same way, and the vehicle is *consistent* unless two sources' pooled
intervals are disjoint (``consistent`` false: a maintainer looks at the sensor or the DB).
How the intervals were checked against the simulated truth: ``bench/NOTES.md`` ("Wheels").
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
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
#: Which of them are measured against the GIS grid's track length (module docstring).
GRID_SOURCES = np.array([1.0, 0.0, 1.0])


@dataclass(frozen=True)
class Combined:
    """Row-wise combination of the sources (module docstring)."""

    mean: FloatArray
    half: FloatArray
    """95 % half-width (Birge-scaled)."""
    grid_half: FloatArray
    """95 % half-width of the shared grid-length part of ``mean``."""
    k: npt.NDArray[np.int64]
    agree: list[Any]


def _gls(d: FloatArray, half: FloatArray, grid: FloatArray | None) -> Combined:
    """GLS of each row's sources with a shared term (module docstring); ``grid`` the 1σ of
    the shared part inside each ``half`` (None: none)."""
    ok = np.isfinite(d) & np.isfinite(half) & (half > 0)
    g = np.zeros(d.shape) if grid is None else np.where(ok, np.nan_to_num(grid), 0.0)
    total = np.where(ok, half / Z95, 1.0) ** 2
    own = np.maximum(total - g * g, 1e-6 * total)
    w = np.where(ok, 1.0 / own, 0.0)
    x = np.nan_to_num(d)
    k = ok.sum(axis=1)
    a, b = np.sum(w * g, axis=1), np.sum(w * g * g, axis=1)

    def quad(u: FloatArray, v: FloatArray) -> FloatArray:
        """uᵀC⁻¹v per row (Sherman–Morrison)."""
        return np.asarray(np.sum(w * u * v, axis=1) - np.sum(w * g * u, axis=1) * np.sum(w * g * v, axis=1) / (1 + b))

    one = np.ones(d.shape)
    with np.errstate(invalid="ignore", divide="ignore"):
        s11 = quad(one, one)
        mean = np.where(k > 0, quad(one, x) / s11, np.nan)
        r = np.where(ok, x - mean[:, None], 0.0)
        chi2 = quad(r, r)
        birge = np.sqrt(np.where(k > 1, chi2 / np.maximum(k - 1, 1), 1.0))
        se = np.where(k > 0, np.maximum(birge, 1.0) / np.sqrt(s11), np.nan)
        c = (w - w * g * (a / (1 + b))[:, None]) / s11[:, None]
        grid_se = np.where(k > 0, np.sum(c * g, axis=1), np.nan)
    apart = np.zeros(d.shape[0], dtype=bool)
    for i in range(d.shape[1]):
        for j in range(i + 1, d.shape[1]):
            both = ok[:, i] & ok[:, j]
            apart |= both & (np.abs(d[:, i] - d[:, j]) > half[:, i] + half[:, j])
    agree = [None if n < 2 else not bool(q) for n, q in zip(k.tolist(), apart.tolist(), strict=True)]
    return Combined(mean, Z95 * se, Z95 * grid_se, k.astype(np.int64), agree)


def combine(
    d: FloatArray, half: FloatArray, grid: FloatArray | None = None
) -> tuple[FloatArray, FloatArray, npt.NDArray[np.int64], list[Any]]:
    """Row-wise over sources (columns; NaN: absent): the combined value, its 95 %
    half-width, the number of sources and whether they agree (None with fewer than two);
    ``grid`` the 1σ of each source's shared grid-length part (module docstring)."""
    c = _gls(d, half, grid)
    return c.mean, c.half, c.k, c.agree


def _aid_columns(runs: Sequence[RunSurvey], name: str) -> tuple[FloatArray, FloatArray, list[str | None]]:
    """λ, se and source of one aid per run (NaN / None where the run has none)."""
    aids: list[AidScale | None] = [getattr(r, name) for r in runs]
    lam = np.array([a.scale if a is not None else np.nan for a in aids], dtype=float)
    se = np.array([a.se if a is not None else np.nan for a in aids], dtype=float)
    return lam, se, [a.source if a is not None else None for a in aids]


def run_wheels(
    runs: Sequence[RunSurvey], scale: FloatArray, scale_se: FloatArray, used_m: FloatArray, cfg: SurveyConfig
) -> pd.DataFrame:
    """One row per run: configured and combined diameter with its interval (and the shared
    grid part of it), whether the sources agree, and each source's diameter and interval
    (``scale``, ``scale_se``: the balise scales and their own standard errors)."""
    cfg_d = np.array([r.wheel_diameter_m for r in runs], dtype=float)
    radar, radar_se, radar_src = _aid_columns(runs, "radar")
    gnss, gnss_se, gnss_src = _aid_columns(runs, "gnss")
    lam = np.column_stack([scale, radar, gnss]) if len(runs) else np.zeros((0, 3))
    se = np.column_stack([scale_se, radar_se, gnss_se]) if len(runs) else np.zeros((0, 3))
    d = lam * cfg_d[:, None]
    grid = np.abs(d) * cfg.track_length_sigma_pct / 100.0 * GRID_SOURCES[None, :]
    with np.errstate(invalid="ignore"):
        half = Z95 * np.sqrt((se * cfg_d[:, None]) ** 2 + grid**2)
    c = _gls(d, half, grid)
    frame: dict[str, Any] = {
        "run_id": [r.run_id for r in runs],
        "vehicle_id": [r.vehicle_id for r in runs],
        "start_time": [r.start_time for r in runs],
        "configured_m": cfg_d,
        "diameter_m": c.mean,
        "ci95_m": c.half,
        "ci95_grid_m": c.grid_half,
        "diff_share": c.mean / cfg_d - 1.0,
        "sources": c.k,
        "consistent": c.agree,
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


def pool(
    d: FloatArray, half: FloatArray, min_runs: int, grid_half: FloatArray | None = None
) -> tuple[float, float, int]:
    """A vehicle's runs pooled (module docstring): mean, 95 % half-width, runs used (NaN
    with fewer than ``min_runs``); ``grid_half`` the 95 % half-width of each run's shared
    grid-length part inside ``half`` (None: none)."""
    ok = np.isfinite(d) & np.isfinite(half) & (half > 0)
    n = int(ok.sum())
    if n < min_runs or n < 2:
        return float("nan"), float("nan"), n
    g = np.zeros(n) if grid_half is None else np.nan_to_num(grid_half[ok]) / Z95
    x, total = d[ok], half[ok] / Z95
    own = np.sqrt(np.maximum(total**2 - g**2, 1e-6 * total**2))
    w = 1.0 / own**2
    mean = float(np.sum(w * x) / np.sum(w))
    se = max(float(np.std(x, ddof=1)) / np.sqrt(n), float(np.sqrt(1.0 / np.sum(w))))
    shared = float(np.sum(w * g) / np.sum(w))
    return mean, float(np.hypot(float(t_quantile(n - 1)) * se, Z95 * shared)), n


VEHICLE_COLUMNS = [
    "vehicle_id",
    "runs",
    "runs_estimated",
    "configured_m",
    "diameter_m",
    "ci95_m",
    "ci95_grid_m",
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
    grid = g["ci95_grid_m"].to_numpy(dtype=float) if "ci95_grid_m" in g else None
    mean, ci, n = pool(d, half, cfg.min_passes, grid)
    row: dict[str, Any] = {"vehicle_id": vid, "runs": len(g), "runs_estimated": n, "configured_m": latest_cfg}
    row.update(diameter_m=mean, ci95_m=ci, diff_share=mean / latest_cfg - 1.0, trend_mm_per_30d=np.nan)
    row["ci95_grid_m"] = float(np.nanmean(grid)) if grid is not None and np.isfinite(grid).any() else np.nan
    if np.isfinite(mean):
        ok = np.isfinite(d)
        row["trend_mm_per_30d"] = _trend_mm_per_30d(g["start_time"][ok], d[ok])
        row["status"] = ALERT if abs(mean / latest_cfg - 1.0) > cfg.wheel_alert_share else OK
    else:
        row["status"] = UNVERIFIED
    means, halves = np.full((1, len(SOURCES)), np.nan), np.full((1, len(SOURCES)), np.nan)
    for j, s in enumerate(SOURCES):
        col_d, col_h = g[f"diameter_{s}_m"].to_numpy(dtype=float), g[f"ci95_{s}_m"].to_numpy(dtype=float)
        share = GRID_SOURCES[j] * Z95 * cfg.track_length_sigma_pct / 100.0
        m, h, k = pool(col_d, col_h, cfg.min_passes, np.abs(col_d) * share)
        row.update({f"diameter_{s}_m": m, f"ci95_{s}_m": h, f"runs_{s}": k})
        means[0, j], halves[0, j] = m, h
    row["consistent"] = combine(means, halves)[3][0]
    return row


def vehicle_wheels(per_run: pd.DataFrame, cfg: SurveyConfig) -> pd.DataFrame:
    """One row per vehicle (module docstring)."""
    rows = [_vehicle(vid, g, cfg) for vid, g in per_run.groupby("vehicle_id", sort=True)]
    return pd.DataFrame(rows, columns=VEHICLE_COLUMNS)
