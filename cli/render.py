"""All terminal rendering: Rich tables, JSON, progress bars. Library code returns data.

Rich is imported by the functions that draw (not at import: ``trainpos --help`` needs none of it).
"""

from __future__ import annotations

import functools
import json
import re
import sys
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from schemas.findings import count_by_severity
from schemas.jsonable import jsonable

if TYPE_CHECKING:
    from rich.console import Console
    from rich.progress import Progress
    from rich.table import Table
    from rich.text import Text

    from schemas.findings import Finding

#: Cap on findings printed as a table; JSON always has all of them.
MAX_TABLE_ROWS = 200


def console() -> Console:
    from rich.console import Console

    return Console(highlight=False, soft_wrap=False, emoji=False)  # ":x:" in a path stays text


def err_console() -> Console:
    """stderr; messages stay on one line whatever the terminal width (greppable logs)."""
    from rich.console import Console

    return Console(stderr=True, highlight=False, soft_wrap=True, emoji=False)


def print_json(data: Any, out: Console | None = None) -> None:
    text = json.dumps(jsonable(data), ensure_ascii=False, indent=2)
    if out is None:
        sys.stdout.write(text + "\n")
    else:
        out.print(text, markup=False, highlight=False, soft_wrap=True)


#: Widest cell kept on one line whatever the terminal: numbers and codes are never split.
MAX_UNSPLIT = 24


def _unsplit_width(cells: Iterable[str]) -> int:
    """Width that keeps every short cell (a number, a code) on one line."""
    return min(max((len(c) for c in cells), default=1), MAX_UNSPLIT)


def findings_table(findings: Sequence[Finding], title: str = "Findings") -> Table:
    """Findings as a table: severity, rule, value and limit never wrap (a number is never split
    across lines, at 80 columns or piped); the location and the message wrap at spaces."""
    from rich.text import Text

    shown = findings[:MAX_TABLE_ROWS]
    rows = [(str(f.severity), f.rule, f.where, _cell(f.value), _cell(f.limit), f.message) for f in shown]
    t = rich_table(title=title, show_lines=False)
    for k, col in enumerate(("severity", "rule", "where", "value", "limit", "message")):
        if col == "where":  # "file:row," stays whole (a table that cannot hold it is printed as blocks)
            first = [r[k].split(" ", 1)[0] for r in rows]
            t.add_column(col, overflow="fold", ratio=1, min_width=max(map(len, first), default=1))
        elif col == "message":
            t.add_column(col, overflow="fold", ratio=2)
        else:
            t.add_column(col, no_wrap=True, min_width=_unsplit_width(r[k] for r in rows))
    for f, r in zip(shown, rows, strict=True):
        style = "red" if f.severity == "error" else "yellow"
        t.add_row(Text(r[0], style=style), *r[1:])
    return t


#: C0 control characters but tab and newline, DEL and the C1 block: a run id or path carrying
#: ESC would otherwise reach the terminal as an escape sequence.
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def visible(text: object) -> str:
    """``text`` with every control character shown as ``\\xNN`` (nothing a user supplied
    reaches the terminal as a control sequence)."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", str(text))


def safe(text: object) -> str:
    """User-supplied text (a path, an id, an exception's message) for a Rich markup string:
    :func:`visible`, and ``[`` escaped so that ``[/x]`` or ``[bold]`` in a path is printed as
    written, never read as markup. Every message that mixes markup with such text uses it."""
    from rich.markup import escape

    # escape() doubles a trailing backslash (so that a tag pasted right after it stays a tag):
    # none of our messages puts a tag there, and the path must print as written
    return escape(visible(text) + " ")[:-1]


def _cell(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_cell(x) for x in v)
    return visible(v)


def print_findings(findings: Sequence[Finding], console: Console | None = None, title: str = "Findings") -> None:
    """Findings as a table when it fits the terminal, else one block per finding (a number
    is never split across lines either way)."""
    out = console or globals()["console"]()
    if findings:
        table = findings_table(findings, title)
        if _table_min_width(table) <= out.width:
            out.print(table)
        else:
            for block in findings_blocks(findings[:MAX_TABLE_ROWS], title):
                out.print(block, soft_wrap=True)  # long lines are the terminal's to wrap: no split
        if len(findings) > MAX_TABLE_ROWS:
            out.print(f"… {len(findings) - MAX_TABLE_ROWS} more (use --format json for all)")
    counts = count_by_severity(findings)
    out.print(f"{safe(counts['error'])} error(s), {safe(counts['warning'])} warning(s)")


#: Narrowest message column worth a table (below it the blocks read better).
MIN_MESSAGE_WIDTH = 20


def _table_min_width(table: Table) -> int:
    """Width the table needs so that no unsplittable cell is cut: the columns' minimum widths
    (the message at least MIN_MESSAGE_WIDTH), cell padding and the borders."""
    widths = [max(c.min_width or 1, MIN_MESSAGE_WIDTH if c.header == "message" else 1) for c in table.columns]
    return sum(widths) + 3 * len(widths) + 1


def findings_blocks(findings: Sequence[Finding], title: str = "Findings") -> list[Text]:
    """One block per finding for narrow terminals: a head line, then the message."""
    from rich.text import Text

    blocks = [Text(title, style="bold")]
    for f in findings:
        head = f"{f.severity} {f.rule} {f.where}"
        extra = ", ".join(f"{k} {_cell(v)}" for k, v in (("value", f.value), ("limit", f.limit)) if v is not None)
        blocks.append(Text(f"{head}{' — ' + extra if extra else ''}\n  {f.message}"))
    return blocks


@functools.cache
def _plain_table() -> type[Table]:
    """``rich.table.Table`` whose title and ``str`` cells are plain text (:func:`visible`),
    never markup: a path, run id or note is printed as written. Styled cells are ``Text``."""
    from rich.table import Table
    from rich.text import Text

    class PlainTable(Table):
        def add_row(self, *renderables: Any, **kwargs: Any) -> None:
            super().add_row(*(Text(visible(c)) if isinstance(c, str) else c for c in renderables), **kwargs)

    return PlainTable


def rich_table(title: str | None = None, **kwargs: Any) -> Table:
    """The table every command draws with (:func:`_plain_table`): title and cells plain text."""
    from rich.text import Text

    return _plain_table()(title=Text(visible(title)) if isinstance(title, str) else title, **kwargs)


def key_value_table(rows: Iterable[tuple[str, Any]], title: str | None = None) -> Table:
    t = rich_table(title=title, show_header=False)
    t.add_column("key", style="bold")
    t.add_column("value", overflow="fold")
    for k, v in rows:
        t.add_row(k, _cell(v))
    return t


#: Narrowest text column worth a table (below it a text column would shrink to nothing).
MIN_TEXT_WIDTH = 8


class FrameView:
    """A pandas DataFrame for the terminal: a table when it fits the console's width (no
    number split across lines, text wraps at spaces), else one block per row (``column=value``
    pairs, wrapped between pairs) so that no column is squeezed out of sight at 80
    columns. Rendered by Rich (``console.print(view)``) at the width it is printed at.
    Built by :func:`frame_table` (a DataFrame) or :func:`rows_table` (rows of text)."""

    def __init__(self, names: Sequence[str], rows: Sequence[Sequence[str]], title: str | None) -> None:
        self.title = title
        self.names = list(names)
        self.rows = [list(r) for r in rows]
        self.numeric = [all(_NUMBER.fullmatch(r[k]) for r in self.rows if r[k]) for k in range(len(self.names))]

    def table(self) -> Table:
        from rich.text import Text

        t = rich_table(title=self.title)
        for name, numeric, width in zip(self.names, self.numeric, self._widths(), strict=True):
            # rich never narrows a column below its min_width: a number column holds its widest number
            t.add_column(Text(name), overflow="fold", min_width=width, justify="right" if numeric else "left")
        for r in self.rows:
            t.add_row(*(Text(c) for c in r))  # as written: "[s]" in a header is a unit, not markup
        return t

    def blocks(self) -> list[Text]:
        from rich.text import Text

        out = [Text(self.title, style="bold")] if self.title else []
        for r in self.rows:
            pairs = [f"{n}={v}" for n, v in zip(self.names, r, strict=True) if v]
            out.append(Text("  ".join(pairs) or "(empty row)"))
        return out

    def _widths(self) -> list[int]:
        """Narrowest width of each column: a number column its widest cell (numbers are never
        split; its header wraps at spaces), a text column MIN_TEXT_WIDTH or its longest cell."""
        widths = []
        for k, name in enumerate(self.names):
            cells = [r[k] for r in self.rows]
            if self.numeric[k]:
                widths.append(max(_unsplit_width(cells), *(len(w) for w in name.split()), 1))
            else:
                widths.append(min(max((len(c) for c in [name, *cells]), default=1), MIN_TEXT_WIDTH))
        return widths

    def __rich_console__(self, console: Console, options: Any) -> Iterable[Table | Text]:
        table = self.table()
        if _table_min_width(table) <= options.max_width:
            yield table
        else:
            yield from self.blocks()


def frame_table(frame: Any, title: str | None = None, max_rows: int = 200) -> FrameView:
    """A pandas DataFrame as a Rich renderable (:class:`FrameView`): a table, or one block
    per row when the table cannot fit the terminal."""
    rows = [[_cell(v) for v in row] for row in frame.head(max_rows).itertuples(index=False, name=None)]
    return FrameView([str(c) for c in frame.columns], rows, title)


def rows_table(names: Sequence[str], rows: Sequence[Sequence[str]], title: str | None = None) -> FrameView:
    """Rows of text cells (as they are to be shown) as a :class:`FrameView`, no pandas needed."""
    return FrameView(names, rows, title)


_NUMBER = re.compile(r"[-+]?(\d[\d,]*(\.\d*)?|\.\d+)([eE][-+]?\d+)?( ?%| ?[a-zA-Z/²]{1,5})?|—|nan|inf|-inf")


def progress(out: Console | None = None) -> Progress:
    """Progress bar for long jobs: count, rate and ETA."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

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


def emit_text(out: Path | None, text: str, *, force: bool, inputs: Sequence[Path] = ()) -> None:
    """A command's text result (JSON, CSV, a rendered table) to ``--out`` under the output
    rule (:func:`write_out`), or to stdout when no file is given."""
    if out is None:
        sys.stdout.write(text)
    else:
        write_out(out, text, force=force, inputs=inputs)


def emit_rendered(
    out: Path | None,
    render: Callable[[Console], None],
    *,
    force: bool,
    inputs: Sequence[Path] = (),
    width: int = 200,
) -> None:
    """Rich tables: drawn on the terminal, or into ``--out`` as plain text ``width``
    columns wide (no colour codes), under the output rule."""
    if out is None:
        render(console())
        return
    import io

    from rich.console import Console

    buf = io.StringIO()
    render(Console(file=buf, width=width, color_system=None))
    write_out(out, buf.getvalue(), force=force, inputs=inputs)


def inputs_of(*items: Path | Sequence[Path] | None) -> list[Path]:
    """A command's input paths (files, folders, lists of them; None left out), for the
    output rule: no output may replace one of them."""
    out: list[Path] = []
    for item in items:
        if item is None:
            continue
        out.extend([Path(item)] if isinstance(item, str | Path) else [Path(p) for p in item])
    return out


def check_outputs(
    *, files: Sequence[Path | None] = (), folders: Sequence[Path | None] = (), force: bool, inputs: Sequence[Path]
) -> None:
    """The output rule for a command's outputs, checked before its work (the writes check
    it again): exit 3 rather than an hour of replay and then a refusal. An existing empty
    folder may be replaced."""
    from dbtools.atomic import check_target

    for f in files:
        if f is not None:
            check_target(f, force=force, kind="file", inputs=inputs)
    for d in folders:
        if d is not None:
            empty = d.is_dir() and not any(d.iterdir())
            check_target(d, force=force or empty, kind="folder", inputs=inputs)
