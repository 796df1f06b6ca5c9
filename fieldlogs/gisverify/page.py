"""Figures and the self-contained HTML report of ``trainpos gis verify``.

One figure per line: per track, the mean lateral offset of every cell (the run-level mean,
with its 95 % interval) along the km, coloured by status, defects shaded, the ±min-shift
band drawn; below, the along-track residual (GPS km − pipeline km) per cell. Matplotlib
headless (Agg), PNG bytes; the HTML embeds them as ``data:`` URIs (no external resource,
no script: the file works offline and can be mailed).
"""

from __future__ import annotations

import base64
import html
import io
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd

from dbtools.gis.verify import DEFECT, UNVERIFIED, VERIFIED
from schemas.units import format_km

if TYPE_CHECKING:
    from fieldlogs.gisverify.evidence import VerifyReport

#: At most this many lines get a figure in the HTML (lines with defects first).
MAX_LINE_FIGURES = 20
STATUS_STYLE = {
    VERIFIED: ("tab:blue", "verified"),
    UNVERIFIED: ("0.65", "unverified"),
    DEFECT: ("tab:red", "defect"),
}
CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:2em;color:#222;max-width:1400px}
table{border-collapse:collapse;margin:1em 0;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td.l,th.l{text-align:left}
.warn{color:#b00;font-weight:bold}.ok{color:#070;font-weight:bold}.note{color:#666}
figure{margin:1.5em 0}img{max-width:100%}.scroll{overflow-x:auto}
"""


def _png(fig: Any) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=96, bbox_inches="tight")
    plt.close(fig)
    return buf.getvalue()


def offset_along_line(cells: pd.DataFrame, defects: pd.DataFrame, line_code: str, min_shift_m: float) -> bytes:
    """Mean lateral offset per cell along one line, one panel per track, plus the
    along-track residual; defects shaded."""
    c = cells[cells["line_code"].astype(str) == str(line_code)]
    tracks = sorted(c["track"].astype(str).unique()) or ["—"]
    fig, axes = plt.subplots(len(tracks) + 1, 1, figsize=(12, 2.6 * len(tracks) + 2.2), sharex=True, squeeze=False)
    d_line = defects[defects["line_code"].astype(str) == str(line_code)] if len(defects) else defects
    for ax, track in zip(axes[:-1, 0], tracks, strict=True):
        ct = c[c["track"].astype(str) == track]
        mid = (ct["km_from_m"].to_numpy(dtype=float) + ct["km_to_m"].to_numpy(dtype=float)) / 2000.0
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
        if len(d_line):
            for r in d_line[d_line["track"].astype(str) == track].itertuples():
                ax.axvspan(r.km_from_m / 1000.0, r.km_to_m / 1000.0, color="tab:red", alpha=0.15)
                ax.annotate(
                    f"#{r.defect_id} {r.shift_m:+.2f} m",
                    (r.km_from_m / 1000.0, 1.0),
                    xycoords=("data", "axes fraction"),
                    va="top",
                    fontsize=8,
                    color="tab:red",
                )
        ax.set_ylabel(f"track {track}\noffset [m] (+ left)")
        if ct.empty:
            ax.text(0.5, 0.5, "no evidence", ha="center", va="center", transform=ax.transAxes, color="0.4")
        elif ax.get_legend_handles_labels()[0]:
            ax.legend(loc="lower right", fontsize=7, ncols=4)
    ax = axes[-1, 0]
    for track in tracks:
        ct = c[(c["track"].astype(str) == track) & c["km_residual_mean_m"].notna()]
        mid = (ct["km_from_m"].to_numpy(dtype=float) + ct["km_to_m"].to_numpy(dtype=float)) / 2000.0
        ax.plot(mid, ct["km_residual_mean_m"].to_numpy(dtype=float), ".", ms=3, label=f"track {track}")
    ax.axhline(0.0, color="0.5", lw=0.6)
    ax.set_ylabel("along-track\nresidual [m]")
    ax.set_xlabel("km")
    if ax.get_legend_handles_labels()[0]:
        ax.legend(loc="lower right", fontsize=7)
    else:
        ax.text(0.5, 0.5, "no pipeline km with a small margin", ha="center", va="center", transform=ax.transAxes)
    axes[0, 0].set_title(f"Line {line_code}: mean lateral offset per 20 m cell (95 % interval)")
    return _png(fig)


# ------------------------------------------------------------------------------ HTML


def _img(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode()
    return (
        f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{html.escape(alt)}</figcaption></figure>"
    )


def _fmt(column: str, v: Any) -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)) or (not isinstance(v, str) and pd.isna(v)):
        return "<td></td>"
    if isinstance(v, str) or isinstance(v, bool):
        return f'<td class="l">{html.escape(str(v))}</td>'
    if column.startswith("km_") and column.endswith("_m") and "residual" not in column:
        return f"<td>{format_km(float(v))}</td>"
    if isinstance(v, int | np.integer):
        return f"<td>{int(v):,}</td>"
    x = float(v)
    if column.startswith(("p_", "q_")):
        return f"<td>{x:.2e}</td>"
    if column.endswith("_share"):
        return f"<td>{100 * x:.1f} %</td>"
    return f"<td>{x:.3f}</td>"


def table_html(frame: pd.DataFrame) -> str:
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    rows = [
        "<tr>" + "".join(_fmt(str(c), v) for c, v in zip(frame.columns, rec, strict=True)) + "</tr>"
        for rec in frame.itertuples(index=False, name=None)
    ]
    return f"<div class='scroll'><table><tr>{head}</tr>{''.join(rows)}</table></div>"


def render_html(report: VerifyReport) -> str:
    """The whole verification as one HTML string."""
    v = report.verification
    cfg = v.config
    n_def = len(v.defects)
    verdict = f"<p class='warn'>{n_def} defect(s) found.</p>" if n_def else "<p class='ok'>No defect found.</p>"
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'><title>trainpos gis verify</title>"
        f"<style>{CSS}</style></head><body>",
        "<h1>GIS grid verification</h1>",
        f"<p>DB <code>{html.escape(report.db)}</code> (version <b>{html.escape(str(report.db_version))}</b>), "
        f"{len(report.runs)} run(s), {v.counts.get('fixes_matched', 0):,} fixes used; "
        f"generated {datetime.now(UTC):%Y-%m-%d %H:%M} UTC.</p>",
        verdict,
        "<p class='note'>Per 20 m cell the run is the unit: the runs' mean offsets are tested against 0 "
        f"(t-test, spread at least the track's pooled between-run spread; {cfg.correction.upper()} correction "
        f"over all testable cells at {cfg.alpha:g}); a defect needs |mean| ≥ {cfg.min_shift_m:g} m. "
        f"Cells with fewer than {cfg.min_runs} runs or {cfg.min_fixes} fixes, or whose 95 % interval reaches "
        f"beyond ±{cfg.tolerance_m:g} m, are unverified. Offsets are positive to the left of increasing km.</p>",
        "<h2>Coverage</h2>",
        table_html(v.coverage),
        "<h2>Defects</h2>",
        table_html(v.defects) if n_def else "<p>None.</p>",
    ]
    if len(v.proposal):
        parts += ["<h2>Proposed GIS points</h2>", table_html(v.proposal)]
    parts += ["<h2>Offsets along the lines</h2>"]
    lines = list(v.coverage["line_code"].astype(str).unique())
    with_defects = set(v.defects["line_code"].astype(str)) if n_def else set()
    lines.sort(key=lambda lc: (lc not in with_defects, lc))
    for lc in lines[:MAX_LINE_FIGURES]:
        parts.append(_img(offset_along_line(v.cells, v.defects, lc, cfg.min_shift_m), f"Line {lc}"))
    if len(lines) > MAX_LINE_FIGURES:
        parts.append(f"<p class='note'>{len(lines) - MAX_LINE_FIGURES} more line(s) not drawn.</p>")
    flagged = v.cells[v.cells["status"] == DEFECT]
    if len(flagged):
        parts += ["<h2>Defect cells</h2>", table_html(flagged)]
    parts += [
        "<h2>Evidence</h2>",
        table_html(pd.DataFrame([report.evidence])),
        table_html(pd.DataFrame(report.runs)),
        "<p class='note'>Along-track residual over all fixes with a pipeline km of small margin: "
        + html.escape(", ".join(f"{k} {val}" for k, val in v.km_residual.items()))
        + "</p>",
        "</body></html>",
    ]
    return "\n".join(parts)
