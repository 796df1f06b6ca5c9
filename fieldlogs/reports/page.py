"""Self-contained HTML audit report: inline CSS, plots as embedded PNG (``data:`` URIs), no
script and no external resource, so the one file works offline and can be mailed.

Plots: position-correction % against the distance between corrections per route; for one
representative run (the one with most slip/slide episodes, then the longest): the margin
along the run, its slip/slide episodes (wheel against inertial speed), its curvature trace
against the feature-point DB and the run on a map drawn from the GIS grid. The last two
need the onboard DB the audit used (its path is recorded in the audit); without it they
are left out with a note.
"""

from __future__ import annotations

import base64
import html
import json
from datetime import UTC, datetime
from pathlib import Path

import numpy as np
import pandas as pd

from dbtools.database import read_network
from fieldlogs.audit.store import read_table, read_trace
from fieldlogs.reports import plots
from fieldlogs.reports.report import CORRECTION_STATS, OTHER_STATS, ROUTE_KEYS, Report
from schemas.audit import AUDIT_RUNS
from schemas.errors import TrainposError

CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;margin:2em;color:#222;max-width:1400px}
table{border-collapse:collapse;margin:1em 0;font-size:13px}
th,td{border:1px solid #ccc;padding:3px 8px;text-align:right}
th{background:#f0f0f0}td.l,th.l{text-align:left}
.warn{color:#b00;font-weight:bold}.note{color:#666}figure{margin:1.5em 0}img{max-width:100%}.scroll{overflow-x:auto}
"""

CORRECTION_COLUMNS = [*ROUTE_KEYS, *CORRECTION_STATS]
OTHER_COLUMNS = [*ROUTE_KEYS, *OTHER_STATS]


def _img(png: bytes, alt: str) -> str:
    data = base64.b64encode(png).decode()
    return (
        f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{data}">'
        f"<figcaption>{html.escape(alt)}</figcaption></figure>"
    )


def _cell(column: str, v: object, target: float | None) -> str:
    if v is None or (isinstance(v, float) and pd.isna(v)):
        return "<td></td>"
    if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
        return f'<td class="l">{html.escape(str(v))}</td>'
    if isinstance(v, int | np.integer):
        return f"<td>{int(v):,}</td>"
    v = float(v)
    txt = f"{v:,.0f}" if abs(v) >= 100 else f"{v:.3f}"
    warn = target is not None and column.endswith("correction_pct") and v > target
    return f'<td class="warn">{txt}</td>' if warn else f"<td>{txt}</td>"


def _table(frame: pd.DataFrame, target: float | None = None) -> str:
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    rows = [
        "<tr>" + "".join(_cell(c, v, target) for c, v in zip(frame.columns, rec, strict=True)) + "</tr>"
        for rec in frame.itertuples(index=False)
    ]
    return f"<div class='scroll'><table><tr>{head}</tr>{''.join(rows)}</table></div>"


def render_html(report: Report, audit_path: Path) -> str:
    """The whole report as one HTML string."""
    t = report.target_pct
    parts = [
        "<!doctype html><html lang='en'><head><meta charset='utf-8'><title>trainpos audit</title>"
        f"<style>{CSS}</style></head><body>",
        "<h1>Positioning audit</h1>",
        f"<p>Audit <code>{html.escape(str(audit_path))}</code>, onboard DB version "
        f"<b>{html.escape(report.meta.get('db_version', '?'))}</b>, {len(report.runs)} run(s) audited, "
        f"{len(report.failed_runs)} failed; target {t:g} %; generated {datetime.now(UTC):%Y-%m-%d %H:%M} UTC.</p>",
        "<h2>Position correction per route (balise corrections)</h2>",
        "<p class='note'>Position-correction % = |correction| / distance since the previous correction × 100, "
        "over balise corrections; values above the target in red.</p>",
        _table(report.routes[CORRECTION_COLUMNS], t),
        "<h2>Slips, feature points, GPS and alarms per route</h2>",
        _table(report.routes[OTHER_COLUMNS]),
    ]
    if report.by == "vehicle":
        parts += ["<h2>Per vehicle</h2>", _table(report.vehicles, t)]
    parts += ["<h2>Runs</h2>", _table(report.runs.drop(columns=["run_path"]), t)]
    if len(report.failed_runs):
        parts += ["<h2 class='warn'>Runs that failed</h2>", _table(report.failed_runs)]
    parts.append("<h2>Plots</h2>")
    parts.append(
        _img(
            plots.correction_vs_distance(report.corrections, t),
            "Position-correction % against the distance between corrections, per route",
        )
    )
    parts += _run_plots(report, audit_path)
    parts.append("</body></html>")
    return "\n".join(parts)


def _run_plots(report: Report, audit_path: Path) -> list[str]:
    """Plots of one representative run: most slip/slide episodes, then the longest."""
    runs = read_table(audit_path, AUDIT_RUNS.name, where={"status": "ok"})
    if runs.empty:
        return ["<p class='note'>No run was audited without error: no run plots.</p>"]
    row = runs.sort_values(["n_slips", "distance_m", "run_path"], ascending=[False, False, True]).iloc[0]
    run_id = str(row["run_id"])
    trace = read_trace(audit_path, str(row["run_path"]))
    summary = json.loads(row["summary_json"] or "{}")
    out = [
        f"<h3>Run {html.escape(run_id)} ({html.escape(str(row['line_code']))} {html.escape(str(row['track']))}, "
        f"{float(row['distance_m'] or 0) / 1000:.1f} km)</h3>",
        _img(plots.margin_along_run(trace, run_id), f"Margin along run {run_id}"),
        _img(
            plots.slip_episodes(trace, summary.get("episodes", []), run_id),
            f"Slip/slide episodes of run {run_id}: wheel against inertial (corrected) speed",
        ),
    ]
    db_path = report.meta.get("db_path")
    try:
        net = read_network(Path(db_path)) if db_path else None
    except TrainposError as exc:
        net = None
        db_path = f"{db_path} ({exc.message})"
    if net is None:
        out.append(
            f"<p class='note'>Onboard DB {html.escape(str(db_path))} not readable: no curvature or map plot.</p>"
        )
        return out
    fp = net.feature_points
    fp = fp[(fp["line_code"] == row["line_code"]) & (fp["track"] == row["track"])]
    out.append(
        _img(
            plots.curvature_vs_db(trace, fp, str(row["track"]), run_id),
            f"Curvature trace of run {run_id} against the feature-point DB",
        )
    )
    gis = net.gis[net.gis["line_code"] == row["line_code"]]
    out.append(_img(plots.run_map(gis, trace, str(row["track"]), run_id), f"Run {run_id} on the GIS grid"))
    return out
