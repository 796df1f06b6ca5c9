"""``trainpos gis …``: the 20 m GIS kilometrage grid."""

from __future__ import annotations

import json
import time
from dataclasses import replace
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING, Any

import typer

from cli.errors import cli_command
from cli.options import NO_VERIFY_HASH, workers_option
from cli.render import (
    check_outputs,
    console,
    emit_rendered,
    emit_text,
    err_console,
    frame_table,
    inputs_of,
    key_value_table,
    print_findings,
    progress,
    safe,
    write_out,
)
from dbtools.gis.verify.config import VerifyConfig
from schemas.errors import EXIT_FINDINGS, UsageError
from schemas.units import format_km

if TYPE_CHECKING:
    import pandas as pd
    from rich.console import Console
    from rich.progress import Progress, TaskID

    from dbtools.gis.verify.result import GisVerification
    from fieldlogs.gisverify.evidence import VerifyReport

app = typer.Typer(
    help="Build the 20 m GIS kilometrage grid from surveys; verify it against GPS runs.", no_args_is_help=True
)


@app.command("grid")
@cli_command
def grid(
    centrelines: Path = typer.Argument(
        ...,
        help="Track centrelines: CSV/XLSX (line_code, track, seq, lon, lat[, height_m][, track_id]) or GeoJSON "
        "LineStrings with properties line_code, track (or track_id).",
    ),
    posts: Path = typer.Option(
        ..., "--posts", help="Kilometre posts CSV/XLSX: line_code, km_m (or 12k345.6), lon, lat[, km_after_m]."
    ),
    out: Path = typer.Option(..., "--out", "-o", help="Output grid in the gis source format (e.g. src/gis.csv)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output (and km_breaks.csv beside it)."),
) -> None:
    """Resample surveyed centrelines every 20 m of kilometrage, km from the kilometre posts.

    Posts are projected onto every track; km is piecewise linear through them (slope 1
    beyond the first/last post). A post's km_after_m is a kilometrage break; breaks are
    written to km_breaks.csv beside the output, which db build reads.

    Centrelines with a track_id (crossovers, connecting and turnout curves: tracks along no
    line km) get a point every 20 m of their own length and at their end, written to
    track_points.csv beside the output; km where their line_code's posts lie near them.

    Example: trainpos gis grid survey/centrelines.csv --posts survey/kmposts.csv --out src/gis.csv
    """
    import pandas as pd

    from dbtools.gis.io import grid_files

    written = grid_files(centrelines, posts, out, force=force)
    out_c = console()
    if written.warnings:
        print_findings(written.warnings, console=out_c, title="Warnings")
    rows: list[tuple[str, object]] = [("file", str(written.path))]
    if written.km_breaks_path is not None:
        rows.append(("km_breaks", f"{written.km_breaks_path} ({len(written.result.km_breaks)} break(s))"))
    if written.removed_stale is not None:
        rows.append(("removed", f"{written.removed_stale} (no breaks any more)"))
    if written.track_points_path is not None:
        n_points = len(written.result.track_points)
        rows.append(("track_points", f"{written.track_points_path} ({n_points} point(s))"))
    rows.append(("points", len(written.result.gis)))
    out_c.print(key_value_table(rows, title="GIS grid"))
    tracks = pd.DataFrame(
        [
            {
                "line_code": t.line_code,
                "track": t.track,
                "points": t.points,
                "first km": format_km(t.km_first_m),
                "last km": format_km(t.km_last_m),
                "length_m": f"{t.length_m:.1f}",
                "posts": t.posts_used,
                "post_offset_m": f"{t.post_offset_m:+.2f}",
                "breaks": t.breaks,
                "reversed": "yes" if t.reversed else "",
            }
            for t in written.result.tracks
        ]
    )
    out_c.print(frame_table(tracks, title="Tracks"))
    if written.result.own_tracks:
        own = pd.DataFrame(
            [
                {
                    "track_id": t.track_id,
                    "points": t.points,
                    "length_m": f"{t.length_m:.2f}",
                    "line_code": t.line_code or "",
                    "km posts": t.posts_used,
                }
                for t in written.result.own_tracks
            ]
        )
        out_c.print(frame_table(own, title="Tracks along no line km (track_points)"))


class VerifyFmt(StrEnum):
    table = "table"
    json = "json"
    html = "html"
    geojson = "geojson"


class _Bar:
    """The library's ``progress(done, total, run)`` callback as a Rich bar with runs/s,
    shown from the first report on (not while the DB is read or runs are searched)."""

    def __init__(self, bar: Progress) -> None:
        self.bar = bar
        self.task: TaskID | None = None
        self.started = time.perf_counter()

    def __call__(self, done: int, total: int, _run: str) -> None:
        if self.task is None:
            self.bar.start()
            self.task = self.bar.add_task("replaying runs", total=total, rate="")
        dt = time.perf_counter() - self.started
        self.bar.update(self.task, completed=done, total=total, rate=f"{done / dt:.2f} runs/s" if dt > 0 else "")


def _km_range(a: float, b: float) -> str:
    return f"{format_km(a, 0)}–{format_km(b, 0)}"


def render_verification(report: VerifyReport, c: Console) -> None:
    """Terminal tables of ``gis verify``: summary, then coverage, defects and along-track
    defects per track (``track_id`` first) — of the line grid, and of the tracks off a line
    (``track_points``, positions in metres along the track) where the DB has them."""
    v = report.verification
    ev = report.evidence
    tp = report.track_points
    rows: list[tuple[str, object]] = [
        ("DB", f"{report.db} (version {report.db_version or '—'})"),
        ("runs", len(report.runs)),
        ("GPS fixes", f"{ev.get('gps_fixes', 0):,} ({ev.get('trusted', 0):,} trusted)"),
        (
            "left out",
            f"{ev.get('no_position', 0):,} track unknown or position undetermined, "
            f"{ev.get('track_conflict', 0):,} GPS decision ≠ pipeline track, "
            f"{v.counts.get('fixes_far', 0):,} beyond {v.config.max_offset_m:g} m",
        ),
        ("fixes used", f"{v.counts.get('fixes_matched', 0):,}"),
        ("cells", _statuses(v)),
    ]
    r = v.km_residual
    if r.get("n"):
        rows.append(("along-track residual", f"median {r['median_m']:+.2f} m, sd {r['sd_m']} m (n {r['n']:,})"))
    rows.append(("defects", len(v.defects)))
    for name, sc in v.scan.items():
        if sc.get("windows_tested"):
            rows.append(
                (
                    f"scan ({name.replace('_', '-')})",
                    f"{sc['windows_tested']:,} windows tested, {sc['windows_selected']} selected",
                )
            )
    if len(v.km_defects):
        rows.append(("along-track defects", len(v.km_defects)))
    if tp is not None:
        rows.append(("tracks off a line", f"{tp.counts.get('fixes_matched', 0):,} fixes used, cells {_statuses(tp)}"))
        rows.append(("their defects", len(tp.defects)))
    c.print(key_value_table(rows, title="GIS verification"))
    _track_tables(v, c, "km", "")
    if tp is not None:
        _track_tables(tp, c, "pos m", " — tracks off a line (track_points)")


def _statuses(v: GisVerification) -> str:
    return ", ".join(f"{n} {s}" for s, n in v.cells["status"].value_counts().sort_index().items()) or "—"


def _span(frame: pd.DataFrame, along: str) -> list[str]:
    """The rows' stretch: a km range on a line, metres along the track off a line."""
    if along == "km":
        return [_km_range(a, b) for a, b in zip(frame["km_from_m"], frame["km_to_m"], strict=True)]
    return [f"{a:.0f}–{b:.0f}" for a, b in zip(frame["pos_from_m"], frame["pos_to_m"], strict=True)]


def _names(frame: pd.DataFrame) -> dict[str, pd.Series]:
    """The key and display columns: track_id, then the line and track names (empty off a line)."""
    return {
        "track_id": frame["track_id"],
        "line": frame["line_code"].fillna(""),
        "track": frame["track"].fillna(""),
    }


def _track_tables(v: GisVerification, c: Console, along: str, title: str) -> None:
    """Coverage, defects and along-track defects of one verification, keyed by track_id."""
    import pandas as pd

    cov = v.coverage
    c.print(
        frame_table(
            pd.DataFrame(
                {
                    **_names(cov),
                    "km": [f"{k:.2f}" for k in cov["length_km"]],
                    "verified": _shares(cov["verified_km"], cov["verified_share"]),
                    "unverified": _shares(cov["unverified_km"], cov["unverified_share"]),
                    "defect": _shares(cov["defect_km"], cov["defect_share"]),
                    "defects": cov["defects"],
                    "runs": cov["runs"],
                    "fixes": cov["fixes"],
                }
            ),
            title=f"Coverage (km, share of the track){title}",
        )
    )
    if len(v.defects):
        d = v.defects
        shown = pd.DataFrame(
            {
                "#": d["defect_id"],
                **_names(d),
                along: _span(d, along),
                "shift m": [f"{x:+.2f}" for x in d["shift_m"]],
                "spread m": [f"{x:.2f}" for x in d["spread_m"]],
                "runs": d["runs"],
                "fixes": d["fixes"],
                "p": [f"{x:.0e}" for x in d["p_value"]],
                "moved": d["points_moved"],
            }
        )
        side = "increasing km" if along == "km" else "the track's begin → end"
        c.print(frame_table(shown, title=f"Defects{title} (shift + = the track lies left of the GIS in {side})"))
    if len(v.km_defects):
        k = v.km_defects
        km_shown = pd.DataFrame(
            {
                **_names(k),
                along: _span(k, along),
                "residual m": [f"{x:+.2f}" for x in k["residual_m"]],
                "se m": [f"{x:.2f}" for x in k["se_m"]],
                "run-epochs": k["run_epochs"],
                "q": [f"{x:.0e}" for x in k["q_value"]],
            }
        )
        c.print(frame_table(km_shown, title=f"Along-track defects{title} (residual = GIS km − pipeline km)"))


def _shares(km: pd.Series, share: pd.Series) -> list[str]:
    return [f"{k:.2f} {100 * s:.0f}%" if s == s else f"{k:.2f}" for k, s in zip(km, share, strict=True)]


_VERIFY = VerifyConfig()
"""The defaults of the options below ([gis_verify] of the configuration tree)."""


@app.command("verify")
@cli_command
def verify(
    db: Path = typer.Argument(..., help="Onboard DB under test (.sqlite)."),
    runs: list[Path] = typer.Argument(..., help="Run folders, or folders to search for runs (run.json)."),
    fmt: VerifyFmt = typer.Option(
        VerifyFmt.table, "--format", help="table, json, html or geojson (html and geojson need --out)."
    ),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write the report to this file instead of stdout."),
    propose: Path | None = typer.Option(
        None, "--propose", help="Write a corrected source set here (defect cells' GIS points moved)."
    ),
    force: bool = typer.Option(False, "--force", help="Replace an existing --propose folder or --out file."),
    config: Path | None = typer.Option(
        None, "--config", help="Settings (TOML): the pipeline's sections and [gis_verify] (options below override it)."
    ),
    alpha: float | None = typer.Option(
        None, "--alpha", help=f"Significance after the multiple-testing correction (default {_VERIFY.alpha:g})."
    ),
    bonferroni: bool = typer.Option(False, "--bonferroni", help="Bonferroni instead of Benjamini–Hochberg over cells."),
    min_shift: float | None = typer.Option(
        None, "--min-shift", help=f"Smallest offset worth correcting [m] (default {_VERIFY.min_shift_m:g})."
    ),
    min_runs: int | None = typer.Option(
        None, "--min-runs", help=f"Fewer runs through a cell or window → unverified (default {_VERIFY.min_runs})."
    ),
    min_fixes: int | None = typer.Option(
        None, "--min-fixes", help=f"Fewer fixes in a cell → unverified (default {_VERIFY.min_fixes})."
    ),
    tolerance: float | None = typer.Option(
        None,
        "--tolerance",
        help=f"Verified only if the 95 % interval is within ±this [m] (default {_VERIFY.tolerance_m:g}).",
    ),
    scan: bool | None = typer.Option(
        None, "--scan/--no-scan", help="Pool neighbouring cells into 100–500 m windows (default: on)."
    ),
    max_km_margin: float | None = typer.Option(
        None,
        "--max-km-margin",
        help="Pipeline margin up to which its km is the along-track reference [m] "
        f"(default {_VERIFY.max_km_margin_m:g}).",
    ),
    workers: int | None = workers_option(),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Verify the 20 m GIS grid against the trusted GPS fixes of recorded runs.

    Every run is replayed through the positioning pipeline on DB; trusted fixes on a track
    known from balises or the GPS up/down decision (never guessed), or on a network from
    the track determined by the hypothesis engine, are map-matched to that track (tracks off
    a line: to their track_points grid). Per 20 m cell the runs' mean lateral offsets are t-tested against 0 (the run is
    the unit, the spread is at least the track's pooled one), Benjamini–Hochberg over all
    cells. The scan pools neighbouring cells: over windows of 100–500 m each run's offset
    is compared with its own offset either side (removing its slow GPS error), the runs'
    contrasts are t-tested (variance moderated per window length), Bonferroni over every
    window of every track; the same scan runs on the along-track residual (GIS km −
    pipeline km). A defect needs |shift| ≥ --min-shift. Cells with little evidence are
    unverified, never good. Defaults of the options come from [gis_verify] (trainpos
    config show --section gis_verify); --config sets them, an option overrides.

    JSON (--format json): {"db", "db_version", "evidence", "runs", "config", "counts",
    "km_residual", "coverage": [per line/track], "defects": [...], "proposal": [moved
    points], "km_defects": [along-track stretches], "scan": {"lateral", "along_track"},
    "cells": [every cell with at least one fix], "track_points": {the same keys from "config"
    on, for the tracks off a line — station tracks, crossovers — with pos_from_m, pos_to_m,
    pos_m (metres along the track from its begin) in the place of km; only for a DB with
    track_points}}. Every row of coverage, defects, proposal, km_defects and cells is keyed
    by track_id (a line's cells: the declared track holding them, else the implied
    LINE:TRACK); line_code and track are the track's names, empty for a track off every line.
    The table, html and geojson outputs and --propose cover the tracks off a line too.

    Exit codes: 0 no defect, 1 defects found, 2 unreadable DB/run or bad usage,
    3 --propose/--out exists (use --force).

    Example: trainpos gis verify net.sqlite logs/ --format html --out gis.html --propose src-fixed/
    """
    from fieldlogs.config import load_tree
    from fieldlogs.gisverify.evidence import verify_runs

    inputs = inputs_of(db, runs, config)
    _check_targets(fmt, out, propose, force, inputs)
    tree = load_tree(config)
    overrides: dict[str, Any] = {
        "alpha": alpha,
        "correction": "bonferroni" if bonferroni else None,
        "min_shift_m": min_shift,
        "min_runs": min_runs,
        "min_fixes": min_fixes,
        "tolerance_m": tolerance,
        "scan": scan,
        "max_km_margin_m": max_km_margin,
    }
    cfg = replace(tree.gis_verify, **{k: v for k, v in overrides.items() if v is not None})
    bar = _Bar(progress(err_console()))
    try:
        report = verify_runs(db, runs, pipeline=tree.pipeline, config=cfg, workers=workers, progress=bar)
    finally:
        if bar.task is not None:
            bar.bar.stop()
    if propose is not None:
        _write_proposal(report, propose, force, inputs)
    _emit_report(report, fmt, out, force, inputs)
    if report.verification.has_defects or (report.track_points is not None and report.track_points.has_defects):
        raise typer.Exit(EXIT_FINDINGS)


def _check_targets(fmt: VerifyFmt, out: Path | None, propose: Path | None, force: bool, inputs: list[Path]) -> None:
    """Usage and output-rule checks of ``gis verify`` before any run is replayed."""
    if fmt in (VerifyFmt.html, VerifyFmt.geojson) and out is None:
        raise UsageError(f"--format {fmt.value} needs --out FILE")
    check_outputs(files=[out], folders=[propose], force=force, inputs=inputs)


def _write_proposal(report: VerifyReport, propose: Path, force: bool, inputs: list[Path]) -> None:
    from dbtools.gis.verify.proposal import proposed_network
    from dbtools.sources import write_source_set

    v = report.verification
    tp = report.track_points
    write_source_set(proposed_network(report.network, v, tp), propose, force=force, inputs=inputs)
    moved_tp = len(tp.proposal) if tp is not None else 0
    moved = len(v.proposal) + moved_tp
    err_console().print(
        f"proposed source set written to {propose} ({len(v.proposal)} GIS point(s) moved"
        + (f", {moved_tp} track point(s) moved)" if tp is not None else ")")
        + ("; build it with: trainpos db build " + str(propose) + " --out NEW.sqlite" if moved else ""),
        highlight=False,
    )


def _emit_report(report: VerifyReport, fmt: VerifyFmt, out: Path | None, force: bool, inputs: list[Path]) -> None:
    """The report as HTML (to ``out``), JSON or a table (to ``out`` or stdout)."""

    if fmt == VerifyFmt.html:
        from fieldlogs.gisverify.page import render_html

        assert out is not None
        write_out(out, render_html(report), force=force, inputs=inputs)
        console().print(f"HTML report written to {safe(out)}")
    elif fmt == VerifyFmt.geojson:  # defects, cells (residuals) and proposed moves for QGIS
        from dbtools.interchange.geojson import verification_geojson, write_geojson

        assert out is not None
        gj = verification_geojson(report.network, report.verification, report.track_points)
        write_geojson(out, gj, force=force, inputs=inputs)
        console().print(f"GeoJSON written to {safe(out)}")
    elif fmt == VerifyFmt.json:
        text = json.dumps(report.to_dict(), ensure_ascii=False, indent=2, default=str) + "\n"
        emit_text(out, text, force=force, inputs=inputs)
    else:
        emit_rendered(out, lambda c: render_verification(report, c), force=force, inputs=inputs, width=160)
