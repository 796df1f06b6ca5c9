"""``trainpos survey``: balises, feature points, wheels and the GIS grid surveyed from many runs."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from cli.errors import cli_command
from cli.gis import _Bar
from cli.options import DASK_SCHEDULER, NO_VERIFY_HASH, workers_option
from cli.render import (
    check_outputs,
    console,
    emit_rendered,
    emit_text,
    err_console,
    frame_table,
    inputs_of,
    key_value_table,
    progress,
    safe,
    write_out,
)
from schemas.errors import EXIT_FINDINGS, UsageError
from schemas.units import format_km

if TYPE_CHECKING:
    import pandas as pd
    from rich.console import Console

    from fieldlogs.survey.result import SurveyReport


class Fmt(StrEnum):
    table = "table"
    json = "json"
    html = "html"
    geojson = "geojson"


def _km(v: object) -> str:
    return format_km(float(v), 1) if isinstance(v, int | float) and v == v else ""


def _num(v: object, fmt: str) -> str:
    return format(float(v), fmt) if isinstance(v, int | float) and v == v else ""


def _balise_table(rep: SurveyReport) -> pd.DataFrame:
    import pandas as pd

    b = rep.balises[rep.balises["status"].isin(["moved", "missed"])]
    return pd.DataFrame(
        {
            "balise": b["balise_id"],
            "kind": b["kind"],
            "track_id": b["track_id"],
            "line": b["line_code"],
            "track": b["track"],
            "km (DB)": [_km(v) for v in b["km_db_m"]],
            "status": b["status"],
            "passes": b["passes"],
            "reads": b["reads"],
            "residual m": [_num(v, "+.2f") for v in b["residual_m"]],
            "± 95 %": [_num(v, ".2f") for v in b["ci95_m"]],
            "reason": b["reason"],
        }
    )


def _feature_table(rep: SurveyReport) -> pd.DataFrame:
    import pandas as pd

    f = rep.features[~rep.features["status"].isin(["ok", "unverified"])]
    return pd.DataFrame(
        {
            "feature": f["feature_id"].fillna(f["curve_id"]),
            "track_id": f["track_id"],
            "line": f["line_code"],
            "track": f["track"],
            "status": f["status"],
            "passes": f["passes"],
            "exit km (DB)": [_km(v) for v in f["exit_km_db_m"]],
            "exit km (runs)": [_km(v) for v in f["exit_km_m"]],
            "R (DB)": [_num(v, ".0f") for v in f["radius_db_m"]],
            "R (runs)": [_num(v, ".0f") for v in f["radius_m"]],
            "dir": [
                f"{a}/{b}" if isinstance(b, str) else str(a)
                for a, b in zip(f["attribute_db"], f["attribute"], strict=True)
            ],
            "reason": f["reason"],
        }
    )


def _source(d: object, h: object) -> str:
    """A source's diameter ± its 95 % half-width in mm."""
    ok = all(isinstance(v, int | float) and v == v for v in (d, h))
    return f"{float(d):.5f} ±{1000 * float(h):.2f}" if ok else ""  # type: ignore[arg-type]


def _wheel_table(rep: SurveyReport) -> pd.DataFrame:
    import pandas as pd

    w = rep.wheels
    out = {
        "vehicle": w["vehicle_id"],
        "runs": [f"{a}/{b}" for a, b in zip(w["runs_estimated"], w["runs"], strict=True)],
        "run.json m": [_num(v, ".4f") for v in w["configured_m"]],
        "estimated m": [_num(v, ".5f") for v in w["diameter_m"]],
        "± 95 % mm": [_num(1000 * v, ".2f") if v == v else "" for v in w["ci95_m"]],
        "diff %": [_num(100 * v, "+.3f") if v == v else "" for v in w["diff_share"]],
    }
    for name, label in (("balise", "balises m"), ("radar", "radar m"), ("gnss", "GNSS m")):
        out[label] = [_source(d, h) for d, h in zip(w[f"diameter_{name}_m"], w[f"ci95_{name}_m"], strict=True)]
    out["agree"] = ["" if a is None or a != a else ("yes" if a else "NO") for a in w["consistent"]]
    out["trend mm/30 d"] = [_num(v, "+.2f") for v in w["trend_mm_per_30d"]]
    out["status"] = w["status"]
    return pd.DataFrame(out)


def _summary_rows(rep: SurveyReport) -> list[tuple[str, object]]:
    import pandas as pd

    s = rep.summary()
    applied = int(rep.changes["applied"].sum()) if len(rep.changes) else 0
    rows: list[tuple[str, object]] = [
        ("DB", f"{rep.db} (version {rep.db_version or '—'})"),
        ("runs", f"{s['runs']} ({s['run_hours']:.1f} run-hours), {s['failed_runs']} failed"),
        ("balises", ", ".join(f"{v} {k}" for k, v in s["balises"].items()) or "—"),
        ("candidate balises", s["candidates_confirmed"]),
        ("feature points", ", ".join(f"{v} {k}" for k, v in s["features"].items()) or "—"),
        ("wheels", ", ".join(f"{v} {k}" for k, v in s["wheels"].items()) or "—"),
        ("wheel sources disagree", s["wheels_inconsistent"]),
        ("GIS defects", s["gis_defects"] if s["gis_defects"] is not None else f"— ({rep.gis_note})"),
        ("proposed changes", f"{applied} of {s['changes']}"),
    ]
    for what, frame in (("balises", rep.balises), ("feature points", rep.features)):
        why = frame.loc[frame["status"] == "unverified", "reason"] if len(frame) else pd.Series(dtype=str)
        if len(why):
            counts = why.str.split(" (", regex=False).str[0].value_counts()
            rows.append((f"unverified {what}", "; ".join(f"{v}× {k}" for k, v in counts.items())))
    return rows


def render_survey(rep: SurveyReport, c: Console) -> None:
    """Terminal tables: summary (unverified items counted by reason), moved and missed
    balises, missed passes, candidates, features moved/new/not seen, wheels, GIS, changes
    (every row of every table is in --format json)."""
    c.print(key_value_table(_summary_rows(rep), title="Survey"))
    tables: list[tuple[bool, pd.DataFrame, str]] = [
        (
            bool(rep.balises["status"].isin(["moved", "missed"]).any()),
            _balise_table(rep),
            "Balises moved or missed (residual = DB km − runs' km)",
        ),
        (len(rep.missed) > 0, rep.missed, "Inspection: passes over missed balises"),
        (len(rep.candidates) > 0, rep.candidates.round(2), "Telegrams the DB does not know"),
        (
            bool(len(rep.features) and (~rep.features["status"].isin(["ok", "unverified"])).any()),
            _feature_table(rep),
            "Feature points moved, new or not seen",
        ),
        (len(rep.wheels) > 0, _wheel_table(rep), "Wheel diameters"),
        (len(rep.changes) > 0, rep.changes.drop(columns=["line_code", "track"]), "Changes --propose writes"),
    ]
    if rep.gis is not None and len(rep.gis.defects):
        cols = ["defect_id", "track_id", "line_code", "track", "km_from_m", "km_to_m", "shift_m", "runs"]
        tables.insert(-1, (True, rep.gis.defects[cols].round(2), "GIS defects"))
    if rep.gis_tracks is not None and len(rep.gis_tracks.defects):
        cols = ["defect_id", "track_id", "line_code", "track", "pos_from_m", "pos_to_m", "shift_m", "runs"]
        tables.insert(-1, (True, rep.gis_tracks.defects[cols].round(2), "GIS defects of tracks off a line (pos m)"))
    for show, frame, title in tables:
        if show:
            c.print(frame_table(frame, title=title))
    for run, err in rep.failed_runs.itertuples(index=False, name=None):
        err_console().print(
            f"[red]failed:[/] {safe(run)}: {safe(str(err).splitlines()[0] if err else '')}", highlight=False
        )


def _check_targets(fmt: Fmt, out: Path | None, propose: Path | None, force: bool, inputs: list[Path]) -> None:
    if fmt in (Fmt.html, Fmt.geojson) and out is None:
        raise UsageError(f"--format {fmt.value} needs --out FILE")
    check_outputs(files=[out], folders=[propose], force=force, inputs=inputs)


def _emit(rep: SurveyReport, fmt: Fmt, out: Path | None, force: bool, inputs: list[Path]) -> None:

    if fmt == Fmt.html:
        from fieldlogs.survey.page import render_html

        assert out is not None
        write_out(out, render_html(rep), force=force, inputs=inputs)
        console().print(f"HTML report written to {safe(out)}")
    elif fmt == Fmt.geojson:  # balises, curves and GIS defects over the grid, for QGIS
        from dbtools.interchange.geojson import survey_geojson, write_geojson

        assert out is not None
        write_geojson(out, survey_geojson(rep.network, rep), force=force, inputs=inputs)
        console().print(f"GeoJSON written to {safe(out)}")
    elif fmt == Fmt.json:
        text = json.dumps(rep.to_dict(), ensure_ascii=False, indent=2, default=str) + "\n"
        emit_text(out, text, force=force, inputs=inputs)
    else:
        emit_rendered(out, lambda c: render_survey(rep, c), force=force, inputs=inputs)


@cli_command
def survey(
    runs: list[Path] = typer.Argument(..., help="Run folders, or folders to search for runs (run.json)."),
    db: Path = typer.Option(..., "--db", help="Onboard DB under survey (.sqlite)."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table, json, html or geojson (html and geojson need --out)."),
    out: Path | None = typer.Option(None, "--out", "-o", help="Write the report to this file instead of stdout."),
    propose: Path | None = typer.Option(
        None, "--propose", help="Write a corrected source set here (flagged items only) with survey_changes.json/.csv."
    ),
    workers: int | None = workers_option(),
    dask_scheduler: str | None = DASK_SCHEDULER,
    config: Path | None = typer.Option(None, "--config", help="Settings (TOML: [survey] and the pipeline's sections)."),
    force: bool = typer.Option(False, "--force", help="Replace an existing --out file or --propose folder."),
    no_verify_hash: bool = NO_VERIFY_HASH,
) -> None:
    """Survey the DB's balises, feature points and the vehicles' wheels from recorded runs.

    Every run is replayed once through the positioning pipeline (the replayer of audit).
    Balises: passes, reads and the residual DB km − the runs' dead-reckoned km from the
    neighbouring balises on both sides (wheel scale accounted, 95 % interval): ok, moved,
    missed (passed but never read: inspection list with times) or unverified; unknown
    telegrams read by several runs are candidates. Feature points: curves located by their
    lower-limit crossings (the pipeline's 20 % rule) on the runs' curvature κ = ωz/v,
    averaged over runs, against the DB: ok, moved, new (six rows proposed) or not seen.
    Wheels: diameter per run and vehicle from the balise intervals, the radar's wheel
    calibration and GNSS (track-constrained, else D-GPS) along-track positions, each with its
    95 % interval, combined by inverse variance; sources that disagree beyond their intervals
    are flagged; alert beyond [survey] wheel_alert_share. GIS: the gis verify statistics on the same runs. Thresholds
    are in [survey] (trainpos config show --section survey).

    Per network track: every balise, missed pass, candidate, feature and change row carries
    its track_id (the declared track holding it; on a line-only DB the implied LINE:TRACK).
    On a network, runs on tracks off every line (crossovers) are surveyed along their pos_m
    (their curves against track_feature_points, per track_id, pos in the km columns;
    --propose writes track_feature_points rows); the track_feature_points of tracks along
    a line are compared on the line's km and proposed back by pos (each feature row names
    its db_table), and the G balises of balise groups are
    identified by NID_C/NID_BG/N_PIG and listed with their passes and reads (missed when never
    read); one on a track off every line is placed by dead reckoning from the run's position
    before its group (the reference's margin in its interval).

    JSON (--format json): {"db", "db_version", "config", "summary", "runs", "failed_runs",
    "balises", "missed_passes", "candidates", "features", "wheels": {"vehicles", "runs"},
    "gis" (with "track_points": the tracks off a line per track_id, on a DB with track
    points), "gis_note", "changes"}.

    Exit codes: 0 nothing to act on, 1 something flagged (moved or missed balise, confirmed
    candidate, moved/new/not seen feature, wheel alert or disagreeing wheel sources, GIS
    defect, a run that failed),
    2 unreadable DB/run/config or bad usage, 3 --out/--propose exists (use --force).

    Example: trainpos survey logs/ --db net.sqlite --format html --out survey.html --propose src-next/
    """
    from fieldlogs.config import load_tree
    from fieldlogs.survey.propose import Proposal, write_proposal
    from fieldlogs.survey.runner import survey as run_survey

    inputs = inputs_of(runs, db, config)
    _check_targets(fmt, out, propose, force, inputs)
    tree = load_tree(config)
    bar = _Bar(progress(err_console()))
    try:
        rep = run_survey(
            runs,
            db,
            pipeline=tree.pipeline,
            config=tree.survey,
            workers=workers,
            scheduler=dask_scheduler,
            progress=bar,
        )
    finally:
        if bar.task is not None:
            bar.bar.stop()
    if propose is not None:
        assert rep.proposed is not None
        write_proposal(Proposal(rep.proposed, rep.changes), propose, force=force or _empty(propose), inputs=inputs)
        applied = int(rep.changes["applied"].sum()) if len(rep.changes) else 0
        err_console().print(
            f"proposed source set written to {propose} ({applied} change(s), evidence in survey_changes.json)"
            + (f"; build it with: trainpos db build {propose} --out NEW.sqlite" if applied else ""),
            highlight=False,
        )
    _emit(rep, fmt, out, force, inputs)
    if rep.flagged:
        raise typer.Exit(EXIT_FINDINGS)


def _empty(folder: Path) -> bool:
    """An existing empty folder may be replaced without --force."""
    return folder.is_dir() and not any(folder.iterdir())
