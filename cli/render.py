"""All terminal rendering: Rich tables, JSON, progress bars. Library code returns data."""

from __future__ import annotations

import json
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn, TimeRemainingColumn
from rich.table import Table

from schemas.findings import Finding, count_by_severity
from schemas.jsonable import jsonable

#: Cap on findings printed as a table; JSON always has all of them.
MAX_TABLE_ROWS = 200


def console() -> Console:
    return Console(highlight=False, soft_wrap=False)


def err_console() -> Console:
    """stderr; messages stay on one line whatever the terminal width (greppable logs)."""
    return Console(stderr=True, highlight=False, soft_wrap=True)


def print_json(data: Any, out: Console | None = None) -> None:
    text = json.dumps(jsonable(data), ensure_ascii=False, indent=2)
    if out is None:
        sys.stdout.write(text + "\n")
    else:
        out.print(text, markup=False, highlight=False, soft_wrap=True)


def findings_table(findings: Sequence[Finding], title: str = "Findings") -> Table:
    t = Table(title=title, show_lines=False)
    for col in ("severity", "rule", "where", "value", "limit", "message"):
        t.add_column(col, overflow="fold")
    for f in findings[:MAX_TABLE_ROWS]:
        style = "red" if f.severity == "error" else "yellow"
        t.add_row(f"[{style}]{f.severity}[/]", f.rule, f.where, _cell(f.value), _cell(f.limit), f.message)
    return t


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_cell(x) for x in v)
    return str(v)


def print_findings(findings: Sequence[Finding], console: Console | None = None, title: str = "Findings") -> None:
    out = console or globals()["console"]()
    if findings:
        out.print(findings_table(findings, title))
        if len(findings) > MAX_TABLE_ROWS:
            out.print(f"… {len(findings) - MAX_TABLE_ROWS} more (use --format json for all)")
    counts = count_by_severity(findings)
    out.print(f"{counts['error']} error(s), {counts['warning']} warning(s)")


def key_value_table(rows: Iterable[tuple[str, Any]], title: str | None = None) -> Table:
    t = Table(title=title, show_header=False)
    t.add_column("key", style="bold")
    t.add_column("value", overflow="fold")
    for k, v in rows:
        t.add_row(k, _cell(v))
    return t


def frame_table(frame: Any, title: str | None = None, max_rows: int = 200) -> Table:
    """A pandas DataFrame as a Rich table."""
    t = Table(title=title)
    for c in frame.columns:
        t.add_column(str(c), overflow="fold")
    for row in frame.head(max_rows).itertuples(index=False, name=None):
        t.add_row(*[_cell(v) for v in row])
    return t


def progress(out: Console | None = None) -> Progress:
    """Progress bar for long jobs: count, rate and ETA."""
    return Progress(
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[rate]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=out or err_console(),
        transient=False,
    )


def write_out(path: Path, text: str, *, force: bool, inputs: Sequence[Path] = ()) -> None:
    """A command's text output, under the suite's one output rule (``dbtools.atomic``):
    refused when it exists without --force, never over a registry, an input or a folder."""
    from dbtools.atomic import write_text

    write_text(path, text, force=force, inputs=inputs)
