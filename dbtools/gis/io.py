"""Files of ``gis grid``: reading centrelines (CSV/XLSX or GeoJSON) and kilometre posts,
writing the grid (and ``km_breaks.csv`` beside it) atomically."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from dbtools.atomic import check_target, publish_mode, temp_sibling
from dbtools.gis.centreline import LABEL_COL, ROW_COL
from dbtools.gis.grid import MAX_POST_OFFSET_M, GridResult, build_grid
from dbtools.tabular import read_raw_table
from schemas.enums import Severity
from schemas.errors import FindingsError, InputError, RefusedError
from schemas.findings import Finding
from schemas.frames import FIRST_DATA_LINE, read_and_check
from schemas.gisinput import CENTRELINE_VERTICES, KM_POSTS
from schemas.network import TRACK_POINTS
from schemas.tables import GIS, KM_BREAKS

GEOJSON_SUFFIXES = (".geojson", ".json")
#: File name ``db build`` reads kilometrage breaks from (beside gis.csv).
KM_BREAKS_FILE = f"{KM_BREAKS.name}.csv"
#: File name ``db build`` reads the grid of the tracks along no line km from (beside gis.csv).
TRACK_POINTS_FILE = f"{TRACK_POINTS.name}.csv"


@dataclass
class InputFrame:
    """A checked input: typed frame (index = position in the input, plus ``_row`` and
    ``_label`` locating each row) and its findings."""

    frame: pd.DataFrame
    findings: list[Finding]
    file: str


def read_centrelines(path: Path) -> InputFrame:
    """Centreline vertices from CSV/XLSX (declared columns) or a GeoJSON FeatureCollection of
    LineStrings with properties ``line_code`` and ``track`` (third coordinate = height)."""
    path = Path(path)
    if path.suffix.lower() in GEOJSON_SUFFIXES:
        raw, labels, findings = _geojson_rows(path)
        co = read_and_check(CENTRELINE_VERTICES, raw, file=str(path))
        for f in co.findings:
            if f.row is not None:
                i = f.row - FIRST_DATA_LINE
                f.message = f"{labels[i]}: {f.message}" if 0 <= i < len(labels) else f.message
                f.row = None
        frame = co.frame
        frame[ROW_COL] = pd.array([None] * len(frame), dtype="Int64")
        frame[LABEL_COL] = pd.array(labels, dtype="string") if labels else pd.array([], dtype="string")
        return InputFrame(frame, findings + co.findings, str(path))
    return _read_tabular(CENTRELINE_VERTICES.name, path)


def read_km_posts(path: Path) -> InputFrame:
    """Kilometre posts from CSV/XLSX (``km_m`` in metres or 12k345.6 notation)."""
    return _read_tabular(KM_POSTS.name, Path(path))


def _read_tabular(name: str, path: Path) -> InputFrame:
    table = CENTRELINE_VERTICES if name == CENTRELINE_VERTICES.name else KM_POSTS
    raw = read_raw_table(path, sheet=name, declared=table)
    co = read_and_check(table, raw, file=str(path))
    frame = co.frame
    frame[ROW_COL] = pd.array(frame.index.to_numpy() + FIRST_DATA_LINE, dtype="Int64")
    return InputFrame(frame, co.findings, str(path))


def _geojson_rows(path: Path) -> tuple[pd.DataFrame, list[str], list[Finding]]:
    """Flatten a FeatureCollection into one text row per vertex (and a label per row)."""
    if not path.exists():
        raise InputError("no such file", path=path)
    try:
        data = json.loads(path.read_text(encoding="utf-8-sig"))
    except UnicodeDecodeError as exc:
        raise InputError(f"not UTF-8 text (byte {exc.start})", path=path) from exc
    except json.JSONDecodeError as exc:
        raise InputError(f"not valid JSON: {exc.msg}", path=path, row=exc.lineno) from exc
    if not isinstance(data, dict) or data.get("type") != "FeatureCollection":
        raise InputError("expected a GeoJSON FeatureCollection of LineStrings", path=path)
    features = data.get("features")
    if not isinstance(features, list):
        raise InputError("GeoJSON FeatureCollection has no 'features' list", path=path)
    rows: list[dict[str, str]] = []
    labels: list[str] = []
    findings: list[Finding] = []
    for k, feat in enumerate(features, 1):
        geom = feat.get("geometry") if isinstance(feat, dict) else None
        props = (feat.get("properties") or {}) if isinstance(feat, dict) else {}
        gtype = geom.get("type") if isinstance(geom, dict) else None
        coords = geom.get("coordinates") if isinstance(geom, dict) else None
        if gtype != "LineString" or not isinstance(coords, list):
            findings.append(
                Finding(
                    "gisinput.geometry",
                    Severity.ERROR,
                    CENTRELINE_VERTICES.name,
                    f"feature {k}: geometry is {gtype or 'missing'}; expected a LineString",
                    file=str(path),
                    value=gtype,
                    limit="LineString",
                )
            )
            continue
        base = {str(key): "" if v is None else str(v) for key, v in props.items() if not isinstance(v, (dict, list))}
        for j, c in enumerate(coords, 1):
            c = c if isinstance(c, list) else [c]
            rows.append(
                {
                    **base,
                    "seq": str(j),
                    "lon": str(c[0]) if len(c) > 0 else "",
                    "lat": str(c[1]) if len(c) > 1 else "",
                    "height_m": str(c[2]) if len(c) > 2 and c[2] is not None else "",
                }
            )
            labels.append(f"feature {k}, vertex {j}")
    columns = sorted({c for r in rows for c in r}, key=lambda c: (c not in CENTRELINE_VERTICES.column_names, c))
    if not rows:
        columns = CENTRELINE_VERTICES.column_names
    raw = pd.DataFrame(rows, columns=columns, dtype=object).fillna("")
    return raw, labels, findings


@dataclass
class GridFiles:
    """What ``gis grid`` wrote."""

    path: Path
    km_breaks_path: Path | None
    """km_breaks.csv written beside the grid (None when the grid has no breaks)."""
    result: GridResult
    removed_stale: Path | None = None
    """A km_breaks.csv from an earlier run that no longer applies (removed with --force)."""
    warnings: list[Finding] = field(default_factory=list)
    track_points_path: Path | None = None
    """track_points.csv written beside the grid (None when no centreline has a track_id)."""


def grid_files(
    centrelines: Path,
    posts: Path,
    out: Path,
    *,
    force: bool = False,
    max_post_offset_m: float = MAX_POST_OFFSET_M,
) -> GridFiles:
    """Read, check, build and write: ``out`` in the ``gis`` source format and, if the grid
    has kilometrage breaks, ``km_breaks.csv`` beside it, and if centrelines have a
    ``track_id``, their grid as ``track_points.csv`` beside it. Nothing is written on an error."""
    centrelines, posts, out = Path(centrelines), Path(posts), Path(out)
    breaks_path = out.parent / KM_BREAKS_FILE
    points_path = out.parent / TRACK_POINTS_FILE
    _refuse_overwrite(centrelines, posts, out, breaks_path, force)
    _refuse_overwrite(centrelines, posts, out, points_path, force)
    cl = read_centrelines(centrelines)
    kp = read_km_posts(posts)
    findings = cl.findings + kp.findings
    if any(f.severity == Severity.ERROR for f in findings):
        n = sum(f.severity == Severity.ERROR for f in findings)
        raise FindingsError(f"{n} error(s) in the survey inputs; nothing was written", findings, path=centrelines)
    result = build_grid(
        cl.frame,
        kp.frame,
        centrelines_file=cl.file,
        posts_file=kp.file,
        max_post_offset_m=max_post_offset_m,
    )
    findings += result.findings
    errors = [f for f in findings if f.severity == Severity.ERROR]
    if errors:
        raise FindingsError(
            f"{len(errors)} error(s) building the grid; nothing was written", findings, path=centrelines
        )
    has_breaks, has_points = not result.km_breaks.empty, not result.track_points.empty
    for has, path in ((has_breaks, breaks_path), (has_points, points_path)):
        if has and path.exists() and not force:
            raise RefusedError(f"{path.name} exists beside the output; use --force to replace it", path=path)

    out.parent.mkdir(parents=True, exist_ok=True)
    files = {out: result.gis[GIS.column_names]}
    if has_breaks:
        files[breaks_path] = result.km_breaks[KM_BREAKS.column_names]
    if has_points:
        files[points_path] = result.track_points[TRACK_POINTS.column_names]
    _write_atomically(files)
    removed = None if has_breaks else _stale_breaks(breaks_path, force, findings)
    if not has_points and points_path.exists():  # never removed: it may come from an import
        findings.append(
            Finding(
                "gisinput.other_track_points",
                Severity.WARNING,
                TRACK_POINTS.name,
                f"no centreline has a track_id, so this grid has no track points; {TRACK_POINTS_FILE} beside "
                "it is not from this run and was kept (db build will read it)",
                file=str(points_path),
            )
        )
    return GridFiles(
        out,
        breaks_path if has_breaks else None,
        result,
        removed_stale=removed,
        warnings=[f for f in findings if f.severity != Severity.ERROR],
        track_points_path=points_path if has_points else None,
    )


def _refuse_overwrite(centrelines: Path, posts: Path, out: Path, beside: Path, force: bool) -> None:
    """RefusedError when the output (or a file ``beside`` it: km_breaks.csv, track_points.csv)
    would overwrite an input, exists without ``force``, or is a folder."""
    check_target(out, force=force, kind="file", inputs=(centrelines, posts))  # the rule of dbtools.atomic
    if beside.resolve() in (centrelines.resolve(), posts.resolve()):
        raise RefusedError(f"{beside.name} beside the output would overwrite an input", path=beside)
    if out.is_dir():
        raise RefusedError("output is a folder; give a file name such as gis.csv", path=out)


def _stale_breaks(breaks_path: Path, force: bool, findings: list[Finding]) -> Path | None:
    """A km_breaks.csv left from an earlier grid that has breaks, beside a new one without:
    removed with ``force`` (returned), else kept with a warning."""
    if not breaks_path.exists():
        return None
    if force:
        breaks_path.unlink()
        return breaks_path
    findings.append(
        Finding(
            "gisinput.stale_km_breaks",
            Severity.WARNING,
            KM_BREAKS.name,
            f"the new grid has no kilometrage breaks but {KM_BREAKS_FILE} exists beside it "
            "(kept; remove it or rerun with --force)",
            file=str(breaks_path),
        )
    )
    return None


def _write_atomically(files: dict[Path, pd.DataFrame]) -> None:
    """Write every frame to a temp file beside its target, then rename them all."""
    temps: dict[Path, Path] = {}
    try:
        for target, frame in files.items():
            # a fresh temporary sibling (the signature of dbtools.atomic), published with the umask's permissions
            temps[target] = tmp = temp_sibling(target)
            with open(tmp, "w", encoding="utf-8", newline="") as fh:
                frame.to_csv(fh, index=False, lineterminator="\n")
            publish_mode(tmp)
        for target, tmp in temps.items():
            os.replace(tmp, target)
    finally:
        for tmp in temps.values():
            tmp.unlink(missing_ok=True)
