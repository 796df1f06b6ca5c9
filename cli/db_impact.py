"""``trainpos db impact`` and the impact report ``db release --impact`` stores: what a new DB
version changes on recorded runs, per route and run (registered on the ``db`` group by
:mod:`cli.db`).

JSON shape (``--format json``): :meth:`fieldlogs.impact.report.ImpactReport.to_dict`.
"""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from cli.errors import cli_command
from cli.options import NO_VERIFY_HASH, workers_option
from cli.render import console, key_value_table, rich_table, safe
from schemas.errors import UsageError
from schemas.registry import REGISTRY_FILE

if TYPE_CHECKING:
    from rich.console import Console
    from rich.table import Table as RichTable

    from dbtools.release import ImpactAttachment
    from fieldlogs.impact.report import ImpactReport


class ImpactFmt(StrEnum):
    table = "table"
    json = "json"
    html = "html"


@cli_command
def impact(
    old: Path = typer.Argument(..., help="Old onboard DB file (.sqlite), e.g. the version in service."),
    new: Path = typer.Argument(..., help="New onboard DB file (.sqlite), the candidate release."),
    runs: list[Path] = typer.Argument(..., help="Run folders, or folders to search for runs (run.json)."),
    fmt: ImpactFmt = typer.Option(ImpactFmt.table, "--format", help="table, json or html (html needs --out)."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write the report to this file instead of stdout."),
    plan: Path | None = typer.Option(
        None, "--plan", help="Possession plan (CSV/XLSX): road-rail runs are checked against it on both versions."
    ),
    workers: int | None = workers_option(),
    config: Path | None = typer.Option(
        None, "--config", help="Settings (TOML): the pipeline's sections, [possession]."
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Replay runs against two DB versions and show what the new one changes, before `db release`.

    Each run is read once and replayed through the positioning pipeline on OLD and on NEW
    (the same replayer as `audit`). Per route (line, track, direction) and per run, old →
    new: balise and feature-point corrections (count, mean/max position-correction %),
    feature corrections refused and their diagnostics, balise anomalies, fail-safes,
    possession alarms (road-rail runs, with --plan) and the largest margin; and every
    correction whose amount changed (e.g. at a balise whose km moved).

    JSON (--format json): {"old": {path, db_version, content_hash}, "new": {…}, "plan",
    "same_content", "totals": {runs, runs_changed, runs_failed: {old, new},
    corrections_changed}, "routes": [{track_id, line_code, track, direction, runs, replayed, old,
    new, delta, refusals: {old, new}}], "runs": [{run, run_id, vehicle_id, vehicle_kind, track_id, line_code, track,
    direction, old, new, delta, refusals, alarms, errors, changed_corrections}]}; the
    figures of old/new/delta: n_balise, balise_mean_pct, balise_max_pct, n_feature,
    feature_mean_pct, feature_max_pct, n_refused, n_anomalies, n_failsafe, n_alarms,
    max_margin_m.

    Exit 0 (a report, whatever changes); 2 if a DB, the plan or the runs cannot be read;
    3 if --out exists (use --force) or would replace an input.

    Example: trainpos db impact net-2026.10.sqlite net-2026.11.sqlite logs/ --format html --out impact.html
    """
    from cli.render import check_outputs, inputs_of
    from fieldlogs.config import load_tree

    if fmt == ImpactFmt.html and out is None:
        raise UsageError("--format html needs --out FILE")
    inputs = inputs_of(old, new, runs, plan, config)
    check_outputs(files=[out], force=force, inputs=inputs)
    report = _impact_report(old, new, runs, plan, load_tree(config), workers)
    _emit_impact(report, fmt, out, force, inputs)


def _impact_report(
    old: Path, new: Path, runs: list[Path], plan: Path | None, tree: object, workers: int | None
) -> ImpactReport:
    """The impact report, with a progress bar on stderr while the runs are replayed."""
    from cli.gis import _Bar
    from cli.render import err_console, progress
    from fieldlogs.impact.runner import impact_runs

    bar = _Bar(progress(err_console()))
    try:
        return impact_runs(old, new, runs, plan=plan, tree=tree, workers=workers, progress=bar)
    finally:
        if bar.task is not None:
            bar.bar.stop()


def _emit_impact(report: ImpactReport, fmt: ImpactFmt, out: Path | None, force: bool, inputs: list[Path]) -> None:
    import json

    from cli.render import emit_rendered, emit_text

    if fmt == ImpactFmt.html:
        from fieldlogs.impact.page import render_html

        emit_text(out, render_html(report), force=force, inputs=inputs)
    elif fmt == ImpactFmt.json:
        text = json.dumps(report.to_dict(), ensure_ascii=False, indent=2, default=str) + "\n"
        emit_text(out, text, force=force, inputs=inputs)
    else:
        emit_rendered(out, lambda c: _print_impact(report, c), force=force, inputs=inputs)
    if out is not None:
        console().print(f"impact report written to {safe(out)}")


def _num_text(v: object) -> str:
    if v is None:
        return "—"
    return f"{v:.3f}" if isinstance(v, float) else str(v)


def _route_table(r: dict[str, Any]) -> RichTable:
    """One route: every figure old, new and the change."""
    from fieldlogs.impact.report import FIGURES

    names = " ".join(str(r[k]) for k in ("line_code", "track") if r[k] not in (None, "—"))
    where = f"{r['track_id']} ({names})" if names and names != str(r["track_id"]) else str(r["track_id"])
    t = rich_table(title=f"{where} {r['direction']}: {r['runs']} run(s)")
    for c in ("figure", "old", "new", "change"):
        t.add_column(c, justify="left" if c == "figure" else "right")
    for k, label in FIGURES.items():
        change = r["delta"].get(k)
        shown = "" if change in (None, 0, 0.0) else ("+" if float(change) > 0 else "") + _num_text(change)
        t.add_row(label, _num_text(r["old"].get(k)), _num_text(r["new"].get(k)), shown)
    refused = r["refusals"]
    for diag in sorted(set(refused["old"]) | set(refused["new"])):
        a, b = refused["old"].get(diag, 0), refused["new"].get(diag, 0)
        t.add_row(f"  refused: {diag}", str(a), str(b), "" if a == b else f"{b - a:+d}")
    return t


def _runs_table(runs: list[dict[str, Any]]) -> RichTable:
    """The runs that change: the change of each figure (new − old)."""
    from fieldlogs.impact.report import FIGURES

    t = rich_table(title="Runs that change (new − old)")
    t.add_column("run")
    for label in FIGURES.values():
        t.add_column(label, justify="right", overflow="fold")
    t.add_column("corrections changed", justify="right")
    for r in runs:
        cells = [_num_text(r["delta"].get(k)) for k in FIGURES]
        t.add_row(str(r["run_id"] or r["run"]), *cells, str(len(r["changed_corrections"])))
    return t


def _print_impact(report: ImpactReport, out: Console) -> None:
    d = report.to_dict()
    tot = d["totals"]
    out.print(
        key_value_table(
            [
                ("old", f"{d['old']['path']} (version {d['old']['db_version']})"),
                ("new", f"{d['new']['path']} (version {d['new']['db_version']})"),
                ("runs", tot["runs"]),
                ("runs changed", tot["runs_changed"]),
                ("corrections changed", tot["corrections_changed"]),
                ("runs not replayed", f"old {tot['runs_failed']['old']}, new {tot['runs_failed']['new']}"),
            ],
            title="db impact",
        )
    )
    for route in d["routes"]:
        out.print(_route_table(route))
    changed = [r for r in d["runs"] if r["changed_corrections"] or any(v not in (None, 0) for v in r["delta"].values())]
    if changed:
        out.print(_runs_table(changed))
    for r in changed:
        for c in r["changed_corrections"][:10]:
            out.print(
                f"• {r['run_id']}: {c['type']} {c['row']} at t {c['t']:.1f} s: "
                f"{_num_text(c['old_m'])} → {_num_text(c['new_m'])} m (change {_num_text(c['delta_m'])} m)",
                markup=False,
            )
    for r in d["runs"]:
        for side in ("old", "new"):
            if r["errors"][side]:
                out.print(f"• {r['run']}: {side} version cannot replay it: {r['errors'][side]}", markup=False)


def _impact_attachment(
    file: Path,
    registry: Path,
    runs: list[Path] | None,
    against: Path | None,
    plan: Path | None,
    config: Path | None,
    workers: int | None,
) -> ImpactAttachment | None:
    """``db release --impact``: the impact report of ``file`` against ``against`` or the
    registry's latest release, as the attachment :func:`release_db` stores."""
    import json

    from dbtools.release import ImpactAttachment, list_releases
    from fieldlogs.config import load_tree

    if not runs:
        if against is not None or plan is not None:
            raise UsageError("--impact-against and --plan need --impact RUNS")
        return None
    if against is None:
        if not (registry / REGISTRY_FILE).exists() or not list_releases(registry):
            raise UsageError("--impact needs a release in the registry to compare with, or --impact-against OLD.sqlite")
        against = registry / list_releases(registry)[-1].file
    report = _impact_report(against, file, runs, plan, load_tree(config), workers)
    data = report.to_dict()
    return ImpactAttachment(
        report_json=(json.dumps(data, ensure_ascii=False, indent=2, default=str) + "\n").encode("utf-8"),
        against_version=data["old"]["db_version"],
        against_content_hash=data["old"]["content_hash"],
        runs=data["totals"]["runs"],
        runs_changed=data["totals"]["runs_changed"],
    )
