"""``trainpos db info`` and ``db show``: what an onboard DB file is, and the rows of one of
its tables (registered on the ``db`` group by :mod:`cli.db`). Both only read: the DB is
opened read-only and is never modified (``dbtools.browse``).

JSON shapes (``--format json``), stable:

* ``db info``: ``{"file", "size_bytes", "application_id", "schema_version",
  "schema_supported", "db_version", "content_hash": {"stored", "actual", "verified",
  "status"}, "source_sha256": {file: sha256}, "georef": {"area", "area_source",
  "metric_crs", "metric_crs_source", "height_datum", "geoid_model"} (the keys meta has),
  "tables": {name: rows}, "meta": {key: value}}``
* ``db show``: ``{"table", "where", "matched", "limit", "columns": [name], "rows":
  [{column: value}]}``
"""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from cli.errors import cli_command
from cli.render import console, err_console, key_value_table, print_json, rich_table, rows_table

if TYPE_CHECKING:
    from rich.console import Console

    from dbtools.browse import TableRows, Value
    from dbtools.db_info import DbInfo


class InfoFmt(StrEnum):
    table = "table"
    json = "json"


class ShowFmt(StrEnum):
    table = "table"
    csv = "csv"
    json = "json"


@cli_command
def info(
    db: Path = typer.Argument(..., help="Onboard DB file (.sqlite); opened read-only."),
    fmt: InfoFmt = typer.Option(InfoFmt.table, "--format", help="table or json."),
    quick: bool = typer.Option(
        False,
        "--quick",
        help="Skip the content check (it reads every row: about 1 s per million GIS points); "
        "only meta, PRAGMAs and COUNT(*) are read.",
    ),
) -> None:
    """Describe an onboard DB file: version, meta, content hash and whether the content still matches it.

    Also the source files' SHA-256, the rows of every table the file has (a newer schema's
    too), the operating area, metric CRS and heights, the file size, schema version and
    application id. Exit 0 (a report: a DB whose content no longer matches its hash is
    shown MODIFIED; `db validate` is the gate), 2 if the file is not an onboard DB or
    cannot be read.

    Example: trainpos db info net.sqlite --format json
    """
    from dbtools.db_info import db_info

    result = db_info(db, verify=not quick)
    if fmt == InfoFmt.json:
        print_json(result.to_dict())
        return
    _print_info(result, console(), quick)


def _escaped(v: object) -> str:
    """A value as text Rich shows as written (a note such as "[fix]" is not markup)."""
    from rich.markup import escape

    return escape("" if v is None else str(v))


def _content_cell(d: DbInfo, quick: bool) -> str:
    c = d.content
    if c.verified is None:
        return _escaped(c.status + (" (--quick)" if quick else ""))
    if c.verified:
        return "[green]matches[/]"
    return f"[red]{'MODIFIED' if c.stored else 'cannot be verified'}[/]: {_escaped(c.status)}"


def _area_text(area: object) -> str:
    """The operating area in one line: a box, or a polygon's vertex count and bounds (as
    stored when it is neither: ``db info`` describes a DB, ``db validate`` judges it)."""
    try:
        if isinstance(area, dict) and isinstance(area.get("polygon"), list) and area["polygon"]:
            ring = area["polygon"]
            lon, lat = [float(v[0]) for v in ring], [float(v[1]) for v in ring]
            return f"polygon of {len(ring)} vertices, lat {min(lat):g}…{max(lat):g}°, lon {min(lon):g}…{max(lon):g}°"
        if isinstance(area, dict):
            lat0, lat1, lon0, lon1 = (float(area[k]) for k in ("lat_min", "lat_max", "lon_min", "lon_max"))
            return f"lat {lat0:g}…{lat1:g}°, lon {lon0:g}…{lon1:g}°"
    except (KeyError, TypeError, ValueError, IndexError):
        pass
    return str(area)


def _georef_rows(d: DbInfo) -> list[tuple[str, str]]:
    g = d.georef

    def with_source(key: str) -> str:
        src = g.get(f"{key}_source")
        return f" ({src})" if src else ""

    rows = []
    if "area" in g:
        rows.append(("operating area", _escaped(_area_text(g["area"]) + with_source("area"))))
    if "metric_crs" in g:
        rows.append(("metric CRS", _escaped(f"{g['metric_crs']}{with_source('metric_crs')}")))
    if "height_datum" in g:
        geoid = f" ({g['geoid_model']})" if g.get("geoid_model") else ""
        rows.append(("heights", _escaped(f"{g['height_datum']}{geoid}")))
    return rows


def _print_info(d: DbInfo, out: Console, quick: bool) -> None:
    from schemas.tables import SCHEMA_VERSION, SOURCE_HASH_PREFIX

    newer = "" if d.schema_version == SCHEMA_VERSION else f" (this tool reads {SCHEMA_VERSION})"
    head: list[tuple[str, object]] = [
        ("file", _escaped(d.path)),
        ("size", f"{d.size_bytes:,} bytes ({d.size_bytes / 2**20:.1f} MiB)"),
        ("application_id", f"{d.application_id:#010x} (TPOS)"),
        ("schema_version", f"{d.schema_version}{newer}"),
        ("db_version", _escaped(d.meta.get("db_version", "—"))),
        ("content_hash", _escaped(d.content.stored or "— (none in meta)")),
        ("content check", _content_cell(d, quick)),
        *_georef_rows(d),
    ]
    out.print(key_value_table(head, title="db info"))
    counts = rich_table(title="Rows")
    counts.add_column("table", overflow="fold")
    counts.add_column("rows", justify="right", no_wrap=True)
    for name, n in d.tables.items():
        counts.add_row(_escaped(name), f"{n:,}")
    out.print(counts)
    sources = d.source_sha256
    if sources:
        out.print(
            key_value_table([(_escaped(k), _escaped(v)) for k, v in sources.items()], title="Source files (SHA-256)")
        )
    meta = [(_escaped(k), _escaped(v)) for k, v in d.meta.items() if not k.startswith(SOURCE_HASH_PREFIX)]
    out.print(key_value_table(meta, title=f"meta ({SOURCE_HASH_PREFIX}* above)" if sources else "meta"))


@cli_command
def show(
    db: Path = typer.Argument(..., help="Onboard DB file (.sqlite); opened read-only."),
    table: str = typer.Argument(..., help="Table name, e.g. gis, balises, feature_points, lines, km_breaks, meta."),
    where: str | None = typer.Option(
        None, "--where", help="SQL expression the rows must match, e.g. \"line_code = '0420' AND km_m < 1000\"."
    ),
    limit: int = typer.Option(20, "--limit", min=0, help="Show at most this many rows (0: only count them)."),
    fmt: ShowFmt = typer.Option(ShowFmt.table, "--format", help="table, csv or json."),
) -> None:
    """Show the rows of one table of an onboard DB, in stored order, with how many match in all.

    --where is one SQL expression, run read-only: anything but a read (a second statement,
    PRAGMA, ATTACH, a write …) is refused. The table's rows are counted (COUNT(*)) and at
    most --limit are read. With --format csv the count goes to stderr. Exit 0; 2 if the DB
    cannot be read, the table does not exist (the message lists the tables) or the
    expression is refused or invalid (the message lists the columns).

    Example: trainpos db show net.sqlite balises --where "kind = 'C'" --limit 5
    """
    from dbtools.browse import select_rows

    rows = select_rows(db, table, where, limit)
    if fmt == ShowFmt.json:
        print_json(rows.to_dict())
    elif fmt == ShowFmt.csv:
        _write_csv(rows)
        err_console().print(_count_line(rows), markup=False)
    else:
        out = console()
        if rows.rows:
            out.print(rows_table(rows.columns, [[_text(v) for v in r] for r in rows.rows], title=rows.table))
        out.print(_count_line(rows), markup=False)


def _text(v: Value) -> str:
    """A cell as shown: NULL empty, a float in full (the shortest text that reads back the same)."""
    if v is None:
        return ""
    return repr(v) if isinstance(v, float) else str(v)


def _count_line(rows: TableRows) -> str:
    """How many rows match in all, and how many of them are shown."""
    what = f"row(s) in {rows.table}" + ("" if rows.where is None else f" where {rows.where}")
    if len(rows.rows) < rows.matched:
        return f"{len(rows.rows):,} of {rows.matched:,} {what} shown (--limit N shows more)"
    return f"{rows.matched:,} {what}"


def _write_csv(rows: TableRows) -> None:
    import csv
    import sys

    w = csv.writer(sys.stdout, lineterminator="\n")
    w.writerow(rows.columns)
    w.writerows([_text(v) for v in r] for r in rows.rows)
