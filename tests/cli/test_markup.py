"""Text a user supplied (paths, run ids, notes) is printed as written (issue 32 item 9): never
read as Rich markup (``[/x]`` gave a traceback, ``[bold]`` vanished so the message named
the wrong file) and never reaching the terminal as a control sequence (an ESC in a run id)."""

from __future__ import annotations

import io
import json
import shutil
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given
from hypothesis import strategies as st
from rich.console import Console
from typer.testing import CliRunner

from cli.main import app
from cli.render import frame_table, key_value_table, safe, visible

SAMPLE = Path(__file__).resolve().parents[2] / "fieldlogs" / "sample_logs" / "sim-d-slips"


def _printed(markup: str) -> str:
    buf = io.StringIO()
    Console(file=buf, width=200, color_system=None, emoji=False).print(markup)  # as cli.render's consoles
    return buf.getvalue().rstrip()


@given(st.text(st.characters(blacklist_characters="\n\t"), max_size=40))
def test_safe_text_prints_as_written(text: str) -> None:
    assert _printed(f"[bold]error:[/] {safe(text)}") == f"error: {visible(text)}".rstrip()


@pytest.mark.parametrize("text", ["\\[", "a\\[b", "\\\\[", "\\[x]", "\\[[x]", "[\\[x]", "\\[\\["])
def test_a_backslash_before_a_bracket_prints_as_written(text: str) -> None:
    # Rich drops the backslash of "\[" even where the "[" starts no tag (found by the property above)
    assert _printed(f"[bold]error:[/] {safe(text)}") == f"error: {text}"


def test_control_characters_are_shown_not_sent() -> None:
    assert visible("run\x1b[2Jid\x07") == "run\\x1b[2Jid\\x07"
    assert visible("tab\tand\nnewline") == "tab\tand\nnewline"


@pytest.mark.parametrize("name", ["runs[/x]", "[bold]net.sqlite", "a[red]b[/red]c"])
def test_a_path_with_brackets_is_named_as_written(name: str, tmp_path: Path) -> None:
    missing = tmp_path / name
    r = CliRunner().invoke(app, ["db", "validate", str(missing)])
    assert r.exit_code == 2, r.output
    assert r.exception is None or isinstance(r.exception, SystemExit), repr(r.exception)
    assert str(missing) in r.output.replace("\n", "")


def test_tables_show_cells_and_titles_as_written() -> None:
    frame = pd.DataFrame({"run": ["[bold]R1[/bold]", "E\x1bX"], "note": ["[/x]", "ok"]})
    buf = io.StringIO()
    console = Console(file=buf, width=120, color_system=None)
    console.print(frame_table(frame, title="runs in [red]x[/]"))
    console.print(key_value_table([("origin", "[/x]/db.sqlite")], title="[bold]t"))
    out = buf.getvalue()
    for text in ("[bold]R1[/bold]", "E\\x1bX", "[/x]", "runs in [red]x[/]", "[/x]/db.sqlite", "[bold]t"):
        assert text in out
    assert "\x1b" not in out


def test_logs_info_shows_an_escape_in_a_run_id(tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(SAMPLE, run)
    meta = json.loads((run / "run.json").read_text())
    meta["run_id"] = "R\x1b[31mED[/x]"
    (run / "run.json").write_text(json.dumps(meta))
    r = CliRunner().invoke(app, ["logs", "info", str(run)])
    assert r.exit_code == 0, r.output
    assert "\x1b" not in r.output
    assert "R\\x1b[31mED[/x]" in r.output.replace("\n", "")
