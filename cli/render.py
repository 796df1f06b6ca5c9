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

    # ":x:" in a path stays text; soft wrap: a line longer than the terminal (a record's long
    # path) is the terminal's to wrap, never cropped; tables are drawn to the width anyway
    return Console(highlight=False, soft_wrap=True, emoji=False)


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


def findings_table(findings: Sequence[Finding], title: str = "Findings") -> Table:
    """Findings as a table (:func:`rich_table`: a record per finding where it cannot fit)."""
    from rich.text import Text

    t = rich_table(title=title)
    for col in ("severity", "rule", "where", "value", "limit", "message"):
        t.add_column(col, justify="right" if col in ("value", "limit") else "left")
    for f in findings[:MAX_TABLE_ROWS]:
        style = "red" if f.severity == "error" else "yellow"
        t.add_row(Text(str(f.severity), style=style), f.rule, f.where, _cell(f.value), _cell(f.limit), f.message)
    return t


#: C0 control characters but tab and newline, DEL and the C1 block: a run id or path carrying
#: ESC would otherwise reach the terminal as an escape sequence.
_CONTROL = re.compile("[\x00-\x08\x0b-\x1f\x7f-\x9f]")


def visible(text: object) -> str:
    """``text`` with every control character shown as ``\\xNN`` (nothing a user supplied
    reaches the terminal as a control sequence)."""
    return _CONTROL.sub(lambda m: f"\\x{ord(m.group()):02x}", str(text))


#: A "[" after a backslash that starts no Rich tag (``rich.markup.RE_TAGS``'s tag start).
_LONE_BRACKET = re.compile(r"(?<=\\)\[(?![a-z#/@][^[]*?\])")


def safe(text: object) -> str:
    """User-supplied text (a path, an id, an exception's message) for a Rich markup string:
    :func:`visible`, and ``[`` escaped so that ``[/x]`` or ``[bold]`` in a path is printed as
    written, never read as markup. Every message that mixes markup with such text uses it."""
    from rich.markup import escape

    # escape() doubles a trailing backslash (so that a tag pasted right after it stays a tag):
    # none of our messages puts a tag there, and the path must print as written
    escaped = escape(visible(text) + " ")[:-1]
    # escape() leaves a "[" that starts no tag alone, but Rich still reads "\[" before it as an
    # escaped bracket and drops the backslash: one more backslash keeps "\[" as written
    return _LONE_BRACKET.sub(r"\\[", escaped)


def _cell(v: Any, scale: float = 1.0) -> str:
    """A value as printed: floats to 4 significant digits, a share (``scale`` 100) as ``12.3 %``."""
    if v is None or (isinstance(v, float) and v != v and scale != 1.0):
        return ""
    if scale != 1.0 and isinstance(v, int | float) and not isinstance(v, bool):
        return f"{v * scale:.1f} %"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, (list, tuple)):
        return ", ".join(_cell(x) for x in v)
    return visible(v)


def print_findings(findings: Sequence[Finding], console: Console | None = None, title: str = "Findings") -> None:
    """Findings as a table when it fits the terminal, else one record per finding (no word
    or number split across lines either way)."""
    out = console or globals()["console"]()
    if findings:
        out.print(findings_table(findings, title))
        if len(findings) > MAX_TABLE_ROWS:
            out.print(f"… {len(findings) - MAX_TABLE_ROWS} more (use --format json for all)")
    counts = count_by_severity(findings)
    out.print(f"{safe(counts['error'])} error(s), {safe(counts['warning'])} warning(s)")


def _plain(renderable: Any) -> str:
    """The text of a cell or header (a ``Text``, a ``str``; anything else by ``str``)."""
    from rich.text import Text

    return renderable.plain if isinstance(renderable, Text) else str(renderable or "")


def _longest_word(text: str) -> int:
    from rich.cells import cell_len

    return max((cell_len(w) for w in text.split()), default=0)


def _longest_line(text: str) -> int:
    from rich.cells import cell_len

    return max((cell_len(line) for line in text.splitlines()), default=0)


#: A column lacking at most this many characters of its longest line is given them whole.
SHORT_LACK = 8


def fit_widths(table: Table, max_width: int) -> list[int] | None:
    """Content width of each column so that ``table`` fits ``max_width`` with its borders and
    no word or number is split: every column at least its longest word (a ``no_wrap`` column
    its longest line), the room left first to the columns that lack at most
    :data:`SHORT_LACK` characters (or an even share) of their longest line — short columns
    whole — and the rest shared in proportion to what each long column lacks (the long texts
    wrap side by side). None when even the longest words
    do not fit (print records instead).

    Rich, left to itself, narrows the widest columns first and then crops: a number split
    across lines, a border lost at 80 columns. Widths fixed here leave it nothing to squeeze."""
    texts = [[_plain(c.header), *(_plain(x) for x in c.cells)] for c in table.columns]
    natural = [max(_longest_line(t) for t in col) or 1 for col in texts]
    least = [
        max(n if c.no_wrap else max(_longest_word(t) for t in col), c.min_width or 0, 1)
        for c, col, n in zip(table.columns, texts, natural, strict=True)
    ]
    natural = [max(a, n) for a, n in zip(least, natural, strict=True)]
    frame = 3 * len(texts) + 1  # padding of one space each side, a border between and around
    room = max_width - frame
    if sum(least) > room:
        return None
    if sum(natural) <= room:
        return natural
    widths, spare = list(least), room - sum(least)
    short = max(SHORT_LACK, spare // len(widths))
    for i in sorted(range(len(widths)), key=lambda i: natural[i] - least[i]):  # the nearly whole first
        if natural[i] - least[i] <= min(short, spare):
            spare -= natural[i] - least[i]
            widths[i] = natural[i]
    lack = [natural[i] - widths[i] for i in range(len(widths))]
    total = sum(lack)
    if total:  # the rest shared in proportion to what each column lacks: no column starves
        grants = [spare * k // total for k in lack]
        for i in sorted(range(len(widths)), key=lambda i: -lack[i])[: spare - sum(grants)]:
            grants[i] += 1
        widths = [w + min(g, k) for w, g, k in zip(widths, grants, lack, strict=True)]
    return widths


def _field(label: str, value: str, indent: int, width: int) -> str:
    """``label: value`` wrapped at spaces to ``width`` under a hanging indent: no word split; a
    word too long for the indent starts its own line at the margin (longer than the
    terminal, it is the terminal's to wrap)."""
    import textwrap

    lines = textwrap.wrap(
        " ".join(value.split()),
        max(width, indent + 1),
        initial_indent=f"{label + ':':<{indent}}",
        subsequent_indent=" " * indent,
        break_long_words=False,
        break_on_hyphens=False,
    ) or [label + ":"]
    out = []
    for line in lines:
        if len(line) > width and line.startswith(" " * indent):
            line = line.lstrip(" ")
        elif len(line) > width and len(line) - indent <= width:  # the label alone, the word below
            out.append(line[:indent].rstrip())
            line = line[indent:]
        out.append(line)
    return "\n".join(out)


def records(table: Table, width: int = 80) -> list[Text]:
    """``table`` as one record per row, for a terminal ``width`` columns wide: its title, then
    per row a ``label: value`` line per non-empty cell (values aligned, wrapped at spaces),
    rows apart by a blank line. The layout of a table too wide for the terminal: every column
    kept, no cell cut, no word or number split."""
    from rich.text import Text

    title = _plain(table.title) if table.title else ""
    out = [Text(title, style="bold")] if title else []
    if not table.show_header and len(table.columns) == 2:  # a key/value table: keys are the labels
        pairs = [[(_plain(k), _plain(v)) for k, v in zip(*(c.cells for c in table.columns), strict=True)]]
    else:
        labels = [" ".join(_plain(c.header).split()) or f"column {k + 1}" for k, c in enumerate(table.columns)]
        columns = [list(c.cells) for c in table.columns]
        pairs = [
            [(lab, _plain(col[r])) for lab, col in zip(labels, columns, strict=True)] for r in range(table.row_count)
        ]
    for row in pairs:
        indent = min(max((len(lab) for lab, _ in row), default=0) + 2, width // 2)
        body = "\n".join(_field(lab, v, indent, width) for lab, v in row if v.strip())
        out.append(Text(body or "(empty row)", end="\n\n"))  # a blank line after each record
    return out


@functools.cache
def _plain_table() -> type[Table]:
    """``rich.table.Table`` whose title and ``str`` cells are plain text (:func:`visible`),
    never markup: a path, run id or note is printed as written. Styled cells are ``Text``.

    Drawn at the width it is printed at by :func:`fit_widths`, or as :func:`records` when it
    cannot fit: at 80 columns or piped, a table keeps its borders and splits no word or number."""
    from rich.table import Table
    from rich.text import Text

    class PlainTable(Table):
        def add_row(self, *renderables: Any, **kwargs: Any) -> None:
            super().add_row(*(Text(visible(c)) if isinstance(c, str) else c for c in renderables), **kwargs)

        def __rich_console__(self, console: Console, options: Any) -> Any:
            widths = fit_widths(self, options.max_width)
            if widths is None:
                for block in records(self, options.max_width):
                    yield from console.render(block, options.update(no_wrap=True, overflow="ignore"))
                return
            for column, width in zip(self.columns, widths, strict=True):
                column.width = width
            yield from super().__rich_console__(console, options)

    return PlainTable


def rich_table(title: str | None = None, **kwargs: Any) -> Table:
    """The table every command draws with (:func:`_plain_table`): title and cells plain text,
    a table where it fits, records where not."""
    from rich.text import Text

    return _plain_table()(title=Text(visible(title)) if isinstance(title, str) else title, **kwargs)


def key_value_table(rows: Iterable[tuple[str, Any]], title: str | None = None) -> Table:
    t = rich_table(title=title, show_header=False)
    t.add_column("key", style="bold")
    t.add_column("value")
    for k, v in rows:
        t.add_row(k, _cell(v))
    return t


def frame_table(frame: Any, title: str | None = None, max_rows: int = 200) -> Table:
    """A pandas DataFrame for the terminal (:func:`rich_table`): each column under its label
    (:func:`schemas.labels.display`: words and ``[unit]``), a share as ``%``, numbers right-aligned."""
    from schemas.labels import display

    shown = [display(str(c)) for c in frame.columns]
    rows = [
        [_cell(v, d.scale) for v, d in zip(row, shown, strict=True)]
        for row in frame.head(max_rows).itertuples(index=False, name=None)
    ]
    return rows_table([d.label for d in shown], rows, title)


def rows_table(names: Sequence[str], rows: Sequence[Sequence[str]], title: str | None = None) -> Table:
    """Rows of text cells (as they are to be shown) under ``names``, no pandas needed; a column
    of numbers is right-aligned."""
    from rich.text import Text

    t = rich_table(title=title)
    for k, name in enumerate(names):
        numeric = all(_NUMBER.fullmatch(r[k]) for r in rows if r[k])
        t.add_column(Text(name), justify="right" if numeric and rows else "left")  # "[s]" is a unit, not markup
    for r in rows:
        t.add_row(*(Text(c) for c in r))
    return t


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
    render(Console(file=buf, width=width, color_system=None, soft_wrap=True))
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
