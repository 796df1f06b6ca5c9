"""``trainpos config show``: every setting with its default, unit, range and meaning."""

from __future__ import annotations

import sys
from enum import StrEnum
from pathlib import Path

import typer

from cli.errors import cli_command
from cli.render import print_json

app = typer.Typer(help="Show the configuration tree (every setting, its unit and meaning).", no_args_is_help=True)


class Fmt(StrEnum):
    toml = "toml"
    json = "json"


@app.command("show")
@cli_command
def show(
    section: str | None = typer.Option(None, "--section", help="Only this section (e.g. odometry, gps)."),
    fmt: Fmt = typer.Option(Fmt.toml, "--format", help="toml (commented, usable as --config) or json."),
    config: Path | None = typer.Option(None, "--config", help="Show the values of this config file instead."),
) -> None:
    """Print every setting as commented TOML (default, unit, range, meaning).

    The output is a valid --config file: fed back unchanged it changes nothing; edit the
    values you need and delete the rest.

    Example: trainpos config show --section odometry > my.toml
    """
    from fieldlogs.config import load_tree, show_dict, show_toml

    tree = load_tree(config)
    if fmt == Fmt.json:
        print_json(show_dict(tree, section))
    else:
        sys.stdout.write(show_toml(tree, section))
