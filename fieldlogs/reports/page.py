"""Self-contained HTML audit report (:mod:`dbtools.pagekit`: inline CSS, plots as embedded
PNG, no script and no external resource, so the one file works offline and can be mailed).

Plots: position-correction % against the distance between corrections per route; for one
representative run (the one with most slip/slide episodes, then the longest): the margin
along the run, its slip/slide episodes (wheel against inertial speed), its curvature trace
against the feature-point DB and the run on a map drawn from the GIS grid. The last two
need the onboard DB the audit used (its path is recorded in the audit); without it they
are left out with a note.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from dbtools import pagekit as kit
from dbtools.database import read_network
from fieldlogs.audit.store import read_table, read_trace
from fieldlogs.reports import plots
from fieldlogs.reports.report import CORRECTION_STATS, OTHER_STATS, ROUTE_COLUMNS, TRACK_COLUMNS, Report
from schemas.audit import AUDIT_RUNS
from schemas.errors import TrainposError

CORRECTION_COLUMNS = [*ROUTE_COLUMNS, *CORRECTION_STATS]
OTHER_COLUMNS = [*ROUTE_COLUMNS, *OTHER_STATS]


def _cells(target: float | None) -> Callable[[str, Any], kit.Cell]:
    """The kit's cells, position-correction % above the target in red."""

    def cell(column: str, v: Any) -> kit.Cell:
        out = kit.default_cell(column, v)
        number = isinstance(v, float | np.floating) and not isinstance(v, bool) and out.text
        if number and target is not None and column.endswith("correction_pct") and float(v) > target:
            return kit.Cell(out.text, kit.Status.WARN.value)
        return out

    return cell


def _table(frame: pd.DataFrame, target: float | None = None) -> str:
    return kit.frame_table(frame, _cells(target))


def render_html(report: Report, audit_path: Path) -> str:
    """The whole report as one HTML string."""
    t = report.target_pct
    parts = [
        f"<p>Audit {kit.code(audit_path)}, onboard DB version "
        f"<b>{kit.escape(report.meta.get('db_version', '?'))}</b>, {len(report.runs)} run(s) audited, "
        f"{len(report.failed_runs)} failed; target {t:g} %; {kit.generated()}.</p>",
        kit.section(
            "Position correction per route (balise corrections)",
            kit.paragraph(
                "Position-correction % = |correction| / distance since the previous correction × 100, "
                "over balise corrections; values above the target in red.",
                kit.Status.NOTE,
            ),
            _table(report.routes[CORRECTION_COLUMNS], t),
        ),
        kit.section("Slips, feature points, GPS and alarms per route", _table(report.routes[OTHER_COLUMNS])),
    ]
    if report.by == "vehicle":
        parts.append(kit.section("Per vehicle", _table(report.vehicles, t)))
    parts += _path_sections(report)
    parts += _unit_sections(report)
    parts.append(kit.section("Runs", _table(report.runs.drop(columns=["run_path"]), t)))
    if len(report.failed_runs):
        parts.append(kit.section("Runs that failed", _table(report.failed_runs), status=kit.Status.WARN))
    parts.append(kit.heading("Plots"))
    parts.append(
        kit.figure(
            plots.correction_vs_distance(report.corrections, t),
            "Position-correction % against the distance between corrections, per route",
        )
    )
    parts += _run_plots(report, audit_path)
    return kit.page("trainpos audit", *parts, heading_text="Positioning audit", verdict=verdict(report))


def path_text(path: pd.DataFrame) -> str:
    """A run's path of tracks in one line: ``0420-U4 (48 m) → {0420-U3|0420-X1} (28 m) → …``,
    an ambiguous stretch as its candidates in braces."""
    out = []
    for r in path.itertuples(index=False):
        cands = json.loads(str(r.candidates)) if isinstance(r.candidates, str) else []
        name = str(r.track_id) if r.state == "determined" else "{" + "|".join(cands) + "}"
        out.append(f"{name} ({float(str(r.distance_m)):.0f} m)")
    return " → ".join(out)


def network_paths(report: Report) -> pd.DataFrame:
    """run_id, path (text) of the runs whose path has more than one stretch (network runs:
    a run on one line and track has a path of one entry and its route says it all)."""
    rows = [
        {"run_id": g["run_id"].iloc[0], "path": path_text(g)}
        for _, g in report.paths.groupby("run_path", sort=True)
        if len(g) > 1
    ]
    return pd.DataFrame(rows, columns=["run_id", "path"])


def _path_sections(report: Report) -> list[str]:
    """For network runs: each run's route as a path of tracks; then the per-track tables (by
    track_id, line and local name as display) for network runs or ``--by track``."""
    paths = network_paths(report)
    out = []
    if not paths.empty:
        note = kit.paragraph(
            "Each run's route as the tracks it was claimed on, in order, with the distance travelled on each; "
            "{A|B}: ambiguous among candidate tracks A and B (not yet told which way a switch went).",
            kit.Status.NOTE,
        )
        out.append(kit.section("Routes as paths of tracks", note, _table(paths)))
    if paths.empty and report.by != "track":
        return out
    tracks = report.tracks
    out.append(
        kit.section(
            "Position correction per track",
            kit.paragraph(
                "Per track id over the stretches determined on it; line and track are its names (empty off a line).",
                kit.Status.NOTE,
            ),
            _table(tracks[[*TRACK_COLUMNS, *CORRECTION_STATS]], report.target_pct),
        )
    )
    if report.by == "track":
        out.append(
            kit.section(
                "Slips, feature points, GPS and alarms per track", _table(tracks[[*TRACK_COLUMNS, *OTHER_STATS]])
            )
        )
    return out


def unit_spans_text(spans: object) -> str:
    """A run's disagreement spans (JSON ``[[t_from, t_to], …]``) in one line: ``12.3–14.0 s, …``."""
    items = json.loads(spans) if isinstance(spans, str) and spans else []
    return ", ".join(f"{float(a):.1f}–{float(b):.1f} s" for a, b in items)


def units_view(report: Report) -> pd.DataFrame:
    """The runs audited with both units: their comparison, the spans as text."""
    return report.units.assign(
        unit_disagreement_spans=[unit_spans_text(v) for v in report.units["unit_disagreement_spans"]]
    )


def _unit_sections(report: Report) -> list[str]:
    """For runs audited with ``--unit both``: the units' comparison per run."""
    if report.units.empty:
        return []
    n = int((report.units["unit_disagreements"].fillna(0) > 0).sum())
    note = kit.paragraph(
        "Unit F's figures are reported; unit R (the R cab's) replayed the same run. A disagreement: both "
        "claim a km and |km F − km R| exceeds the sum of their margins, or both are determined on different "
        f"tracks. {n} of {len(report.units)} run(s) with a disagreement.",
        kit.Status.WARN if n else kit.Status.NOTE,
    )
    return [kit.section("Units F and R compared", note, _table(units_view(report)))]


def verdict(report: Report) -> kit.Verdict:
    """Passed when every route's mean position-correction % is within the target, no run
    failed and (runs audited with both units) the units agree; else how many routes are above
    it, how many runs failed and in how many the units disagree."""
    t = report.target_pct
    means = report.routes["mean_correction_pct"] if "mean_correction_pct" in report.routes else pd.Series([])
    above = int((means > t).sum())
    n_routes, n_failed = len(report.routes), len(report.failed_runs)
    failed = f"; {n_failed} run(s) failed to audit" if n_failed else ""
    n_split = int((report.units["unit_disagreements"].fillna(0) > 0).sum())
    split = f"; units F and R disagree in {n_split} run(s)" if n_split else ""
    if above:
        text = (
            f"Above target: {above} of {n_routes} route(s) with a mean position correction above {t:g} %"
            f"{failed}{split}."
        )
        return kit.Verdict(text, kit.Status.WARN)
    if n_split:
        text = f"Units disagree: {n_routes} route(s) within the {t:g} % target{failed}{split}."
        return kit.Verdict(text, kit.Status.WARN)
    if n_failed or not n_routes:
        text = f"Incomplete: {n_routes} route(s) within the {t:g} % target{failed or '; no run audited'}."
        return kit.Verdict(text, kit.Status.CAUTION)
    return kit.Verdict(
        f"Passed: all {n_routes} route(s) within the {t:g} % position-correction target (mean), "
        f"{len(report.runs)} run(s) audited.",
        kit.Status.OK,
    )


def _run_plots(report: Report, audit_path: Path) -> list[str]:
    """Plots of one representative run: most slip/slide episodes, then the longest."""
    runs = read_table(audit_path, AUDIT_RUNS.name, where={"status": "ok"})
    if runs.empty:
        return [kit.paragraph("No run was audited without error: no run plots.", kit.Status.NOTE)]
    row = runs.sort_values(["n_slips", "distance_m", "run_path"], ascending=[False, False, True]).iloc[0]
    run_id = str(row["run_id"])
    trace = read_trace(audit_path, str(row["run_path"]))
    summary = json.loads(row["summary_json"] or "{}")
    names = " ".join(str(row[c]) for c in ("line_code", "track") if isinstance(row[c], str) and row[c])
    where = f"track {row['track_id'] or '—'}" + (f" = {names}" if names else "")
    out = [
        kit.heading(f"Run {run_id} ({where}, {float(row['distance_m'] or 0) / 1000:.1f} km)", 3),
        kit.figure(plots.margin_along_run(trace, run_id), f"Margin along run {run_id}"),
        kit.figure(
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
        out.append(kit.paragraph(f"Onboard DB {db_path} not readable: no curvature or map plot.", kit.Status.NOTE))
        return out
    fp = net.feature_points
    fp = fp[(fp["line_code"] == row["line_code"]) & (fp["track"] == row["track"])]
    out.append(
        kit.figure(
            plots.curvature_vs_db(trace, fp, str(row["track"]), run_id),
            f"Curvature trace of run {run_id} against the feature-point DB",
        )
    )
    gis = net.gis[net.gis["line_code"] == row["line_code"]]
    out.append(kit.figure(plots.run_map(gis, trace, str(row["track"]), run_id), f"Run {run_id} on the GIS grid"))
    return out
