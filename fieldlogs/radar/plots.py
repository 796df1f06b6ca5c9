"""Plots of the radar speed meter (matplotlib, headless Agg, imported here only).

One PNG, two panels:

* **Speed along the run** [km/h, magnitude]: the radar's V_G of every ``ok`` frame (its
  ±2σ band), ``standstill`` frames at 0, frames without a speed marked by status; the wheel
  (tachometer pulses × π·D/teeth over 1 s), the GNSS speed (distance between consecutive
  fixes with fix ≥ 1; missing, shaded, under an overpass or in a tunnel) and the simulator's truth
  where the run has them; the naive strongest-line speed, faint.
* **One frame as a person checks the radar**: every paired line as (Doppler speed V_m,
  range R_m), coloured by SNR when used in eq. 2, grey when at a ground range but left
  out, red crosses when aliased, hollow when elsewhere; the ground-range gate; and eq. 1
  for the frame's V_G, R = h / √(1 − (V_m/V_G)²): used lines lie on that curve.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from dbtools.atomic import atomic_file
from dbtools.masks import true_runs
from fieldlogs.radar.config import RadarConfig
from fieldlogs.radar.framing import Frames
from fieldlogs.radar.solve import range_gate
from fieldlogs.radar.speed import FrameDetail, RadarSpeed, frame_detail
from fieldlogs.runs.handle import Run
from schemas.enums import GpsFix, RadarStatus

KMH = 3.6
M_PER_DEG = 111_320.0
STATUS_MARK = {
    RadarStatus.ALIASED.value: ("v", "tab:red"),
    RadarStatus.LOW_QUALITY.value: ("x", "tab:orange"),
    RadarStatus.NO_REFLECTIONS.value: ("s", "tab:purple"),
}


def wheel_speed(run: Run) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
    """(t, speed m/s) from the tachometer over 1 s windows, nominal wheel diameter."""
    tacho, d, teeth = run.stream("tacho"), run.field("wheel_diameter_m"), run.field("teeth")
    if tacho is None or len(tacho) < 12 or d is None or teeth is None:
        return None
    t = tacho["t"].to_numpy(dtype=float, na_value=np.nan)
    p = tacho["pulses"].to_numpy(dtype=float, na_value=np.nan)
    ok = np.isfinite(t) & np.isfinite(p)
    t, p = t[ok], p[ok]
    k = 10
    v = (p[k:] - p[:-k]) / (t[k:] - t[:-k]) * np.pi * d / teeth
    return 0.5 * (t[k:] + t[:-k]), v


def gnss_speed(run: Run) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64]] | None:
    """(t, speed m/s) between consecutive GPS fixes (NaN where either has no fix)."""
    gps = run.stream("gps")
    if gps is None or len(gps) < 2:
        return None
    t = gps["t"].to_numpy(dtype=float, na_value=np.nan)
    lat = gps["lat"].to_numpy(dtype=float, na_value=np.nan)
    lon = gps["lon"].to_numpy(dtype=float, na_value=np.nan)
    fix = gps["fix"].to_numpy(dtype=float, na_value=0.0)
    lat = np.where(fix >= GpsFix.GPS, lat, np.nan)
    dy = np.diff(lat) * M_PER_DEG
    dx = np.diff(lon) * M_PER_DEG * np.cos(np.radians(lat[1:]))
    return 0.5 * (t[1:] + t[:-1]), np.hypot(dx, dy) / np.diff(t)


def _gnss_lost(ax: Any, run: Run) -> None:
    """Shade the spans without a GNSS fix (tunnels, overpasses)."""
    gps = run.stream("gps")
    if gps is None or len(gps) < 2:
        return
    t = gps["t"].to_numpy(dtype=float, na_value=np.nan)
    lost = gps["fix"].to_numpy(dtype=float, na_value=0.0) < GpsFix.GPS
    for k, (a, b) in enumerate(zip(*true_runs(lost), strict=True)):
        ax.axvspan(
            t[a] - 0.5, t[b - 1] + 0.5, color="tab:olive", alpha=0.15, lw=0, label="no GNSS fix" if k == 0 else None
        )


def _speed_panel(ax: Any, run: Run, result: RadarSpeed) -> None:
    c = result.columns
    t, v, sig, status = c["t"], np.abs(c["speed_mps"]) * KMH, c["sigma_mps"] * KMH, c["status"]
    truth = run.stream("truth")
    if truth is not None:
        ax.plot(truth["t"], np.abs(truth["speed_mps"]) * KMH, color="black", lw=1.0, label="truth")
    for series, label, style in (
        (wheel_speed(run), "wheel (pulses)", "tab:green"),
        (gnss_speed(run), "GNSS", "tab:olive"),
    ):
        if series is not None:
            ax.plot(series[0], series[1] * KMH, color=style, lw=1.0, label=label)
    _gnss_lost(ax, run)
    ax.plot(t, np.abs(c["v_naive_mps"]) * KMH, ".", color="tab:gray", ms=2, alpha=0.5, label="naive single peak")
    ax.fill_between(t, v - 2 * sig, v + 2 * sig, color="tab:blue", alpha=0.25, lw=0)
    ax.plot(t, v, ".-", color="tab:blue", ms=3, lw=0.8, label="radar V_G (eq. 2) ±2σ")
    for st, (marker, colour) in STATUS_MARK.items():
        m = status == st
        if m.any():
            ax.plot(t[m], np.zeros(int(m.sum())), marker, color=colour, ms=5, label=st)
    ax.set_xlabel("t [s]")
    ax.set_ylabel("speed [km/h]")
    ax.set_title(f"Run {result.run_id}: radar vs wheel vs truth")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8, ncol=2)


def _scatter_panel(ax: Any, detail: FrameDetail, result: RadarSpeed, cfg: RadarConfig) -> None:
    p = result.params
    lines, cls = detail.lines, detail.classes
    vm, r, snr_db = lines.v_m * KMH, lines.range_m, 10 * np.log10(np.maximum(lines.snr, 1e-12))
    other = ~cls.ground & ~cls.alias
    ax.scatter(vm[other], r[other], facecolors="none", edgecolors="tab:gray", s=18, label="other range")
    ax.scatter(vm[cls.alias], r[cls.alias], marker="x", color="tab:red", s=22, label="aliased")
    left = cls.ground & ~cls.used
    ax.scatter(vm[left], r[left], color="lightgray", s=18, label="ground, left out")
    sc = ax.scatter(vm[cls.used], r[cls.used], c=snr_db[cls.used], cmap="viridis", s=22, label="used (eq. 2)")
    if cls.used.any():
        ax.figure.colorbar(sc, ax=ax, label="SNR [dB]")
    r0, r1 = range_gate(p, cfg.gate_beamwidths)
    ax.axhspan(r0, r1, color="tab:blue", alpha=0.06, label="ground-range gate")
    v_g = float(detail.fit.v[0]) if np.isfinite(detail.fit.v[0]) else np.nan
    if np.isfinite(v_g):
        sgn = float(detail.fit.direction[0]) or 1.0
        x = np.linspace(0.0, 0.999, 200) * v_g
        ax.plot(sgn * x * KMH, p.height_m / np.sqrt(1 - (x / v_g) ** 2), color="tab:blue", lw=1, label="eq. 1 at V_G")
    ax.set_ylim(0, min(p.r_max_m, max(3 * r1, float(np.max(r, initial=0.0)) * 1.05 + 0.1)))
    ax.set_xlabel("Doppler speed V_m [km/h] (+ approaching)")
    ax.set_ylabel("range R_m [m] (f1/f2 phase)")
    speed = f"V_G = {v_g * KMH:.2f} km/h" if np.isfinite(v_g) else "no V_G"
    ax.set_title(f"Frame at t = {detail.t:.2f} s: {len(lines)} lines, {speed}, {detail.status}")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize=8)


def default_frame_t(result: RadarSpeed) -> float:
    """The ``ok`` frame with the most used lines (the first frame when none is ok)."""
    c = result.columns
    ok = c["status"] == RadarStatus.OK.value
    if not ok.any():
        return float(c["t"][0]) if len(c["t"]) else 0.0
    return float(c["t"][np.flatnonzero(ok)[np.argmax(c["n_used"][ok])]])


def plot_run(
    run: Run,
    frames: Frames,
    result: RadarSpeed,
    path: Path,
    *,
    frame_t: float | None = None,
    force: bool = False,
    inputs: Sequence[Path] = (),
) -> Path:
    """Write the two-panel PNG (atomically, under the output rule of :mod:`dbtools.atomic`)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    detail = frame_detail(frames, default_frame_t(result) if frame_t is None else frame_t, result.params, result.cfg)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(11, 9), gridspec_kw={"height_ratios": [3, 2]})
    try:
        _speed_panel(top, run, result)
        top.axvline(detail.t, color="tab:blue", ls=":", lw=0.8)
        _scatter_panel(bottom, detail, result, result.cfg)
        fig.tight_layout()
        with atomic_file(Path(path), force=force, inputs=inputs) as tmp:
            fig.savefig(tmp, format="png", dpi=100)
    finally:
        plt.close(fig)
    return Path(path)
