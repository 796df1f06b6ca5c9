"""Root of the ``trainpos`` command: one sub-app per file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import typer
from typer._coercion import RuntimeParam
from typer._param_types import coerce_cli_path
from typer.core import TyperCommand, TyperGroup, _TyperParameter

from cli import audit, config, db, demo, gis, gnss, logs, possession, radar, run, schema, simulate, survey, track


class Group(TyperGroup):
    """typer's group, its ``--help`` flag defaulting to False instead of None.

    typer coerces a flag's missing value (None) through pydantic, which it imports for
    that: for ``trainpos COMMAND --help`` the groups above COMMAND would import pydantic
    for nothing, more than the rest of the start-up costs (issue 21: ≤ 0.3 s). False is
    what a missing flag means, so the help shown and every exit stay the same.
    """

    def get_help_option(self, ctx: Any) -> Any:
        return _help_default_false(super().get_help_option(ctx))


def _help_default_false(option: Any) -> Any:
    if option is not None and option.default is None:
        option.default = False
    return option


@dataclass(frozen=True)
class _PlainPath(RuntimeParam):
    """typer's coercion of a plain ``Path`` parameter without pydantic: typer turns the text
    into a Path through a pydantic ``TypeAdapter(Path)`` (``Path(text)``) and then calls
    ``coerce_cli_path``; this calls it with ``Path(text)`` itself."""

    def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
        return coerce_cli_path(
            Path(value) if isinstance(value, str) else value, self.parameter_info, path_type=Path, param=param, ctx=ctx
        )


@dataclass(frozen=True)
class _PlainStr(RuntimeParam):
    """typer's coercion of a plain ``str`` parameter without pydantic (``TypeAdapter(str)`` of
    a command-line text is the text itself)."""

    def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
        return value


class PathCommand(TyperCommand):
    """typer's command, its plain ``Path`` parameters coerced without importing pydantic
    (0.1–0.2 s of a ``trainpos run``, issue 21) and its ``--help`` flag defaulting to False
    (as :class:`Group`'s). Plain: annotated ``Path`` (or ``Path |
    None``), none of typer's path checks (exists, resolve_path, allow_dash, path_type),
    which keep typer's own coercion; every other parameter too. A plain ``str`` (no parser)
    is taken as given, as pydantic would."""

    def get_help_option(self, ctx: Any) -> Any:
        return _help_default_false(super().get_help_option(ctx))

    def parse_args(self, ctx: Any, args: list[str]) -> list[str]:
        for p in self.params:
            if isinstance(p, _TyperParameter) and p._runtime_param is None and _plain_path(p):
                p._runtime_param = _PlainPath(p.type_descriptor.parameter_info, Path)
            elif isinstance(p, _TyperParameter) and p._runtime_param is None and _plain_str(p):
                p._runtime_param = _PlainStr(p.type_descriptor.parameter_info, str)
        return super().parse_args(ctx, args)


def _plain_str(p: _TyperParameter) -> bool:
    d = p.type_descriptor
    return d.annotation is str and d.parameter_info.parser is None and not (p.multiple or p.nargs != 1)


def _plain_path(p: _TyperParameter) -> bool:
    d = p.type_descriptor
    info = d.parameter_info
    checks = (info.exists, info.resolve_path, info.allow_dash, info.path_type, info.parser, d.file_annotation)
    return d.annotation is Path and not any(c for c in checks) and not (p.multiple or p.nargs != 1)


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
