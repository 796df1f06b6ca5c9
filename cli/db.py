"""``trainpos db …``: build, validate, diff and release onboard DB versions."""

from __future__ import annotations

from enum import StrEnum
from pathlib import Path

import typer

from cli.errors import cli_command
from cli.render import console, key_value_table, print_findings, print_json
from dbtools.build import build_db
from schemas.findings import findings_report, has_errors

app = typer.Typer(help="Build, validate, diff and release onboard DB versions.", no_args_is_help=True)


class Fmt(StrEnum):
    table = "table"
    json = "json"


@app.command("build")
@cli_command
def build(
    source_dir: Path = typer.Argument(..., help="Source set folder: gis, balises, feature_points (.csv/.xlsx)."),
    out: Path = typer.Option(..., "--out", "-o", help="Output onboard DB file (.sqlite)."),
    version: str | None = typer.Option(None, "--version", help="DB version (default: UTC date-time)."),
    note: str = typer.Option("", "--note", help="Release note: who and why."),
    force: bool = typer.Option(False, "--force", help="Replace an existing output file."),
) -> None:
    """Build an onboard DB version from a source set.

    Example: trainpos db build network/ --out net-2026.11.sqlite --version 2026.11 --note "new curve table"
    """
    result = build_db(source_dir, out, db_version=version, note=note, force=force)
    out_c = console()
    if result.warnings:
        print_findings(result.warnings, console=out_c, title="Source warnings")
    rows = [(f"rows: {k}", v) for k, v in result.rows.items()]
    out_c.print(
        key_value_table(
            [
                ("file", str(result.path)),
                ("db_version", result.db_version),
                ("content_hash", result.content_hash),
                *rows,
            ],
            title="Built",
        )
    )


@app.command("validate")
@cli_command
def validate(
    target: Path = typer.Argument(..., help="Onboard DB file (.sqlite) or source set folder."),
    fmt: Fmt = typer.Option(Fmt.table, "--format", help="table or json."),
    strict: bool = typer.Option(False, "--strict", help="Warnings also fail (exit 1)."),
) -> None:
    """Check every consistency rule; exit 0 clean, 1 errors (or warnings with --strict), 2 unreadable.

    Example: trainpos db validate net-2026.11.sqlite --format json
    """
    from dbtools.validate import validate_path

    findings = validate_path(target)
    if fmt == Fmt.json:
        report = findings_report(findings)
        report["ok"] = not has_errors(findings, strict)
        print_json(report)
    else:
        print_findings(findings, console=console(), title=f"Validation of {target}")
    if has_errors(findings, strict):
        raise typer.Exit(1)
