"""Report figures (matplotlib, headless Agg) returned as PNG bytes."""

from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure

from schemas.enums import direction_sign


def _png(fig: Figure) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def correction_vs_distance(corrections: pd.DataFrame, target_pct: float) -> bytes:
    """Position-correction % against the distance between corrections, per route."""
    fig, ax = plt.subplots(figsize=(8, 4.5))
    c = corrections.dropna(subset=["correction_pct", "distance_since_m"])
    for key, g in c.groupby(["line_code", "track", "direction"], dropna=False):
        ax.scatter(g["distance_since_m"] / 1000.0, g["correction_pct"], s=14, alpha=0.7, label=" ".join(map(str, key)))
    ax.axhline(target_pct, color="red", ls="--", lw=1, label=f"target {target_pct:g} %")
    ax.set_xlabel("distance since the previous correction [km]")
    ax.set_ylabel("position-correction [%]")
    ax.set_title("Position-correction percentage per route")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def margin_along_run(trace: pd.DataFrame, run_id: str) -> bytes:
    """Safety margin along a run (and the true error when the run has ground truth)."""
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(trace["t"], trace["margin_m"], label="margin", color="C0")
    ax.plot(trace["t"], -trace["margin_m"], color="C0")
    if trace["error_m"].notna().any():
        ax.plot(trace["t"], trace["error_m"], label="error vs truth", color="C3", lw=0.8)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("[m]")
    ax.set_title(f"Margin along run {run_id}")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def slip_episodes(trace: pd.DataFrame, episodes: list[dict[str, float]], run_id: str, max_panels: int = 4) -> bytes:
    """Wheel (pulse) speed against the corrected (inertial) speed around slip/slide episodes."""
    eps = episodes[:max_panels]
    n = max(len(eps), 1)
    fig, axes = plt.subplots(1, n, figsize=(4 * n, 3.5), squeeze=False)
    for ax, ep in zip(axes[0], eps, strict=False):
        w = trace[(trace["t"] >= ep["t_start"] - 5) & (trace["t"] <= ep["t_end"] + 5)]
        ax.plot(w["t"], w["v_pulse_mps"] * 3.6, label="wheel (pulses)")
        ax.plot(w["t"], w["speed_mps"] * 3.6, label="corrected")
        ax.axvspan(ep["t_start"], ep["t_end"], color="orange", alpha=0.2)
        ax.set_title(f"{ep.get('kind', 'slip')} t={ep['t_start']:.0f} s", fontsize=9)
        ax.set_xlabel("t [s]")
        ax.set_ylabel("km/h")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=8)
    if not eps:
        axes[0][0].text(0.5, 0.5, "no slip/slide episodes", ha="center", va="center", transform=axes[0][0].transAxes)
    fig.suptitle(f"Slip/slide episodes, run {run_id}")
    return _png(fig)


def curvature_vs_db(trace: pd.DataFrame, features: pd.DataFrame, track: str, run_id: str) -> bytes:
    """Measured curvature κ = ωz / v along km against the feature-point DB's curves."""
    fig, ax = plt.subplots(figsize=(9, 3.8))
    ok = trace["kappa"].notna() & trace["km_m"].notna()
    ax.plot(trace.loc[ok, "km_m"] / 1000.0, trace.loc[ok, "kappa"] * 1000.0, lw=0.7, label="measured κ")
    sign_run = direction_sign(track)
    for _, g in features.groupby("feature_id"):
        g = g.sort_values("seq")
        body = g[g["attribute"].isin(["left", "right"])]
        if body.empty or len(g) < 4:
            continue
        r = float(body["radius_m"].iloc[0])
        s = (1.0 if body["attribute"].iloc[0] == "left" else -1.0) * sign_run
        k3, k4 = float(g["km_m"].iloc[2]), float(g["km_m"].iloc[3])
        ax.plot([k3 / 1000.0, k4 / 1000.0], [s * 1000.0 / r] * 2, color="C3", lw=2)
    ax.plot([], [], color="C3", lw=2, label="DB curve 1/R (rows 3–4)")
    ax.set_xlabel("km")
    ax.set_ylabel("κ [1/km]")
    ax.set_title(f"Curvature against the feature-point DB, run {run_id} (track {track})")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _png(fig)


def run_map(gis: pd.DataFrame, trace: pd.DataFrame, run_id: str) -> bytes:
    """The GIS grid's tracks and the run's GPS fixes."""
    fig, ax = plt.subplots(figsize=(6, 6))
    for (line, track), g in gis.groupby(["line_code", "track"]):
        ax.plot(g["lon"], g["lat"], lw=1, label=f"{line} {track}")
    ok = trace["lat"].notna()
    if ok.any():
        ax.scatter(trace.loc[ok, "lon"], trace.loc[ok, "lat"], s=3, color="k", label=f"GPS {run_id}")
    ax.set_aspect(1.0 / np.cos(np.radians(float(gis["lat"].mean()) if len(gis) else 35.0)))
    ax.set_xlabel("lon")
    ax.set_ylabel("lat")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("Run on the GIS grid")
    return _png(fig)
