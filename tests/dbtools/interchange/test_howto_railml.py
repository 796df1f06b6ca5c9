"""docs/howto/import-railml.md runs as written: its ``sh`` blocks, top to bottom, in one
scratch folder with a copy of the data it names, each command exiting as the page says
(``# exit N``) — README's walk-through convention (:mod:`tests.test_walkthrough`)."""

from __future__ import annotations

import subprocess
from pathlib import Path

from tests.test_walkthrough import ROOT, _env, _tail, scratch, walkthrough

HOWTO = ROOT / "docs" / "howto" / "import-railml.md"


def test_howto_commands_run_as_documented(tmp_path: Path) -> None:
    steps = walkthrough(HOWTO.read_text(encoding="utf-8"))
    cmds = [c for _, _, cs in steps for c in cs]
    assert len(cmds) >= 10 and all(k == 0 for k, _, _ in steps)
    folder = scratch(tmp_path / "howto", cmds)
    env = _env()
    for cmd in cmds:
        res = subprocess.run(
            ["bash", "-c", cmd.text], cwd=folder, env=env, capture_output=True, text=True, timeout=600, check=False
        )
        assert res.returncode == cmd.expected_exit, (
            f"{HOWTO.name} line {cmd.line}: $ {cmd.text}\nexit {res.returncode}, the page says {cmd.expected_exit}\n"
            f"{_tail(res.stdout)}\n{_tail(res.stderr)}"
        )
    assert "no content differences" in res.stdout  # the last command: the round trip's diff
