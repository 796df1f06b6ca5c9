"""``trainpos schema show [NAME]``: the declarations every reader and validator uses."""

from __future__ import annotations

from enum import StrEnum
from typing import TYPE_CHECKING

import typer

from cli.errors import cli_command
from cli.render import console, print_json, rich_table
from schemas.errors import UsageError

if TYPE_CHECKING:
    from schemas.model import Table

app = typer.Typer(help="Show table, source-file and log-stream schemas.", no_args_is_help=True)


class Fmt(StrEnum):
    table = "table"
    json = "json"
    markdown = "markdown"


def schema_markdown(t: Table) -> str:
    """Markdown for one declaration (the docs' schema reference, ``schema show --format markdown``)."""
    lines = [
        f"**{t.name}** ({t.kind}) — {t.description}",
        "",
        "| column | type | unit | required | null ok | allowed |",
        "|---|---|---|---|---|---|",
    ]
    for c in t.columns:
        allowed = ", ".join(c.enum) if c.enum else _range(c.min, c.max)
        lines.append(
            f"| `{c.name}` | {c.dtype} | {c.unit} | {'yes' if c.required else 'no'} | "
            f"{'yes' if c.nullable else 'no'} | {allowed} |"
        )
    if t.primary_key:
        stored = "; an SQLite `WITHOUT ROWID` table: a finding names a row by this key" if t.without_rowid else ""
        lines += ["", f"Key: ({', '.join(t.primary_key)}){stored}"]
    return "\n".join(lines)


def _range(lo: float | None, hi: float | None) -> str:
    if lo is None and hi is None:
        return ""
    return f"[{'' if lo is None else f'{lo:g}'}, {'' if hi is None else f'{hi:g}'}]"


def schema_dict(t: Table) -> dict[str, object]:
    return {
        "name": t.name,
        "kind": t.kind,
        "description": t.description,
        "primary_key": list(t.primary_key),
        "rate_hz": t.rate_hz,
        "required": t.required,
        "columns": [
            {
                "name": c.name,
                "dtype": c.dtype,
                "unit": c.unit,
                "required": c.required,
                "nullable": c.nullable,
                "enum": list(c.enum) if c.enum else None,
                "min": c.min,
                "max": c.max,
                "description": c.description,
            }
            for c in t.columns
        ],
    }


@app.command("show")
@cli_command
def show(
    name: str | None = typer.Argument(None, help="Table, source file or log stream; all when omitted."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table, json or markdown."),
) -> None:
    """Show the columns, types, units and limits of a schema (all schemas without NAME).

    Example: trainpos schema show gis
    """
    from schemas.catalog import ALL_SCHEMAS

    if name is not None and name not in ALL_SCHEMAS:
        from schemas.frames import suggest  # pandas and pandera: only for a misspelled name

        hint = suggest(name, list(ALL_SCHEMAS))
        raise UsageError(
            f"unknown schema '{name}'"
            + (f"; did you mean '{hint}'?" if hint else "")
            + f" (known: {', '.join(ALL_SCHEMAS)})"
        )
    chosen = [ALL_SCHEMAS[name]] if name else list(ALL_SCHEMAS.values())
    if fmt == Fmt.json:
        print_json([schema_dict(t) for t in chosen] if name is None else schema_dict(chosen[0]))
        return
    if fmt == Fmt.markdown:
        typer.echo("\n\n".join(schema_markdown(t) for t in chosen))
        return
    out = console()
    for t in chosen:
        rt = rich_table(title=f"{t.name} ({t.kind})", caption=t.description, caption_justify="left")
        for h in ("column", "type", "unit", "required", "null ok", "allowed", "description"):
            rt.add_column(h, overflow="fold")
        for c in t.columns:
            allowed = ", ".join(c.enum) if c.enum else _range(c.min, c.max)
            rt.add_row(
                c.name + (" *" if c.name in t.primary_key else ""),
                c.dtype,
                c.unit,
                "yes" if c.required else "no",
                "yes" if c.nullable else "no",
                allowed,
                c.description,
            )
        out.print(rt)
