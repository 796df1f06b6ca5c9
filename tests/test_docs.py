"""README stays true to the CLI: every command is documented, every documented command and
option exists, and every command has help text."""

from __future__ import annotations

import re
import shlex
from pathlib import Path
from typing import Any

import pytest
import typer
from typer.testing import CliRunner

from cli.main import app

README = (Path(__file__).resolve().parent.parent / "README.md").read_text(encoding="utf-8")
ROOT = typer.main.get_command(app)


def _is_group(cmd: object) -> bool:
    return hasattr(cmd, "commands")  # typer's click groups (typer may vendor its own click)


def _commands(group: Any, prefix: tuple[str, ...] = ()) -> list[tuple[tuple[str, ...], Any]]:
    out = []
    if _is_group(group):
        for name, cmd in group.commands.items():
            out += _commands(cmd, (*prefix, name))
    else:
        out.append((prefix, group))
    return out


COMMANDS = dict(_commands(ROOT))


@pytest.mark.parametrize("path", sorted(COMMANDS), ids=" ".join)
def test_every_command_has_help_and_is_in_readme(path: tuple[str, ...]) -> None:
    cmd = COMMANDS[path]
    assert (cmd.help or "").strip(), f"`trainpos {' '.join(path)}` has no help text"
    assert f"trainpos {' '.join(path)}" in README, f"README does not document `trainpos {' '.join(path)}`"


def _readme_invocations() -> list[list[str]]:
    """Every `trainpos …` line of README's code blocks (continuations joined)."""
    calls = []
    for block in re.findall(r"```sh\n(.*?)```", README, flags=re.S):
        text = block.replace("\\\n", " ")
        for line in text.splitlines():
            line = line.split("#")[0].strip()
            if line.startswith("trainpos "):
                calls.append(shlex.split(line)[1:])
    return calls


def test_readme_examples_name_real_commands_and_options() -> None:
    calls = _readme_invocations()
    assert len(calls) >= 15
    for argv in calls:
        group: Any = ROOT
        path: list[str] = []
        while _is_group(group) and argv and argv[0] in group.commands:
            path.append(argv[0])
            group = group.commands[argv.pop(0)]
        assert not _is_group(group), f"README: `trainpos {' '.join(path)}` is not a command"
        known = {o for p in group.params for o in (*p.opts, *p.secondary_opts)}
        for token in argv:
            if token.startswith("-"):
                assert token.split("=")[0] in known, f"README: `trainpos {' '.join(path)}` has no option {token}"


def test_help_runs_for_every_command_and_keeps_units() -> None:
    runner = CliRunner()
    for path, cmd in COMMANDS.items():
        result = runner.invoke(app, [*path, "--help"], env={"COLUMNS": "400"})
        assert result.exit_code == 0, (path, result.output)
        flat = " ".join(result.output.split())
        for p in cmd.params:
            for unit in re.findall(r"\[[^\]]+\]", getattr(p, "help", None) or ""):
                assert unit in flat, f"`trainpos {' '.join(path)} --help` lost {unit} (rich markup?)"


def test_exit_codes_documented() -> None:
    for code in ("| 0 |", "| 1 |", "| 2 |", "| 3 |", "| 4 |"):
        assert code in README


def test_readme_schema_tables_match_the_declarations() -> None:
    from cli.schema_docs import with_schemas

    assert with_schemas(README) == README, "README schema section is stale: run python -m cli.schema_docs"
