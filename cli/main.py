"""Root of the ``trainpos`` command: one sub-app per file."""

from __future__ import annotations

from typing import Any

import typer
from typer.core import TyperGroup

from cli import audit, config, db, demo, gis, gnss, logs, possession, radar, run, schema, simulate, survey


class Group(TyperGroup):
    """typer's group, its ``--help`` flag defaulting to False instead of None.

    typer coerces a flag's missing value (None) through pydantic, which it imports for
    that: for ``trainpos COMMAND --help`` the groups above COMMAND would import pydantic
    for nothing, more than the rest of the start-up costs (issue 21: ≤ 0.3 s). False is
    what a missing flag means, so the help shown and every exit stay the same.
    """

    def get_help_option(self, ctx: Any) -> Any:
        option = super().get_help_option(ctx)
        if option is not None and option.default is None:
            option.default = False
        return option


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
app.command("simulate")(simulate.simulate)
app.command("run")(run.run)
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
