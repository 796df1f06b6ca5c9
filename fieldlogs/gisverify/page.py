"""Figures and the self-contained HTML report of ``trainpos gis verify``.

One figure per line: per track, the mean lateral offset of every cell (the run-level mean,
with its 95 % interval) along the km, coloured by status, defects shaded, the ±min-shift
band drawn; below, the along-track residual (GPS km − pipeline km) per cell. The tracks off
a line (``track_points``, per track_id) get their own section, with one figure whose panels
are those tracks, along the distance from each track's begin. Matplotlib
headless (Agg, through :func:`dbtools.pagekit.pyplot`), PNG bytes; the page
(:mod:`dbtools.pagekit`) embeds them as ``data:`` URIs (no external resource, no script:
the file works offline and can be mailed).

The verdict is green ("No defect found.") only when no line is mostly unverified: a grid
that could not be checked is not shown to be right (:func:`verdict`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from dbtools import pagekit as kit
from dbtools.gis.verify.config import DEFECT, UNVERIFIED, VERIFIED
from schemas.units import format_km

if TYPE_CHECKING:
    from dbtools.gis.verify.result import GisVerification
    from fieldlogs.gisverify.evidence import VerifyReport

#: At most this many lines get a figure in the HTML (lines with defects first).
MAX_LINE_FIGURES = 20
#: A line with more than this share of its length unverified keeps "no defect found" from
#: showing green.
MAX_UNVERIFIED_SHARE = 0.5
STATUS_STYLE = {
    VERIFIED: ("tab:blue", "verified"),
    UNVERIFIED: ("0.65", "unverified"),
    DEFECT: ("tab:red", "defect"),
}


def _offset_panel(ax: Any, ct: pd.DataFrame, dt: pd.DataFrame, min_shift_m: float, along: str, scale: float) -> None:
    """One track's mean lateral offset per cell (95 % interval) coloured by status, the
    ±min-shift band, its defects shaded; x = ``{along}_from_m``/``{along}_to_m`` ÷ ``scale``."""
    lo, hi = f"{along}_from_m", f"{along}_to_m"
    mid = (ct[lo].to_numpy(dtype=float) + ct[hi].to_numpy(dtype=float)) / (2.0 * scale)
    for status, (colour, label) in STATUS_STYLE.items():
        m = (ct["status"] == status).to_numpy()
        if not m.any():
            continue
        half = 1.96 * ct["se_m"].to_numpy(dtype=float)[m]
        ax.errorbar(
            mid[m],
            ct["offset_mean_m"].to_numpy(dtype=float)[m],
            yerr=np.where(np.isfinite(half), half, 0.0),
            fmt="o",
            ms=2.5,
            lw=0.6,
            color=colour,
            label=label,
        )
    ax.axhspan(-min_shift_m, min_shift_m, color="0.9", zorder=0, label=f"±{min_shift_m:g} m")
    ax.axhline(0.0, color="0.5", lw=0.6)
    for r in dt.to_dict("records"):
        ax.axvspan(r[lo] / scale, r[hi] / scale, color="tab:red", alpha=0.15)
        ax.annotate(
            f"#{r['defect_id']} {r['shift_m']:+.2f} m",
            (r[lo] / scale, 1.0),
            xycoords=("data", "axes fraction"),
            va="top",
            fontsize=8,
            color="tab:red",
        )
    if ct.empty:
        ax.text(0.5, 0.5, "no evidence", ha="center", va="center", transform=ax.transAxes, color="0.4")
    elif ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower right", fontsize=7, ncols=4)


def offset_along_line(cells: pd.DataFrame, defects: pd.DataFrame, line_code: str, min_shift_m: float) -> bytes:
    """Mean lateral offset per cell along one line, one panel per track, plus the
    along-track residual; defects shaded."""
    c = cells[cells["line_code"].astype(str) == str(line_code)]
    tracks = sorted(c["track"].astype(str).unique()) or ["—"]
    fig, axes = kit.pyplot().subplots(
        len(tracks) + 1, 1, figsize=(12, 2.6 * len(tracks) + 2.2), sharex=True, squeeze=False
    )
    d_line = defects[defects["line_code"].astype(str) == str(line_code)] if len(defects) else defects
    for ax, track in zip(axes[:-1, 0], tracks, strict=True):
        dt = d_line[d_line["track"].astype(str) == track] if len(d_line) else d_line
        _offset_panel(ax, c[c["track"].astype(str) == track], dt, min_shift_m, "km", 1000.0)
        ax.set_ylabel(f"track {track}\noffset [m] (+ left)")
    ax = axes[-1, 0]
    for track in tracks:
        ct = c[(c["track"].astype(str) == track) & c["km_residual_mean_m"].notna()]
        mid = (ct["km_from_m"].to_numpy(dtype=float) + ct["km_to_m"].to_numpy(dtype=float)) / 2000.0
        ax.plot(mid, ct["km_residual_mean_m"].to_numpy(dtype=float), ".", ms=3, label=f"track {track}")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_ylabel("along-track\nresidual [m]")
    ax.set_xlabel("km [km]")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower right", fontsize=7)
    else:
        ax.text(0.5, 0.5, "no pipeline km with a small margin", ha="center", va="center", transform=ax.transAxes)
    axes[0, 0].set_title(f"Line {line_code}: mean lateral offset per 20 m cell (95 % interval)")
    return kit.png(fig)


def offset_along_tracks(cells: pd.DataFrame, defects: pd.DataFrame, track_ids: list[str], min_shift_m: float) -> bytes:
    """Mean lateral offset per cell along each of ``track_ids`` (tracks off a line: x is the
    distance from the track's begin, pos), one panel per track; defects shaded."""
    fig, axes = kit.pyplot().subplots(len(track_ids), 1, figsize=(12, 2.6 * len(track_ids) + 0.6), squeeze=False)
    for ax, tid in zip(axes[:, 0], track_ids, strict=True):
        dt = defects[defects["track_id"].astype(str) == tid] if len(defects) else defects
        _offset_panel(ax, cells[cells["track_id"].astype(str) == tid], dt, min_shift_m, "pos", 1.0)
        ax.set_ylabel(f"{tid}\noffset [m] (+ left)")
    axes[-1, 0].set_xlabel("pos [m] along the track from its begin")
    axes[0, 0].set_title("Tracks off a line: mean lateral offset per 20 m cell (95 % interval)")
    return kit.png(fig)


# ------------------------------------------------------------------------------ HTML


def _cell(column: str, v: Any) -> kit.Cell:
    """km columns in railway notation, p/q values in scientific notation, shares in %,
    other numbers with three decimals."""
    if kit.is_missing(v) or (isinstance(v, float | np.floating) and not np.isfinite(v)):
        return kit.Cell("")
    if isinstance(v, str | bool) or not isinstance(v, int | float | np.integer | np.floating):
        return kit.Cell(str(v), "l")
    if column.startswith("km_") and column.endswith("_m") and "residual" not in column:
        return kit.Cell(format_km(float(v)))
    if isinstance(v, int | np.integer):
        return kit.Cell(f"{int(v):,}")
    x = float(v)
    if column.startswith(("p_", "q_")):
        return kit.Cell(f"{x:.2e}")
    if column.endswith("_share"):
        return kit.Cell(f"{100 * x:.1f} %")
    return kit.Cell(f"{x:.3f}")


def table_html(frame: pd.DataFrame) -> str:
    return kit.frame_table(frame, _cell)


def mostly_unverified(coverage: pd.DataFrame) -> pd.DataFrame:
    """Lines (all tracks together; a track off a line on its own, its ``where`` label given)
    with more than :data:`MAX_UNVERIFIED_SHARE` of their length unverified: ``where``,
    ``length_km``, ``unverified_km``."""
    if coverage.empty:
        return pd.DataFrame({"where": [], "length_km": [], "unverified_km": []})
    where = coverage["where"] if "where" in coverage else "line " + coverage["line_code"].astype(str)
    per = coverage.groupby(where.rename("where"))[["length_km", "unverified_km"]].sum().reset_index()
    return per[(per["length_km"] > 0) & (per["unverified_km"] > MAX_UNVERIFIED_SHARE * per["length_km"])]


def verdict(coverage: pd.DataFrame, n_defects: int, n_km_defects: int = 0) -> kit.Verdict:
    """Defects in red; "No defect found." in green only when no line is mostly unverified,
    else in amber, naming those lines and how much of them is unverified."""
    if n_defects or n_km_defects:
        km = f" and {n_km_defects} along-track (km) defect(s)" if n_km_defects else ""
        return kit.Verdict(f"Failed: {n_defects} defect(s){km} found.", kit.Status.WARN)
    if coverage.empty or not float(coverage["length_km"].sum()) > 0:
        return kit.Verdict("Not verified: no defect found, but no grid cell could be checked.", kit.Status.CAUTION)
    thin = mostly_unverified(coverage)
    if thin.empty:
        return kit.Verdict("Passed: no defect found.", kit.Status.OK)
    lines = "; ".join(f"{r.where}: {r.unverified_km:.1f} of {r.length_km:.1f} km unverified" for r in thin.itertuples())
    return kit.Verdict(
        f"Mostly unverified: no defect found where the evidence suffices, but most of the grid is unverified "
        f"({lines}): the grid there is not shown to be right.",
        kit.Status.CAUTION,
    )


def _method(report: VerifyReport) -> str:
    cfg = report.verification.config
    scan = (
        f"Neighbouring cells are pooled into windows of {', '.join(f'{w:g}' for w in cfg.scan_windows_m)} m: "
        f"each run's offset there minus its own offset over {cfg.background_m:g} m either side, the runs' "
        f"contrasts t-tested (variance moderated per window length), {cfg.scan_correction.upper()} over every "
        "window of every track; the same on the along-track residual (GIS km − pipeline km). "
        if cfg.scan
        else "The pooled scan is off. "
    )
    return kit.paragraph(
        "Per 20 m cell the run is the unit: the runs' mean offsets are tested against 0 "
        f"(t-test, spread at least the track's pooled between-run spread; {cfg.correction.upper()} correction "
        f"over all testable cells at {cfg.alpha:g}). {scan}A defect needs |shift| ≥ {cfg.min_shift_m:g} m. "
        f"Cells with fewer than {cfg.min_runs} runs or {cfg.min_fixes} fixes, or whose 95 % interval reaches "
        f"beyond ±{cfg.tolerance_m:g} m, are unverified. Offsets are positive to the left of increasing km.",
        kit.Status.NOTE,
    )


def _line_figures(report: VerifyReport) -> list[str]:
    v = report.verification
    lines = list(v.coverage["line_code"].astype(str).unique())
    with_defects = set(v.defects["line_code"].astype(str)) if len(v.defects) else set()
    lines.sort(key=lambda lc: (lc not in with_defects, lc))
    out = [
        kit.figure(offset_along_line(v.cells, v.defects, lc, v.config.min_shift_m), f"Line {lc}")
        for lc in lines[:MAX_LINE_FIGURES]
    ]
    if len(lines) > MAX_LINE_FIGURES:
        out.append(kit.paragraph(f"{len(lines) - MAX_LINE_FIGURES} more line(s) not drawn.", kit.Status.NOTE))
    return out


def render_html(report: VerifyReport) -> str:
    """The whole verification as one HTML string."""
    v = report.verification
    n_def = len(v.defects)
    n_tp = len(report.track_points.defects) if report.track_points is not None else 0
    parts = [
        f"<p>DB {kit.code(report.db)} (version <b>{kit.escape(report.db_version)}</b>), "
        f"{len(report.runs)} run(s), {v.counts.get('fixes_matched', 0):,} fixes used; {kit.generated()}.</p>",
        _method(report),
        kit.section("Coverage", table_html(v.coverage)),
        kit.section("Defects", table_html(v.defects) if n_def else "<p>None.</p>"),
    ]
    if len(v.proposal):
        parts.append(kit.section("Proposed GIS points", table_html(v.proposal)))
    if len(v.km_defects):
        parts.append(kit.section("Along-track (km) defects", table_html(v.km_defects)))
    parts.append(kit.section("Offsets along the lines", *_line_figures(report)))
    flagged = v.cells[v.cells["status"] == DEFECT]
    if len(flagged):
        parts.append(kit.section("Defect cells", table_html(flagged)))
    if report.track_points is not None:
        parts.append(_track_points_section(report.track_points))
    residual = ", ".join(f"{k} {val}" for k, val in v.km_residual.items())
    parts.append(
        kit.section(
            "Evidence",
            table_html(pd.DataFrame([report.evidence])),
            table_html(pd.DataFrame(report.runs)),
            kit.paragraph(
                f"Along-track residual over all fixes with a pipeline km of small margin: {residual}", kit.Status.NOTE
            ),
        )
    )
    return kit.page(
        "trainpos gis verify",
        *parts,
        heading_text="GIS grid verification",
        verdict=verdict(_all_coverage(report), n_def + n_tp, len(v.km_defects)),
    )


def _all_coverage(report: VerifyReport) -> pd.DataFrame:
    """The coverage of the line grid and of the tracks off a line together (the verdict's)."""
    tp = report.track_points
    lines = report.verification.coverage
    if tp is None or tp.coverage.empty:
        return lines
    lines = lines.assign(where="line " + lines["line_code"].astype(str))
    tracks = tp.coverage.assign(where="track " + tp.coverage["track_id"].astype(str))
    return pd.concat([lines, tracks], ignore_index=True)


def _track_points_section(tp: GisVerification) -> str:
    """The tracks off a line (``track_points``), per track_id: coverage, defects, proposed
    points and defect cells, positions in metres along the track from its begin."""
    parts = [
        kit.paragraph(
            f"Station tracks, crossovers and connecting curves verified against their own 20 m grid "
            f"(track_points), per track_id; positions (pos_*) in metres along the track from its begin, offsets "
            f"positive to the left of begin → end. {tp.counts.get('fixes_matched', 0):,} fixes used.",
            kit.Status.NOTE,
        ),
        kit.section("Coverage of the tracks off a line", table_html(tp.coverage), level=3),
        kit.section(
            "Defects of the tracks off a line", table_html(tp.defects) if len(tp.defects) else "<p>None.</p>", level=3
        ),
    ]
    if len(tp.proposal):
        parts.append(kit.section("Proposed track points", table_html(tp.proposal), level=3))
    seen = list(dict.fromkeys(tp.cells["track_id"].astype(str)))  # the tracks with evidence, defects first
    with_defects = set(tp.defects["track_id"].astype(str)) if len(tp.defects) else set()
    seen.sort(key=lambda t: t not in with_defects)
    if seen:
        png = offset_along_tracks(tp.cells, tp.defects, seen[:MAX_LINE_FIGURES], tp.config.min_shift_m)
        parts.append(kit.figure(png, "Offsets along the tracks off a line"))
    flagged = tp.cells[tp.cells["status"] == DEFECT]
    if len(flagged):
        parts.append(kit.section("Defect cells of the tracks off a line", table_html(flagged), level=3))
    return kit.section("Tracks off a line (track_points)", *parts)
