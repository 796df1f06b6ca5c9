"""Report figures (matplotlib through :func:`dbtools.pagekit.pyplot`: headless Agg, imported
on first use) returned as PNG bytes."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from dbtools import pagekit as kit
from schemas.enums import EventType, direction_sign

if TYPE_CHECKING:
    from matplotlib.axes import Axes

#: Speed below which the measured curvature is not drawn (κ = ωz / v is noise) [m/s].
KAPPA_MIN_SPEED_MPS = 3.0


def _empty(ax: Axes, text: str) -> None:
    ax.text(0.5, 0.5, text, ha="center", va="center", transform=ax.transAxes, color="0.4")


def _legend(ax: Axes, **kw: Any) -> None:
    if ax.get_legend_handles_labels()[0]:
        ax.legend(**kw)


def correction_vs_distance(corrections: pd.DataFrame, target_pct: float) -> bytes:
    """Position-correction % of balise corrections against the distance since the previous
    correction, one colour per route (track id and direction); feature-point corrections as
    grey crosses (not part of the statistics: their % is meaningless a few hundred metres
    after a balise)."""
    fig, ax = kit.pyplot().subplots(figsize=(8, 4.5))
    c = corrections.dropna(subset=["correction_pct", "distance_since_m"])
    bal = c[c["type"] == EventType.BALISE_CORRECTION]
    for key, g in bal.groupby(["track_id", "direction"], dropna=False):
        label = " ".join(map(str, key))
        ax.scatter(g["distance_since_m"] / 1000.0, g["correction_pct"], s=18, alpha=0.8, label=f"{label} (balise)")
    feat = c[c["type"] == EventType.FEATURE_CORRECTION]
    if len(feat):
        ax.scatter(
            feat["distance_since_m"] / 1000.0,
            feat["correction_pct"],
            s=14,
            marker="x",
            color="0.6",
            label="feature points (not in the statistics)",
        )
    if c.empty:
        _empty(ax, "no corrections with a percentage")
    ax.axhline(target_pct, color="red", ls="--", lw=1, label=f"target {target_pct:g} %")
    ax.set_xlabel("distance since the previous correction [km]")
    ax.set_ylabel("position correction [%]")
    ax.set_title("Position-correction percentage per route")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    _legend(ax, fontsize=8)
    return kit.png(fig)


def margin_along_run(trace: pd.DataFrame, run_id: str) -> bytes:
    """Safety margin (±) along a run, and the true error when the run has ground truth."""
    fig, ax = kit.pyplot().subplots(figsize=(8, 4))
    t = trace["t"]
    ax.fill_between(t, -trace["margin_m"], trace["margin_m"], color="C0", alpha=0.15, label="± margin")
    ax.plot(t, trace["margin_m"], color="C0", lw=1)
    ax.plot(t, -trace["margin_m"], color="C0", lw=1)
    if trace["error_m"].notna().any():
        ax.plot(t, trace["error_m"], label="error against truth", color="C3", lw=1)
    if trace["margin_m"].isna().all():
        _empty(ax, "position never determined")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("margin, error [m]")
    ax.set_title(f"Margin along run {run_id}")
    ax.grid(alpha=0.3)
    _legend(ax, fontsize=8)
    return kit.png(fig)


def slip_episodes(trace: pd.DataFrame, episodes: list[dict[str, float]], run_id: str, max_panels: int = 4) -> bytes:
    """Wheel (pulse) speed against the corrected (inertial) speed around slip/slide episodes."""
    eps = episodes[:max_panels]
    n = max(len(eps), 1)
    fig, axes = kit.pyplot().subplots(1, n, figsize=(3.6 * n + 0.8, 3.5), squeeze=False)
    for ax, ep in zip(axes[0], eps, strict=False):
        w = trace[(trace["t"] >= ep["t_start"] - 5) & (trace["t"] <= ep["t_end"] + 5)]
        ax.plot(w["t"], w["v_pulse_mps"] * 3.6, label="wheel (pulses)", color="C1")
        ax.plot(w["t"], w["speed_mps"] * 3.6, label="corrected (inertial)", color="C0")
        ax.axvspan(ep["t_start"], ep["t_end"], color="orange", alpha=0.2)
        state = "fail-safe" if ep.get("failsafe") else "re-adhered" if ep.get("readhered") else ""
        ax.set_title(f"{ep.get('kind', 'slip')} at t = {ep['t_start']:.0f} s {state}", fontsize=9)
        ax.grid(alpha=0.3)
    for ax in axes[0]:
        ax.set_xlabel("t [s]")
        ax.set_ylabel("speed [km/h]")
    _legend(axes[0][0], fontsize=8)
    if not eps:
        _empty(axes[0][0], "no slip/slide episodes")
    fig.suptitle(f"Slip/slide episodes, run {run_id}")
    return kit.png(fig)


def curvature_vs_db(trace: pd.DataFrame, features: pd.DataFrame, track: str, run_id: str) -> bytes:
    """Measured curvature κ = ωz / v along km against the feature-point DB's curves.

    Both are drawn as seen running in the track's normal direction (DB attributes are
    given that way; κ of the run is in its travel direction, so it is flipped where the
    run's km moved against the normal direction).
    """
    fig, ax = kit.pyplot().subplots(figsize=(9, 3.8))
    km = trace["km_m"].to_numpy(dtype=float)
    kappa = trace["kappa"].to_numpy(dtype=float)
    moving = np.sign(np.gradient(km)) if km.size > 1 else np.zeros(km.size)
    ok = np.isfinite(kappa) & np.isfinite(km) & (moving != 0) & (trace["speed_mps"].to_numpy() >= KAPPA_MIN_SPEED_MPS)
    normal = direction_sign(track)
    k_norm = kappa * moving * normal
    ax.plot(km[ok] / 1000.0, k_norm[ok] * 1000.0, ".", ms=2, label="measured κ (run)")
    drawn = False
    for _, g in features.groupby("feature_id"):
        g = g.sort_values("seq")
        body = g[g["attribute"].isin(["left", "right"])]
        if body.empty or len(g) < 4:
            continue
        r = float(body["radius_m"].iloc[0])
        s = 1.0 if body["attribute"].iloc[0] == "left" else -1.0
        k3, k4 = float(g["km_m"].iloc[2]), float(g["km_m"].iloc[3])
        ax.plot([k3 / 1000.0, k4 / 1000.0], [s * 1000.0 / r] * 2, color="C3", lw=2.5, solid_capstyle="butt")
        ax.axvspan(min(g["km_m"]) / 1000.0, max(g["km_m"]) / 1000.0, color="C3", alpha=0.06)
        drawn = True
    if drawn:
        ax.plot([], [], color="C3", lw=2.5, label="feature-point DB: 1/R between rows 3 and 4")
    if ok.any():
        lo, hi = np.nanmin(km[ok]), np.nanmax(km[ok])
        ax.set_xlim((lo - 100.0) / 1000.0, (hi + 100.0) / 1000.0)
    else:
        _empty(ax, "no curvature trace (no IMU or never determined)")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel("km [km]")
    ax.set_ylabel("κ [1/km] (+ left)")
    ax.set_title(f"Curvature against the feature-point DB, run {run_id} (track {track}, normal direction)")
    ax.grid(alpha=0.3)
    _legend(ax, fontsize=8)
    return kit.png(fig)


def run_map(gis: pd.DataFrame, trace: pd.DataFrame, track: str, run_id: str) -> bytes:
    """The GIS grid's tracks, the run's estimated positions (km placed on the grid of its
    track) and its GPS fixes."""
    fig, ax = kit.pyplot().subplots(figsize=(7, 6))
    for (line, trk), g in gis.groupby(["line_code", "track"]):
        g = g.sort_values("km_m")
        ax.plot(g["lon"], g["lat"], lw=1, color="0.6" if trk != track else "0.3", label=f"GIS {line} {trk}")
    own = gis[gis["track"] == track].sort_values("km_m")
    km = trace["km_m"].to_numpy(dtype=float)
    ok = np.isfinite(km)
    if len(own) > 1 and ok.any():
        g_km = own["km_m"].to_numpy(dtype=float)
        inside = ok & (km >= g_km[0]) & (km <= g_km[-1])
        lat = np.interp(km[inside], g_km, own["lat"].to_numpy(dtype=float))
        lon = np.interp(km[inside], g_km, own["lon"].to_numpy(dtype=float))
        ax.plot(lon, lat, color="C0", lw=4, alpha=0.6, label=f"run {run_id} (estimated km)")
        if lon.size:
            ax.plot(lon[0], lat[0], "o", color="C2", ms=8, label="start")
            ax.plot(lon[-1], lat[-1], "s", color="C3", ms=8, label="end")
    fix = trace["lat"].notna() & trace["lon"].notna()
    if fix.any():
        ax.scatter(trace.loc[fix, "lon"], trace.loc[fix, "lat"], s=3, color="k", label="GPS fixes", zorder=3)
    if gis.empty:
        _empty(ax, "no GIS grid for this line")
    else:
        # a roughly square window in metres, so that a line running north-south stays readable
        lat0 = float(gis["lat"].mean())
        cos0 = float(np.cos(np.radians(lat0)))
        lon_c, lat_c = (gis["lon"].min() + gis["lon"].max()) / 2, (gis["lat"].min() + gis["lat"].max()) / 2
        half = 0.55 * max(float(gis["lon"].max() - gis["lon"].min()) * cos0, float(gis["lat"].max() - gis["lat"].min()))
        half = max(half, 1e-3)
        ax.set_xlim(lon_c - half / cos0, lon_c + half / cos0)
        ax.set_ylim(lat_c - half, lat_c + half)
        ax.set_aspect(1.0 / cos0)
    ax.set_xlabel("longitude [°]")
    ax.set_ylabel("latitude [°]")
    ax.ticklabel_format(useOffset=False)
    ax.tick_params(axis="x", labelrotation=30)
    ax.grid(alpha=0.3)
    _legend(ax, fontsize=7, loc="best")
    ax.set_title(f"Run {run_id} on the GIS grid")
    return kit.png(fig)
