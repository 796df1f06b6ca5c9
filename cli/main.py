"""Root of the ``trainpos`` command: one sub-app per file."""

from __future__ import annotations

import typer

from cli import audit, config, db, demo, gis, gnss, logs, possession, radar, run, schema, simulate, survey, track
from cli.commands import Group, PathCommand

__all__ = ["Group", "PathCommand", "app"]

app = typer.Typer(
    name="trainpos",
    cls=Group,
    help="Onboard train-positioning databases and field-log audits.",
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    add_completion=False,
    rich_markup_mode=None,  # help texts are plain: units like [m] must not vanish as markup
)
app.add_typer(db.app, name="db", cls=Group)
app.add_typer(gis.app, name="gis", cls=Group)
app.add_typer(schema.app, name="schema", cls=Group)
app.add_typer(logs.app, name="logs", cls=Group)
app.add_typer(possession.app, name="possession", cls=Group)
app.add_typer(config.app, name="config", cls=Group)
app.add_typer(radar.app, name="radar", cls=Group)
app.add_typer(gnss.app, name="gnss", cls=Group)
app.add_typer(track.app, name="track", cls=Group)
app.command("simulate")(simulate.simulate)
app.command("run", cls=PathCommand)(run.run)
app.command("audit")(audit.audit)
app.command("report")(audit.report)
app.command("survey")(survey.survey)
app.command("demo")(demo.demo)


def _version(value: bool) -> None:
    if value:
        from dbtools.build import tool_version

        typer.echo(f"trainpos {tool_version()}")
        raise typer.Exit()


@app.callback()
def root(
    version: bool = typer.Option(False, "--version", callback=_version, is_eager=True, help="Print the version."),
) -> None:
    """Onboard train-positioning databases and field-log audits.

    Exit codes: 0 ok; 1 errors found; 2 input unreadable or bad usage; 3 refused
    (would overwrite, already released); 4 internal error.
    """
