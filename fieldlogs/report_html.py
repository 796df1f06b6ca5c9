"""Self-contained HTML audit report (inline CSS, plots as embedded PNG, works offline)."""

from __future__ import annotations

import base64
import html
import json
from datetime import UTC, datetime
from pathlib import Path

import pandas as pd

from dbtools.database import read_network
from fieldlogs import plots
from fieldlogs.auditdb import read_table
from fieldlogs.report import Report

CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,sans-serif;margin:2em;color:#222}
table{border-collapse:collapse;margin:1em 0;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td.l,th.l{text-align:left}
.warn{color:#b00}.ok{color:#070}figure{margin:1.5em 0}img{max-width:100%}
"""


def _img(png: bytes, alt: str) -> str:
    return (f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,'
            f'{base64.b64encode(png).decode()}"><figcaption>{html.escape(alt)}</figcaption></figure>')


def _table(frame: pd.DataFrame, target: float | None = None) -> str:
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    rows = []
    for rec in frame.itertuples(index=False):
        cells = []
        for c, v in zip(frame.columns, rec, strict=True):
            cls = ""
            if isinstance(v, float):
                txt = "" if pd.isna(v) else f"{v:.3f}" if abs(v) < 100 else f"{v:,.0f}"
                if target is not None and c.endswith("correction_pct") and not pd.isna(v) and v > target:
                    cls = ' class="warn"'
            else:
                txt = html.escape(str(v))
                cls = ' class="l"'
            cells.append(f"<td{cls}>{txt}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(rows)}</table>"


def render_html(report: Report, audit_path: Path) -> str:
    """The whole report as one HTML string."""
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>trainpos audit</title>"
             f"<style>{CSS}</style></head><body>",
             "<h1>Positioning audit</h1>",
             f"<p>Audit <code>{html.escape(str(audit_path))}</code>, onboard DB version "
             f"<b>{html.escape(report.meta.get('db_version', '?'))}</b>, target "
             f"{report.target_pct:g} %, generated {datetime.now(UTC):%Y-%m-%d %H:%M} UTC.</p>",
             "<h2>Per route</h2>", _table(report.routes, report.target_pct),
             f"<h2>Per {report.by}</h2>" if report.by != "route" else "",
             _table(report.groups, report.target_pct) if report.by != "route" else "",
             "<h2>Runs</h2>", _table(report.runs, report.target_pct)]
    if len(report.failed_runs):
        parts += ["<h2 class='warn'>Runs that failed</h2>", _table(report.failed_runs)]
    parts.append("<h2>Plots</h2>")
    if len(report.corrections):
        parts.append(_img(plots.correction_vs_distance(report.corrections, report.target_pct),
                          "Position-correction % against distance between corrections"))
    parts += _run_plots(report, audit_path)
    parts.append("</body></html>")
    return "\n".join(parts)


def _run_plots(report: Report, audit_path: Path) -> list[str]:
    """Plots of one representative run: the longest, preferring one with slips."""
    runs = read_table(audit_path, "runs", "WHERE status = 'ok'")
    if runs.empty:
        return []
    runs = runs.sort_values(["n_slips", "distance_m"], ascending=False)
    row = runs.iloc[0]
    trace = read_table(audit_path, "traces", "WHERE run_path = ? ORDER BY t", (row["run_path"],))
    out = [_img(plots.margin_along_run(trace, str(row["run_id"])), f"Margin along run {row['run_id']}")]
    summary = json.loads(row["summary_json"] or "{}")
    out.append(_img(plots.slip_episodes(trace, summary.get("episodes", []), str(row["run_id"])),
                    f"Slip/slide episodes of run {row['run_id']}: wheel vs corrected speed"))
    db_path = report.meta.get("db_path")
    if db_path and Path(db_path).exists():
        net = read_network(Path(db_path))
        fp = net.feature_points
        fp = fp[(fp["line_code"] == row["line_code"]) & (fp["track"] == row["track"])]
        out.append(_img(plots.curvature_vs_db(trace, fp, str(row["track"]), str(row["run_id"])),
                        "Curvature trace against the feature-point DB"))
        gis = net.gis[net.gis["line_code"] == row["line_code"]]
        out.append(_img(plots.run_map(gis, trace, str(row["run_id"])), "The run on the GIS grid"))
    return out
