"""The self-contained HTML page of ``trainpos survey`` (:mod:`dbtools.pagekit`).

Figures (matplotlib, headless, embedded as PNG): per line, the balise residuals along the
km with their 95 % intervals, coloured by status (missed balises marked on the axis), the
±``moved_min_m`` band drawn; per line/track, the runs' mean curvature κ̄ with the DB's
feature points (±1/R between their lower-limit crossings) and the proposed ones; per
vehicle, the wheel diameter of every run (combined, and per source) against its start time
with the configured one.
Tables of every status follow. The verdict is green only when nothing is flagged and most
balises could be checked.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from dbtools import pagekit as kit
from fieldlogs.survey.features import db_features, db_track_features
from fieldlogs.survey.frames import rows as frame_rows
from schemas.units import format_km

if TYPE_CHECKING:
    from fieldlogs.survey.result import SurveyReport

#: At most this many lines (tracks) get a figure.
MAX_FIGURES = 12
BALISE_STYLE = {"ok": "tab:blue", "moved": "tab:red", "unverified": "0.6", "missed": "tab:purple"}


def balise_residuals(balises: pd.DataFrame, line: str, moved_min_m: float) -> bytes:
    """Residual (DB km − the runs' km) of every balise of a line along the km, per track."""
    b = balises[balises["line_code"] == line]
    tracks = sorted(b["track"].unique()) or ["—"]
    fig, axes = kit.pyplot().subplots(len(tracks), 1, figsize=(12, 2.4 * len(tracks) + 0.6), sharex=True, squeeze=False)
    for ax, track in zip(axes[:, 0], tracks, strict=True):
        bt = b[b["track"] == track]
        for status, colour in BALISE_STYLE.items():
            s = bt[bt["status"] == status]
            if not len(s):
                continue
            km = s["km_db_m"].to_numpy(dtype=float) / 1000.0
            if status == "missed":
                ax.plot(km, np.zeros(km.size), "x", color=colour, ms=8, label="missed")
                continue
            y = s["residual_m"].to_numpy(dtype=float)
            err = np.nan_to_num(s["ci95_m"].to_numpy(dtype=float))
            ok = np.isfinite(y)
            ax.errorbar(km[ok], y[ok], yerr=err[ok], fmt="o", ms=3, lw=0.8, color=colour, label=status)
        ax.axhspan(-moved_min_m, moved_min_m, color="0.92", zorder=0, label=f"±{moved_min_m:g} m")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_ylabel(f"track {track}\nresidual [m]")
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper right", fontsize=7, ncols=5)
    axes[-1, 0].set_xlabel("km [km]")
    axes[0, 0].set_title(f"Line {line}: balise residual DB km − runs' km (95 % interval)")
    return kit.png(fig)


def _feature_bands(ax: Any, rows: pd.DataFrame, colour: str, label: str) -> None:
    """±1/R between the lower-limit crossings of each feature (sign: its direction)."""
    first = True
    for r in frame_rows(rows):
        if not (np.isfinite(r.entry) and np.isfinite(r.exit) and r.radius > 0):
            continue
        k = (1.0 if r.attribute == "left" else -1.0) / float(r.radius)
        a, b = sorted((float(r.entry) / 1000.0, float(r.exit) / 1000.0))
        ax.plot([a, a, b, b], [0.0, k, k, 0.0], color=colour, lw=1.2, label=label if first else None)
        first = False


def curvature_overlay(rep: SurveyReport, key: tuple[str, str]) -> bytes:
    """Mean curvature of a track with the DB's and the proposed feature points."""
    fig, ax = kit.pyplot().subplots(1, 1, figsize=(12, 3.0))
    tc = rep.curves.get(key)
    if tc is not None and len(tc.profile):
        p = tc.profile
        ax.plot(p["km_m"] / 1000.0, p["kappa"], ".", ms=1.5, color="0.3", label="runs' mean κ")
    dbf = db_features(rep.network.feature_points) if key[0] else db_track_features(rep.network.track_feature_points)
    dbf = dbf[(dbf["line_code"] == key[0]) & (dbf["track"] == key[1])]
    _feature_bands(
        ax,
        dbf.rename(columns={"entry_km_m": "entry", "exit_km_m": "exit", "radius_m": "radius"}),
        "tab:blue",
        "DB feature",
    )
    f = rep.features
    here = (f["line_code"] == key[0]) & (f["track"] == key[1]) if key[0] else f["track_id"] == key[1]
    prop = f[here & f["status"].isin(["new", "moved"])]
    _feature_bands(
        ax,
        prop.rename(columns={"entry_km_m": "entry", "exit_km_m": "exit", "radius_m": "radius"}),
        "tab:red",
        "proposed",
    )
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_xlabel("km [km]" if key[0] else "pos from the track's begin [km]")
    ax.set_ylabel("κ [1/m] (+ left)")
    where = f"Line {key[0]} track {key[1]}" if key[0] else f"Track {key[1]}"
    ax.set_title(f"{where}: curvature in the normal running direction")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="upper right", fontsize=7)
    return kit.png(fig)


#: How each source's per-run diameter is drawn beside the combined one.
SOURCE_MARKERS = (("balise", "s"), ("radar", "^"), ("gnss", "v"))


def wheel_trend(wheel_runs: pd.DataFrame) -> bytes:
    """Per vehicle: each run's combined diameter (95 % interval) and each source's against
    its start time."""
    w = wheel_runs.assign(time=pd.to_datetime(wheel_runs["start_time"], utc=True, errors="coerce", format="ISO8601"))
    vehicles = sorted(w["vehicle_id"].unique())[:MAX_FIGURES] or ["—"]
    fig, axes = kit.pyplot().subplots(
        len(vehicles), 1, figsize=(12, 2.2 * len(vehicles) + 0.6), sharex=True, squeeze=False
    )
    for ax, vid in zip(axes[:, 0], vehicles, strict=True):
        g = w[w["vehicle_id"] == vid].sort_values("time")
        ok = np.isfinite(g["diameter_m"].to_numpy(dtype=float)) & g["time"].notna().to_numpy()
        if ok.any():
            ax.errorbar(
                g["time"][ok],
                1000 * g["diameter_m"][ok],
                yerr=1000 * np.nan_to_num(g["ci95_m"][ok].to_numpy(dtype=float)),
                fmt="o-",
                ms=3,
                lw=0.8,
                color="tab:blue",
                label="combined",
            )
            for name, marker in SOURCE_MARKERS:
                col = g[f"diameter_{name}_m"].to_numpy(dtype=float)
                has = np.isfinite(col) & g["time"].notna().to_numpy()
                if has.any():
                    ax.plot(g["time"][has], 1000 * col[has], marker, ms=4, mfc="none", color="0.35", label=name)
            ax.step(
                g["time"][ok], 1000 * g["configured_m"][ok], where="post", color="tab:orange", lw=1.0, label="run.json"
            )
            ax.legend(loc="upper right", fontsize=7)
        else:
            ax.text(0.5, 0.5, "no estimate", ha="center", va="center", transform=ax.transAxes, color="0.4")
        ax.set_ylabel(f"{vid}\nD [mm]")
    axes[0, 0].set_title("Wheel diameter per run (95 % interval)")
    axes[-1, 0].set_xlabel("run start [UTC]")
    fig.autofmt_xdate()
    return kit.png(fig)


def _cell(column: str, v: Any) -> kit.Cell:
    if kit.is_missing(v) or (isinstance(v, float | np.floating) and not np.isfinite(v)):
        return kit.Cell("")
    if isinstance(v, str | bool) or not isinstance(v, int | float | np.integer | np.floating):
        return kit.Cell(str(v), "l")
    if column.startswith("km") and column.endswith("_m") and "diff" not in column:
        return kit.Cell(format_km(float(v)))
    if isinstance(v, int | np.integer):
        return kit.Cell(f"{int(v):,}")
    if column.endswith("_share"):
        return kit.Cell(f"{100 * float(v):+.3f} %")
    return kit.Cell(f"{float(v):.3f}")


def _wheel_cell(column: str, v: Any) -> kit.Cell:
    """Diameters and their intervals to 0.01 mm (a wheel wears a few tenths of a mm a month)."""
    if column == "configured_m" or column.startswith(("diameter", "ci95")):
        if isinstance(v, float | np.floating) and np.isfinite(v):
            return kit.Cell(f"{float(v):.5f}")
    return _cell(column, v)


def _table(frame: pd.DataFrame, cell: Any = _cell) -> str:
    return kit.frame_table(frame, cell) if len(frame) else "<p>None.</p>"


def _verdict(rep: SurveyReport) -> kit.Verdict:
    s = rep.summary()
    if rep.flagged:
        parts = [f"{v} {k} balise(s)" for k, v in s["balises"].items() if k in ("moved", "missed")]
        parts += [f"{v} {k} feature(s)" for k, v in s["features"].items() if k in ("moved", "new", "not seen")]
        if s["candidates_confirmed"]:
            parts.append(f"{s['candidates_confirmed']} unknown balise(s)")
        if s["wheels"].get("alert"):
            parts.append(f"{s['wheels']['alert']} wheel alert(s)")
        if s["wheels_inconsistent"]:
            parts.append(f"{s['wheels_inconsistent']} vehicle(s) whose wheel sources disagree")
        if s["gis_defects"]:
            parts.append(f"{s['gis_defects']} GIS defect(s)")
        if s["failed_runs"]:
            parts.append(f"{s['failed_runs']} run(s) failed")
        return kit.Verdict("To act on: " + ", ".join(parts) + ".", kit.Status.WARN)
    n = max(sum(s["balises"].values()), 1)
    if s["balises"].get("unverified", 0) > n / 2:
        return kit.Verdict(
            f"Mostly unverified: nothing flagged, but {s['balises']['unverified']} of {n} balises are unverified: "
            "the DB is not shown to be right.",
            kit.Status.CAUTION,
        )
    return kit.Verdict("Passed: nothing flagged.", kit.Status.OK)


def _key(line: object, track: object, track_id: object) -> tuple[str, str]:
    """A feature row's curvature key: (line, track), or ("", track_id) off every line."""
    return (str(line), str(track)) if isinstance(line, str) and line else ("", str(track_id))


def _title(key: tuple[str, str]) -> str:
    return f"Curvature, line {key[0]} track {key[1]}" if key[0] else f"Curvature, track {key[1]} (pos from its begin)"


def _figures(rep: SurveyReport) -> list[str]:
    out = []
    lines = sorted(rep.balises["line_code"].unique())
    for line in lines[:MAX_FIGURES]:
        out.append(kit.figure(balise_residuals(rep.balises, line, rep.config.moved_min_m), f"Balises, line {line}"))
    keys = sorted(set(rep.curves) | {_key(*k) for k in rep.features[["line_code", "track", "track_id"]].to_numpy()})
    for key in keys[:MAX_FIGURES]:
        out.append(kit.figure(curvature_overlay(rep, key), _title(key)))
    if len(keys) > MAX_FIGURES or len(lines) > MAX_FIGURES:
        out.append(kit.paragraph("More lines/tracks not drawn (the tables have them all).", kit.Status.NOTE))
    return out


def render_html(rep: SurveyReport) -> str:
    """The whole survey as one HTML string."""
    s = rep.summary()
    rows = [
        ("DB", f"{rep.db} (version {rep.db_version or '—'})"),
        ("runs", f"{s['runs']} ({s['run_hours']} run-hours)"),
    ]
    rows += [
        (f"{k}", ", ".join(f"{n} {st}" for st, n in s[k].items()) or "—") for k in ("balises", "features", "wheels")
    ]
    rows += [("GIS defects", s["gis_defects"] if s["gis_defects"] is not None else rep.gis_note)]
    parts = [
        f"<p>{kit.generated()}.</p>",
        kit.key_value_table(rows),
        kit.section("Along the lines", *_figures(rep)),
        kit.section(
            "Wheels",
            kit.figure(wheel_trend(rep.wheel_runs), "Wheel diameter per vehicle"),
            _table(rep.wheels, _wheel_cell),
            _table(rep.wheel_runs, _wheel_cell),
        ),
        kit.section("Balises", _table(rep.balises)),
        kit.section("Inspection: passes over missed balises", _table(rep.missed)),
        kit.section("Telegrams the DB does not know", _table(rep.candidates)),
        kit.section("Feature points", _table(rep.features)),
    ]
    if rep.gis is not None:
        parts.append(kit.section("GIS grid (gis verify)", _table(rep.gis.coverage), _table(rep.gis.defects)))
    if rep.gis_tracks is not None:
        tp = rep.gis_tracks
        parts.append(
            kit.section(
                "GIS of the tracks off a line (track_points, pos m along the track)",
                _table(tp.coverage),
                _table(tp.defects),
            )
        )
    else:
        parts.append(
            kit.section("GIS grid (gis verify)", kit.paragraph(rep.gis_note or "not verified", kit.Status.NOTE))
        )
    parts.append(kit.section("Changes --propose writes", _table(rep.changes)))
    parts.append(kit.section("Runs", _table(rep.runs), _table(rep.failed_runs)))
    return kit.page(
        "trainpos survey", *parts, heading_text="Survey of balises, feature points and wheels", verdict=_verdict(rep)
    )
